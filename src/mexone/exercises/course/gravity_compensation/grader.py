"""Exercise 5, gravity compensation: hold a raised arm with a weak PD (kp 5 N m/rad) plus the
arm's own gravity torque g(q). Hidden variant: the arm's pose and a payload in the hand (the
forearm 0.7x to 1.6x as heavy) -- a controller that reads g(q) from the model holds any of them,
one with torques written down for the given arm does not.

The method is checked too: after the hold, each arm joint is pushed (+PROBE, then -PROBE N m,
then let go) and the torque the controller applies, less g(q), is fitted against the joints'
position and speed: its stiffness and damping must be the grader's kp and kd. A stiff PD holds
the arm without g(q) (7.2/10 before this check); it earns no "holds the arm" here."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mexone.dynamics import Dynamics
from mexone.exercises.course._labtools import (
    ARM,
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

NAME = "gravity_compensation"
FILE, CLASS = "gravity_compensation.py", "GravityCompensation"
GIVEN = {"pose": {"l_shoulder_pitch": -1.2, "l_elbow": -0.6}, "payload": 1.0}
KP, KD = 5.0, 0.5
SECONDS = 1.0
HOLD, SAG = 2e-3, 20e-3  # rad: full marks within HOLD, none beyond SAG
PROBE = 0.3  # N m on each arm joint, in turns + - 0 (SIGNS) for PROBE_S each
# 0.6 s of probe: the fitted gains within 1.1 % of the applied (1.3 % with + - + 0 of 0.25 s
# each: 1 s, a fifth of a graded run's CPU; 1.8 % at 0.15 s); a gain earns full marks within 25 %
PROBE_S = 0.2
SIGNS = (1.0, -1.0, 0.0)
METHOD = "applies kp and kd"  # the check the hold presumes: the stated law's gains


def variant(r: np.random.Generator | None) -> dict:
    """The given arm (r None: the self-check) or the hidden one drawn from the secret seed."""
    if r is None:
        return GIVEN  # always away from the given arm: lighter or heavier, another pose
    side = r.choice([-1.0, 1.0], size=2)
    return {"pose": {"l_shoulder_pitch": -1.2 + side[0] * float(r.uniform(0.2, 0.35)),
                     "l_elbow": -0.6 + side[1] * float(r.uniform(0.2, 0.3))},
            "payload": float(r.uniform(0.6, 0.8) if r.random() < 0.5 else r.uniform(1.3, 1.6))}


def measure(submission: Path, var: dict) -> tuple[float, tuple[tuple[float, float], ...],
                                                 str | None]:
    """The arm's largest joint error (rad) over SECONDS; then, under the probe torques, each
    joint's (stiffness, damping) the controller applies (fit_gains); the controller's fault."""
    with tempfile.TemporaryDirectory() as tmp:
        path = student_yaml(Path(tmp), submission, FILE, CLASS, NAME, ARM, {"kp": KP, "kd": KD})
        lab = controller_lab(path, var["pose"], [scale_mass(HAND, var["payload"])])
    sim = lab.sim
    start = sim.data.qpos[[int(sim.model.joint(j).qposadr[0]) for j in ARM]].copy()
    log = JointLog(lab, ARM)
    sim.run(SECONDS)
    sim.remove_periodic(log.timer)
    sag = float(np.abs(np.array(log.q) - start).max())
    dofs = [int(sim.model.joint(j).dofadr[0]) for j in ARM]
    dynamics = Dynamics.live(sim)  # the grader's own view of the (varied) model: g(q)
    rows: list[np.ndarray] = []

    def sample(s) -> None:  # the applied torque (the actuators'), q, dq, g(q) of each arm joint
        dynamics.refresh()
        rows.append(np.stack([s.data.qfrc_actuator[dofs], log.positions(s), s.data.qvel[dofs],
                              dynamics.gravity()[dofs]]))

    timer = sim.add_periodic(sim.timestep, sample)
    for sign in SIGNS:
        for joint in ARM if sign else ():
            sim.apply_joint_effort(joint, sign * PROBE, duration=PROBE_S)
        sim.run(PROBE_S)
    sim.remove_periodic(timer)
    tau, q, dq, g = np.moveaxis(np.array(rows), 1, 0)
    gains = tuple(fit_gains(tau[:, i] - g[:, i], q[:, i], dq[:, i])[:2] for i in range(len(ARM)))
    return sag, gains, controller_fault(lab, NAME)


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    sag, gains, fault = ctx.measure(measure, ctx.submission, var)
    runs = check("runs", 1.0, 0.0 if fault else 1.0, fault or f"ran {SECONDS} s without a fault")
    method = gains_check(METHOD, gains, KP, KD, fault, ("N m/rad", "N m s/rad"),
                         "shoulder pitch, roll, elbow: the torque less g(q) fitted against q and "
                         f"dq under +-{PROBE:g} N m pushes")
    frac = 0.0 if fault else float(np.clip((SAG - sag) / (SAG - HOLD), 0.0, 1.0))
    hold = check("holds the arm", 3.0, frac,
                 f"largest joint error {sag * 1e3:.2f} mrad (full marks <= {HOLD * 1e3:g}, none "
                 f">= {SAG * 1e3:g}) at kp {KP:g}, payload x{var['payload']:.2f}", requires=METHOD)
    return [runs, method, hold]
