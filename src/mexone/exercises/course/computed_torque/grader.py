"""Exercise 6, computed torque: track q0 + A sin(2 pi f t) on the left shoulder pitch and elbow,
at least 5x closer than the shipped position PIDs. Hidden variant: A, f and a payload in the
hand (the forearm lighter or heavier) -- feedback linearisation with the live model's M and h
tracks any of them.

The method is checked too: after the sine, each joint is pushed in turns (+PROBE, -PROBE N m)
while the sine goes on, and the acceleration the controller asked for -- M^-1 (tau - ID(0)), its
torque less the grader's inverse dynamics at zero acceleration (h, less the joints' damping), on
the grader's view of the varied model -- less the sine's own acceleration is fitted against the
error and its rate: its kp and kd must be the grader's (within 25 %). A stiff PD plus g(q) (kp
1e6, kd 2000: the starter's two numbers changed) tracked within 1.7 mrad and scored 10/10; it
fits a stiffness thousands of times KP, and earns no tracking."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from mexone.dynamics import Dynamics
from mexone.exercises.course._labtools import (
    HAND,
    JointLog,
    check,
    controller_fault,
    controller_lab,
    fit_gains,
    gains_check,
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
KP, KD = 2500.0, 100.0  # 1/s^2, 1/s: the error's gains the grader sets (the starter's)
PROBE, PROBE_S = 0.3, 0.2  # N m on each joint in turns, + then -, for PROBE_S s each
METHOD = "applies computed torque"  # the check the tracking presumes: the stated law's gains


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


def student_rms(submission: Path, var: dict) -> tuple[float, tuple[tuple[float, float], ...],
                                                     str | None]:
    """The RMS tracking error over SECONDS; then, under the probe torques, each joint's (kp, kd)
    of the acceleration the controller asks for (module docstring); the controller's fault."""
    params = {"amplitude": var["amplitude"], "frequency": var["frequency"], "kp": KP, "kd": KD}
    with tempfile.TemporaryDirectory() as tmp:
        path = student_yaml(Path(tmp), submission, FILE, CLASS, NAME, JOINTS, params)
        lab = controller_lab(path, POSE, [scale_mass(HAND, var["payload"])])
    log = JointLog(lab, JOINTS)
    sim = lab.sim
    sim.run(SECONDS)
    error = rms(log, var)
    sim.remove_periodic(log.timer)
    dofs = [int(sim.model.joint(j).dofadr[0]) for j in JOINTS]
    dynamics = Dynamics.live(sim)  # the grader's own view of the (varied) model
    rows: list[np.ndarray] = []

    def sample(s) -> None:  # per joint: asked acceleration less the sine's, e, de
        dynamics.refresh()
        m = dynamics.mass_matrix()[np.ix_(dofs, dofs)]
        free = dynamics.inverse_dynamics(np.zeros(sim.model.nv), contacts=True)[dofs]
        asked = np.linalg.solve(m, s.data.qfrc_actuator[dofs] - free)
        w = 2.0 * math.pi * var["frequency"]
        phase = w * s.time
        q_ref = reference(np.array([s.time]), var["amplitude"], var["frequency"])[0]
        dq_ref = var["amplitude"] * w * math.cos(phase)
        ddq_ref = -var["amplitude"] * w * w * math.sin(phase)
        rows.append(np.stack([asked - ddq_ref, q_ref - log.positions(s),
                              dq_ref - s.data.qvel[dofs]]))

    timer = sim.add_periodic(sim.timestep, sample)
    for joint in JOINTS:
        for sign in (1.0, -1.0):
            sim.apply_joint_effort(joint, sign * PROBE, duration=PROBE_S)
            sim.run(PROBE_S)
    sim.remove_periodic(timer)
    asked, e, de = np.moveaxis(np.array(rows), 1, 0)
    # asked = kp e + kd de: fit_gains fits force = k (rest - x) - d v, so x = -e, v = -de
    gains = tuple(fit_gains(asked[:, i], -e[:, i], -de[:, i])[:2] for i in range(len(JOINTS)))
    return error, gains, controller_fault(lab, NAME)


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
    error, gains, fault = ctx.measure(student_rms, ctx.submission, var)
    shipped = ctx.measure(shipped_rms, var)
    runs = check("runs", 1.0, 0.0 if fault else 1.0, fault or f"ran {SECONDS} s without a fault")
    method = gains_check(METHOD, gains, KP, KD, fault, ("1/s^2", "1/s"),
                         "shoulder pitch, elbow: the acceleration your torque asks for, M^-1 "
                         f"(tau - h), less the sine's, fitted against e and de under +-{PROBE:g} "
                         "N m pushes", digits=4)
    frac = 0.0 if fault else float(np.clip((BAD - error) / (BAD - GOOD), 0.0, 1.0))
    what = (f"A {var['amplitude']:.2f} rad, f {var['frequency']:.2f} Hz, payload "
            f"x{var['payload']:.2f}")
    track = check("tracks the sine", 3.0, frac, f"RMS error {error * 1e3:.2f} mrad (full marks "
                  f"<= {GOOD * 1e3:g}, none >= {BAD * 1e3:g}), {what}", requires=METHOD)
    ratio = shipped / error if error > 0 else math.inf
    beats = check("beats the shipped PIDs", 1.0, 0.0 if fault else min(1.0, ratio / RATIO),
                  f"{ratio:.1f}x closer than the shipped PIDs ({shipped * 1e3:.2f} mrad RMS), "
                  f"{RATIO:g}x asked", requires=METHOD)
    return [runs, method, track, beats]
