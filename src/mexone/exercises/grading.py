"""Grade one submission: the exercise's grader.py draws the hidden variation from the secret
seed here, in the grading process, which runs no student code and holds the teacher's secret
(non-dumpable: no process of its user reads its memory or environment). The episodes run out of
it (exercises.isolate): ctx.simulate and ctx.measure in the simulator, where a student's routine
or controller runs in a jail of its own; ctx.run in a jail with the student's part. Each sees a
private copy of the submission only. A submission that fails (raises, hangs, ends the process,
runs out of memory) gets 0 points with the reason; only a broken exercise is an error of the
grader.
"""

from __future__ import annotations

import csv
import hashlib
import hmac
import json
import logging
import os
import re
import secrets
import shutil
import tempfile
import time
import unicodedata
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mexone.errors import InputError, printable
from mexone.exercises.exercise import Exercise
from mexone.exercises.isolate import (
    SECRET_ENV,
    SubmissionFailed,
    prewarm,
    run_jailed,
    run_trusted,
)
from mexone.exercises.sim import Variation, simulate
from mexone.files import replacing
from mexone.inputs import read_input
from mexone.sandbox import isolation, keep_private

__all__ = ["Check", "GradeContext", "Result", "grade", "gradescope_json", "write_csv",
           "submissions_in", "not_handed_in", "existing_plots", "SECRET_ENV", "SECRET_MIN",
           "hidden_rng", "csv_cell", "refused_link"]

SECRET_MIN = 16  # characters of $MEXONE_EXERCISE_SECRET: fewer could be guessed from a variant
REASON_LIMIT = 500  # characters of a reason or a check's output a report shows


@dataclass
class Check:
    """One check of a submission: the share of its weight it earned (0..1) and why.

    `requires` names another check of the same episode that this one presumes (a pose held, a
    joint at home: "stays upright"): when that one did not pass, this one earns nothing, so a
    robot lying still on the floor scores no "holds home"."""

    name: str
    fraction: float
    weight: float = 1.0
    output: str = ""
    visibility: str = "visible"  # Gradescope's: visible, hidden, after_due_date, after_published
    requires: str | None = None

    @classmethod
    def at_most(cls, name: str, value: float | None, limit: float, unit: str = "",
                weight: float = 1.0, requires: str | None = None) -> Check:
        """Passes when value <= limit (None, e.g. "never settled", fails)."""
        ok = value is not None and np.isfinite(value) and value <= limit
        shown = "none" if value is None else f"{value:.4g}{unit}"
        return cls(name, 1.0 if ok else 0.0, weight, f"{shown} (limit {limit:g}{unit})",
                   requires=requires)

    @classmethod
    def at_least(cls, name: str, value: float | None, limit: float, unit: str = "",
                 weight: float = 1.0, requires: str | None = None) -> Check:
        """Pass if `value` is at least `limit` (finite), saying both (with `unit`)."""
        ok = value is not None and np.isfinite(value) and value >= limit
        shown = "none" if value is None else f"{value:.4g}{unit}"
        return cls(name, 1.0 if ok else 0.0, weight, f"{shown} (at least {limit:g}{unit})",
                   requires=requires)

    @classmethod
    def true(cls, name: str, ok: bool, output: str = "", weight: float = 1.0,
             requires: str | None = None) -> Check:
        """Pass if `ok`, saying `output`."""
        return cls(name, 1.0 if ok else 0.0, weight, output, requires=requires)

    @property
    def passed(self) -> bool:
        """Whether the check passed."""
        return self.fraction >= 1.0


def presumed(checks: list[Check], grader: Path) -> list[Check]:
    """The episode's checks with each whose `requires` did not pass set to 0 (the one rule:
    a check that presumes another earns nothing without it)."""
    by_name = {c.name: c for c in checks}
    out = []
    for check in checks:
        if check.requires is not None:
            needed = by_name.get(check.requires)
            if needed is None:
                raise InputError(f"check '{check.name}' requires '{check.requires}', which "
                                 "grade(ctx) did not return", file=grader)
            if not needed.passed:
                check = replace(check, fraction=0.0, output=f"not counted: {needed.name} "
                                f"failed ({needed.output})" if needed.output else
                                f"not counted: {needed.name} failed")
        out.append(check)
    return out


