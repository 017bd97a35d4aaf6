"""Exercise 7, task-space impedance: the left hand a spring K and damper D to where it started,
in the world frame, so a force F on it moves it F/K (sideways and up). Hidden variant: K, the
force and a payload in the hand -- tau = J^T (K (x0 - x) - D v) + g(q) from the live model moves
F/K whatever they are; a joint-space spring does not."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mexone.exercises.course._labtools import (
    ARM,
    HAND,
    HAND_POINT,
    check,
    controller_fault,
    controller_lab,
    scale_mass,
    student_yaml,
)

NAME = "hand_impedance"
FILE, CLASS = "hand_impedance.py", "HandImpedance"
POSE = {"l_shoulder_pitch": -0.6, "l_elbow": -1.2}  # forward, elbow bent: no singularity
GIVEN = {"stiffness": 200.0, "force": 10.0, "payload": 1.0}
DIRECTIONS = {"sideways": (0.0, 1.0, 0.0), "up": (0.0, 0.0, 1.0)}
TOLERANCE, NONE = 0.10, 0.30  # relative error of F/K: full marks within, none beyond
BACK = 8e-3  # m: the hand returns within this after the push


def variant(r: np.random.Generator | None) -> dict:
    if r is None:
        return GIVEN
    return {"stiffness": float(r.uniform(120.0, 300.0)), "force": float(r.uniform(6.0, 12.0)),
            "payload": float(r.uniform(0.6, 0.8) if r.random() < 0.5 else r.uniform(1.3, 1.6))}


def measure(submission: Path, var: dict) -> tuple[dict[str, float], float, str | None]:
    """Along each direction: how far the hand moved under the push (m, the mean over the push's
    last 0.5 s); the largest distance from its start 0.5 s after the pushes; the fault if any."""
    params = {"stiffness": var["stiffness"], "damping": 0.1 * var["stiffness"]}
    with tempfile.TemporaryDirectory() as tmp:
        path = student_yaml(Path(tmp), submission, FILE, CLASS, NAME, ARM, params)
        lab = controller_lab(path, POSE, [scale_mass(HAND, var["payload"])])
    sim = lab.sim
    body = sim.body_id(HAND)

    def hand() -> np.ndarray:
        return sim.data.xpos[body] + sim.data.xmat[body].reshape(3, 3) @ HAND_POINT

    moved, back = {}, 0.0
    sim.run(0.3)
    for name, direction in DIRECTIONS.items():
        before = hand()
        sim.apply_wrench(HAND, var["force"] * np.array(direction), point=before, duration=1.2)
        sim.run(0.7)
        samples: list[np.ndarray] = []
        timer = sim.add_periodic(sim.timestep, lambda s, samples=samples: samples.append(hand()))
        sim.run(0.5)
        sim.remove_periodic(timer)
        moved[name] = float((np.mean(samples, axis=0) - before) @ np.array(direction))
        sim.run(0.5)
        back = max(back, float(np.linalg.norm(hand() - before)))
    return moved, back, controller_fault(lab, NAME)


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    moved, back, fault = ctx.measure(measure, ctx.submission, var)
    expected = var["force"] / var["stiffness"]
    checks = [check("runs", 1.0, 0.0 if fault else 1.0, fault or "ran the pushes without a fault")]
    for name, value in moved.items():
        err = abs(value / expected - 1)
        checks.append(check(f"F/K {name}", 2.0, 0.0 if fault else float(
            np.clip((NONE - err) / (NONE - TOLERANCE), 0.0, 1.0)),
            f"{var['force']:.1f} N {name} moved the hand {value * 1e3:.1f} mm; F/K = "
            f"{expected * 1e3:.1f} mm (K {var['stiffness']:.0f} N/m), off by {err:.0%} "
            f"(full marks within {TOLERANCE:.0%}, none beyond {NONE:.0%})"))
    checks.append(check("springs back", 1.0, 0.0 if fault or back > BACK else 1.0,
                        f"the hand ended {back * 1e3:.1f} mm from where it was pushed from "
                        f"(<= {BACK * 1e3:g} mm asked)"))
    return checks
