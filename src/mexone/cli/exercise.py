"""`mexone exercise list | show | start | grade | new | autograder`: exercises a teacher assigns
and grades."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

from mexone.cli.sweep import WORKERS, check_ray_address
from mexone.errors import InputError, OutputExistsError, printable
from mexone.files import check_output, replacing, write_text

HELP = """\
Exercises: a statement, a starter file, a grader with fixed seeds and a hidden variation of the
robot (mass, damping, friction) drawn from a secret seed. `start` writes an exercise's statement,
starter and a self-check (check.py) into a folder for a student; `grade` runs a submission
headless in its own process with CPU-time and memory limits and prints each check and the
score (--json: Gradescope's results.json); given a folder of submissions, --csv writes one row
per student. `new` writes a teacher's own exercise that grades as written (docs/exercises.md).
`autograder` writes Gradescope's autograder zip for an exercise (docs/teaching.md).

A submission that raises, hangs, exits or runs out of memory gets 0 points with the reason:
that is a grade, exit status 0. exit status: 0 graded, 2 bad input (a missing file, a broken
exercise)"""

CHECK_PY = '''"""Self-check for the exercise {name}: grades your {file} on the nominal robot.
The real grade uses other seeds and a hidden variation of the robot."""

import sys
from pathlib import Path

from mexone.exercises import self_check

sys.exit(self_check({name!r}, str(Path(__file__).resolve().parent / {file!r})))
'''


def add_parser(sub) -> None:
    p = sub.add_parser("exercise", help="list, start and grade exercises",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="action", metavar="<action>", required=True)
    verbs.add_parser("list", help="the exercises there are")
    s = verbs.add_parser("show", help="print an exercise's statement")
    s.add_argument("name", help="exercise name or folder")
    s = verbs.add_parser("start", help="write an exercise's statement, starter and check.py")
    s.add_argument("name", help="exercise name or folder")
    s.add_argument("dir", nargs="?", type=Path, help="where (default: ./NAME)")
    s.add_argument("--force", action="store_true", help="overwrite files already there")
    s = verbs.add_parser("grade", help="grade a submission (or a folder of them)")
    s.add_argument("name", help="exercise name or folder")
    s.add_argument("submission", type=Path,
                   help="the student's file, or a folder of submissions (one per student: a "
                        "subfolder holding the file, or NAME.<same suffix>)")
    s.add_argument("--json", type=Path, nargs="?", const=Path("-"), metavar="FILE",
                   help="write Gradescope's results.json (to FILE, default stdout)")
    s.add_argument("--csv", type=Path, metavar="FILE", help="a folder's grades as CSV (-: on "
                   "stdout, the progress on stderr)")
    s.add_argument("--plots", type=Path, metavar="DIR", help="save the grader's plots here")
    s.add_argument("--local", action="store_true",
                   help="the self-check: the nominal robot, no hidden variation")
    s.add_argument("--workers", type=WORKERS, default=1, metavar="N",
                   help="grade a folder's submissions N at a time, each in its own isolated "
                        "process (default 1; the report and CSV are the same in any case)")
    s.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="grade on this machine's processes, or as Ray tasks (the cluster at "
                        "--address, else a local Ray of --workers CPUs; the `cluster` extra)")
    s.add_argument("--address", help="the Ray cluster's address (ray://HOST:10001, HOST:6379 or "
                   "auto; its nodes started with $MEXONE_EXERCISE_SECRET exported)")
    s.add_argument("--force", action="store_true", help="overwrite --json/--csv files and "
                   "--plots PNGs")
    s = verbs.add_parser("new", help="write a new exercise folder that grades as written")
    s.add_argument("name", help="the new exercise's name (letters, digits, _)")
    s.add_argument("dir", nargs="?", type=Path, help="where (default: ./NAME)")
    s.add_argument("--force", action="store_true", help="overwrite files already there")
    s = verbs.add_parser("autograder", help="write Gradescope's autograder zip for an exercise")
    s.add_argument("name", help="exercise name or folder")
    s.add_argument("-o", "--output", type=Path, default=Path("autograder.zip"),
                   help="the zip to write (default: autograder.zip)")
    s.add_argument("--wheel", type=Path, help="mexone's wheel to carry (default: built from "
                   "the mexone that runs this)")
    s.add_argument("--force", action="store_true", help="overwrite the zip")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    return {"list": _list, "show": _show, "start": _start, "grade": _grade,
            "new": _new, "autograder": _autograder}[args.action](args)


def _list(_args) -> int:
    from mexone.exercises.exercise import exercises, load_exercise

    found = exercises()
    width = max((len(name) for name in found), default=0)
    for name, folder in found.items():
        try:
            ex = load_exercise(folder)
            print(f"{name:<{width}} {ex.points:>4g} pts  {ex.submission:<10} {ex.title}"
                  + (f": {ex.summary}" if ex.summary else ""))
        except InputError as exc:
            print(f"{name:<{width}} broken: {exc.one_line()}")
    return 0


def _show(args) -> int:
    from mexone.exercises.exercise import find_exercise

    ex = find_exercise(args.name)
    print(ex.statement.read_text() if ex.statement.is_file() else ex.title)
    print(f"\nhand in: {ex.file} ({ex.submission}); {ex.points:g} points, pass mark "
          f"{ex.pass_mark:g}; {ex.limits.time:g} s per episode, {len(ex.seeds)} episodes")
    return 0


def _copy_tree(files: dict[Path, Path | str], force: bool) -> None:
    """Write every (destination: source path or text) or none: refused if one exists, or if
    a folder it needs is a file."""
    for dest in files:
        folder = dest.parent
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        if not folder.is_dir():
            raise InputError("is a file, not a folder", file=folder, hint="name a folder")
    clash = [d for d in files if d.exists()]
    if clash and not force:
        raise OutputExistsError(f"{clash[0]} exists", hint="give another folder or --force")
    for dest, source in files.items():
        dest.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(source, Path):
            shutil.copyfile(source, dest)
        else:
            dest.write_text(source)


def _handed_out(path: Path) -> bool:
    """A file of the exercise's folder the student gets: not the bytecode that pip (or a
    teacher's test run) compiled next to the starter."""
    return path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc"


def _start(args) -> int:
    from mexone.exercises.exercise import find_exercise

    ex = find_exercise(args.name)
    dest = args.dir or Path(ex.name)
    files: dict[Path, Path | str] = {dest / "README.md": ex.statement}
    starter = ex.folder / "starter"
    for path in sorted(starter.rglob("*")) if starter.is_dir() else []:
        if _handed_out(path):
            files[dest / path.relative_to(starter)] = path
    figures = ex.folder / "figures"
    for path in sorted(figures.rglob("*")) if figures.is_dir() else []:
        if _handed_out(path):
            files[dest / "figures" / path.relative_to(figures)] = path
    extra = getattr(ex.grader(), "files", None)  # optional: more files the student needs
    for name, text in (extra() if callable(extra) else {}).items():
        if not isinstance(name, str) or not isinstance(text, str) or Path(name).name != name \
                or name in ("", ".", "..", "check.py", "README.md", ex.file):
            raise InputError(f"files() names {name!r}: a file name (no folder) for text, not the "
                             "statement, the starter or check.py", file=ex.folder / "grader.py",
                             hint="return {'controllers.yaml': text, ...}")
        files[dest / name] = text
    files[dest / "check.py"] = CHECK_PY.format(name=ex.name if ex.folder.parent.name == "course"
                                               else str(ex.folder), file=ex.file)
    _copy_tree(files, args.force)
    more = "".join(f", {p.name}" for p in files if p.parent == dest and p.name not in
                   ("README.md", ex.file, "check.py"))
    print(f"mexone: wrote {ex.title} to {dest}/: README.md (the statement), {ex.file} (your "
          f"starting point){more}, check.py (python3 {dest}/check.py checks it)")
    return 0


def _grade(args) -> int:
    from tqdm import tqdm

    from mexone.exercises.exercise import find_exercise
    from mexone.exercises.grading import (
        as_text,
        grade,
        gradescope_json,
        submissions_in,
        write_csv,
    )
    from mexone.exercises.pool import grade_all

    ex = find_exercise(args.name)
    if args.address is not None:
        check_ray_address(args.address, args.backend)
    for out in (args.json, args.csv):  # before any grading: a class's grades take minutes
        if out is not None and out != Path("-"):
            if out.exists() and not out.is_dir() and not args.force:
                raise OutputExistsError(f"{out} exists", hint="give another file or --force")
            check_output(out, force=True)  # a folder, a missing or read-only folder
    if args.plots is not None and args.plots.exists() and not args.plots.is_dir():
        raise InputError("--plots names a file, not a folder", file=args.plots,
                         hint="give a folder; it is created if missing")
    if args.submission.is_dir():
        if args.json is not None:
            raise InputError("--json writes one submission's results.json",
                             hint="grade a folder with --csv, or each file with --json")
        found = submissions_in(args.submission, ex.file)
        if not found:
            raise InputError(f"no submissions in {args.submission}",
                             hint=f"one subfolder per student holding {ex.file}, or "
                                  f"STUDENT{Path(ex.file).suffix} files")
        if args.plots is not None:
            _plots_clear(ex, [args.plots / student for student in found], args.force)
        results = {}
        to_stdout = args.csv == Path("-")
        report = sys.stderr if to_stdout else sys.stdout
        # submissions done / total, on a terminal only: a test's or a pipe's stderr stays clean
        bar = tqdm(total=len(found), unit="submission", desc="grading", leave=False,
                   disable=not sys.stderr.isatty())
        try:
            for student, result in grade_all(ex, found, args.workers, local=args.local,
                                             plots=args.plots, force=args.force,
                                             backend=args.backend, address=args.address,
                                             progress=bar.update):
                results[student] = result
                line = (f"{printable(student, 80):<24} {result.score:6.2f}/{result.max_score:g} "
                        f"{'passed' if result.passed else 'not passed':<11} "
                        + (result.failure or " ".join(f"FAIL {n}" for n in result.failing)))
                bar.write(line, file=report)  # above the bar (print() when there is none)
                report.flush()
        finally:
            bar.close()
        if to_stdout:  # was: a file named "-"
            with tempfile.TemporaryDirectory() as tmp:
                write_csv(results, Path(tmp) / "grades.csv")
                sys.stdout.write((Path(tmp) / "grades.csv").read_text())
        elif args.csv:
            with replacing(args.csv, args.force) as temporary:
                write_csv(results, temporary)
            print(f"mexone: wrote {args.csv} ({len(results)} submissions)")
        return 0
    if args.csv:
        raise InputError("--csv grades a folder of submissions", hint="give a folder")
    if args.plots is not None:
        _plots_clear(ex, [args.plots], args.force)
    result = grade(ex, args.submission, local=args.local, plots=args.plots, force=args.force)
    if args.json is not None:
        text = json.dumps(gradescope_json(result), indent=2)
        if args.json == Path("-"):
            print(text)
            print(as_text(result), file=sys.stderr)
            return 0
        write_text(args.json, text + "\n", args.force)
    print(as_text(result))
    return 0


def _plots_clear(ex, folders: list[Path], force: bool) -> None:
    """Before any grading: refuse --plots folders that hold this exercise's PNGs (without
    --force), naming the first; or that cannot be written in."""
    from mexone.exercises.grading import existing_plots

    for folder in folders:
        if folder.exists() and not folder.is_dir():
            raise InputError("is a file, not a folder for the plots", file=folder,
                             hint="give another --plots folder")
        if folder.is_dir():
            check_output(folder / "plot.png", force=True)  # a read-only folder
        clash = [] if force else existing_plots(ex, folder)
        if clash:
            raise OutputExistsError("already exists; nothing was graded", file=clash[0],
                                    hint="pass --force to overwrite the plots, or give another "
                                         "--plots folder")


def _new(args) -> int:
    from mexone.exercises.exercise import COURSE

    name = args.name
    if not name.replace("_", "").isalnum() or not name[0].isalpha():
        raise InputError(f"'{name}' is not a name", hint="letters, digits and _, e.g. my_arms")
    dest = args.dir or Path(name)
    template = COURSE.parent / "template"
    files: dict[Path, Path | str] = {}
    for path in sorted(template.rglob("*")):
        if path.is_file() and "__pycache__" not in path.parts:
            files[dest / path.relative_to(template)] = path.read_text().replace("TEMPLATE", name)
    _copy_tree(files, args.force)
    print(f"mexone: wrote the exercise {name} to {dest}/ (grade its solution: mexone exercise "
          f"grade {dest} {dest}/solution/routine.py)")
    return 0


def _autograder(args) -> int:
    import os

    from mexone.exercises.autograder import write_bundle
    from mexone.exercises.grading import SECRET_ENV, SECRET_MIN

    secret = os.environ.get(SECRET_ENV, "")
    if len(secret) < SECRET_MIN:  # the zip could grade nothing (grading.hidden_rng refuses it)
        said = "is not set" if not secret else f"has {len(secret)} characters"
        raise InputError(f"${SECRET_ENV} {said}: the zip carries the secret your grades are "
                         f"keyed by (at least {SECRET_MIN} characters)",
                         hint=f"export {SECRET_ENV}=<the secret you grade with>")
    bundle = write_bundle(args.name, args.output, args.force, args.wheel, secret)
    print(f"mexone: wrote {bundle.path} (Gradescope's autograder: setup.sh, run_autograder, "
          f"{bundle.wheel}, your secret): upload it as "
          "the assignment's autograder, Ubuntu base image")
    return 0
