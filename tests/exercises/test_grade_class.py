"""A class graded at scale: right, wrong, crashing (raises, NaN, syntax error) and hanging
submissions and one not handed in, graded serially, by `--workers 2` and as Ray tasks, give the
same CSV byte for byte, every student once; a Ray worker killed mid-submission has that
submission graded again, never lost and never counted twice; nothing a killed worker's runs
started outlives it."""

from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path

import pytest

from helpers import run_cli, wait_until
from mexone.exercises import find_exercise
from mexone.routines import processes

pytestmark = pytest.mark.slow

EXERCISE = "gravity_compensation"  # about 1 s of simulation per submission
STUDENTS = ["ada", "bob", "cy", "dee", "eve", "fay", "gus", "hal"]
PASSED = ["yes", "no", "no", "no", "no", "no", "no", "no"]


def _variants(starter: str) -> dict[str, str]:
    """The starter's update changed into a student's usual crashes and hangs."""
    ret = "        return self.kp"
    assert ret in starter  # the starter these are made from is still the one they expect
    return {"raises": starter.replace(ret, "        raise RuntimeError('oops')\n" + ret),
            "nan": starter.replace(ret, "        return float('nan') * self.kp"),
            "syntax": "def update(self:\n",
            # one line: the watchdog names the line it stopped the loop on, which in a loop of
            # several lines is whichever the interrupt landed in (two serial runs differ too)
            "spins": starter.replace(ret, "        while True: pass\n" + ret),
            "sleeps": starter.replace(ret, "        import time\n        time.sleep(600)\n" + ret)}


@pytest.fixture(scope="module")
def klass(tmp_path_factory) -> Path:
    ex = find_exercise(EXERCISE)
    kinds = _variants(ex.starter.read_text())
    folder = tmp_path_factory.mktemp("class")
    texts = [ex.solution.read_text(), ex.starter.read_text(), kinds["raises"], kinds["nan"],
             kinds["syntax"], kinds["spins"], kinds["sleeps"]]
    for student, text in zip(STUDENTS[:-1], texts, strict=True):
        (folder / f"{student}.py").write_text(text)
    (folder / STUDENTS[-1]).mkdir()  # hal handed in nothing
    return folder


@pytest.fixture(scope="module")
def serial(klass, tmp_path_factory) -> str:
    return _grade(klass, tmp_path_factory.mktemp("serial"))


@pytest.fixture(scope="module")
def ray():
    """One local Ray for the module (its start is the slow part): grade_all and the CLI use the
    session running in this process, as a notebook's would be."""
    ray = pytest.importorskip("ray")
    from mexone.cluster import ray_session

    with ray_session(2) as session:
        yield session
    assert not ray.is_initialized()


def _grade(folder: Path, tmp: Path, *more: str) -> str:
    code, out, err = run_cli(["exercise", "grade", EXERCISE, folder, "--csv", tmp / "grades.csv",
                              "--force", *more])
    assert code == 0, err
    assert err == ""  # no progress bar off a terminal, no Ray chatter
    return (tmp / "grades.csv").read_text()


def test_the_serial_grades_are_each_kinds(serial):
    rows = [row.split(",") for row in serial.splitlines()[1:]]
    assert [r[0] for r in rows] == STUDENTS
    assert [r[3] for r in rows] == PASSED
    assert float(rows[1][1]) > 0 and all(float(r[1]) == 0 for r in rows[2:])


def test_two_workers_give_the_serial_csv(klass, serial, tmp_path):
    assert _grade(klass, tmp_path, "--workers", "2") == serial


def _grading_workers() -> list[int]:
    """This process's Ray workers busy with a submission (Ray titles them by their task)."""
    out = []
    for pid in processes.descendants(os.getpid()):
        try:
            if Path(f"/proc/{pid}/cmdline").read_bytes().startswith(b"ray::_grade_one"):
                out.append(pid)
        except OSError:
            pass
    return out


def test_ray_gives_the_serial_csv_though_a_worker_is_killed(klass, serial, ray, tmp_path):
    """A Ray worker is SIGKILLed while it grades (the OOM killer, a node lost): Ray runs its
    submission again, and the CSV is the serial run's, each student once; the runs the dead
    worker started end with it. Also: the teacher's secret reached Ray's workers (the hidden
    variation drawn from it decides bob's score)."""
    assert os.environ.get("MEXONE_EXERCISE_SECRET")
    killed: list[tuple[int, list[int]]] = []

    def kill_one() -> None:
        if wait_until(lambda: _grading_workers(), timeout=120):
            victim = _grading_workers()[0]
            if wait_until(lambda: processes.descendants(victim), timeout=30):  # runs started
                below = processes.descendants(victim)
                os.kill(victim, signal.SIGKILL)
                killed.append((victim, below))

    killer = threading.Thread(target=kill_one)
    killer.start()
    try:
        graded = _grade(klass, tmp_path, "--backend", "ray", "--workers", "2")
    finally:
        killer.join()
    assert killed, "no worker was grading"
    assert graded == serial
    _, below = killed[0]
    assert wait_until(lambda: not set(below) & _running(), timeout=20), below


def _running() -> set[int]:
    return {p.pid for p in processes.table().values() if p.running}


def test_without_ray_the_backend_says_how_to_install_it(klass, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    code, out, err = run_cli(["exercise", "grade", EXERCISE, klass, "--backend", "ray"])
    assert code == 2 and out == ""
    assert err.strip().count("\n") <= 1 and "needs Ray" in err and "[cluster]" in err, err
