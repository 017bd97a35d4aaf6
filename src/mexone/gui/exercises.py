"""The Exercises panel (`mexone sim --exercise NAME_OR_DIR`): the statement, the student's file
and a Check button, on the page of the running lab.

Check does two things with the file the student edits (the started folder's, never a path the
page sends):

1. it puts the file into the running lab where that means something (simulation thread):
   a gains YAML retunes the running controllers of the same names and resets the robot (the
   episode from t = 0, with your gains, on the page); a Python controller the lab runs from
   that file is reloaded in place (the Controllers panel's Reload); a URDF is opened by Load
   (the View panel's Center of Mass and Inertia show what the checks mean) -- code and models
   only after the self-check below ran them (one that hangs or crashes there is never imported
   into the page's process). A routine is never started by Check (a routine runs in the
   simulator's process: one that hangs would stall the lab): it is listed in the Routines
   panel, to Start by hand;
2. it runs the exercise's self-check (`python3 check.py`: the grader on the nominal robot, the
   student's part in a process of its own with the exercise's limits) in a worker process, and
   shows each check, its points, the score and the failing checks' names.

The page and the simulation never wait for a check: it runs in a process group of its own,
which the worker thread watches and ends at the budget or when the page closes; a second Check
while one runs is refused. See docs/exercises.md.
"""

from __future__ import annotations

import ast
import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import viser

from mexone import yamlio
from mexone.errors import InputError, MexoneError
from mexone.exercises.exercise import Exercise, exercises, find_exercise
from mexone.gui.panels import Panel, register_panel
from mexone.physics.compile import Spawn

__all__ = ["ExercisesPanel", "ExerciseTarget", "open_exercise", "CheckOutcome", "run_self_check",
           "check_budget", "inside", "fenced", "outcome_markdown", "outcome_summary", "LIVE"]

LIVE = {  # what Check does in the running lab, per submission kind (docs/exercises.md)
    "gains": "retunes the running controllers of the same names with your gains and resets "
             "the robot",
    "controller": "reloads your controller where the lab runs it from your file, or restarts "
                  "the lab with it where the exercise says how (once the self-check ran it)",
    "routine": "starts nothing: your routine is in the Routines panel's list, to Start by hand",
    "urdf": "opens your model (Load): see View > Center of Mass / Inertia",
    "params": "nothing: the self-check runs it",
    "json": "nothing: the self-check runs it",
    "function": "nothing: the self-check runs it",
}
MAX_SHOWN = 200_000  # bytes of a file shown on the page
STARTUP = 60.0  # s: a grading process's start-up and the grader's own work, beyond the limits


@dataclass(frozen=True)
class ExerciseTarget:
    """What --exercise named: the exercise, and the folder `mexone exercise start` wrote (None:
    the statement only; Check says how to start it)."""

    exercise: Exercise
    folder: Path | None

    @property
    def submission(self) -> Path | None:
        return None if self.folder is None else self.folder / self.exercise.file

    @property
    def live(self) -> str:
        """The submission kind's live step, or "" when the exercise says it has none."""
        if not self.exercise.live:
            return ""
        kind = self.exercise.submission
        return kind if kind in ("gains", "controller", "routine", "urdf") else ""


def _started_name(check_py: Path) -> str | None:
    """The exercise a started folder's check.py checks: self_check('NAME', ...)'s first
    argument, read without running the file."""
    try:
        tree = ast.parse(check_py.read_text(), str(check_py))
    except (OSError, SyntaxError, ValueError):
        return None
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "self_check" \
                and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            return node.args[0].value
    return None


def open_exercise(name_or_dir: str | Path, cwd: Path | None = None) -> ExerciseTarget:
    """A folder `mexone exercise start` wrote (its check.py names the exercise), or an
    exercise's name or folder (with ./NAME as the started folder when it is one)."""
    path = Path(name_or_dir)
    if path.is_dir() and (path / "check.py").is_file():
        name = _started_name(path / "check.py")
        if name is None:
            raise InputError("check.py does not name its exercise", file=path / "check.py",
                             hint="write the folder again: mexone exercise start NAME DIR --force")
        exercise = find_exercise(name)
        if not (path / exercise.file).is_file():
            raise InputError(f"no {exercise.file} in {path}", hint="it is the file you hand in: "
                             f"copy it back, or mexone exercise start {exercise.name} {path} --force")
        return ExerciseTarget(exercise, path.resolve())
    exercise = find_exercise(name_or_dir)
    started = (cwd or Path.cwd()) / exercise.name
    if (started / "check.py").is_file() and _started_name(started / "check.py") in (
            exercise.name, str(exercise.folder)) and (started / exercise.file).is_file():
        return ExerciseTarget(exercise, started.resolve())
    return ExerciseTarget(exercise, None)


