"""A Python-API user cannot miss a routine's failure: RoutineRunner.run raises RoutineError with
the routine's FILE:LINE, and `mexone render` of a failing routine leaves no video."""

from __future__ import annotations

import subprocess
import sys

import pytest

from mexone.errors import MexoneError, RoutineError
from mexone.lab import Lab
from mexone.routines.runner import RoutineRunner

FAILING = """from mexone import rospy
rospy.init_node("failing")
rospy.sleep(0.05)
[][1]
"""


def test_run_raises_the_routines_error_with_its_file_and_line(tmp_path):
    path = tmp_path / "failing.py"
    path.write_text(FAILING)
    lab = Lab.create()
    runner = RoutineRunner(lab, path)
    with pytest.raises(RoutineError) as raised:
        runner.run(1.0)
    error = raised.value
    assert isinstance(error, MexoneError)
    assert str(error) == f"{path}:4: IndexError: list index out of range"
    assert error.details == runner.error and "Traceback" in error.details
    assert lab.sim.time == pytest.approx(0.05, abs=0.01)  # the run ended with the routine


def test_a_routine_that_ends_well_raises_nothing(tmp_path):
    path = tmp_path / "fine.py"
    path.write_text(FAILING.replace("[][1]\n", ""))
    runner = RoutineRunner(Lab.create(), path)
    runner.run(1.0)
    assert runner.error is None


def test_render_of_a_failing_routine_leaves_no_file_and_the_rerun_is_not_refused(tmp_path):
    (tmp_path / "failing.py").write_text(FAILING)
    for _ in range(2):  # the second run is not refused with "already exists"
        out = subprocess.run([sys.executable, "-m", "mexone", "render", "failing.py", "-o", "v.gif",
                              "--duration", "0.5", "--size", "32x24", "--fps", "10"],
                             cwd=tmp_path, capture_output=True, text=True, timeout=120)
        assert out.returncode == 1, out.stderr
        lines = [line for line in out.stderr.splitlines() if line.startswith("mexone")]
        assert lines == ["mexone: failing.py:4: IndexError: list index out of range; "
                         "no video written"], out.stderr
        assert "Traceback" not in out.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["failing.py"]  # nor a temporary file
