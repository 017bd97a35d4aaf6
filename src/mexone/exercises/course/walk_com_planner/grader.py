"""Exercise 11, your own COM planner: the walking stack with the student's class in
com_planner's place walks 4.5 s at 0.3 m/s. Method: the class in the chain is the student's
(not the shipped planner, mexone.walking.mpc, nor built on it: its imports read, no import by
name at run time; in the lab's process also its class's bases and what it imported -- a class
in a worker process is seen by its source only) and its `com` finite all along (a NaN `com`
stands the robot: the whole-body controller's safe stop).
Hidden variant: masses, friction and a push forward or backward while walking."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from mexone.exercises.course._labtools import check
from mexone.exercises.course._walktools import (
    UP,
    built_on,
    draw,
    handout,
    refused_import,
    rows,
    speed_check,
    stack_yaml,
    walk,
)

FILE, CLASS, PART = "com_planner.py", "MyComPlanner", "com_planner"
SHIPPED = "mexone.walking.mpc"
SECONDS, VX = 4.5, 0.3  # s of walk, m/s commanded
GAIT = {"footsteps": {"vx": VX, "settle": 0.5}}
WINDOW, NONE, FULL = 2.0, 0.08, 0.22  # the speed over the last WINDOW s: m/s for none, full marks
METHOD = "your planner in the chain"


def files() -> dict[str, str]:
    """What `mexone exercise start` writes beside the starter: the stack's YAML with the
    student's class in its part's place, walking as graded."""
    return handout(PART, FILE, CLASS, GAIT, "walk_com_planner")


def variant(r: np.random.Generator | None):
    return draw(r, push=(2.0, 3.0))


def run(submission: Path, var) -> dict:
    """In the isolated child: the stack with the student's planner walks."""
    with tempfile.TemporaryDirectory() as tmp:
        path = stack_yaml(Path(tmp), PART, submission, FILE, CLASS, GAIT)
        return walk(path, var, SECONDS, PART)


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    what = var.describe()
    why = refused_import(ctx.submission, SHIPPED, "the shipped planner")
    if why:  # no walk: the shipped planner would be graded
        return [check("runs", 1.0, 0.0, "not run: " + why), check(METHOD, 2.0, 0.0, why),
                check(UP, 3.0, 0.0, "not run"), check("speed", 4.0, 0.0, "not run")]
    out = ctx.run(run, ctx.submission, var)
    data = rows(out, 16)
    t, x, ref = data[:, 0], data[:, 1], data[:, 10:16]
    up = out["fell"] is None
    shipped = built_on(out, SHIPPED)
    finite = bool(np.isfinite(ref).all()) and len(ref) > 0
    if shipped:
        method, why = 0.0, f"your class is built on the shipped planner ({shipped})"
    else:
        method = 1.0 if finite else 0.0
        why = (f"{CLASS} ran in com_planner's place, " + ("its `com` finite all along" if finite
               else "but its `com` was not finite: the whole-body controller stood the robot"))
    speed, _ = speed_check("speed", 4.0, t, x, WINDOW, NONE, FULL, f"{VX:g} m/s commanded")
    fault = out["fault"] or (out["faults"][0] if out["faults"] else None)
    stood = check(UP, 3.0, 1.0 if up else 0.0, f"stood all {SECONDS:g} s ({what})" if up
                  else f"fell at {out['fell']:.2f} s ({what})")
    if method < 1.0:  # the walk is not the student's planner's: nothing of it counts
        stood, speed = (check(c.name, c.weight, 0.0, f"not counted: {METHOD} failed ({c.output})")
                        for c in (stood, speed))
    return [check("runs", 1.0, 0.0 if fault else 1.0, fault or "no fault"),
            check(METHOD, 2.0, method, why), stood, speed]
