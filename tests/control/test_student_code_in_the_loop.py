"""A student's controller can neither end, freeze nor forge the lab (issue 36). Each case that
did, run as a student runs it -- `mexone sim --headless --duration 2 --controllers
CASE/controllers.yaml --json` -- ends in one line naming the student's file:line, the controller
stopped (its joints held), the lab running on to its duration, nothing left behind (no process,
no thread: the controller's process ends with what it started), the right exit status and no
traceback. The cases of the update loop share one run (one controller each, on a joint of its
own); those that refuse the load (at import, in configure) are a run each.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import uuid
from pathlib import Path

import numpy as np
import pytest

from helpers import wait_until

MARK = "MEXONE_TEST_MARK"

# class name -> (joint, body); the line a case's message must name ends with `# <-`
LOOP_CASES = {
    "DeactivateHangs": ("waist_yaw", """
        def update(self, state, t, dt):
            if t > 0.05:
                raise RuntimeError("first fault")  # <-
            return 0.0 * state.q
        def deactivate(self):
            while True: pass  # one line: the dump lands on it wherever it stops # <- deactivate
        """),
    "SysExitInDeactivate": ("neck_yaw", """
        def update(self, state, t, dt):
            if t > 0.05:
                raise RuntimeError("first fault")  # <-
            return 0.0 * state.q
        def deactivate(self):
            sys.exit(4)  # <- deactivate
        """),
    "Recursion": ("neck_pitch", """
        def update(self, state, t, dt):
            if t > 0.05:
                sys.setrecursionlimit(10**7)
                def deeper(n):
                    return deeper(n + 1) + 1  # <-
                deeper(0)
            return 0.0 * state.q
        """),
    "NanIntoAllQ": ("l_hip_yaw", """
        def update(self, state, t, dt):
            if t > 0.05:
                state.all_q[0] = np.nan  # <-
            return 0.0 * state.q
        """),
    "HugeIntoAllDq": ("l_hip_roll", """
        def update(self, state, t, dt):
            if t > 0.05:
                state.all_dq[0] = 1e12  # <-
            return 0.0 * state.q
        """),
    "RaisesKeyboardInterrupt": ("l_hip_pitch", """
        def update(self, state, t, dt):
            if t > 0.05:
                raise KeyboardInterrupt  # <-
            return 0.0 * state.q
        """),
    "OsExit": ("l_knee", """
        def update(self, state, t, dt):
            if t > 0.05:
                os._exit(0)  # <-
            return 0.0 * state.q
        """),
    "PosixExit": ("l_ankle_pitch", """
        def update(self, state, t, dt):
            if t > 0.05:
                import posix
                posix._exit(0)  # <-
            return 0.0 * state.q
        """),
    "LibcExit": ("l_ankle_roll", """
        def update(self, state, t, dt):  # <- (no Python frame survives _exit: the def line)
            if t > 0.05:
                ctypes.CDLL(None)._exit(3)
            return 0.0 * state.q
        """),
    "Forks": ("l_shoulder_pitch", """
        def update(self, state, t, dt):
            if t > 0.05:
                os.fork()  # <-
            return 0.0 * state.q
        """),
    "StrRaises": ("l_shoulder_roll", """
        def update(self, state, t, dt):
            if t > 0.05:
                raise Weird()  # <-
            return 0.0 * state.q
        """),
    "ThreadRaises": ("l_elbow", """
        def activate(self, state):
            def boom():
                time.sleep(0.05)
                raise ValueError("from my thread")  # <-
            threading.Thread(target=boom, name="boomer").start()
        def update(self, state, t, dt):
            return 0.0 * state.q
        """),
    "WritesIntoTheState": ("r_hip_yaw", """
        def update(self, state, t, dt):
            if t > 0.05:
                ctypes.memmove(state.all_q.ctypes.data, b"\\0" * 8, 8)  # <-
            return 0.0 * state.q
        """),
    "BlockedInC": ("r_hip_roll", """
        def update(self, state, t, dt):
            if t > 0.05:
                time.sleep(1e9)  # <-
            return 0.0 * state.q
        """),
    "NonDaemonThread": ("r_hip_pitch", """
        def configure(self):
            threading.Thread(target=time.sleep, args=(3600,), name="sleeper").start()  # <-
        def update(self, state, t, dt):
            return 0.0 * state.q
        """),
}
HEADER = """\
import ctypes, os, sys, threading, time
import numpy as np
from mexone.control import PythonController


