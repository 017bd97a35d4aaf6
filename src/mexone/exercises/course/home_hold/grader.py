"""Home hold (seed 4.3.1): the student's controller YAML holds every joint at 0 on a robot
whose masses, joint damping and friction are varied (hidden), for 3 s of sim time."""

import numpy as np

from mexone.exercises import Check

DURATION = 3.0  # s of sim time
WINDOW = 1.0  # s at the end where the hold is judged
TOLERANCE = 0.01  # rad: every joint within this of home
STILL = 0.005  # rad: peak-to-peak of any joint over the window (no oscillation)
UPRIGHT = "stays upright"  # a fallen robot lying still holds no home: the others require it


def grade(ctx):
    variation = ctx.variation(mass=0.1, damping=0.3, friction=0.2)  # drawn here, hidden
    run = ctx.simulate(DURATION, routine="home", controllers=ctx.submission,
                       variation=variation)
    end = run.t >= run.t[-1] - WINDOW
    q = run.position[end]
    finite = bool(np.isfinite(q).all()) and run.error is None
    worst = float(np.abs(q).max()) if finite else None
    swing = float(np.ptp(q, axis=0).max()) if finite else None
    fig = ctx.figure("joints")
    ax = fig.add_subplot()
    ax.plot(run.t, run.position)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("joint position (rad)")
    return [
        Check.true(UPRIGHT, run.fell_at is None and finite,
                   "stood" if run.fell_at is None else f"fell at {run.fell_at:.2f} s"
                   + (f"; {run.error}" if run.error else ""), weight=4),
        Check.at_most("holds home", worst, TOLERANCE, " rad", weight=3, requires=UPRIGHT),
        Check.at_most("no oscillation", swing, STILL, " rad", weight=3, requires=UPRIGHT),
    ]
