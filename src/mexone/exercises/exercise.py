"""An exercise is a folder: exercise.yaml (what it is and its limits), grader.py (its checks),
statement.md, starter/ and (a teacher's own) solution/. This module reads one and finds them:
shipped ones under mexone/exercises/course/, a teacher's from a path or the `mexone.exercises`
entry-point group. The shipped ones' reference solutions are not in mexone: they are in the
teacher's pack (`pip install ./teacher`), found through the `mexone.solutions` group."""

from __future__ import annotations

import importlib.util
import sys
import traceback
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from types import ModuleType

from mexone import yamlio
from mexone.errors import InputError
from mexone.exercises.isolate import Limits
from mexone.inputs import read_input_text

__all__ = ["Exercise", "LiveController", "SUBMISSION_KINDS", "load_exercise", "find_exercise", "exercises",
           "COURSE", "ENTRY_POINT_GROUP", "SOLUTIONS_GROUP", "TEACHER_PACK"]

COURSE = Path(__file__).resolve().parent / "course"
ENTRY_POINT_GROUP = "mexone.exercises"
SOLUTIONS_GROUP = "mexone.solutions"  # a teacher's pack: <folder>/<exercise>/<file>
TEACHER_PACK = "pip install ./teacher (from a clone of mexone's repository; teachers only)"
# what a student hands in: a rospy routine, a PythonController, a controllers YAML, a routine's
# parameters, a model, JSON, or a Python file of functions the grader calls (ctx.run)
SUBMISSION_KINDS = ("routine", "controller", "gains", "params", "urdf", "json", "function")
_FIELDS = {"name", "title", "points", "pass_mark", "time_limit", "cpu_limit", "memory_mb", "seeds",
           "secret_seed", "submission", "file", "summary", "number", "live", "live_controller"}


@dataclass(frozen=True)
class LiveController:
    """exercise.yaml's `live_controller:` how the page's Check runs a controller plug-in in the
    running lab: its class on these joints (the shipped controllers on the rest), these
    parameters, the robot's joints at `pose` (docs/exercises.md)."""

    cls: str
    joints: tuple[str, ...]
    params: tuple[tuple[str, float | bool | str], ...] = ()
    pose: tuple[tuple[str, float], ...] = ()
    name: str = "student_controller"


@dataclass(frozen=True)
class Exercise:
    """One exercise, as its exercise.yaml says."""

    folder: Path
    name: str
    title: str
    points: float
    pass_mark: float
    submission: str  # one of SUBMISSION_KINDS
    file: str  # the file the student edits and hands in (in starter/ and solution/)
    seeds: tuple[int, ...]  # the fixed episodes every submission runs
    secret_seed: int  # draws the hidden variation (mixed with $MEXONE_EXERCISE_SECRET)
    limits: Limits
    summary: str = ""
    number: int | None = None  # its place in a course (`exercise list` sorts by it)
    live: bool = True  # the page's Check puts the file into the running lab (docs/exercises.md)
    live_controller: LiveController | None = None  # a controller exercise's run on the page

    @property
    def statement(self) -> Path:
        """The exercise's statement (Markdown) in its folder."""
        return self.folder / "statement.md"

    @property
    def starter(self) -> Path:
        """The starter file a student edits, in the exercise's folder."""
        return self.folder / "starter" / self.file

    @property
    def solution(self) -> Path:
        """The reference solution: the exercise's own solution/FILE (a teacher's exercise), else
        the teacher's pack's. The shipped course's are only in the pack, never in mexone's wheel:
        without it this is an InputError saying where they are."""
        own = self.folder / "solution" / self.file
        if own.is_file():
            return own
        for folder in _entry_point_folders(SOLUTIONS_GROUP).values():
            path = folder / self.name / self.file
            if path.is_file():
                return path
        raise InputError(f"no reference solution of '{self.name}' here: the shipped course's are "
                         "in the teacher's pack, not in mexone", hint=TEACHER_PACK)

    def grader(self) -> ModuleType:
        """The exercise's grader.py, imported (it is the teacher's code, run in the grader)."""
        path = self.folder / "grader.py"
        if not path.is_file():
            raise InputError("the exercise has no grader.py", file=self.folder,
                             hint="write grader.py with a grade(ctx) function (docs/exercises.md)")
        spec = importlib.util.spec_from_file_location(f"mexone_exercise_{self.name}", path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # its functions pickle by name into the isolated child
        try:
            spec.loader.exec_module(module)
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - the teacher's file: one line
            sys.modules.pop(spec.name, None)
            raise InputError(f"grader.py does not import: {type(exc).__name__}: "
                             f"{exc.msg if isinstance(exc, SyntaxError) else exc}",
                             file=path, line=_line_in(exc, path),
                             hint="fix the grader; `python3 grader.py` shows the traceback") from None
        if not callable(getattr(module, "grade", None)):
            raise InputError("grader.py has no grade(ctx) function", file=path,
                             hint="def grade(ctx): return [Check(...), ...]")
        return module


def _line_in(exc: BaseException, path: Path) -> int | None:
    """The line of `path` an exception came from (a SyntaxError's own, else the deepest frame
    in that file)."""
    if isinstance(exc, SyntaxError):
        return exc.lineno
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if Path(f.filename) == path]
    return frames[-1].lineno if frames else None