class Weird(Exception):
    def __str__(self):
        raise RuntimeError("no")
"""


def marked(path: Path, marker: str = "# <-") -> int:
    """The line of `path` ending with `marker` (or holding `# <- (`)."""
    lines = path.read_text().splitlines()
    return next(i for i, text in enumerate(lines, 1)
                if text.rstrip().endswith(marker) or (marker == "# <-" and "# <- (" in text))


def run_sim(yaml_path: Path, duration: float = 2.0, until=None) -> tuple[int, str, list[str], list]:
    """`mexone sim --headless --json` as a student runs it: its exit status, stdout, stderr
    lines, and the processes it left (any process that inherited its marked environment)."""
    mark = uuid.uuid4().hex
    env = dict(os.environ, **{MARK: mark})
    child = subprocess.Popen([sys.executable, "-m", "mexone", "sim", "--headless", "--json",
                              "--duration", str(duration), "--controllers", str(yaml_path)],
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             cwd=yaml_path.parent)
    err: list[str] = []
    reader = threading.Thread(target=lambda: err.extend(child.stderr), daemon=True)
    reader.start()
    try:
        if until is not None:
            until(child, err)
        out = child.stdout.read()
        code = child.wait(300)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    reader.join(10)
    left = wait_until(lambda: not marked_processes(mark), 10) or marked_processes(mark)
    return code, out, err, [] if left is True else left


def marked_processes(mark: str) -> list[str]:
    """Processes (not zombies) whose environment holds MARK=mark."""
    found = []
    needle = f"{MARK}={mark}".encode()
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            if needle not in Path(f"/proc/{entry}/environ").read_bytes():
                continue
            state = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[0]
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if state not in ("Z", "X"):
            found.append(f"{entry} {cmd}")
    return found


@pytest.fixture(scope="module")
def loop_run(tmp_path_factory):
    """Every update-loop case in one run, each a controller on its own joint."""
    folder = tmp_path_factory.mktemp("cases")
    body = HEADER + "".join(f"\n\nclass {name}(PythonController):\n"
                            + textwrap.indent(textwrap.dedent(code).strip("\n"), "    ") + "\n"
                            for name, (_, code) in LOOP_CASES.items())
    (folder / "cases.py").write_text(body)
    yaml = ["mex_rb:"]
    for name, (joint, _) in LOOP_CASES.items():
        yaml += [f"  {name.lower()}:", f"    type: cases/{name}", f"    joints: [{joint}]",
                 "    hang_timeout: 0.3"]
    (folder / "controllers.yaml").write_text("\n".join(yaml) + "\n")
    code, out, err, left = run_sim(folder / "controllers.yaml")
    return folder / "cases.py", code, json.loads(out), err, left


def _case_line(file: Path, name: str, marker: str = "# <-") -> int:
    """The marked line inside class `name` of the cases file."""
    lines = file.read_text().splitlines()
    start = next(i for i, text in enumerate(lines) if text.startswith(f"class {name}("))
    for i in range(start + 1, len(lines)):
        text = lines[i].rstrip()
        if text.startswith("class "):
            break
        if text.endswith(marker) or (marker == "# <-" and "# <- (" in text):
            return i + 1
    raise AssertionError(f"no {marker} in {name}")


def test_the_lab_runs_to_its_duration_and_exits_1_naming_every_fault(loop_run):
    file, code, summary, err, left = loop_run
    assert code == 1, err  # faults: not a clean run, not a crash (was: 0, 4, 130 or killed)
    assert summary["sim_time"] == pytest.approx(2.0) and not summary["diverged"]
    assert not any("Traceback" in line for line in err), err
    assert left == [], left  # no controller's process, nor anything one started
    assert err[-1].startswith("mexone: the run went on, but 14 controllers stopped on a fault")


@pytest.mark.parametrize("name", [n for n in LOOP_CASES if n != "NonDaemonThread"])
def test_each_fault_is_one_line_naming_the_students_line(loop_run, name):
    file, _, summary, err, _ = loop_run
    controller = name.lower()
    fault = summary["controllers"][controller]["fault"]
    assert f"{file}:{_case_line(file, name)}" in fault, fault
    said = [line for line in err if f"controller '{controller}' stopped" in line]
    assert len(said) == 1 and fault in said[0], said


def test_what_the_faults_say(loop_run):
    _, _, summary, err, _ = loop_run
    faults = {name: entry["fault"] for name, entry in summary["controllers"].items()
              if "fault" in entry}
    assert "ValueError: assignment destination is read-only" in faults["nanintoallq"]
    assert "ValueError: assignment destination is read-only" in faults["hugeintoalldq"]
    assert "KeyboardInterrupt" in faults["raiseskeyboardinterrupt"]
    assert "Refused: _exit(0) would end a controller's process" in faults["osexit"]
    assert "Refused: _exit(0)" in faults["posixexit"]
    assert "its process ended (exit status 3)" in faults["libcexit"]
    assert "Refused: fork(): a controller may not start processes" in faults["forks"]
    assert "Weird: (its str() raised RuntimeError)" in faults["strraises"]
    assert "its thread 'boomer' raised" in faults["threadraises"]
    assert "crashed (SIGSEGV)" in faults["writesintothestate"]
    assert "did not return within hang_timeout 0.3 s" in faults["blockedinc"]
    assert "fault" not in summary["controllers"]["nondaemonthread"]  # a thread is allowed
    assert summary["controllers"]["nondaemonthread"]["budget"]["updates"] == 2001


def test_deactivate_that_hangs_or_exits_is_said_and_the_stop_goes_on(loop_run):
    file, _, _, err, _ = loop_run
    hangs = [line for line in err if "controller 'deactivatehangs': deactivate" in line]
    line = _case_line(file, "DeactivateHangs", "# <- deactivate")
    assert len(hangs) == 1 and f"did not return within 0.3 s (ended at {file}:{line})" in hangs[0]
    exits = [line for line in err if "controller 'sysexitindeactivate': deactivate" in line]
    line = _case_line(file, "SysExitInDeactivate", "# <- deactivate")
    assert len(exits) == 1 and f"raised {file}:{line}: SystemExit: 4" in exits[0]


def test_a_thread_left_running_ends_with_the_controllers_process(loop_run):
    file, _, _, err, left = loop_run
    said = [line for line in err if "controller 'nondaemonthread'" in line]
    line = _case_line(file, "NonDaemonThread")
    assert said == [f"mexone: warning: controller 'nondaemonthread': its thread 'sleeper', "
                    f"started at {file}:{line}, was still running: it ended with the "
                    "controller's process\n"]
    assert left == []


# ----- what refuses the load: a run each ---------------------------------------------------------
LOAD_CASES = {
    "exit_at_import": ("""
        import os
        from mexone.control import PythonController
        os._exit(0)  # <-


        class Ctl(PythonController):
            pass
        """, "importing ctl.py failed: {where}: Refused: _exit(0) would end a controller's process"),
    "base_exception_in_configure": ("""
        from mexone.control import PythonController


        class Mine(BaseException):
            pass


        class Ctl(PythonController):
            def configure(self):
                raise Mine("mine")  # <-
        """, "configure failed: {where}: Mine: mine"),
    "program_in_configure": ("""
        import subprocess
        from mexone.control import PythonController


        class Ctl(PythonController):
            def configure(self):
                subprocess.Popen(["sleep", "3600"])  # <-
        """, "configure failed: {where}: Refused: subprocess.Popen(): a controller may not start "
             "processes"),
}


@pytest.mark.parametrize("case", LOAD_CASES)
def test_a_controller_that_cannot_load_is_refused_in_one_line(tmp_path, case):
    code_text, said = LOAD_CASES[case]
    (tmp_path / "ctl.py").write_text(textwrap.dedent(code_text))
    (tmp_path / "controllers.yaml").write_text(
        "mex_rb:\n  ctl:\n    type: ctl/Ctl\n    joints: [l_elbow]\n")
    code, out, err, left = run_sim(tmp_path / "controllers.yaml")
    where = f"{tmp_path / 'ctl.py'}:{marked(tmp_path / 'ctl.py')}"
    assert code == 2 and out == "", err  # bad input, before the run (was: exit 0, a traceback)
    assert len(err) == 1 and said.format(where=where) in err[0], err
    assert left == [], left  # the sleep it tried to start: never started


def test_a_real_sigint_stops_the_run_a_raised_keyboardinterrupt_does_not(tmp_path):
    (tmp_path / "ctl.py").write_text(textwrap.dedent("""\
        from mexone.control import PythonController


        class Ctl(PythonController):
            def activate(self, state):
                self.log.warning("up")

            def update(self, state, t, dt):
                return 0.0 * state.q
        """))
    (tmp_path / "controllers.yaml").write_text(
        "mex_rb:\n  ctl:\n    type: ctl/Ctl\n    joints: [l_elbow]\n")

    def interrupt(child, err) -> None:
        assert wait_until(lambda: any("ctl: up" in line for line in err)
                          or child.poll() is not None, 120), err
        child.send_signal(signal.SIGINT)

    code, out, err, left = run_sim(tmp_path / "controllers.yaml", duration=600, until=interrupt)
    assert code == 130, err  # the user's Ctrl-C: the summary, then 130
    assert json.loads(out)["sim_time"] < 600 and left == []
    assert not any("Traceback" in line for line in err)


def test_the_live_model_stays_the_simulators(tmp_path):
    """`self.dynamics.model.opt.gravity[:] = 0` changes the controller's own copy of the model
    (its dynamics say g = 0), not the simulated physics (was: 10/10 on gravity_compensation)."""
    from mexone.lab import Lab

    (tmp_path / "ctl.py").write_text(textwrap.dedent("""\
        from mexone.control import PythonController


        class Ctl(PythonController):
            def activate(self, state):
                self.dynamics.model.opt.gravity[:] = 0
                self.dynamics.model.body_mass[:] = 0

            def update(self, state, t, dt):
                self.g = self.dynamics.gravity()[self.dofs]
                return 0.0 * state.q

            def report(self):
                return {"gravity": self.dynamics.model.opt.gravity, "g": self.g}
        """))
    (tmp_path / "controllers.yaml").write_text(
        "mex_rb:\n  ctl:\n    type: ctl/Ctl\n    joints: [l_shoulder_pitch, l_elbow]\n")
    lab = Lab.create(controllers=tmp_path / "controllers.yaml")
    masses = lab.sim.model.body_mass.copy()
    lab.sim.step(5)
    report = lab.manager.controllers["ctl"].report()
    assert report["gravity"] == [0.0, 0.0, 0.0] and report["g"] == [0.0, 0.0]
    assert list(lab.sim.model.opt.gravity) == [0.0, 0.0, -9.81]
    np.testing.assert_array_equal(lab.sim.model.body_mass, masses)
    assert masses.sum() > 10  # Mex-One's 15 kg
    lab.sim.set_gravity([0.0, 0.0, -1.62])  # the Moon: the controller's copy follows the change
    lab.sim.step(2)
    assert lab.manager.controllers["ctl"].report()["gravity"] == [0.0, 0.0, -1.62]