@dataclass
class GradeContext:
    """What grader.py's grade(ctx) gets, once per seed of the exercise."""

    exercise: Exercise
    submission: Path
    seed: int
    local: bool = False  # the self-check: no hidden variation
    plots: Path | None = None  # where ctx.figure()s are saved (grade --plots DIR)
    force: bool = False  # replace plots already there (grade --force)
    _figures: list = field(default_factory=list, repr=False)
    _scratch: Path | None = field(default=None, repr=False)

    @property
    def rng(self) -> np.random.Generator:
        """The hidden variation's generator for this seed, keyed by the teacher's
        $MEXONE_EXERCISE_SECRET (hidden_rng): draw from it here, in the grader; hand only the
        drawn values to ctx.simulate. Without the secret it is refused (InputError): the
        exercise's secret_seed is in the wheel, and a variation anyone can draw is no secret.
        The self-check (local) hides nothing: its generator is the public one of the exercise's
        secret_seed and the episode, the same on every machine."""
        if self.local:
            return np.random.default_rng([self.exercise.secret_seed, self.seed])
        return hidden_rng(self.exercise, self.seed, os.environ.get(SECRET_ENV, ""))

    def variation(self, mass: float = 0.0, damping: float = 0.0,
                  friction: float = 0.0) -> Variation:
        """A Variation with each scale drawn uniformly within +-the given share (0.1: +-10%);
        the nominal robot for the self-check."""
        if self.local:
            return Variation()
        rng = self.rng
        return Variation(*(float(1 + rng.uniform(-s, s)) for s in (mass, damping, friction)))

    def run(self, target: Callable, *args, **kwargs):
        """`target(*args, **kwargs)` in a jail under the exercise's limits (it loads and runs
        the student's part: an `estimate(bag)` function, a model); its return value, read
        against `target`'s return annotation: the student's own answer, not a measurement. A
        Path argument is copied into the jail (the submission's folder is readable there). A
        failure ends the grading of this submission with 0 points and its reason."""
        return run_jailed(target, *args, limits=self.exercise.limits,
                          readable=(self.submission.parent,), **kwargs)

    def measure(self, target: Callable, *args, **kwargs):
        """`target(*args, **kwargs)` in the simulator under the exercise's limits (it builds a
        lab, runs it and measures): a process that runs no student code -- a student's routine
        or controller in its lab runs in a jail of its own -- so what it returns is what the
        simulator observed, which the student cannot forge."""
        return run_trusted(target, *args, limits=self.exercise.limits, **kwargs)

    def simulate(self, duration: float, **kwargs):
        """sim.simulate(duration, ...) in the simulator (ctx.measure): a Run of plain arrays. A
        routine runs in a jail of its own (no model, no variation), unless it is mexone's
        shipped one or a file of the exercise's own folder (the teacher's, trusted)."""
        routine = kwargs.get("routine")
        if routine is not None and "own_process" not in kwargs and Path(routine).is_file():
            path = Path(routine).resolve()
            if path != self.submission.resolve() \
                    and path.is_relative_to(self.exercise.folder.resolve()):
                kwargs["own_process"] = False
        return self.measure(simulate, duration, **kwargs)

    def beside(self, files: dict[str, str], as_name: str | None = None) -> Path:
        """A scratch folder holding a copy of the submission (named `as_name`, default its own
        name) and `files` (name: text), e.g. a controller YAML whose `type: my_law/MyLaw`
        finds the student's my_law.py next to it; the folder's path. Removed after grading."""
        if self._scratch is None:
            self._scratch = Path(tempfile.mkdtemp(prefix="mexone-exercise-"))
            os.chmod(self._scratch, 0o711)  # a jail's uid reads its folders, lists none
        folder = Path(tempfile.mkdtemp(dir=self._scratch))
        os.chmod(folder, 0o755)
        shutil.copyfile(self.submission, folder / (as_name or self.submission.name))
        for name, text in files.items():
            (folder / name).write_text(text)
        for path in folder.iterdir():
            os.chmod(path, 0o644)
        return folder

    def cleanup(self) -> None:
        """Remove the grading's scratch folder."""
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)
            self._scratch = None

    def figure(self, name: str):
        """A matplotlib figure saved as PLOTS/<seed>-<name>.png when grading with --plots."""
        import matplotlib

        matplotlib.use("Agg")
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6, 3.5), tight_layout=True)
        self._figures.append((name, fig))
        return fig

    def save_figures(self) -> list[Path]:
        """Write the figures whole (files.replacing): a PNG already there only with force."""
        saved = []
        if self.plots is not None:
            try:
                self.plots.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise InputError(f"cannot make the plots folder: {exc.strerror or exc}",
                                 file=self.plots) from None
            for name, fig in self._figures:
                path = plot_path(self.exercise, self.plots, self.seed, name)
                with replacing(path, self.force) as temporary:
                    fig.savefig(temporary, dpi=80)
                saved.append(path)
        self._figures.clear()
        return saved


