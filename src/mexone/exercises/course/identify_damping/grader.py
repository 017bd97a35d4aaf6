"""Exercise 10, identify a joint's damping from a bag: the student's estimate(bag) -> N m s/rad
for the left elbow. The bag is made here, by the grader, from the seed: Mex-One hung on a stand
(fixed base, 0.3 m up), the shipped excitation routine for SECONDS, recorded with every topic
(`mexone record`), on a model whose l_elbow damping is the hidden truth.

Why generated and not shipped: a recorded bag is about 0.75 MB per second (3 MB for these 4 s),
over what the repository should hold, and a fixed bag fixes the answer -- a student could hand in
the number. The truth comes from the exercise's secret seed (and the teacher's
$MEXONE_EXERCISE_SECRET), which the student never sees; the self-check (--local) records the
given bag (the truth 2.5x the URDF's 0.2)."""

from __future__ import annotations

import importlib.util
import math
import tempfile
from pathlib import Path

import numpy as np

from mexone.errors import InputError
from mexone.exercises.course._labtools import check
from mexone.exercises.isolate import SubmissionFailed

JOINT = "l_elbow"
NOMINAL = 0.2  # N m s/rad: the URDF's damping of l_elbow
GIVEN = 0.5
SECONDS = 4.0  # s of excitation recorded (2 s ramp to the working pose, then the multisine)
GOOD, BAD = 0.10, 0.30  # relative error: full marks within GOOD, none beyond BAD


def variant(r: np.random.Generator | None) -> float:
    """The true damping: the given one, or drawn away from the URDF's (lower or higher)."""
    if r is None:
        return GIVEN
    return float(r.uniform(0.3, 0.6) if r.random() < 0.5 else r.uniform(1.6, 3.5)) * NOMINAL


def make_bag(folder: Path, damping: float) -> Path:
    """Record the excitation on a Mex-One whose l_elbow damping is `damping` (grading process:
    trusted code, no student's part)."""
    from mexone.identify.patch import Change, patch_urdf
    from mexone.lab import Lab
    from mexone.physics.compile import CompileOptions, Spawn
    from mexone.record.bag import BagRecorder
    from mexone.robots import mex_one
    from mexone.routines.runner import RoutineRunner

    truth = folder / "truth.urdf"
    truth.write_text(patch_urdf(Path(mex_one.urdf_path()).read_text(),
                                [Change("damping", JOINT, "", NOMINAL, damping)], "the truth"))
    lab = Lab.create(truth, mex_one.controllers_path(), options=CompileOptions(fixed_base=True),
                     spawn=Spawn((0.0, 0.0, 0.3)))
    bag = folder / "hung.mcap"
    runner = RoutineRunner(lab, "excitation", {"_base": "fixed", "_seed": 0})
    recorder = BagRecorder(lab, bag)
    try:
        runner.run(SECONDS)
    finally:
        recorder.close()
    truth.unlink()  # the student's part sees the bag only
    data = bag.read_bytes()
    if b"<robot" in data or str(folder).encode() in data:  # the truth must not ride along
        raise RuntimeError(f"{bag}: the recording holds the model or its path")
    return bag


def estimate(submission: Path, bag: Path) -> float:
    """In the isolated child: the student's estimate(bag) as a float."""
    spec = importlib.util.spec_from_file_location("identify_damping_submission", submission)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    if not callable(getattr(module, "estimate", None)):
        raise InputError(f"{submission.name}: no function estimate(bag)",
                         hint="define estimate(bag: str) -> float")
    value = module.estimate(str(bag))
    try:
        return float(value)
    except (TypeError, ValueError):  # the student's answer, not the grader, is at fault
        raise SubmissionFailed(f"estimate(bag) returned {type(value).__name__} "
                               f"{str(value)[:40]!r}, not a number (N m s/rad)") from None


def grade(ctx) -> list:
    truth = variant(None if ctx.local else ctx.rng)
    with tempfile.TemporaryDirectory() as tmp:
        bag = make_bag(Path(tmp), truth)
        value = ctx.run(estimate, ctx.submission, bag)
    if not math.isfinite(value) or value <= 0:
        return [check("damping", 1.0, 0.0, f"estimate(bag) returned {value!r}, not a damping > 0")]
    err = abs(value / truth - 1)
    return [check("damping", 1.0, (BAD - err) / (BAD - GOOD),
                  f"estimated {value:.4g} N m s/rad: {band(err)} (full marks within {GOOD:.0%}, "
                  f"none beyond {BAD:.0%})")]


def band(err: float) -> str:
    """How far off an estimate is, without the truth or the error itself: the variant is the
    class's (keyed by the teacher's secret, the same for every submission), and a report that
    stated it (was: "truth 0.3284: off by 39.1%") answered the exercise to whoever handed in
    the starter first, and to a resubmission of `return 0.3284` (10/10)."""
    if err <= GOOD:
        return f"within {GOOD:.0%} of the truth"
    if err >= BAD:
        return f"off by more than {BAD:.0%}"
    return f"off by {GOOD:.0%} to {BAD:.0%}"
