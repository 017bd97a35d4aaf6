"""`mexone run`'s report: a fall the routine's last lines set off is reported (the run lasts its
duration, the controllers holding the last commands), and --json keeps stdout JSON while the
routine's log goes to stderr."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

# The README's Whole-body motion example, with the impulse as a parameter
WHOLE_BODY = """from mexone import rospy
from mexone.motion import reach, look_at, push

rospy.init_node("whole_body")  # where _impulse:= puts ~impulse, as rosrun
reach("l_hand", (0.25, 0.2, 0.75))
look_at((1.0, 0.0, 0.3))
rospy.loginfo("pushing")
push("torso", (rospy.get_param("~impulse"), 0.0, 0.0))
"""


def run(tmp_path, *args):
    routine = tmp_path / "whole_body.py"
    routine.write_text(WHOLE_BODY)
    return subprocess.run([sys.executable, "-m", "mexone", "run", str(routine), *args],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("impulse,fell", [(5.0, True), (2.5, False)])
def test_a_fall_after_the_routines_last_line_is_reported(tmp_path, impulse, fell):
    """PD alone survives 3.5 N s forward (README's push table): 5 fells it after the routine
    ended, 2.5 does not."""
    out = run(tmp_path, f"_impulse:={impulse}", "--json", "--duration", "6")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)  # stdout is the JSON alone
    assert report["sim_time"] == pytest.approx(6.0, abs=0.01)  # held to the end
    assert report["fell"] is fell and (report["fell_at"] is not None) is fell
    if fell:
        assert report["tilt"] > 1.0 and report["fell_at"] < 6.0
    assert "[INFO]" in out.stderr and "pushing" in out.stderr  # the routine's log, on stderr


def test_the_text_report_says_when_it_fell(tmp_path):
    out = run(tmp_path, "_impulse:=5.0", "--duration", "6")
    assert out.returncode == 0, out.stderr
    assert "pushing" in out.stdout and "fell over at " in out.stdout.splitlines()[-1]
