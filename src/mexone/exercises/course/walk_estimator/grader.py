"""Exercise 13, walk on your own state estimate: the walking stack with the student's class in
the estimator's place walks 4.5 s at 0.3 m/s, every other part computing at its estimate. The
truth is hidden from the class (_walktools.blind_base: its view of the floating base stays where
the robot was put, at rest), so an estimator that copies the simulator's base exports a robot
standing still; the estimate is also graded against the truth. The class's encoders are noisy
(Encoders: the angles' quantisation, the velocities' differentiation), so leg odometry alone
misses the velocity by about 0.06 m/s: a filter is the exercise. The shipped estimator
(mexone.walking.estimator) is refused, as exercise 11 refuses the shipped planner. Hidden
variant: masses, friction and a push forward or backward while walking; the noise's draws."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mexone.exercises.course import _walktools as tools
from mexone.exercises.course._labtools import check
from mexone.exercises.course._walktools import UP

FILE, CLASS, PART = "estimator.py", "MyEstimator", "estimator"
SHIPPED = "mexone.walking.estimator"  # the shipped Kalman filter: the student writes their own
SECONDS, VX = 4.5, 0.3  # s of walk, m/s commanded
GAIT = {"footsteps": {"vx": VX, "settle": 0.5}}
WINDOW, NONE, FULL = 2.0, 0.08, 0.22  # the speed over the last WINDOW s: m/s for none, full marks
# m/s RMS of the horizontal velocity's error: full marks, none. Measured on hidden variants: a
# Kalman filter 0.013-0.016, leg odometry without a filter 0.061-0.065 (the encoders' noise)
VELOCITY = (0.025, 0.05)
POSITION = (0.05, 0.15)  # m: the horizontal position's error at the end: full marks, none
TRACKS = "estimate tracks the truth"
ANGLE_NOISE, VELOCITY_NOISE = 2e-4, 0.1  # rad, rad/s: the encoders' noise (Encoders)


def files() -> dict[str, str]:
    """What `mexone exercise start` writes beside the starter: the stack's YAML with the
    student's class in its part's place, walking as graded."""
    return tools.handout(PART, FILE, CLASS, GAIT, "walk_estimator")


def variant(r: np.random.Generator | None):
    return tools.draw(r, push=(2.0, 3.0))


def run(submission: Path, var, encoders: tools.Encoders) -> dict:
    """In the isolated child: the stack walks on the student's estimate, the truth hidden from
    the student's class, its encoders noisy."""
    with tempfile.TemporaryDirectory() as tmp:
        path = tools.stack_yaml(Path(tmp), PART, submission, FILE, CLASS, GAIT)
        return tools.walk(path, var, SECONDS, PART, blind=True, encoders=encoders)


def _share(error: float, limits: tuple[float, float]) -> float:
    return float(np.clip((limits[1] - error) / (limits[1] - limits[0]), 0.0, 1.0))


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    what = var.describe()
    why = tools.refused_import(ctx.submission, SHIPPED, "the shipped estimator")
    if why:  # no walk: the shipped filter would be graded
        return [check("runs", 1.0, 0.0, "not run: " + why), check(UP, 2.0, 0.0, "not run"),
                check(TRACKS, 4.0, 0.0, why), check("speed", 3.0, 0.0, "not run")]
    # the noise's draws keyed by the secret too: a class that knew them could subtract them
    seed = 0 if ctx.local else int(ctx.rng.integers(2**32))
    out = ctx.run(run, ctx.submission, var, tools.Encoders(ANGLE_NOISE, VELOCITY_NOISE, seed))
    data = tools.rows(out, 20)
    t, x = data[:, 0], data[:, 1]
    true_p, true_v, est_p, est_v = data[:, 1:3], data[:, 4:6], data[:, 10:12], data[:, 17:19]
    up = out["fell"] is None
    shipped = tools.built_on(out, SHIPPED)
    if shipped:
        tracks, why = 0.0, f"your class is built on the shipped estimator ({shipped})"
    elif np.isfinite(est_p).all() and np.isfinite(est_v).all() and len(t):
        v_err = float(np.sqrt(np.mean(np.sum((est_v - true_v) ** 2, axis=1))))
        p_err = float(np.linalg.norm(est_p[-1] - true_p[-1]))
        tracks = min(_share(v_err, VELOCITY), _share(p_err, POSITION))
        why = (f"velocity {v_err:.3f} m/s RMS from the truth (full marks within {VELOCITY[0]:g}, "
               f"none at {VELOCITY[1]:g}), position {p_err * 100:.1f} cm off at the end (full "
               f"marks within {POSITION[0] * 100:g}, none at {POSITION[1] * 100:g})")
    else:
        tracks, why = 0.0, "your `base` was not finite at every sample"
    speed, _ = tools.speed_check("speed", 3.0, t, x, WINDOW, NONE, FULL, f"{VX:g} m/s commanded")
    if up and tracks < 0.5:  # a walk on a wrong estimate is no walk on the estimate
        speed = check("speed", 3.0, 0.0, f"not counted: {TRACKS} earned {tracks:.0%} (at least "
                      f"50 % counts the speed; {speed.output})")
    fault = out["fault"] or (out["faults"][0] if out["faults"] else None)
    return [check("runs", 1.0, 0.0 if fault else 1.0, fault or "no fault"),
            check(UP, 2.0, 1.0 if up else 0.0, f"stood all {SECONDS:g} s ({what})" if up
                  else f"fell at {out['fell']:.2f} s ({what})"),
            check(TRACKS, 4.0, tracks, why, requires=UP),
            speed]