def _number(data: dict, key: str, path: Path, low: float, high: float, default=None,
            integer: bool = False) -> float:
    value = data.get(key, default)
    if value is None:
        raise InputError(f"'{key}' is missing", file=path, hint=f"add '{key}: <number>'")
    if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high \
            or (integer and not isinstance(value, int)):
        kind = "an integer" if integer else "a number"
        raise InputError(f"'{key}' is {value!r}: it must be {kind} from {low:g} to {high:g}",
                         file=path)
    return value


def _flag(data: dict, key: str, path: Path, default: bool = True) -> bool:
    value = data.get(key, default)
    if not isinstance(value, bool):
        raise InputError(f"'{key}' is {value!r}: write true or false", file=path)
    return value


def _live_controller(data: dict, path: Path, name: str) -> LiveController | None:
    raw = data.get("live_controller")
    if raw is None:
        return None
    example = "live_controller: {class: MyLaw, joints: [l_elbow], params: {kp: 5}}"
    if not isinstance(raw, dict) or set(raw) - {"class", "joints", "params", "pose", "name"}:
        raise InputError("'live_controller' must be a mapping of class, joints, params, pose, "
                         "name", file=path, hint=example)
    cls, joints = raw.get("class"), raw.get("joints")
    if not isinstance(cls, str) or not cls.isidentifier():
        raise InputError(f"live_controller: 'class' is {cls!r}: the class name in the file",
                         file=path, hint=example)
    if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
        raise InputError(f"live_controller: 'joints' is {joints!r}: a list of joint names",
                         file=path, hint=example)
    params, pose = raw.get("params") or {}, raw.get("pose") or {}
    if not isinstance(params, dict) or not all(
            isinstance(k, str) and isinstance(v, int | float | bool | str) for k, v in params.items()):
        raise InputError("live_controller: 'params' must map names to values", file=path,
                         hint=example)
    if not isinstance(pose, dict) or not all(
            isinstance(k, str) and isinstance(v, int | float) and not isinstance(v, bool)
            for k, v in pose.items()):
        raise InputError("live_controller: 'pose' must map joint names to angles (rad)",
                         file=path, hint="pose: {l_elbow: -0.6}")
    label = raw.get("name", name)
    if not isinstance(label, str) or not label.replace("_", "").isalnum():
        raise InputError(f"live_controller: 'name' is {label!r}", file=path)
    return LiveController(cls, tuple(joints), tuple(params.items()),
                          tuple((k, float(v)) for k, v in pose.items()), label)


