"""Any exit code a routine gives, in the lab's own process: os._exit(n) ends the routine with a
line naming the call, never the process; sys.exit(None or 0) ends it as returning does, any
other sys.exit(x) is its error. Property-based: random codes, a fixed seed."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mexone.errors import RoutineError
from mexone.lab import Lab
from mexone.routines.runner import RoutineRunner

CODES = st.one_of(st.none(), st.integers(-(2 ** 40), 2 ** 40), st.booleans(),
                  st.text(max_size=12))
_count = itertools.count()


@pytest.fixture(scope="module")
def lab():
    return Lab.create()


def _run(lab, folder, body: str) -> RoutineRunner:
    path = folder / f"exits_{next(_count)}.py"
    path.write_text("import os, sys\nfrom mexone import rospy\nrospy.init_node('exits')\n"
                    "rospy.sleep(0.01)\n" + body + "rospy.logerr('after the exit')\n")
    runner = RoutineRunner(lab, path)
    start = lab.sim.time
    try:
        runner.run(0.2)
    except RoutineError as exc:  # raised exactly when the runner holds an error: that one
        assert exc.details == runner.error and exc.file == str(path)
    else:
        assert runner.error is None
    assert lab.sim.time > start  # the lab is here, and its simulation ran
    assert not any(level == "ERROR" for _, level, _ in runner.log_lines)  # the exit ended it
    return runner


@settings(derandomize=True, max_examples=15, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(code=st.integers(-(2 ** 40), 2 ** 40))
def test_os_exit_with_any_code_ends_the_routine_not_the_process(lab, tmp_path, code):
    runner = _run(lab, tmp_path, f"os._exit({code!r})\n")
    assert runner.error is not None
    assert runner.error.startswith(f"the routine called os._exit({code!r}), which would end the lab")


@settings(derandomize=True, max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(code=CODES)
def test_sys_exit_zero_is_an_end_and_anything_else_an_error(lab, tmp_path, code):
    runner = _run(lab, tmp_path, f"sys.exit({code!r})\n")
    if code is None or code == 0:  # False == 0 too, as for the interpreter's own exit status
        assert runner.error is None
    else:
        assert runner.error == f"routine exited with status {code}"
