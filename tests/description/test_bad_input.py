"""A corpus of broken files, each with the exact one-line error it must give (exit 2)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

BROKEN = Path(__file__).parents[1] / "data" / "broken"
EXPECTED = yaml.safe_load((BROKEN / "expected.yaml").read_text())


def test_corpus_is_complete():
    files = {p.name for p in BROKEN.iterdir()} - {"expected.yaml"}
    assert files == set(EXPECTED)
    assert len(files) >= 20


# messages that name ROS_PACKAGE_PATH must not depend on the machine's
ENV = {k: v for k, v in os.environ.items() if k != "ROS_PACKAGE_PATH"}


@dataclass
class Checked:
    returncode: int
    stderr: str
    cpu: float  # s of CPU the check used (user + system): a bomb is work, whatever the load


def _check(name: str) -> Checked:
    """`mexone check` on one broken file, with the CPU time it used (os.wait4's rusage)."""
    args = ["check", "--controllers", name] if name.endswith(".yaml") else ["check", name]
    with tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, "-m", "mexone", *args], cwd=BROKEN, env=ENV,
                                stdout=subprocess.DEVNULL, stderr=err, text=True)
        killer = threading.Timer(60.0, os.kill, (proc.pid, signal.SIGKILL))  # a hang fails
        killer.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            killer.cancel()
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped: Popen must not wait again
        err.seek(0)
        return Checked(proc.returncode, err.read(), usage.ru_utime + usage.ru_stime)


@pytest.fixture(scope="module")
def checked() -> dict[str, Checked]:
    """Every file of the corpus checked, as many at once as there are cores (each check is a
    Python start-up: one at a time left the other core idle)."""
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        return dict(zip(sorted(EXPECTED), pool.map(_check, sorted(EXPECTED)), strict=True))


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_broken_file_gives_its_one_line_error(name, checked):
    out = checked[name]
    assert out.cpu < 10
    assert out.returncode == 2
    assert out.stderr.strip() == EXPECTED[name]
    assert "Traceback" not in out.stderr and out.stderr.count("\n") == 1


def test_missing_file():
    out = subprocess.run([sys.executable, "-m", "mexone", "check", "nowhere.urdf"],
                         capture_output=True, text=True)
    assert (out.returncode, out.stderr) == (2, "mexone: nowhere.urdf: no such file (check the path)\n")

