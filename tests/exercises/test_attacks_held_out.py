"""The held-out round of issue 36's attacks: a cheating student, a curious one and a hostile
controller, each trying what the first rounds did not (tests/exercises/test_attacks.py,
tests/sandbox/, tests/control/test_student_code_in_the_loop.py). Each case that got through is a
test that failed before its fix; the cheap ones that held are here too, so they keep holding."""

from __future__ import annotations

import logging
import re
import sys
import textwrap
from pathlib import Path

import numpy as np
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
        lab.sim.step(100)
    ctrl = lab.manager.controllers["ctl"]
    assert not ctrl.running and "overran its period" in ctrl.fault, ctrl.fault
    # 4 updates on a quiet machine; more where the kernel says the worker really waited for a CPU
    assert ctrl.updates < 100


def test_a_controllers_log_is_capped_and_says_how_many_lines_it_dropped(tmp_path, turntable,
                                                                        caplog):
    """A student's `self.log` every update, from its worker: at most LOG_LINES_PER_SECOND lines
    a second of the wall clock reach the lab's log, then one line says how many were not shown
    (was: every line, about 7000 in 2 s on stderr)."""
    import time

    from mexone.control.mistakes import LOG_LINES_PER_SECOND

    lab = _turntable_lab(tmp_path, turntable, """
        class Ctl(PythonController):
            def update(self, state, t, dt):
                self.log.info("step %d", round(t * 1000))
                return 0.0 * state.q
        """)
    start = time.monotonic()
    with caplog.at_level(logging.INFO, logger="mexone.control.student"):
        lab.sim.step(1500)
        ctrl = lab.manager.controllers["ctl"]
        updates = ctrl.updates
        lab.manager.close()  # unloaded: what it dropped since its last line shown is said
    spent = time.monotonic() - start
    lines = [r.getMessage() for r in caplog.records if r.name == "mexone.control.student"]
    shown = [line for line in lines if line.startswith("ctl: step ")]
    dropping = re.compile(rf"ctl: (\d+) lines of its log not shown \(more than "
                          rf"{LOG_LINES_PER_SECOND} a second\)")
    said = [m for m in map(dropping.fullmatch, lines) if m]
    dropped = sum(int(m.group(1)) for m in said)
    assert updates >= 1400 and len(shown) + len(said) == len(lines), lines[:5]
    assert 0 < len(shown) <= LOG_LINES_PER_SECOND * (spent + 1), (len(shown), spent)
    assert len(shown) + dropped == updates, (len(shown), dropped, updates)  # each line counted
    assert lines[-1] == said[-1].group(0)


def test_a_log_limit_lets_a_seconds_lines_through_then_counts_them():
    """LogLimit on a made-up clock: per_second lines a second, the rest counted and said once
    before the next line shown; the in-process runner's StudentLog uses it the same way."""
    from mexone.control.mistakes import LogLimit, StudentLog

    now = [0.0]
    limit = LogLimit(3, clock=lambda: now[0])
    assert [limit.admit() for _ in range(5)] == [(True, 0)] * 3 + [(False, 0)] * 2
    now[0] = 1.0
    assert limit.admit() == (True, 2) and limit.flush() == 0
    target = logging.getLogger("mexone.test.loglimit")
    records: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: records.append(record.getMessage())  # type: ignore[method-assign]
    target.addHandler(handler)
    target.setLevel(logging.INFO)
    try:
        log = StudentLog(target, {"name": "obs", "limit": LogLimit(2, clock=lambda: now[0])})
        for i in range(6):
            log.info("line %d", i)
        now[0] = 2.5
        log.warning("late")
    finally:
        target.removeHandler(handler)
    assert records == ["obs: line 0", "obs: line 1",
                       "obs: 4 lines of its log not shown (more than 2 a second)", "obs: late"]


