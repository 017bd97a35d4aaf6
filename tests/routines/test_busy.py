"""mexone's own long computations are not a student's busy loop: reach() to an unreachable
target runs its IK restarts for seconds of wall time on a loaded machine without yielding, and
the routine watchdog lets it (runtime.busy), while it still stops a routine's own loop."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

import mexone.motion  # noqa: F401 - imported here: the routine's import is not what is timed
from mexone.errors import RoutineError
from mexone.lab import Lab
from mexone.routines.runner import RoutineRunner
from mexone.routines.runtime import busy

STALL = 0.25  # s: the watchdog, far below what the IK takes (a second or more), and above a tick

UNREACHABLE = """
from mexone import rospy
from mexone.motion import reach
rospy.init_node("reacher")
reach("r_hand", [1.5, -0.2, 0.7], duration=1.0)
"""

STUDENTS_LOOP = """
import time
from mexone import rospy
rospy.init_node("busy")
end = time.perf_counter() + 3.0
while time.perf_counter() < end:
    pass
rospy.sleep(0.1)
"""


@pytest.fixture
def burning_cores():
    """Another process keeps every core busy meanwhile (a loaded CI machine)."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
               for _ in range(os.cpu_count() or 2)]
    yield
    for proc in burners:
        proc.kill()
        proc.wait()


def _run(tmp_path, text: str) -> RoutineRunner:
    path = tmp_path / "routine.py"
    path.write_text(text)
    runner = RoutineRunner(Lab.create(), path, stall=STALL)
    try:
        runner.run(9.0)
    except RoutineError as exc:  # raised exactly when the runner holds an error: that one
        assert exc.details == runner.error
    else:
        assert runner.error is None
    return runner


@pytest.mark.slow
def test_reach_to_an_unreachable_target_on_a_busy_machine_ends_with_its_warning(tmp_path,
                                                                               burning_cores):
    start = time.perf_counter()
    runner = _run(tmp_path, UNREACHABLE)
    assert time.perf_counter() - start > 4 * STALL  # the IK alone took longer than the watchdog
    assert runner.error is None
    warnings = [text for _, level, text in runner.log_lines if level == "WARN"]
    assert len(warnings) == 1 and "out of reach" in warnings[0], warnings


def test_the_same_watchdog_stops_a_students_own_loop(tmp_path, burning_cores):
    runner = _run(tmp_path, STUDENTS_LOOP)
    assert runner.error == f"routine did not yield to the simulation for {STALL:g} s " \
                           "(call rate.sleep())"


def test_busy_outside_a_routine_does_nothing():
    with busy("a library call"):
        pass


@pytest.fixture
def starved():
    """This process and four others on one core: every thread of it gets a fifth of a CPU."""
    before = os.sched_getaffinity(0)
    core = min(before)
    os.sched_setaffinity(0, {core})  # this thread, and the threads it starts from now on
    burners = [subprocess.Popen([sys.executable, "-c", f"import os; os.sched_setaffinity(0, {{{core}}})\n"
                                 "while True: pass"]) for _ in range(4)]
    yield
    for proc in burners:
        proc.kill()
        proc.wait()
    os.sched_setaffinity(0, before)


STARVED_ROUTINE = """
import time
from mexone import rospy
rospy.init_node("starved")
for _ in range(3):
    start = time.thread_time()
    while time.thread_time() - start < 0.1:  # 0.1 s of its own computing, then it yields
        pass
    rospy.sleep(0.01)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the run queue's wait is Linux's")
def test_a_routine_the_machine_starves_is_not_abandoned_for_it(tmp_path, starved):
    """0.1 s of its own computing takes about 0.5 s of wall time on a fifth of a core, over the
    watchdog's 0.25 s: the time it waited for the CPU is the machine's, not the routine's."""
    start = time.perf_counter()
    runner = _run(tmp_path, STARVED_ROUTINE)
    assert time.perf_counter() - start > 3 * 0.1 * 2  # it really was starved
    assert runner.error is None