def hidden_rng(exercise: Exercise, seed: int, secret: str) -> np.random.Generator:
    """The generator of episode `seed`'s hidden variation: seeded by HMAC-SHA256 keyed with the
    teacher's secret over the exercise's name, its secret_seed and the episode. Whoever lacks
    the secret cannot tell one variant from another; secret_seed only tells exercises (and a
    teacher's redraws) apart."""
    if len(secret) < SECRET_MIN:
        said = "is not set" if not secret else f"has {len(secret)} characters"
        raise InputError(f"${SECRET_ENV} {said}: the hidden variation is keyed by the teacher's "
                         f"secret (at least {SECRET_MIN} characters)",
                         hint=f"export {SECRET_ENV}=\"$(python3 -c 'import secrets; "
                              "print(secrets.token_urlsafe())')\" on the grading machine, or "
                              "grade the nominal robot with --local")
    message = f"mexone-exercise\0{exercise.name}\0{exercise.secret_seed}\0{seed}".encode()
    digest = hmac.new(secret.encode(), message, hashlib.sha256).digest()
    return np.random.default_rng(np.frombuffer(digest, dtype=np.uint32))


@dataclass
class Result:
    """A graded submission: its score and each check's (the worst over the seeds)."""

    exercise: Exercise
    submission: Path
    score: float
    checks: list[tuple[Check, float, float]]  # (check, score, max_score)
    failure: str | None = None  # why the submission could not be graded (0 points)
    output: str = ""  # the submission's own output, its tail, when it failed
    plots: list[Path] = field(default_factory=list)
    seconds: float = 0.0  # wall time the grading took

    @property
    def max_score(self) -> float:
        """The points the checks are worth together."""
        return self.exercise.points

    @property
    def passed(self) -> bool:
        """Whether the score reaches the exercise's pass mark."""
        return self.score >= self.exercise.pass_mark

    @property
    def failing(self) -> list[str]:
        """The names of the checks that did not pass (the submission's failure if it had one)."""
        if self.failure:
            return ["runs"]
        return [c.name for c, _, _ in self.checks if not c.passed]


def plot_path(exercise: Exercise, folder: Path, seed: int, name: str) -> Path:
    """Where grading saves the figure `name` of episode `seed`."""
    return folder / f"{exercise.name}-seed{seed}-{name}.png"


def existing_plots(exercise: Exercise, folder: Path) -> list[Path]:
    """The files in `folder` that grading with --plots there may replace: the figures' names
    are known only once the grader ran, so any of the exercise's plots (checked before it runs)."""
    if not folder.is_dir():
        return []
    return sorted(p for seed in exercise.seeds
                  for p in folder.glob(plot_path(exercise, folder, seed, "*").name))