def inside(folder: Path, name: str) -> Path:
    """`folder/name` if that names a regular file directly in `folder` (no other folder, no
    link out of it), else a refusal: a page's message may name anything."""
    text = str(name)
    refusal = InputError(f"'{' '.join(text[:80].splitlines())}' is not a file of the exercise "
                         f"folder {folder}", hint="pick one from the list")
    if not text or "/" in text or "\\" in text or text in (".", "..") or "\0" in text:
        raise refusal
    candidate = folder / text
    if candidate.is_symlink() or not candidate.is_file() \
            or candidate.resolve().parent != folder.resolve():
        raise refusal
    return candidate


@dataclass
class CheckOutcome:
    """One Check's result: the grader's report (Gradescope's JSON) or why there is none."""

    report: dict | None = None
    error: str | None = None  # the check could not run at all (one line)
    seconds: float = 0.0
    live: str = ""  # what Check did in the running lab
    checks: list[dict] = field(default_factory=list)

    @property
    def failing(self) -> list[str]:
        return [t["name"] for t in self.checks if t.get("status") != "passed"]


def _command(exercise: Exercise, submission: Path) -> list[str]:
    argv = [sys.executable, "-m", "mexone", "exercise", "grade", str(exercise.folder),
            str(submission), "--local", "--json", "-"]
    nice = shutil.which("nice")
    return [nice, "-n", "5", *argv] if nice else argv  # the live lab keeps its share of the CPU


def check_budget(exercise: Exercise) -> float:
    """Wall seconds a self-check may take before the panel ends it: three isolated runs per
    episode at the exercise's limit, plus start-up (the grader's own limits end a hanging
    submission long before)."""
    return STARTUP + 3 * exercise.limits.time * len(exercise.seeds)


def run_self_check(exercise: Exercise, submission: Path, cancel: threading.Event,
                   started: list | None = None) -> CheckOutcome:
    """`mexone exercise grade FOLDER FILE --local --json -` in a process group of its own;
    its report. Ends the group at the budget or when `cancel` is set. (A worker thread's.)"""
    began = time.monotonic()
    budget = check_budget(exercise)
    try:
        proc = subprocess.Popen(_command(exercise, submission), cwd=submission.parent,
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, start_new_session=True)
    except OSError as exc:
        return CheckOutcome(error=f"could not start the grading process: {exc.strerror}")
    if started is not None:
        started.append(proc)
    reason = None
    try:
        while True:
            try:
                out, err = proc.communicate(timeout=0.2)
                break
            except subprocess.TimeoutExpired:
                if cancel.is_set():
                    reason = "stopped: the page closed"
                elif time.monotonic() - began > budget:
                    reason = f"the self-check took more than {budget:g} s and was stopped"
                if reason:
                    _end(proc)
                    out, err = proc.communicate()
                    break
    finally:
        _end(proc)
    seconds = time.monotonic() - began
    if reason:
        return CheckOutcome(error=reason, seconds=seconds)
    report = _report(out.decode("utf-8", "replace"))
    if proc.returncode != 0 or not isinstance(report, dict):
        lines = [line for line in err.decode("utf-8", "replace").splitlines() if line.strip()]
        said = next((line for line in reversed(lines) if line.startswith("mexone:")),
                    lines[-1] if lines else f"exit status {proc.returncode}")
        return CheckOutcome(error=f"the self-check did not run: {said.strip()[:300]}",
                            seconds=seconds)
    return CheckOutcome(report=report, seconds=seconds, checks=list(report.get("tests", [])))


def _report(text: str) -> dict | None:
    """The results.json `grade --json -` printed last (a grader's own prints may come first)."""
    at = 0 if text.startswith("{") else text.rfind("\n{\n") + 1
    if at == 0 and not text.startswith("{"):
        return None
    try:
        report = json.loads(text[at:])
    except ValueError:
        return None
    return report if isinstance(report, dict) else None


def _end(proc: subprocess.Popen) -> None:
    """End the grading process and everything it started (its own process group)."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=5)
    else:  # its leader is gone: whatever it left in its group goes too
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGKILL)


def _cell(text: object) -> str:
    """Text from a grader or a submission's error as plain text in a table cell (no markup of
    its own: a student's exception message is not HTML for the page)."""
    one_line = " ".join(str(text)[:300].splitlines())  # \r, \x1e, \u2028 break lines too
    return (one_line.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace("|", "\\|"))