def load_exercise(folder: str | Path) -> Exercise:
    """Read a folder's exercise.yaml (every field checked, one line per mistake)."""
    folder = Path(folder)
    path = folder / "exercise.yaml"
    if not path.is_file():
        raise InputError(f"no exercise.yaml in {folder}", hint="an exercise is a folder with "
                         "exercise.yaml, grader.py, statement.md, starter/ (mexone exercise new)")
    data = yamlio.load(read_input_text(path), path)
    if not isinstance(data, dict):
        raise InputError("exercise.yaml is not a mapping", file=path, hint="name: ..., title: ...")
    unknown = sorted(set(data) - _FIELDS)
    if unknown:
        raise InputError(f"unknown field '{unknown[0]}'", file=path,
                         hint="fields: " + ", ".join(sorted(_FIELDS)))
    name = data.get("name", folder.name)
    if not isinstance(name, str) or not name.replace("_", "").replace("-", "").isalnum():
        raise InputError(f"'name' is {name!r}: use letters, digits, _ and -", file=path)
    kind = data.get("submission")
    if kind not in SUBMISSION_KINDS:
        raise InputError(f"'submission' is {kind!r}", file=path,
                         hint="one of: " + ", ".join(SUBMISSION_KINDS))
    file = data.get("file")
    if not isinstance(file, str) or not file or "/" in file or file.startswith("."):
        raise InputError(f"'file' is {file!r}: the name of the file the student hands in",
                         file=path, hint="e.g. file: routine.py")
    points = _number(data, "points", path, 0.0, 1e6, default=10)
    if points <= 0:
        raise InputError("'points' must be > 0", file=path)
    pass_mark = _number(data, "pass_mark", path, 0.0, points, default=points / 2)
    seeds = data.get("seeds", [0])
    if not isinstance(seeds, list) or not seeds or not all(
            isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds):
        raise InputError(f"'seeds' is {seeds!r}: a list of integers >= 0", file=path,
                         hint="e.g. seeds: [1, 2, 3]")
    wall = _number(data, "time_limit", path, 1.0, 3600.0, default=60.0)
    limits = Limits(time=wall, cpu=_number(data, "cpu_limit", path, 1.0, 7200.0, default=wall),
                    memory_mb=int(_number(data, "memory_mb", path, 256, 65536, default=2048,
                                          integer=True)))
    return Exercise(folder.resolve(), name, str(data.get("title", name)), float(points),
                    float(pass_mark), kind, file, tuple(seeds),
                    int(_number(data, "secret_seed", path, 0, 2**63, default=0, integer=True)),
                    limits, str(data.get("summary", "")),
                    None if data.get("number") is None else
                    int(_number(data, "number", path, 0, 10000, integer=True)),
                    _flag(data, "live", path), _live_controller(data, path, name))


def _course_order(folder: Path) -> tuple:
    """A shipped exercise's place: its exercise.yaml's `number:` (read without checks: a
    broken one is listed as broken), then its name."""
    try:
        data = yamlio.load(read_input_text(folder / "exercise.yaml"))
        number = data.get("number") if isinstance(data, dict) else None
    except Exception:  # noqa: BLE001 - `exercise list` shows why it is broken
        number = None
    return (number if isinstance(number, int) else 10**6, folder.name)


def exercises() -> dict[str, Path]:
    """Every exercise by name: the shipped course, then the entry points' (a teacher's package
    declares `[project.entry-points."mexone.exercises"] name = "package.module"`, the module's
    folder being the exercise's, or "package:FOLDER" for a folder inside it)."""
    found = {p.name: p for p in sorted(COURSE.iterdir(), key=_course_order)
             if (p / "exercise.yaml").is_file()}
    for name, folder in _entry_point_folders(ENTRY_POINT_GROUP).items():
        found.setdefault(name, folder)
    return found


def _entry_point_folders(group: str) -> dict[str, Path]:
    """name -> folder of each entry point of `group`: "package.module" names the module's
    folder, "package:FOLDER" a folder inside it (found without importing the package)."""
    found: dict[str, Path] = {}
    for ep in entry_points(group=group):
        try:
            module, _, sub = ep.value.partition(":")
            spec = importlib.util.find_spec(module)
        except (ImportError, ValueError):
            continue
        if spec is None or spec.origin is None:
            continue
        base = Path(spec.origin).parent
        found.setdefault(ep.name, base / sub if sub else base)
    return found


def find_exercise(name_or_path: str | Path) -> Exercise:
    """An exercise by name (shipped or an entry point's) or by its folder's path."""
    known = exercises()
    if str(name_or_path) in known:
        return load_exercise(known[str(name_or_path)])
    path = Path(name_or_path)
    if path.is_dir():
        return load_exercise(path)
    raise InputError(f"no exercise '{name_or_path}'",
                     hint="give a folder with exercise.yaml or one of: " + ", ".join(known))
