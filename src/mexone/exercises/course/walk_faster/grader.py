"""Exercise 12, weigh the whole-body QP's tasks to walk faster: the walking stack on a fast gait
(steps every 0.28 s, up to 0.16 m, 0.55 m/s commanded) with the student's weights and gains for
the shipped whole-body controller; the speed over the walk's last 1.5 s. The submission is
data: only the whole-body tasks' weights and gains are taken (each in its Param's range), so
the speed cannot come from a longer step, another friction assumed or another part. Hidden
variant: masses, friction and a push early in the walk (before the speed is measured)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from mexone import yamlio
from mexone.errors import InputError
from mexone.exercises.course._labtools import check
from mexone.exercises.course._walktools import UP, draw, handout, rows, speed_check, stack_yaml, walk
from mexone.exercises.isolate import SubmissionFailed

SECONDS = 4.5  # s of walk
GAIT = {"vx": 0.55, "max_forward": 0.16, "single_support": 0.22, "double_support": 0.06,
        "settle": 0.5}
TASKS = ("com", "foot", "torso", "posture")
KEYS = tuple(f"{p}_{task}" for task in TASKS for p in ("w", "kp", "kd"))
WINDOW, NONE, FULL = 1.5, 0.42, 0.50  # the speed over the last WINDOW s: m/s for none, full marks


def files() -> dict[str, str]:
    """What `mexone exercise start` writes beside the starter: the stack's YAML on the graded
    fast gait, the shipped weights under whole_body: (put yours there to watch them)."""
    return handout(None, "", "", {"footsteps": GAIT}, "walk_faster")


def variant(r: np.random.Generator | None):
    return draw(r, push=(1.0, 1.5), at=(1.2, 1.6))


def weights(path: Path) -> dict[str, float]:
    """The student's file read and checked (in the grading process: it is data): only KEYS,
    each a number in the whole-body controller's Param range."""
    from mexone.walking.wbc import WholeBodyController

    try:
        raw = yamlio.load(path.read_text(errors="replace"), path) or {}
    except InputError as exc:
        raise SubmissionFailed(exc.one_line().replace(str(path), path.name)) from None
    if not isinstance(raw, dict):
        raise SubmissionFailed(f"{path.name}: a mapping of the whole-body controller's weights "
                               "and gains (w_com: 100.0, ...)")
    out = {}
    for key, value in raw.items():
        if key not in KEYS:
            raise SubmissionFailed(f"{path.name}: '{key}' is not a task weight or gain of the "
                                   f"whole-body QP; the keys taken: {', '.join(KEYS)}")
        param = vars(WholeBodyController)[key]
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
                or not param.low <= value <= param.high:
            raise SubmissionFailed(f"{path.name}: '{key}' is {value!r}: a number from "
                                   f"{param.low:g} to {param.high:g}")
        out[key] = float(value)
    return out


def run(values: dict[str, float], var) -> dict:
    """In the isolated child: the shipped stack on the fast gait with these weights."""
    with tempfile.TemporaryDirectory() as tmp:
        path = stack_yaml(Path(tmp), params={"footsteps": GAIT, "whole_body": values})
        return walk(path, var, SECONDS, "whole_body")


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    what = var.describe()
    values = weights(ctx.submission)
    out = ctx.run(run, values, var)
    data = rows(out, 4)
    up = out["fell"] is None
    speed, _ = speed_check("speed", 6.0, data[:, 0], data[:, 1], WINDOW, NONE, FULL,
                           f"{GAIT['vx']:g} m/s commanded")
    fault = out["fault"] or (out["faults"][0] if out["faults"] else None)
    return [check("runs", 1.0, 0.0 if fault else 1.0, fault or "no fault"),
            check(UP, 3.0, 1.0 if up else 0.0, f"stood all {SECONDS:g} s ({what})" if up
                  else f"fell at {out['fell']:.2f} s ({what})"),
            speed]