def grade(exercise: Exercise, submission: str | Path, local: bool = False,
          plots: Path | None = None, force: bool = False) -> Result:
    """Grade `submission` (the student's file) on every seed of the exercise; its figures go to
    `plots` (a PNG already there is replaced only with `force`)."""
    submission = Path(submission)
    link = refused_link(submission)
    if link is not None:
        return zero(exercise, submission, link)
    if not submission.is_file():
        raise InputError(f"no submission file {submission}",
                         hint=f"hand in the exercise's {exercise.file}")
    keep_private()  # the teacher's secret is in this process: no one of its user reads it
    prewarm()  # the runs' fork server starts while the grader imports and draws
    _warn_if_exposed()
    with tempfile.TemporaryDirectory(prefix="mexone-grade-") as work:
        try:
            copy = _private_copy(submission, Path(work))
        except InputError as exc:  # the student's file, not the grader: 0 points and why
            return zero(exercise, submission, exc.one_line())
        result = _grade(exercise, submission, copy, local, plots, force)
    return _scrubbed(result, copy.parent)


_warned: list[bool] = []


def _warn_if_exposed() -> None:
    """Once per process: a warning when this machine cannot keep the teacher's secret from a
    submission (no namespace, no other uid, no Landlock: it runs as the grader's own user)."""
    iso = isolation()
    if iso.mode == "none" and not iso.landlock and os.environ.get(SECRET_ENV) and not _warned:
        _warned.append(True)
        logging.getLogger("mexone.sandbox").warning(
            "mexone: warning: this machine isolates a submission with limits only (no user "
            "namespace, no root, no Landlock): it runs as your user and can read %s from this "
            "process's ancestors (docs/exercises.md, what a grading machine needs)", SECRET_ENV)


def _private_copy(submission: Path, work: Path) -> Path:
    """The submission as the runs see it: a copy, read-only, alone in a folder of its own
    (readable by a jail's uid, not listable): never the student's folder, nor another's. Read
    as every file a user names is (inputs.read_input: a regular file within the input size
    cap, $MEXONE_MAX_INPUT_MB): a sparse file of 800 MB was copied whole onto the grading
    machine's disk and read into the grader's memory (1.7 GB; a few GB more would end the
    class's grading), an InputError (the caller's zero) now."""
    try:
        data = read_input(submission, label=submission.name, follow=False)
    except InputError as exc:
        exc.hint = f"hand in the {submission.name} you wrote"
        raise
    os.chmod(work, 0o711)
    folder = work / secrets.token_hex(8)
    folder.mkdir(mode=0o755)
    copy = folder / submission.name
    copy.write_bytes(data)
    os.chmod(copy, 0o444)
    return copy


def _scrubbed(result: Result, folder: Path) -> Result:
    """The result as the student reads it: the private copy's folder not named (the file by
    its name), and the teacher's secret nowhere, whatever a run wrote."""
    secret = os.environ.get(SECRET_ENV, "")

    def clean(text: str) -> str:
        text = text.replace(str(folder) + "/", "")
        text = re.sub(r"/\S*/mexone-jail-[^/\s]+/scratch/inputs/\d+/", "", text)
        return text.replace(secret, "[the secret]") if secret else text

    result.failure = clean(result.failure) if result.failure else result.failure
    result.output = clean(result.output)
    result.checks = [(replace(c, output=clean(c.output)), s, m) for c, s, m in result.checks]
    return result


def _grade(exercise: Exercise, submission: Path, copy: Path, local: bool, plots: Path | None,
           force: bool) -> Result:
    grader = exercise.grader()
    began = time.monotonic()
    per_seed: list[list[Check]] = []
    saved: list[Path] = []
    for seed in exercise.seeds:
        ctx = GradeContext(exercise, copy, seed, local, plots, force)
        try:
            checks = list(grader.grade(ctx))
        except SubmissionFailed as exc:
            return zero(exercise, submission, exc.reason, exc.output, time.monotonic() - began)
        finally:
            ctx.cleanup()
        saved += ctx.save_figures()
        if not checks or not all(isinstance(c, Check) for c in checks):
            raise InputError("grade(ctx) must return a non-empty list of Check",
                             file=exercise.folder / "grader.py")
        per_seed.append(presumed(checks, exercise.folder / "grader.py"))
    combined: dict[str, Check] = {}
    for checks in per_seed:  # the worst episode counts
        for check in checks:
            fraction = float(np.clip(np.nan_to_num(check.fraction), 0.0, 1.0))
            seen = combined.get(check.name)
            if seen is None or fraction < seen.fraction:
                combined[check.name] = Check(printable(check.name, 80), fraction, check.weight,
                                             printable(check.output, REASON_LIMIT),
                                             check.visibility)
    total = sum(max(c.weight, 0.0) for c in combined.values()) or 1.0
    rows = []
    for check in combined.values():
        top = exercise.points * max(check.weight, 0.0) / total
        rows.append((check, round(top * check.fraction, 4), round(top, 4)))
    score = round(exercise.points * sum(max(c.weight, 0.0) * c.fraction
                                        for c in combined.values()) / total, 4)
    return Result(exercise, submission, score, rows, plots=saved,
                  seconds=time.monotonic() - began)


