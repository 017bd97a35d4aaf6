"""Arms routine (seed 4.3.2): the student's rospy routine moves the arms through POSES; scored on
tracking (each pose held within TOLERANCE over its window) and on staying upright, on a robot
with hidden mass and damping changes."""

import numpy as np

from mexone.exercises import Check

# the poses (rad) and when each must be held, as the statement's table gives them
JOINTS = ("l_shoulder_pitch", "r_shoulder_pitch", "l_elbow", "r_elbow")
POSES = (  # (from s, to s): the window where the arms must be at the pose
    ((1.5, 2.0), (-0.6, -0.6, -0.5, -0.5)),   # arms forward, elbows a little bent
    ((3.0, 3.5), (-1.2, 0.0, -1.2, 0.0)),     # left arm up, right arm down
    ((4.5, 5.0), (0.0, -1.2, 0.0, -1.2)),     # the other way round
    ((6.0, 6.5), (-0.3, -0.3, -1.0, -1.0)),   # elbows bent
)
DURATION = 6.5

TOLERANCE = 0.05  # rad, each arm joint over each pose's window
UPRIGHT = "stays upright"  # the poses are held "while it stands": a fall voids them


def grade(ctx):
    variation = ctx.variation(mass=0.1, damping=0.3, friction=0.2)
    run = ctx.simulate(DURATION, routine=ctx.submission, variation=variation)
    columns = [run.joints.index(j) for j in JOINTS]
    checks = [Check.true(UPRIGHT, run.fell_at is None,
                         "stood" if run.fell_at is None else f"fell at {run.fell_at:.2f} s",
                         weight=2)]
    for k, ((start, end), pose) in enumerate(POSES, 1):
        window = (run.t >= start) & (run.t <= end)
        q = run.position[window][:, columns]
        worst = float(np.abs(q - np.array(pose)).max()) if q.size and np.isfinite(q).all() \
            else None
        checks.append(Check.at_most(f"pose {k} at {start:g}-{end:g} s", worst, TOLERANCE,
                                    " rad", weight=2, requires=UPRIGHT))
    fig = ctx.figure("arms")
    ax = fig.add_subplot()
    ax.plot(run.t, run.position[:, columns], label=list(JOINTS))
    for (start, end), pose in POSES:
        for value in pose:
            ax.plot([start, end], [value, value], "k-", lw=3, alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("rad")
    return checks
