"""Exercise 15, a design with margins: the student's arm controller (500 Hz) must hold against a
push and stay stable with a delay on its commands (MuJoCo's actuator delay on the arm's motors)
and with its commands scaled up by k and down by 1/k (a disk margin's gain range: the arm
motors' gear times k in the grader's model, so the student's code sees the same class, the same
commands and no sign of the trial it is in). Hidden variant: the delay, k and a payload in the
hand."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mexone.exercises.course._labtools import (
    ARM,
    HAND,
    check,
    controller_fault,
    controller_lab,
    scale_mass,
    student_yaml,
)

NAME = "arm"
FILE, CLASS = "robust_arm.py", "RobustArm"
POSE = {"l_shoulder_pitch": -1.2, "l_elbow": -0.6}
RATE = 500.0
GIVEN = {"payload": 1.0, "delay": 0.010, "k": 2.0}
PUSH = 0.3  # N s on the hand over 0.1 s, sideways
HISTORY = 40  # command samples kept for the delay (40 ms at the 1 ms step)
PEAK = (40e-3, 80e-3)  # rad: full marks, none
LEFT = (1e-3, 3e-3)  # rad, 1 s after the push
STILL, SWING = 3e-3, 0.5  # rad, N m peak to peak over the last 0.5 s: stable (settled)


def variant(r: np.random.Generator | None) -> dict:
    if r is None:
        return GIVEN
    return {"payload": float(r.uniform(0.6, 0.8) if r.random() < 0.5 else r.uniform(1.3, 1.6)),
            "delay": float(r.uniform(0.008, 0.012)), "k": float(r.uniform(1.8, 2.2))}


def _history(spec, robot) -> None:
    for joint in ARM:
        actuator = spec.actuator(joint)
        actuator.nsample, actuator.delay = HISTORY, 0.0


def trial(submission: Path, var: dict, delay: float, scale: float) -> dict:
    """One run: settle 0.5 s, push, 1.8 s more -> peak and final deviation, the last 0.5 s's
    largest deviation and force swing, the fault."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = student_yaml(folder, submission, FILE, CLASS, NAME, ARM, {"update_rate": RATE})
        lab = controller_lab(path, POSE, [scale_mass(HAND, var["payload"]), _history])
        model = lab.sim.model
        motors = [model.actuator(j).id for j in ARM]
        adr = [int(model.joint(j).qposadr[0]) for j in ARM]
        # the amplifier k times stronger (or weaker): the hardware divides each effort by the
        # gear it read at the start, MuJoCo multiplies the motor's force by this one
        model.actuator_gear[motors, 0] *= scale
        lab.sim.run(0.5)
        model.actuator_delay[motors] = delay
        q0 = lab.sim.data.qpos[adr].copy()
        log: list[np.ndarray] = []
        gear = model.actuator_gear[motors, 0].copy()
        lab.sim.add_periodic(lab.sim.timestep, lambda s: log.append(  # the joints' torques
            np.r_[s.data.qpos[adr] - q0, gear * s.data.actuator_force[motors]]))
        lab.sim.run(0.2)
        lab.sim.apply_wrench(HAND, (0.0, PUSH / 0.1, 0.0), (0.0, 0.0, 0.0), duration=0.1)
        lab.sim.run(1.8)
        fault = controller_fault(lab, NAME)
    trace = np.array(log)
    deviation = np.abs(trace[:, :3]).max(axis=1)
    late = trace[-500:]
    swing = float((late[:, 3:].max(axis=0) - late[:, 3:].min(axis=0)).max())
    drift = float((late[:, :3].max(axis=0) - late[:, :3].min(axis=0)).max())
    return {"peak": float(deviation.max()), "left": float(deviation[-500:].max()),
            "drift": drift, "swing": swing, "fault": fault,
            "finite": bool(np.isfinite(trace).all())}


def trials(submission: Path, var: dict) -> dict:
    """In the isolated child: the nominal run, the delayed one, the scaled up and down ones."""
    return {"nominal": trial(submission, var, 0.0, 1.0),
            "delay": trial(submission, var, var["delay"], 1.0),
            "up": trial(submission, var, 0.0, var["k"]),
            "down": trial(submission, var, 0.0, 1.0 / var["k"])}


def _stable(run: dict) -> bool:
    return run["finite"] and not run["fault"] and run["drift"] <= STILL and run["swing"] <= SWING


def _said(run: dict) -> str:
    if run["fault"]:
        return run["fault"]
    return (f"last 0.5 s: joints moving by up to {run['drift'] * 1e3:.2f} mrad, force swinging "
            f"{run['swing']:.3g} N m")


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    runs = ctx.run(trials, ctx.submission, var)
    nominal = runs["nominal"]
    fault = nominal["fault"]
    what = f"payload x{var['payload']:.2f}"
    ok = check("runs", 1.0, 0.0 if fault else 1.0, fault or "held the arm through the push")
    peak = (PEAK[1] - nominal["peak"]) / (PEAK[1] - PEAK[0])
    left = (LEFT[1] - nominal["left"]) / (LEFT[1] - LEFT[0])
    push = check("holds against a push", 4.0, min(peak, left),
                 f"largest deviation {nominal['peak'] * 1e3:.1f} mrad (full marks <= "
                 f"{PEAK[0] * 1e3:g}, none >= {PEAK[1] * 1e3:g}), {nominal['left'] * 1e3:.2f} mrad "
                 f"left 1 s later (full marks <= {LEFT[0] * 1e3:g}, none >= {LEFT[1] * 1e3:g}); "
                 f"{what}", requires="runs")
    delay = check("delay margin", 2.0, 1.0 if _stable(runs["delay"]) else 0.0,
                  f"{var['delay'] * 1e3:.1f} ms on every command: {_said(runs['delay'])}",
                  requires="runs")
    up = check("gain up", 1.5, 1.0 if _stable(runs["up"]) else 0.0,
               f"commands x{var['k']:.2f}: {_said(runs['up'])}", requires="runs")
    down = check("gain down", 1.5, 1.0 if _stable(runs["down"]) else 0.0,
                 f"commands x{1 / var['k']:.2f}: {_said(runs['down'])}", requires="runs")
    return [ok, push, delay, up, down]