def zero(exercise: Exercise, submission: Path, reason: str, output: str = "",
         seconds: float = 0.0) -> Result:
    """0 points for a submission that could not be graded, and why (one line, as printable)."""
    reason = printable(reason, REASON_LIMIT)
    return Result(exercise, submission, 0.0,
                  [(Check("runs", 0.0, 1.0, reason), 0.0, exercise.points)], reason, output,
                  seconds=seconds)


def refused_link(path: Path) -> str | None:
    """Why a submission that is a symbolic link (a file, or a student's folder in a folder of
    submissions) is refused, not read and not run: it could name anything (/etc/passwd, the
    reference, another student's file). None for anything else."""
    if not path.is_symlink():
        return None
    try:
        target = os.readlink(path)
    except OSError:
        target = "?"
    return (f"{printable(path.name, 80)} is a symbolic link (to {printable(target, 120)}): "
            "refused, not read; hand in the file itself")


def gradescope_json(result: Result) -> dict:
    """Gradescope's results.json (its documented fields only: score, execution_time, output,
    visibility, stdout_visibility, extra_data and one test per check with score, max_score,
    status, name, output, visibility); the exercise's maximum is each test's max_score summed,
    and in extra_data."""
    tests = []
    for check, score, top in result.checks:
        tests.append({"name": check.name, "score": score, "max_score": top,
                      "output": check.output or ("passed" if check.passed else "failed"),
                      "visibility": check.visibility, "status": "passed" if check.passed
                      else "failed"})
    summary = f"{result.exercise.title}: {result.score:g}/{result.max_score:g}"
    if result.failure:
        summary += f" -- {result.failure}"
        if result.output.strip():
            summary += "\n\nthe submission's output (its end):\n" + "\n".join(
                output_lines(result))
    return {"score": result.score, "execution_time": max(0, round(result.seconds)),
            "output": summary, "visibility": "visible", "stdout_visibility": "hidden",
            "tests": tests,
            "extra_data": {"exercise": result.exercise.name, "max_score": result.max_score,
                           "pass_mark": result.exercise.pass_mark, "passed": result.passed,
                           "failure": result.failure}}


def submissions_in(folder: Path, file: str) -> dict[str, Path]:
    """A folder of submissions: each student a subfolder holding `file`, or a file of the
    same kind (its stem is the student's name; .yml counts as .yaml). A subfolder without
    `file` is a student too, mapped to the missing path (not_handed_in grades it 0, with why):
    no student drops out of the CSV. A symbolic link (a file or a subfolder) is the student's
    entry itself, which grade refuses (refused_link). Two submissions of one student are
    refused, also when their names are the same letters written two ways (é composed, and e
    with a combining accent: both print as é, one row in every report)."""
    found: dict[str, Path] = {}
    seen: dict[str, str] = {}  # a name in Unicode's composed form (NFC): the name found
    suffix = Path(file).suffix
    kinds = {".yaml", ".yml"} if suffix in (".yaml", ".yml") else {suffix}
    for entry in sorted(folder.iterdir()):
        if entry.name.startswith("."):
            continue
        if entry.is_symlink():
            student, path = entry.stem if entry.suffix in kinds else entry.name, entry
        elif entry.is_dir():
            student, path = entry.name, entry / file
        elif entry.is_file() and entry.suffix in kinds:
            student, path = entry.stem, entry
        else:
            continue
        same = seen.get(unicodedata.normalize("NFC", student))
        if same is not None:
            shown = printable(student, 80)
            if same != student:  # the same letters written two ways: one row in every report
                shown += f" (written as {ascii(same)[1:-1]} and as {ascii(student)[1:-1]})"
            raise InputError(f"two submissions of {shown}: {printable(found[same])} and "
                             f"{printable(path)}", hint="keep one of them in the folder")
        seen[unicodedata.normalize("NFC", student)] = student
        found[student] = path
    return found


