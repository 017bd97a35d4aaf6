"""Model checks (seed 4.1-4.2): the student's URDF must pass `mexone check` (the three planted
mistakes gone, nothing new) and, without controllers, fall like the reference robot: the same
fall time and rest pose (the ground's friction is varied, hidden, for both alike)."""

import numpy as np

from mexone.exercises import Check, SubmissionFailed
from mexone.robots import mex_one

REFERENCE = mex_one.urdf_path()  # the robot as shipped: the planted mistakes are its variant's
DURATION = 2.5  # s of sim time: it falls within about 1 s and comes to rest
FALL_TIME = 0.1  # s
REST_HEIGHT = 0.03  # m, the base's height at rest
REST_TILT = 0.15  # rad
PLANTED = {  # check: the finding codes that name the mistake
    "centre of mass": ("com-outside",),
    "inertia": ("inertia-triangle", "inertia-too-large", "inertia-not-positive",
                "inertia-too-small"),
    "collision": ("collision-misplaced",),
}


def findings(path: str) -> tuple[list[tuple[str, str, str]], list[str]]:
    """(code, severity, one line) of `mexone check`'s model rules, and the model's links and
    joints (a planted mistake is fixed only on the robot that had it); runs in the isolated
    child."""
    from mexone.description.check import check_model
    from mexone.description.loader import load_model
    from mexone.errors import MexoneError
    from mexone.exercises import SubmissionFailed

    try:
        model = load_model(path)
    except MexoneError as exc:
        raise SubmissionFailed(f"mexone check cannot read it: {exc.one_line()}") from None
    return ([(f.code, f.severity, f"line {f.line}: {f.element}: {f.message}")
             for f in check_model(model)],
            sorted([f"link {n}" for n in model.links] + [f"joint {n}" for n in model.joints]))


def _missing(names: list[str]) -> str | None:
    """What of the given robot the submission lacks: deleting the links that held the mistakes
    (or the whole robot) does not fix them."""
    from mexone.description.loader import load_model

    given = load_model(str(REFERENCE))
    wanted = [f"link {n}" for n in given.links] + [f"joint {n}" for n in given.joints]
    gone = [n for n in wanted if n not in set(names)]
    return None if not gone else (f"not the given robot: {gone[0]} is missing"
                                  + (f" (and {len(gone) - 1} more)" if len(gone) > 1 else ""))


def grade(ctx):
    variation = ctx.variation(friction=0.3)
    found, names = ctx.run(findings, str(ctx.submission))
    missing = _missing(names)
    try:
        student = ctx.simulate(DURATION, model=ctx.submission, controllers=False,
                               variation=variation)
    except SubmissionFailed as exc:  # MuJoCo cannot build it: the fall checks fail, not all
        student, why = None, exc.reason
    reference = ctx.simulate(DURATION, model=REFERENCE, controllers=False, variation=variation)
    checks = []
    planted = set()
    for name, codes in PLANTED.items():
        hits = [line for code, _, line in found if code in codes]
        planted |= set(codes)
        checks.append(Check.true(f"{name} fixed", not hits and missing is None,
                                 hits[0] if hits else missing or "clean", weight=1.5))
    other = [line for code, sev, line in found
             if code not in planted and sev in ("error", "warning")]
    checks.append(Check.true("check clean", not other and missing is None,
                             other[0] if other else missing or "no other errors or warnings",
                             weight=0.5))
    if student is None:
        return [*checks, Check("fall time like the reference", 0.0, 2.0, why),
                Check("rest pose like the reference", 0.0, 3.0, why)]
    if student.fell_at is None or reference.fell_at is None:
        fall = None if student.fell_at is None else abs(student.fell_at - reference.fell_at)
    else:
        fall = abs(student.fell_at - reference.fell_at)
    checks.append(Check.at_most("fall time like the reference", fall, FALL_TIME, " s", weight=2))
    height = abs(student.base_height[-1] - reference.base_height[-1])
    tilt = abs(student.tilt[-1] - reference.tilt[-1])
    rest_ok = bool(np.isfinite([height, tilt]).all()) and height <= REST_HEIGHT \
        and tilt <= REST_TILT
    checks.append(Check.true("rest pose like the reference", rest_ok,
                             f"height differs by {height:.3f} m (limit {REST_HEIGHT}), tilt by "
                             f"{tilt:.3f} rad (limit {REST_TILT})", weight=3))
    fig = ctx.figure("fall")
    ax = fig.add_subplot()
    ax.plot(reference.t, reference.base_height, label="reference")
    ax.plot(student.t, student.base_height, label="yours")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("base height (m)")
    ax.legend()
    return checks
