"""`mexone exercise grade NAME DIR --workers N`: a class graded by N worker processes gets the
serial run's report and CSV, in the same order, every student once; a worker that dies has its
submissions graded again by a new pool, none twice; a signal ends the workers and every run
they started."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import run_cli, wait_until
from mexone.exercises import find_exercise, pool
from mexone.routines import processes

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def klass(tmp_path_factory) -> Path:
    """Right, wrong, broken and missing submissions, in an order no finishing order keeps."""
    ex = find_exercise("home_hold")
    folder = tmp_path_factory.mktemp("class")
    (folder / "ada.yaml").write_text(ex.solution.read_text())
    (folder / "bob.yaml").write_text(ex.starter.read_text())  # graded, not passed
    (folder / "cat.yaml").write_text("mex_rb: [unclosed\n")  # at once: 0, malformed YAML
    (folder / "dan").mkdir()  # handed in nothing
    (folder / "eve.yaml").write_text(ex.solution.read_text())
    return folder


def _grade(folder: Path, tmp: Path, *more: str) -> tuple[str, str]:
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder, "--csv",
                              tmp / "grades.csv", "--force", *more])
    assert code == 0, err
    return out, (tmp / "grades.csv").read_text()


def test_two_workers_give_the_serial_report_and_csv(klass, tmp_path):
    serial = _grade(klass, tmp_path)
    parallel = _grade(klass, tmp_path, "--workers", "2")
    assert parallel == serial
    rows = serial[1].splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["ada", "bob", "cat", "dan", "eve"]
    assert [r.split(",")[3] for r in rows[1:]] == ["yes", "no", "no", "no", "yes"]


MARKS: list[Path] = []  # the folder where _dies_once leaves a mark per call (a fork sees it)
GRADE_ONE = pool._grade_one


def _dies_once(exercise, path, *args):
    """pool._grade_one, but the worker grading bob dies the first time (the OOM killer, an
    admin's kill): the whole pool breaks."""
    (MARKS[0] / f"{path.name}-{os.getpid()}-{time.monotonic_ns()}").touch()
    if path.name == "bob.yaml" and not (MARKS[0] / "died").exists():
        (MARKS[0] / "died").touch()
        os._exit(9)
    return GRADE_ONE(exercise, path, *args)


def test_a_dead_workers_submissions_are_graded_again_none_twice(klass, tmp_path, monkeypatch):
    monkeypatch.setattr(pool, "_grade_one", _dies_once)  # by name: the workers are forks
    monkeypatch.setattr(sys.modules[__name__], "MARKS", [tmp_path])
    found = {p.stem: p for p in sorted(klass.glob("*.yaml"))}
    results = list(pool.grade_all(find_exercise("home_hold"), found, workers=2))
    assert [s for s, _ in results] == list(found)
    assert [r.passed for _, r in results] == [True, False, False, True]
    assert (tmp_path / "died").exists()
    started = [p.name.split("-")[0] for p in tmp_path.iterdir() if p.name != "died"]
    assert started.count("bob.yaml") == 2  # once in the pool that broke, once after
    assert all(started.count(f"{name}.yaml") in (1, 2) for name in found)  # a result: never again


def test_a_signal_ends_the_workers_and_their_runs(tmp_path):
    for student in ("ann", "ben", "cy"):
        (tmp_path / f"{student}.py").write_text("import time\ntime.sleep(60)\n")
    grader = subprocess.Popen([sys.executable, "-m", "mexone", "exercise", "grade",
                               "arms_routine", str(tmp_path), "--workers", "2"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:  # two workers, each: the fork server, a run's monitor, the run, the routine's process
        assert wait_until(lambda: len(processes.descendants(grader.pid)) >= 10, timeout=60)
        below = set(processes.descendants(grader.pid))
        grader.send_signal(signal.SIGINT)  # Ctrl-C
        _, err = grader.communicate(timeout=20)
    finally:
        grader.kill()
    assert grader.returncode == 130, err
    assert wait_until(lambda: not below & _running(), timeout=5), below & _running()


def _running() -> set[int]:
    return {p.pid for p in processes.table().values() if p.running}
