"""Exercise 8, balance under pushes: an ankle controller that keeps the standing robot up under
the largest push forward at the torso. Hidden variant: the torso lighter or heavier than the
robot given (0.75-0.85x or 1.2-1.35x): a controller built on the live model's mass and centre of
mass balances either; gains tuned by hand on the given robot may not. The shipped PD alone
survives 3.5 N s (benchmarks/RESULTS.md) and, on a heavy torso, 4.5 N s but never 5.0 (4.5 was
the pass line once: the starter scored 6.7/10 on half the variants). The pushes scale with the
variant's total mass (the same change of speed on any variant)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import mujoco
import numpy as np

from mexone.exercises.course._labtools import (
    check,
    controller_fault,
    controller_lab,
    scale_mass,
    student_yaml,
)
from mexone.lab import Lab
from mexone.motion.recovery import PushTrial, survives

NAME = "balance"
FILE, CLASS = "balance.py", "Balance"
JOINTS = ("l_ankle_pitch", "r_ankle_pitch")
GIVEN = {"torso": 1.0}
PASS = 5.0  # N s: survived, or the check fails (the PD alone: 3.5 given, 4.5 on a heavy torso)
SCAN = (5.5,)  # N s: then these, in order, until a fall; full marks at the last
TRIAL = PushTrial(direction=(1.0, 0.0, 0.0), settle=0.5, after=2.0)


def variant(r: np.random.Generator | None) -> dict:
    if r is None:
        return GIVEN
    return {"torso": float(r.uniform(0.75, 0.85) if r.random() < 0.5 else r.uniform(1.2, 1.35))}


def mass_ratio(var: dict) -> float:
    """The variant's total mass over the given robot's."""
    variant_lab = Lab.create(controllers=False, edits=(scale_mass("torso", var["torso"]),))
    given = Lab.create(controllers=False)
    return mujoco.mj_getTotalmass(variant_lab.sim.model) / mujoco.mj_getTotalmass(given.sim.model)


def trials(submission: Path, var: dict, scale: float) -> tuple[bool, float, str | None]:
    """In the isolated child: the push at PASS, then SCAN until a fall -> (PASS survived, the
    largest survived, the controller's first fault)."""
    faults: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        path = student_yaml(Path(tmp), submission, FILE, CLASS, NAME, JOINTS, {})

        def make_lab():
            lab = controller_lab(path, {}, [scale_mass("torso", var["torso"])])
            labs.append(lab)
            return lab

        def trial(impulse: float) -> bool:
            up = survives(TRIAL, impulse * scale, make_lab)
            fault = controller_fault(labs[-1], NAME)
            if fault:
                faults.append(fault)
            return up and not fault

        labs: list = []
        passed = trial(PASS)
        largest = PASS if passed else 0.0
        for impulse in SCAN if passed else ():
            if not trial(impulse):
                break
            largest = impulse
    return passed, largest, (faults[0] if faults else None)


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    scale = mass_ratio(var)
    passed, largest, fault = ctx.measure(trials, ctx.submission, var, scale)
    what = (f"torso x{var['torso']:.2f}, pushed forward at the torso over 0.1 s, every push x"
            f"{scale:.3f}, the robot's mass ratio")
    return [check("runs", 1.0, 0.0 if fault else 1.0, fault or "no fault in any trial"),
            check(f"survives {PASS:g} N s", 4.0, 1.0 if passed else 0.0,
                  f"{'stood' if passed else 'fell'} after {PASS:g} N s ({what})"),
            check("largest push", 1.0, (largest - PASS) / (SCAN[-1] - PASS) if passed else 0.0,
                  f"survived every push up to {largest:g} N s of {PASS:g}, "
                  f"{', '.join(f'{s:g}' for s in SCAN)} (full marks at {SCAN[-1]:g})")]