def fenced(text: str, lang: str = "") -> str:
    """`text` as a code block no line of it can close (a fence longer than its backtick runs)."""
    longest = max((len(run) for run in re.findall(r"`+", text)), default=0)
    fence = "`" * max(3, longest + 1)
    return f"{fence}{lang}\n{text}\n{fence}"


def outcome_markdown(exercise: Exercise, outcome: CheckOutcome) -> str:
    """The result block the page shows: each check, its points, the score, what failed."""
    lines = []
    if outcome.live:
        lines.append(f"*in the lab:* {_cell(outcome.live)}")
        lines.append("")
    if outcome.error:
        lines.append(f"**Check failed to run** — {_cell(outcome.error)}")
        return "\n".join(lines)
    report = outcome.report or {}
    extra = report.get("extra_data", {})
    top = extra.get("max_score", exercise.points)
    verdict = "passed" if extra.get("passed") else "not passed"
    lines.append(f"**score {report.get('score', 0):g}/{top:g}** ({verdict}; pass mark "
                 f"{exercise.pass_mark:g}) in {outcome.seconds:.1f} s")
    if extra.get("failure"):
        lines.append("")
        lines.append(f"**your submission did not run:** {_cell(extra['failure'])}")
    lines += ["", "| | check | points | |", "|---|---|---|---|"]
    for test in outcome.checks:
        mark = "✅" if test.get("status") == "passed" else "❌"
        lines.append(f"| {mark} | {_cell(test.get('name', '?'))} | {test.get('score', 0):g}/"
                     f"{test.get('max_score', 0):g} | {_cell(test.get('output', ''))} |")
    if outcome.failing:
        lines += ["", "failing: " + ", ".join(f"**{_cell(n)}**" for n in outcome.failing)]
    lines += ["", "*the self-check: the nominal robot; the grade adds a hidden variation*"]
    return "\n".join(lines)


