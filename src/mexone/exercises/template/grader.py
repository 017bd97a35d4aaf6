"""Grader of TEMPLATE: both shoulders at TARGET over the last second, standing. grade(ctx) runs
in the grading process once per seed; the student's routine runs only inside ctx.simulate,
an isolated process with the exercise's limits."""

import numpy as np

from mexone.exercises import Check

TARGET = -0.8  # rad, l_shoulder_pitch and r_shoulder_pitch
TOLERANCE = 0.05  # rad
DURATION = 3.0  # s of sim time


def grade(ctx):
    variation = ctx.variation(mass=0.1, damping=0.3)  # hidden: drawn from the secret seed here
    run = ctx.simulate(DURATION, routine=ctx.submission, variation=variation)
    last = run.t >= run.t[-1] - 1.0
    error = None
    for joint in ("l_shoulder_pitch", "r_shoulder_pitch"):
        _, q = run.joint(joint)
        worst = float(np.abs(q[last] - TARGET).max())
        error = worst if error is None else max(error, worst)
    return [
        Check.true("stays upright", run.fell_at is None,
                   "stood" if run.fell_at is None else f"fell at {run.fell_at:.2f} s", weight=3),
        # a fallen robot's arms earn nothing: the check requires the one above
        Check.at_most("arms forward", error, TOLERANCE, " rad", weight=7,
                      requires="stays upright"),
    ]
