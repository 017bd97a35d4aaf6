"""Exercise 6, computed torque: track q0 + A sin(2 pi f t) on the left shoulder pitch and elbow,
at least 5x closer than the shipped position PIDs. Hidden variant: A, f and a payload in the
hand (the forearm lighter or heavier) -- feedback linearisation with the live model's M and h
tracks any of them."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from mexone.exercises.course._labtools import (
    HAND,
    JointLog,
    check,
    controller_fault,
    controller_lab,
    scale_mass,
    student_yaml,
)
from mexone.lab import Lab
from mexone.physics.compile import Spawn

NAME = "computed_torque"
FILE, CLASS = "computed_torque.py", "ComputedTorque"
JOINTS = ("l_shoulder_pitch", "l_elbow")
POSE = {"l_shoulder_pitch": -0.6, "l_elbow": -1.2}  # the sine's centre, q0
GIVEN = {"amplitude": 0.5, "frequency": 0.5, "payload": 1.0}
SECONDS = 2.0
GOOD, BAD = 3e-3, 15e-3  # rad RMS: full marks within GOOD, none beyond BAD
RATIO = 5.0  # times closer than the shipped PIDs


def variant(r: np.random.Generator | None) -> dict:
    if r is None:
        return GIVEN
    return {"amplitude": float(r.uniform(0.3, 0.5)), "frequency": float(r.uniform(0.4, 0.7)),
            "payload": float(r.uniform(0.6, 0.8) if r.random() < 0.5 else r.uniform(1.3, 1.6))}


def reference(t: np.ndarray, amplitude: float, frequency: float) -> np.ndarray:
    """q_ref(t) for both joints, (len(t), 2)."""
    q0 = np.array([POSE[j] for j in JOINTS])
    return q0 + amplitude * np.sin(2 * math.pi * frequency * np.asarray(t))[:, None]


def rms(log: JointLog, var: dict) -> float:
    errors = np.array(log.q) - reference(np.array(log.times), var["amplitude"], var["frequency"])
    return float(np.sqrt(np.mean(errors**2)))


def student_rms(submission: Path, var: dict) -> tuple[float, str | None]:
    params = {"amplitude": var["amplitude"], "frequency": var["frequency"]}
    with tempfile.TemporaryDirectory() as tmp:
        path = student_yaml(Path(tmp), submission, FILE, CLASS, NAME, JOINTS, params)
        lab = controller_lab(path, POSE, [scale_mass(HAND, var["payload"])])
        log = JointLog(lab, JOINTS)
        lab.sim.run(SECONDS)
        return rms(log, var), controller_fault(lab, NAME)


def shipped_rms(var: dict) -> float:
    """The shipped position PIDs fed the sine as a setpoint every step, as a node would."""
    lab = Lab.create(spawn=Spawn(joints=tuple(POSE.items())), edits=(scale_mass(HAND, var["payload"]),))
    pids = [f"{j}_position_controller" for j in JOINTS]

    def command(sim) -> None:
        q = reference(np.array([sim.time]), var["amplitude"], var["frequency"])[0]
        for name, value in zip(pids, q, strict=True):
            lab.manager.command(name, [float(value)])

    log = JointLog(lab, JOINTS)
    lab.sim.add_periodic(lab.sim.timestep, command)
    lab.sim.run(SECONDS)
    return rms(log, var)


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    error, fault = ctx.measure(student_rms, ctx.submission, var)
    shipped = ctx.measure(shipped_rms, var)
    runs = check("runs", 1.0, 0.0 if fault else 1.0, fault or f"ran {SECONDS} s without a fault")
    frac = 0.0 if fault else float(np.clip((BAD - error) / (BAD - GOOD), 0.0, 1.0))
    what = (f"A {var['amplitude']:.2f} rad, f {var['frequency']:.2f} Hz, payload "
            f"x{var['payload']:.2f}")
    track = check("tracks the sine", 3.0, frac, f"RMS error {error * 1e3:.2f} mrad (full marks "
                  f"<= {GOOD * 1e3:g}, none >= {BAD * 1e3:g}), {what}")
    ratio = shipped / error if error > 0 else math.inf
    beats = check("beats the shipped PIDs", 1.0, 0.0 if fault else min(1.0, ratio / RATIO),
                  f"{ratio:.1f}x closer than the shipped PIDs ({shipped * 1e3:.2f} mrad RMS), "
                  f"{RATIO:g}x asked")
    return [runs, track, beats]