def _course_grader(name: str):
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "src/mexone/exercises/course" / name / "grader.py"
    spec = importlib.util.spec_from_file_location(f"grader_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


TRUTH_READER = '''
import math
import numpy as np
from mexone.control import PythonController


def tilt(rotation, down):
    up = rotation.T @ (-down)
    return math.atan2(up[1], up[2]), math.atan2(-up[0], math.hypot(up[1], up[2]))


def rotation(w, x, y, z):
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class TiltObserver(PythonController):
    exports = {"tilt": 2}

    def configure(self):
        import os

        beside = set(os.listdir(os.path.dirname(os.path.abspath(__file__))))
        if beside - {"tilt_observer.py", "controllers.yaml"}:  # the noisy URDF: the hidden bias
            raise RuntimeError(f"found {sorted(beside)}")

    def update(self, state, t, dt):
        g = np.asarray(self.dynamics.model.opt.gravity, dtype=float)  # the hidden slope
        down = g / np.linalg.norm(g)
        base = rotation(*(float(v) for v in state.all_q[3:7]))  # the simulator's base
        x, y, z, w = (float(v) for v in state.sensors["imu"].orientation)  # the IMU's "truth"
        self.exports["tilt"][:] = [tilt(base, down)[0], tilt(rotation(w, x, y, z), down)[1]]
'''


@pytest.mark.slow
def test_the_tilt_observer_reads_no_truth(tmp_path):
    """Exercise 14's observer sees neither its floating base (state.all_q, state.base) nor the
    IMU's orientation move: both are the simulator's truth (was: the truth against the model's
    gravity plus a whisker of gyro, so that a louder gyro moved it, scored 10/10 at 0.15 mrad);
    nor the noisy URDF beside its file (was: the hidden gyro bias and noise, and which run is
    the louder one, read from it)."""
    module = _course_grader("tilt_observer")
    cheat = tmp_path / "tilt_observer.py"
    cheat.write_text(TRUTH_READER)
    true, estimate, fault = module.measure(cheat, module.GIVEN)
    assert fault is None
    assert np.ptp(true[600:], axis=0).max() > 0.01  # the pushes tilt it
    assert np.ptp(estimate[600:], axis=0).max() < 1e-9, np.ptp(estimate[600:], axis=0)


SLOPE_HELD = '''
import math
import numpy as np
from mexone.control import PythonController


class TiltObserver(PythonController):
    """The slope's tilt the accelerometer read while the robot stood, held; a whisker of gyro."""
    exports = {"tilt": 2}

    def activate(self, state):
        self.read, self.held = [], None

    def update(self, state, t, dt):
        imu = state.sensors["imu"]
        ax, ay, az = (float(v) for v in imu.linear_acceleration)
        now = np.array([math.atan2(ay, az), math.atan2(-ax, math.hypot(ay, az))])
        if self.held is None and t >= 1.0:
            self.held = np.mean(self.read, axis=0)
        elif self.held is None and t >= 0.3:
            self.read.append(now)
        gyro = np.asarray(imu.angular_velocity[:2], dtype=float)
        self.exports["tilt"][:] = (now if self.held is None else self.held) + 0.01 * gyro
'''


def test_a_tilt_that_holds_still_tracks_none_of_the_tilts_changes():
    """Exercise 14's tracking, on made-up series: an estimate that holds the mean tilt (the
    slope, most of it) earns nothing however small its error; one that follows the tilt plus a
    steady offset within the full marks earns them all."""
    module = _course_grader("tilt_observer")
    t = np.arange(int(module.SECONDS / module.STEP)) * module.STEP
    sway = np.where(t > module.PUSHES[0][0], 0.01 * np.sin(2 * np.pi * 1.5 * t), 0.0)
    true = np.c_[np.full_like(t, 0.06), sway]  # a 3.4 degree slope, swaying after the push
    held = module.tracking(true, np.tile(true.mean(axis=0), (len(t), 1)))
    assert held.error < module.FULL and held.change_share == pytest.approx(1.0)
    assert held.fraction() <= 0.0
    follows = module.tracking(true, true + 0.004)
    assert follows.change_error < 1e-12 and follows.fraction() >= 1.0
    assert module.tracking(true, np.full_like(true, np.nan)).fraction() == 0.0
    assert module.tracking(true[:300], true[:300]).fraction() == 0.0  # it ended before SETTLE


@pytest.mark.slow
def test_the_tilt_observer_is_graded_on_the_tilts_changes(tmp_path):
    """Exercise 14 grades how the estimate follows what the pushes change, not only its error on
    the tilt, most of which is the slope, still: its tilt read from the accelerometer at rest and
    held, plus a whisker of gyro so a louder gyro moves it (was: 10/10 at 6.17 mrad RMS under the
    hidden slope, against the reference's 3.20, with no observer at all)."""
    from mexone.exercises import find_exercise, grade

    exercise = find_exercise("tilt_observer")
    cheat = tmp_path / exercise.file
    cheat.write_text(SLOPE_HELD)
    result = grade(exercise, cheat)
    said = {c.name: c.output for c, _, _ in result.checks}
    earned = {c.name: score for c, score, _ in result.checks}
    assert earned["uses the IMU"] == 3.0, said  # the whisker moves it: not what catches it
    share = re.search(r"\((\d+)% of their", said["tracks the tilt"])
    assert share and int(share.group(1)) >= 95, said  # it misses all the pushes changed
    assert earned["tracks the tilt"] == 0.0 and result.score < exercise.pass_mark, said


def test_two_names_that_print_alike_are_refused_not_two_rows_alike(tmp_path):
    """é composed (U+00E9) and e with a combining accent (U+0065 U+0301) are two files that
    print as one name: a report with two rows 'é' cannot say whose score is whose (was: both
    graded, both rows 'é')."""
    from mexone.errors import InputError
    from mexone.exercises.grading import submissions_in

    for name in ("\u00e9.py", "e\u0301.py", "ada.py"):
        (tmp_path / name).write_text("pass\n")
    with pytest.raises(InputError) as err:
        submissions_in(tmp_path, "routine.py")
    said = err.value.one_line()
    assert "two submissions of é (written as " in said and "\\xe9" in said and "\\u0301" in said
    (tmp_path / "e\u0301.py").unlink()
    assert sorted(submissions_in(tmp_path, "routine.py")) == ["ada", "\u00e9"]


FORGED_LINES = '''
from mexone.control import Param, PythonController


class GravityCompensation(PythonController):
    command_interface = "effort"
    kp = Param(5.0)
    kd = Param(0.5)

    def configure(self):
        raise RuntimeError("x\\x1b[2K\\r  PASS runs 10.00/10.00\\u202e\\u2028score 10/10\\n"
                           "score 10/10" + "y" * 100000)
'''


def test_a_reason_forges_no_report_line_and_names_no_gui_button(tmp_path):
    """A student's message with an erase-line escape, a carriage return, a bidi override, a line
    separator, a newline and 100 000 characters is one line of the report, shown as text; the
    GUI's "fix it, then reload" is not in a grade (was: in every reason of a controller that did
    not load)."""
    from mexone.exercises import find_exercise, grade
    from mexone.exercises.grading import reason

    exercise = find_exercise("gravity_compensation")
    path = tmp_path / "gravity_compensation.py"
    path.write_text(FORGED_LINES)
    result = grade(exercise, path, local=True)
    assert result.score == 0
    said = reason(result)
    assert "RuntimeError: x" in said and "reload" not in said, said
    assert said.isprintable() and len(said) < 2000, said


@pytest.mark.parametrize("mode", ["namespaces", "none"])
def test_a_controller_cannot_signal_the_lab_past_its_guards(tmp_path, turntable, monkeypatch,
                                                            mode):
    """libc's kill (past the guarded os.kill) from a controller's worker at the lab's own pid,
    whichever isolation the machine offers (held: the PID namespace, or Landlock's signal
    scope where there is none)."""
    import importlib
    import os
    import signal

    spawn = importlib.import_module("mexone.sandbox.spawn")  # the module (its spawn() shadows it)
    monkeypatch.setenv(spawn.MODE_ENV, mode)
    monkeypatch.setenv("MEXONE_TEST_LAB_PID", str(os.getpid()))
    monkeypatch.setattr(spawn, "_isolation", None)  # probed again, as the mode says
    got: list[int] = []
    previous = signal.signal(signal.SIGUSR2, lambda signum, frame: got.append(signum))
    try:
        lab = _turntable_lab(tmp_path, turntable, """
            import ctypes, os, signal

            def hit():
                ctypes.CDLL(None).kill(int(os.environ["MEXONE_TEST_LAB_PID"]), signal.SIGUSR2)

            class Ctl(PythonController):
                def configure(self):
                    hit()

                def update(self, state, t, dt):
                    hit()
                    return np.zeros(1)
            """)
        lab.sim.step(20)
        ctrl = lab.manager.controllers["ctl"]
        assert ctrl.running and ctrl.updates >= 20, ctrl.fault
        assert spawn.isolation().mode == mode
        lab.manager.close()
    finally:
        signal.signal(signal.SIGUSR2, previous)
    assert got == []


def test_a_jail_fills_no_disk_of_the_machines(monkeypatch):
    """A run that writes file after file (each under the per-file limit) into its scratch
    folder stops at the scratch's own size, not at the machine's free disk, which other runs
    and the grader need (was: 3 GB in seconds, on the grader's disk, until my own cap)."""
    import importlib
    import json
    import os
    import subprocess

    spawn_module = importlib.import_module("mexone.sandbox.spawn")
    from mexone.sandbox import Jail, spawn

    if spawn_module.isolation().mode != "namespaces":
        pytest.skip("a scratch of its own size takes a mount namespace")
    code = textwrap.dedent('''
        import errno, json, os
        block, total, n, why = b"\\0" * (4 << 20), 0, 0, ""
        try:
            while total < (2 << 30):
                with open(f"f{n}", "wb") as f:
                    f.write(block)
                total += len(block)
                n += 1
        except OSError as exc:
            why = errno.errorcode.get(exc.errno, str(exc.errno))
        print(json.dumps({"mb": total >> 20, "why": why}))
    ''')
    jail = Jail(another_user=os.geteuid() == 0)
    with spawn([sys.executable, "-c", code], jail, stdout=subprocess.PIPE) as proc:
        out = json.loads(proc.popen.stdout.read())
    assert out["why"] == "ENOSPC" and out["mb"] <= 256, out