@register_panel
class ExercisesPanel(Panel):
    """The statement, the student's file and Check (see the module's doc)."""

    name = "exercises"
    order = 0
    period = 5

    def __init__(self, host):
        super().__init__(host)
        self.started: ExerciseTarget = host.settings.exercise  # what --exercise named
        self.cwd = Path.cwd()  # where `mexone exercise start NAME` puts ./NAME
        self.target = self.started
        self._offer_routine()
        self.outcome: CheckOutcome | None = None
        self.running_since: float | None = None
        self._worker: threading.Thread | None = None
        self._procs: list[subprocess.Popen] = []
        self._cancel = threading.Event()
        self._lock = threading.Lock()
        self._shown_outcome: object = None
        self._notified: object = None
        self.shown_file: str | None = None
        self._scratch: Path | None = None  # the live controller's YAML and file copy

    @classmethod
    def wanted(cls, host) -> bool:
        return host.settings.exercise is not None

    def _offer_routine(self) -> None:
        """A started routine exercise's file in the Routines panel's list (to Start by hand)."""
        routines = self.host.extra_routines
        for key in [k for k in routines if k.startswith("exercise: ")]:
            del routines[key]
        if self.target.folder is not None and self.target.live == "routine":
            routines[f"exercise: {self.target.exercise.file}"] = self.target.submission

    def choices(self) -> dict[str, ExerciseTarget | str]:
        """The Exercise list: the one --exercise named (its started folder), then the course's
        and the entry points' by name."""
        first = self.started.exercise.name
        if self.started.folder is not None:
            first += f" ({self.started.folder.name}/)"
        return {first: self.started, **{name: name for name in exercises()
                                         if name != first}}

    def _label(self) -> str:
        for label, choice in self.choices().items():
            if choice is self.target or (isinstance(choice, str) and self.target is not
                                         self.started and choice == self.target.exercise.name):
                return label
        return next(iter(self.choices()))

    def choose(self, label: str) -> None:
        """Simulation thread: show another exercise (one of the list; never a path a page
        sent), with ./NAME as its started folder if it is one."""
        try:
            if self.running:
                raise InputError("a check is running: pick another exercise when it ends")
            choice = self.choices().get(label)
            if choice is None:
                raise InputError(f"'{str(label)[:80]}' is not an exercise this page offers",
                                 hint="pick one from the list")
        except InputError:
            self.pick.value = self._label()
            raise
        if label == self._label():
            return
        self.target = choice if isinstance(choice, ExerciseTarget) else \
            open_exercise(choice, cwd=self.cwd)
        self.outcome = None
        self._offer_routine()
        routines = self.host.panel("routines")
        if routines is not None:
            routines.refresh()
        self._order = self.folder.order  # rebuilt where it was
        self.folder.remove()
        self.build()

    # ----- the page ----------------------------------------------------------------------------
    def files(self) -> dict[str, Path]:
        """The started folder's files the page may show (the statement, the submission, ...)."""
        folder = self.target.folder
        if folder is None:
            return {}
        found = {}
        for path in sorted(folder.iterdir()):
            if path.is_file() and not path.is_symlink() and not path.name.startswith(".") \
                    and path.suffix in (".md", ".py", ".yaml", ".yml", ".urdf", ".json", ".txt"):
                found[path.name] = path
        return found

    def build(self) -> None:
        ex, gui = self.target.exercise, self.server.gui
        order, self._order = getattr(self, "_order", None), None  # first (order 0) unless rebuilt
        self.folder = gui.add_folder("Exercises", order=order)
        folder = self.target.folder
        with self.folder:
            labels = tuple(self.choices())
            self.pick = gui.add_dropdown("Exercise", labels, initial_value=self._label(),
                                         hint="the one mexone sim --exercise named, and the "
                                              "course's (./NAME if you started it there)")
            self.pick.on_update(lambda e: e.client is not None and self.host.do(
                lambda v=e.target.value: self.choose(v)))
            gui.add_markdown(f"### {ex.number or ''}{'. ' if ex.number else ''}{ex.title}\n"
                             f"hand in **{ex.file}** ({ex.submission}): {ex.points:g} points, pass "
                             f"mark {ex.pass_mark:g}")
            statement = folder / "README.md" if folder and (folder / "README.md").is_file() \
                else ex.statement
            with gui.add_folder("Statement", expand_by_default=False):
                self.statement = gui.add_markdown(self._read(statement),
                                                  image_root=statement.parent)
            with gui.add_folder("Your file", expand_by_default=False):
                names = tuple(self.files()) or ("(not started)",)
                first = ex.file if ex.file in names else names[0]
                self.file_choice = gui.add_dropdown("File", names, initial_value=first,
                                                    hint=f"the files of {folder}")
                self.file_view = gui.add_markdown("")
                self.file_choice.on_update(lambda e: self.host.do(
                    lambda v=e.target.value: self.show_file(v)))
            where = f"`{self.target.submission}`" if folder else \
                f"not started: `mexone exercise start {ex.name} DIR`, then `mexone sim " \
                "--exercise DIR`"
            live = LIVE.get(self.target.live, "") if self.target.live else "nothing"
            gui.add_markdown(f"Check grades {where} on the nominal robot (as `python3 check.py`); "
                             f"in this lab it {live}.")
            self.check_button = gui.add_button("Check", icon=viser.Icon.CHECKLIST,
                                               hint="run the exercise's self-check on your file")
            self.check_button.on_click(lambda _: self.host.do(self.check))
            self.result = gui.add_markdown("*no check yet*")
        self._shown_outcome = None
        if folder is not None:
            self.show_file(first)
        self.update()

    def _read(self, path: Path) -> str:
        try:
            data = path.read_bytes()[:MAX_SHOWN]
        except OSError as exc:
            return f"*{path.name}: {exc.strerror}*"
        return data.decode("utf-8", "replace")

    def show_file(self, name: str) -> None:
        """Simulation thread: show one file of the started folder (never one elsewhere)."""
        if self.target.folder is None:
            raise InputError(f"{self.target.exercise.name} is not started",
                             hint=f"mexone exercise start {self.target.exercise.name} DIR")
        path = inside(self.target.folder, name)
        if path.name not in self.files():  # a hidden or binary file of the folder: not listed
            raise InputError(f"'{path.name}' is not one of the files this page shows",
                             hint="pick one from the list")
        text = self._read(path)
        if path.suffix == ".md":
            shown = text
        else:
            lang = {".py": "python", ".yaml": "yaml", ".yml": "yaml", ".urdf": "xml"}.get(
                path.suffix, "")
            shown = fenced(text, lang)
        self.shown_file = path.name
        self.file_view.content = shown

    # ----- Check -------------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        return self.running_since is not None

    def check(self) -> None:
        """Simulation thread: the self-check in a worker; the live step now for a gains file
        (no code of the student's runs), after the self-check for a file of code or a model
        (only one that ran there is imported into the page's process)."""
        ex = self.target.exercise
        if self.running:
            raise InputError(f"a check of {ex.name} is running ({time.monotonic() - self.running_since:.0f} "
                             "s so far): wait for its result")
        if self.target.folder is None:
            raise InputError(f"{ex.name} is not started: there is no file to check",
                             hint=f"mexone exercise start {ex.name} DIR, then mexone sim "
                                  "--exercise DIR")
        submission = inside(self.target.folder, ex.file)
        self.file_choice.options = tuple(self.files()) or ("(not started)",)
        self.file_choice.value = ex.file
        self.show_file(ex.file)  # the file as it is checked
        later = self.target.live in ("controller", "urdf")
        live = "" if later else self._live(submission)
        self.running_since = time.monotonic()
        self.outcome = None
        self._cancel.clear()
        self._worker = threading.Thread(target=self._work, args=(submission, live, later),
                                        daemon=True, name="exercise-check")
        self._worker.start()
        self.update()

    def _work(self, submission: Path, live: str, later: bool) -> None:
        """Worker thread: the self-check; then the live step handed to the simulation thread."""
        try:
            outcome = run_self_check(self.target.exercise, submission, self._cancel, self._procs)
        except Exception as exc:  # noqa: BLE001 - shown on the page; the lab goes on
            outcome = CheckOutcome(error=f"{type(exc).__name__}: {exc}")
        with self._lock:
            self._procs.clear()
        outcome.live = live
        if not later:
            self._publish(outcome)
        elif outcome.report is None or outcome.report.get("extra_data", {}).get("failure"):
            outcome.live = "not applied: your file did not run in the self-check"
            self._publish(outcome)
        elif not self._cancel.is_set():
            self.host.do(lambda: self._live_then_publish(submission, outcome))

    def _live_then_publish(self, submission: Path, outcome: CheckOutcome) -> None:
        """Simulation thread: the live step after a self-check the file ran in."""
        try:
            outcome.live = self._live(submission)
        except Exception as exc:  # noqa: BLE001 - a bug here must not end the page's loop
            outcome.live = f"not applied: {type(exc).__name__}: {exc}"
        self._publish(outcome)
        self.update()

    def _publish(self, outcome: CheckOutcome) -> None:
        with self._lock:
            self.outcome = outcome
            self.running_since = None

    def _live(self, submission: Path) -> str:
        """Simulation thread: put the file into the running lab (one line on what it did; a
        file the lab cannot take is said, and the self-check runs all the same)."""
        kind = self.target.live
        try:
            if kind == "gains":
                return self._live_gains(submission)
            if kind == "controller":
                return self._live_controller(submission)
            if kind == "urdf":
                self.host.load(submission)  # rebuilds every panel, this one too
                return f"opened {submission.name} (Load)"
        except MexoneError as exc:
            return f"not applied: {exc.one_line()}"
        return ""

    def _live_gains(self, submission: Path) -> str:
        from mexone.control.config import CONTROLLER_TYPES, parse_control_config

        manager = self.host.lab.manager
        if manager is None:
            return "not applied: this lab runs no controllers"
        text = submission.read_text(encoding="utf-8", errors="replace")
        raw = yamlio.load(text, submission)
        types = [v.get("type") for space in (raw or {}).values() if isinstance(space, dict)
                 for v in [space, *space.values()] if isinstance(v, dict) and "type" in v]
        other = [t for t in types if t not in CONTROLLER_TYPES]
        if other:  # a plug-in's file would be imported here: gains files name shipped types only
            return f"not applied: '{str(other[0])[:60]}' is not a shipped controller type"
        config = parse_control_config(text, submission)
        done = []
        for name, spec in config.controllers.items():
            ctrl = manager.controllers.get(name)
            if spec.pid is None or ctrl is None or ctrl.gains is None:
                continue
            manager.set_gains(name, spec.pid)
            done.append(name)
        if not done:
            return "not applied: no controller of your file runs in this lab with PID gains"
        self._show_gains(done)
        self.host.reset_model()  # the episode from t = 0, with the new gains
        return f"your gains retune {len(done)} running controllers; the robot was reset"

    def _show_gains(self, names: list[str]) -> None:
        """The Joints panel's Gains fields show what the controllers now hold."""
        from mexone.control.spec import joint_label

        manager = self.host.lab.manager
        fields = {getattr(f.handle, "label", None): f.handle for f in self.host.fields.fields}
        for name in names:
            gains = manager.controllers[name].gains[0]
            for key in ("p", "i", "d"):
                handle = fields.get(f"{key} ({joint_label(name)})")
                if handle is not None:
                    self.host.fields.set_held(handle, [float(getattr(gains, key))])

    def _live_controller(self, submission: Path) -> str:
        manager = self.host.lab.manager
        mine = [n for n, c in (manager.controllers.items() if manager else ())
                if c.code_file and Path(c.code_file).resolve() == submission.resolve()]
        for name in mine:  # the lab runs it from the student's own file: the panel's Reload
            manager.reload(name)
        if mine:
            return f"reloaded {', '.join(mine)} from {submission.name}"
        live = self.target.exercise.live_controller
        if live is None:
            return (f"not reloaded: this lab runs no controller from {submission.name} (give mexone "
                    "sim --controllers a YAML that uses it to watch it here)")
        yaml_path = self._live_yaml(submission, live)
        self.host.load(None, controllers=yaml_path, spawn=Spawn(joints=live.pose))
        return (f"the lab restarted with your {live.cls} on {', '.join(live.joints)} (the "
                "Controllers panel shows it; a fault there is your controller's)")

    def _live_yaml(self, submission: Path, live) -> Path:
        """A controllers YAML in a scratch folder of the panel's: a copy of the student's file,
        its class on the exercise's joints, the running lab's controllers on the others."""
        import yaml

        from mexone.robots import mex_one

        if self._scratch is None:
            self._scratch = Path(tempfile.mkdtemp(prefix="mexone-exercise-page-"))
        manager = self.host.lab.manager
        given = manager.config.parameters if manager is not None else None
        if not isinstance(given, dict) or not given:
            given = yaml.safe_load(Path(mex_one.controllers_path()).read_text())
        spaces = [(k, v) for k, v in given.items() if isinstance(v, dict) and "type" not in v]
        ns, controllers = spaces[0] if len(spaces) == 1 and len(given) == 1 else (None, given)
        claimed = set(live.joints)

        def free(entry) -> bool:
            if not isinstance(entry, dict) or "type" not in entry:
                return True
            joints = {entry.get("joint"), *(entry.get("joints") or [])} - {None}
            return not joints & claimed

        kept = {k: v for k, v in controllers.items() if free(v) and k != live.name}
        stem = f"exercise_{self.target.exercise.name}"  # the copy's module name
        shutil.copyfile(submission, self._scratch / f"{stem}.py")
        entry = {"type": f"{stem}/{live.cls}", "joints": list(live.joints), **dict(live.params)}
        body = {live.name: entry, **kept}
        path = self._scratch / "controllers.yaml"
        path.write_text(yaml.safe_dump({ns: body} if ns else body, sort_keys=False))
        return path

    def update(self) -> None:
        """Simulation thread: the result block (a worker's outcome lands here)."""
        with self._lock:
            outcome, since = self.outcome, self.running_since
        if since is not None:
            text = f"⏳ checking `{self.target.exercise.file}`… {time.monotonic() - since:.0f} s " \
                   f"(the lab runs on; at most {check_budget(self.target.exercise):g} s)"
            if self.result.content != text:
                self.result.content = text
            return
        if outcome is not None and outcome is not self._shown_outcome:
            self.result.content = outcome_markdown(self.target.exercise, outcome)
            self._shown_outcome = outcome
        if outcome is not None and outcome is not self._notified:
            self._notified = outcome
            title = "Check" if outcome.error is None else "Check failed"
            self.host.notify(title, outcome_summary(outcome),
                            color="green" if outcome.report and outcome.report.get(
                                "extra_data", {}).get("passed") else "orange")

    def stop(self) -> None:
        self._cancel.set()
        for proc in list(self._procs):
            _end(proc)
        if self._worker is not None:
            self._worker.join(timeout=5)
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)


def outcome_summary(outcome: CheckOutcome) -> str:
    """One line: the score and the failing checks, or why it did not run."""
    if outcome.error:
        return outcome.error
    report = outcome.report or {}
    extra = report.get("extra_data", {})
    text = f"score {report.get('score', 0):g}/{extra.get('max_score', 0):g}"
    if extra.get("failure"):
        return f"{text}: {extra['failure']}"
    if outcome.failing:
        text += "; failing: " + ", ".join(outcome.failing)
    return text
