"""PID to a specification: the grader's step.py steps l_elbow from 0 to -1 rad at 0.5 s; the
student's controller YAML must meet SPEC on a robot with hidden mass and damping changes.
The metrics are mexone's own (control/metrics.py), as `mexone run` reports them."""

from pathlib import Path

import numpy as np

from mexone.control.metrics import overshoot, rise_time, settling_time
from mexone.exercises import Check

STEP = Path(__file__).resolve().parent / "step.py"
JOINT, AT, TARGET = "l_elbow", 0.5, -1.0
DURATION = 2.0
UPRIGHT = "stays upright"  # a step measured while the robot falls is no step response
SPEC = {"rise time": 0.1, "overshoot": 0.05, "settling time": 0.3, "steady-state error": 0.003}


CONTROLLER, TYPE = f"{JOINT}_position_controller", "effort_controllers/JointPositionController"


def not_a_pid(path: str) -> str | None:
    """Why the submission's elbow is not a PID to grade (an ideal servo teleports the joint: a
    0 s rise time), or None; runs in the isolated child (a YAML may import a .py beside it)."""
    from mexone.control import load_control_config

    spec = load_control_config(path).controllers.get(CONTROLLER)
    if spec is None:
        return f"no {CONTROLLER}: tune its pid, do not remove it"
    if spec.type != TYPE or spec.pid is None or spec.ideal_servo:
        return f"{CONTROLLER} must stay {TYPE} with pid gains (the PID is what is graded)"
    return None


def grade(ctx):
    variation = ctx.variation(mass=0.1, damping=0.3)
    why = ctx.run(not_a_pid, str(ctx.submission))
    run = ctx.simulate(DURATION, routine=STEP, controllers=ctx.submission, variation=variation)
    _, q = run.joint(JOINT)
    after = run.t >= AT
    t, q = run.t[after] - AT, q[after]
    ok = bool(np.isfinite(q).all())
    rise = rise_time(t, q, 0.0, TARGET) if ok else None
    over = overshoot(q, 0.0, TARGET) if ok else None
    settle = settling_time(t, q, TARGET, TARGET) if ok else None
    error = float(np.abs(q[t >= t[-1] - 0.5] - TARGET).max()) if ok else None
    fig = ctx.figure("step")
    ax = fig.add_subplot()
    ax.plot(t, q, label=JOINT)
    ax.axhline(TARGET, color="k", lw=0.5)
    ax.set_xlabel("time after the step (s)")
    ax.set_ylabel("rad")
    upright = Check.true(UPRIGHT, run.fell_at is None,
                         "stood" if run.fell_at is None else f"fell at {run.fell_at:.2f} s")
    if why is not None:
        return [upright, *(Check(name, 0.0, 2.0, why) for name in SPEC)]
    return [
        upright,
        Check.at_most("rise time", rise, SPEC["rise time"], " s", weight=2, requires=UPRIGHT),
        Check.at_most("overshoot", None if over is None else over * 100,
                      SPEC["overshoot"] * 100, " %", weight=2, requires=UPRIGHT),
        Check.at_most("settling time", settle, SPEC["settling time"], " s", weight=2,
                      requires=UPRIGHT),
        Check.at_most("steady-state error", error, SPEC["steady-state error"], " rad", weight=2,
                      requires=UPRIGHT),
    ]
