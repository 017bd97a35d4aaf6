"""Exercise 7, task-space impedance: the left hand a spring K and damper D to where it started,
in the world frame, so a force F on it moves it F/K (sideways and up). Hidden variant: K, the
force and a payload in the hand -- tau = J^T (K (x0 - x) - D v) + g(q) from the live model moves
F/K whatever they are; a joint-space spring does not.

The method is checked too: over the pushes, the force the controller applies at the hand
(J^-T (tau - g(q)), tau the actuators' torques) is fitted against the hand's position and
velocity, sideways and up: its stiffness must be K, its damping D = 0.1 K, and the spring's rest
point where the hand started (without g(q) the arm's weight moves it: 6-30 mm down). Without the
damper, or without g(q), the pushes alone scored 10/10."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mexone.dynamics import Dynamics
from mexone.exercises.course._labtools import (
    ARM,
    HAND,
    HAND_POINT,
    check,
    controller_fault,
    controller_lab,
    fit_gains,
    gain_share,
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
CENTRE, OFF_CENTRE = 1.5e-3, 4e-3  # m: the spring's rest point from the start, full / no marks
METHOD = "a spring K, damper D to the start"  # what the F/K checks presume: the stated law


def variant(r: np.random.Generator | None) -> dict:
    if r is None:
        return GIVEN
    return {"stiffness": float(r.uniform(120.0, 300.0)), "force": float(r.uniform(6.0, 12.0)),
            "payload": float(r.uniform(0.6, 0.8) if r.random() < 0.5 else r.uniform(1.3, 1.6))}


def measure(submission: Path, var: dict) -> tuple[dict[str, float], float, dict, str | None]:
    """Along each direction: how far the hand moved under the push (m, the mean over the push's
    last 0.5 s); the largest distance from its start 0.5 s after the pushes; the law applied
    along each direction (the hand's force fitted, fit_gains: stiffness, damping, the spring's
    rest point less the start, m); the fault if any."""
    params = {"stiffness": var["stiffness"], "damping": 0.1 * var["stiffness"]}
    with tempfile.TemporaryDirectory() as tmp:
        path = student_yaml(Path(tmp), submission, FILE, CLASS, NAME, ARM, params)
        lab = controller_lab(path, POSE, [scale_mass(HAND, var["payload"])])
    sim = lab.sim
    body = sim.body_id(HAND)
    dofs = [int(sim.model.joint(j).dofadr[0]) for j in ARM]
    dynamics = Dynamics.live(sim)  # the grader's own view of the (varied) model

    def hand() -> np.ndarray:
        return sim.data.xpos[body] + sim.data.xmat[body].reshape(3, 3) @ HAND_POINT

    rows: list[np.ndarray] = []

    def sample(s) -> None:  # the hand's force the torques (less g(q)) make, its x and v
        dynamics.refresh()
        jacobian = dynamics.jacobian(HAND, hand())[:3, dofs]
        torque = s.data.qfrc_actuator[dofs] - dynamics.gravity()[dofs]
        rows.append(np.stack([np.linalg.lstsq(jacobian.T, torque, rcond=None)[0], hand(),
                              jacobian @ s.data.qvel[dofs]]))

    start = hand()
    moved, back = {}, 0.0
    sim.run(0.3)
    law = sim.add_periodic(sim.timestep, sample)
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
    sim.remove_periodic(law)
    force, x, v = np.moveaxis(np.array(rows), 1, 0)
    applied = {}
    for name, direction in DIRECTIONS.items():
        axis = int(np.argmax(direction))
        stiffness, damping, rest = fit_gains(force[:, axis], x[:, axis], v[:, axis])
        applied[name] = (stiffness, damping, rest - float(start[axis]))
    return moved, back, applied, controller_fault(lab, NAME)


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    moved, back, applied, fault = ctx.measure(measure, ctx.submission, var)
    expected = var["force"] / var["stiffness"]
    stiffness, damping = var["stiffness"], 0.1 * var["stiffness"]
    checks = [check("runs", 1.0, 0.0 if fault else 1.0, fault or "ran the pushes without a fault")]
    share = 0.0 if fault else min(
        min(gain_share(k, stiffness), gain_share(d, damping),
            float(np.clip((OFF_CENTRE - abs(r)) / (OFF_CENTRE - CENTRE), 0.0, 1.0)))
        for k, d, r in applied.values())
    shown = "; ".join(f"{name} K {k:.0f} N/m, D {d:.3g} N s/m, rest point {r * 1e3:+.1f} mm"
                      for name, (k, d, r) in applied.items())
    checks.append(check(METHOD, 2.0, share,
                        f"{shown} (the hand's force from the torques less g(q), fitted); asked K "
                        f"{stiffness:.0f}, D {damping:.3g}, rest point within "
                        f"{CENTRE * 1e3:g} mm of the start"))
    for name, value in moved.items():
        err = abs(value / expected - 1)
        checks.append(check(f"F/K {name}", 2.0, 0.0 if fault else float(
            np.clip((NONE - err) / (NONE - TOLERANCE), 0.0, 1.0)),
            f"{var['force']:.1f} N {name} moved the hand {value * 1e3:.1f} mm; F/K = "
            f"{expected * 1e3:.1f} mm (K {var['stiffness']:.0f} N/m), off by {err:.0%} "
            f"(full marks within {TOLERANCE:.0%}, none beyond {NONE:.0%})", requires=METHOD))
    checks.append(check("springs back", 1.0, 0.0 if fault or back > BACK else 1.0,
                        f"the hand ended {back * 1e3:.1f} mm from where it was pushed from "
                        f"(<= {BACK * 1e3:g} mm asked)"))
    return checks
