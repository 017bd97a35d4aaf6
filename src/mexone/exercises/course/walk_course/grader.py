"""Exercise 9, walk a course: tune the gait (the `walk` routine's walk.yaml) so Mex-One walks
GOAL m forward, straight and fast; a fall disqualifies. Hidden variation: every link's mass
(+-10 %) and the floor's friction (0.6-0.9x) -- a gait on the edge of falling on the given robot
falls on some variants."""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
import yaml

from mexone import yamlio
from mexone.errors import InputError, RoutineError
from mexone.exercises.course._labtools import check
from mexone.exercises.isolate import SubmissionFailed
from mexone.exercises.sim import Variation

GOAL = 1.0  # m forward
REACHED = 0.9  # m: the course counts as walked from here (full marks for distance)
SHORT = 0.5  # m: no marks for distance below this
SECONDS = 11.0  # s of sim time the run lasts
FAST, SLOW = 7.0, SECONDS  # s to REACHED: full marks within FAST, none at SLOW
STRAIGHT, CROOKED = 0.05, 0.20  # m sideways at the end: full marks within, none beyond
SAMPLE = 0.01  # s
UP = "stays up"


def variant(r: np.random.Generator | None) -> Variation:
    if r is None:
        return Variation()
    return Variation(mass=float(r.uniform(0.9, 1.1)), friction=float(r.uniform(0.6, 0.9)))


def walk(gait: Path, variation: Variation) -> dict:
    """In the simulator (ctx.measure): the walk routine with the student's gait on the course [forward
    GOAL]; the base's x, y every SAMPLE s and when the robot fell (None: it did not)."""
    from mexone.lab import Lab
    from mexone.physics.monitor import has_fallen
    from mexone.routines.runner import RoutineRunner

    raw = yamlio.load(gait.read_text(), gait) or {}
    if not isinstance(raw, dict):
        raise InputError(f"{gait}: a gait is a mapping of parameters (see walk.yaml)")
    raw["course"] = [["forward", GOAL]]  # the grader's course, whatever the file says
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "gait.yaml"
        path.write_text(yaml.safe_dump(raw))
        lab = Lab.create(edits=[variation.edit])
        sim = lab.sim
        start = sim.base_height
        rows: list[tuple[float, float, float]] = []
        fell: list[float] = []

        def sample(s) -> None:
            x, y = (float(v) for v in s.data.qpos[:2])
            rows.append((s.time, x, y))
            if not fell and has_fallen(s, start):
                fell.append(s.time)

        sim.add_periodic(SAMPLE, sample)
        try:
            RoutineRunner(lab, "walk", {"_gait": str(path)}).run(SECONDS, hold=True)
        except RoutineError as exc:  # the gait's fault: said with the student's file, not ours
            text = str(exc).replace(str(path), gait.name).split("mexone.errors.InputError: ")[-1]
            text = re.sub(r"\S*/walk\.py(?::\d+)?: ", "", text)
            raise SubmissionFailed(f"the walk routine cannot walk this gait: {text}") from None
    return {"t": [r[0] for r in rows], "x": [r[1] for r in rows], "y": [r[2] for r in rows],
            "fell": fell[0] if fell else None}


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    run = ctx.measure(walk, ctx.submission, var)
    t, x, y = (np.asarray(run[k]) for k in ("t", "x", "y"))
    x, y = x - x[0], y - y[0]
    what = f"mass x{var.mass:.2f}, friction x{var.friction:.2f}"
    up = run["fell"] is None  # a fall disqualifies: the others require "stays up"
    reached = t[np.argmax(x >= REACHED)] if (x >= REACHED).any() else None
    shown = "never" if reached is None else f"at {reached:.2f} s"
    return [check(UP, 1.0, 1.0 if up else 0.0, f"stood all {SECONDS:g} s ({what})" if up
                  else f"disqualified: fell at {run['fell']:.1f} s ({what})"),
            check("distance", 3.0, (x[-1] - SHORT) / (REACHED - SHORT), f"walked {x[-1]:.2f} m "
                  f"forward, {GOAL:g} m planned (full marks from {REACHED:g}, none below {SHORT:g})",
                  requires=UP),
            check("drift", 2.0, (CROOKED - abs(y[-1])) / (CROOKED - STRAIGHT),
                  f"ended {y[-1] * 100:+.1f} cm sideways (full marks within {STRAIGHT * 100:g} "
                  f"cm, none beyond {CROOKED * 100:g})", requires=UP),
            check("time", 2.0, 0.0 if reached is None else (SLOW - reached) / (SLOW - FAST),
                  f"reached {REACHED:g} m {shown} (full marks within {FAST:g} s, none at "
                  f"{SLOW:g})", requires=UP)]
