"""The held-out round of issue 36's attacks: a cheating student, a curious one and a hostile
controller, each trying what the first rounds did not (tests/exercises/test_attacks.py,
tests/sandbox/, tests/control/test_student_code_in_the_loop.py). Each case that got through is a
test that failed before its fix; the cheap ones that held are here too, so they keep holding."""

from __future__ import annotations

import logging
import sys
import textwrap
from pathlib import Path

import pytest

from mexone.control import load_control_config
from mexone.description.urdf import read_urdf
from mexone.lab import Lab

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="the jail's layers are Linux's")


def _turntable_lab(folder: Path, turntable, body: str, extra: str = "") -> Lab:
    write_urdf, _ = turntable
    (folder / "ctl.py").write_text("import sys, time\nimport numpy as np\n"
                                   "from mexone.control import PythonController\n\n"
                                   + textwrap.dedent(body))
    (folder / "controllers.yaml").write_text(textwrap.dedent("""\
        turntable:
          ctl:
            type: ctl/Ctl
            joints: [yaw]
        """) + textwrap.indent(textwrap.dedent(extra), " " * 4))
    return Lab.create(read_urdf(write_urdf(folder)), load_control_config(folder / "controllers.yaml"))


def test_a_worker_cannot_excuse_its_overrun_by_writing_its_own_run_delay(tmp_path, turntable,
                                                                          caplog):
    """The run-queue delay that excuses a slow update on a loaded machine is the kernel's
    figure for the worker, read by mexone; not the number the worker writes in its shared
    memory from what it measured (was: a made-up clock there, and an update 3x over its period was never a fault)."""
    lab = _turntable_lab(tmp_path, turntable, """
        class Ctl(PythonController):
            def update(self, state, t, dt):
                time.sleep(0.003)  # 3 ms at 1 kHz
                # the worker's own measure of its wait for a CPU, made up: "a century"
                sys._getframe(1).f_globals["run_delay"] = lambda: time.perf_counter() * 3e9
        """, "max_overruns: 3\n")
    with caplog.at_level(logging.ERROR):
        lab.sim.step(30)
    ctrl = lab.manager.controllers["ctl"]
    assert not ctrl.running and "overran its period" in ctrl.fault, ctrl.fault
    assert ctrl.updates == 4
