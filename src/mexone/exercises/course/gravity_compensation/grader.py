"""Exercise 5, gravity compensation: hold a raised arm with a weak PD (kp 5 N m/rad) plus the
arm's own gravity torque g(q). Hidden variant: the arm's pose and a payload in the hand (the
forearm 0.7x to 1.6x as heavy) -- a controller that reads g(q) from the model holds any of them,
one with torques written down for the given arm does not."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mexone.exercises.course._labtools import (
    ARM,
    HAND,
    JointLog,
    check,
    controller_fault,
    controller_lab,
    scale_mass,
    student_yaml,
)

NAME = "gravity_compensation"
FILE, CLASS = "gravity_compensation.py", "GravityCompensation"
GIVEN = {"pose": {"l_shoulder_pitch": -1.2, "l_elbow": -0.6}, "payload": 1.0}
KP, KD = 5.0, 0.5
SECONDS = 1.0
HOLD, SAG = 2e-3, 20e-3  # rad: full marks within HOLD, none beyond SAG


def variant(r: np.random.Generator | None) -> dict:
    """The given arm (r None: the self-check) or the hidden one drawn from the secret seed."""
    if r is None:
        return GIVEN  # always away from the given arm: lighter or heavier, another pose
    side = r.choice([-1.0, 1.0], size=2)
    return {"pose": {"l_shoulder_pitch": -1.2 + side[0] * float(r.uniform(0.2, 0.35)),
                     "l_elbow": -0.6 + side[1] * float(r.uniform(0.2, 0.3))},
            "payload": float(r.uniform(0.6, 0.8) if r.random() < 0.5 else r.uniform(1.3, 1.6))}


def measure(submission: Path, var: dict) -> tuple[float, str | None]:
    """The arm's largest joint error (rad) over SECONDS, and the controller's fault if any."""
    with tempfile.TemporaryDirectory() as tmp:
        path = student_yaml(Path(tmp), submission, FILE, CLASS, NAME, ARM, {"kp": KP, "kd": KD})
        lab = controller_lab(path, var["pose"], [scale_mass(HAND, var["payload"])])
        start = lab.sim.data.qpos[[int(lab.sim.model.joint(j).qposadr[0]) for j in ARM]].copy()
        log = JointLog(lab, ARM)
        lab.sim.run(SECONDS)
        return float(np.abs(np.array(log.q) - start).max()), controller_fault(lab, NAME)


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    sag, fault = ctx.measure(measure, ctx.submission, var)
    runs = check("runs", 1.0, 0.0 if fault else 1.0, fault or f"ran {SECONDS} s without a fault")
    frac = 0.0 if fault else float(np.clip((SAG - sag) / (SAG - HOLD), 0.0, 1.0))
    hold = check("holds the arm", 4.0, frac,
                 f"largest joint error {sag * 1e3:.2f} mrad (full marks <= {HOLD * 1e3:g}, none "
                 f">= {SAG * 1e3:g}) at kp {KP:g}, payload x{var['payload']:.2f}")
    return [runs, hold]