def not_handed_in(exercise: Exercise, path: Path) -> Result:
    """0 points for a student's subfolder without the exercise's file, saying what it holds."""
    held = sorted(p.name for p in path.parent.iterdir()) if path.parent.is_dir() else []
    reason = f"no {exercise.file} in {path.parent}" + (
        f" (it holds {', '.join(held[:5])}{', ...' if len(held) > 5 else ''}: hand in "
        f"{exercise.file})" if held else " (it is empty)")
    return zero(exercise, path, reason)


def reason(result: Result) -> str:
    """Why a submission lost points, in one line: the reason it could not be graded, else each
    failing check and what it measured ("" for full marks)."""
    if result.failure:
        return result.failure
    return "; ".join(f"{c.name}: {c.output}" if c.output else c.name
                     for c, _, _ in result.checks if not c.passed)


CSV_FORMULA = ("=", "+", "-", "@", "\t", "\r")  # what a spreadsheet reads as a formula (OWASP)


def csv_cell(value: object) -> str:
    """A CSV cell a spreadsheet shows as text: printable, and a leading ' where it would start
    with = + - @ tab or CR (OWASP's rule against CSV injection)."""
    raw = str(value)
    text = printable(raw, REASON_LIMIT * 4)
    return "'" + text if raw.startswith(CSV_FORMULA) or text.startswith(CSV_FORMULA) else text


def write_csv(results: dict[str, Result], path: Path) -> None:
    """One row per student: score, passed, each check's points (runs included: they add up to
    the score; empty where a submission has no such check), the failing checks, and the reason
    (reason()) for every score below full marks. Every cell is csv_cell'd."""
    names: list[str] = []
    for result in results.values():
        for check, _, _ in result.checks:
            if check.name not in names:
                names.append(check.name)
    if "runs" in names:  # first: a submission that did not run has nothing else
        names.insert(0, names.pop(names.index("runs")))
    with open(path, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow([csv_cell(c) for c in
                      ("student", "score", "max_score", "passed", *names, "failing", "reason")])
        for student, r in results.items():
            by_name = {c.name: s for c, s, _ in r.checks}
            out.writerow([csv_cell(c) for c in (
                student, f"{r.score:g}", f"{r.max_score:g}", "yes" if r.passed else "no",
                *(f"{by_name[n]:g}" if n in by_name else "" for n in names),
                " ".join(r.failing), reason(r))])


def as_text(result: Result) -> str:
    """The report `mexone exercise grade` prints."""
    lines = [f"{result.exercise.title} ({result.exercise.name}): {printable(result.submission)}"]
    for check, score, top in result.checks:
        mark = "PASS" if check.passed else "FAIL"
        lines.append(f"  {mark} {check.name:<28} {score:6.2f}/{top:<6.2f} {check.output}")
    if result.failure and result.output.strip():
        lines.append("  the submission's output (its end):")
        lines += ["    | " + line for line in output_lines(result)[-15:]]
    for path in result.plots:
        lines.append(f"  plot: {path}")
    verdict = "passed" if result.passed else "not passed"
    lines.append(f"score {result.score:g}/{result.max_score:g} ({verdict}; pass mark "
                 f"{result.exercise.pass_mark:g})")
    return "\n".join(lines)


def output_lines(result: Result) -> list[str]:
    """The submission's own output (its end), each line printable: whatever it printed (a
    carriage return, an escape sequence, "score 10/10") stays inside its own quoted lines."""
    return [printable(line, 200) for line in result.output.strip().splitlines()]


def dumps(data: dict) -> str:
    return json.dumps(data, indent=2)
