"""The routine sandbox: a routine that forks, execs, ends the process, exits, raises in a thread
of its own, or leaves a program running gets one clear line and a non-zero exit from `mexone run`
(sys.exit(0) ends it as returning does: exit 0), and no process is left behind. In the lab's own
process (the GUI's routines) the same routines end themselves, never the lab."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from helpers import free_port, wait_until
from mexone.errors import RoutineError
from mexone.lab import Lab
from mexone.routines.runner import RoutineRunner

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists() or not hasattr(os, "fork"),
                                reason="the sandbox's process checks need Linux /proc")

HEAD = "import os, sys, signal, subprocess, threading, time\nfrom mexone import rospy\n" \
       "rospy.init_node('hostile')\nrospy.sleep(0.2)\n"
# a program that sleeps forever, named by TOKEN (the test's folder) so the test can find it
SLEEPER = "[sys.executable, '-c', 'import time; time.sleep(1000)', TOKEN]"
SLEEP = "sys.executable, [sys.executable, '-c', 'import time; time.sleep(1000)', TOKEN]"

# name: (the routine after HEAD, exit status, what the output says)
CASES = {
    "fork": ("pid = os.fork()\nrospy.sleep(0.5)\n", 1, "the routine forked the lab's process"),
    "fork, the copy spins": ("if os.fork() == 0:\n    while True:\n        pass\nrospy.sleep(0.5)\n",
                             1, "the routine left process"),
    "os.execv": (f"os.execv({SLEEP})\n", 1, "the routine called os.execv('/"),
    "posix.execv": (f"import posix\nposix.execv({SLEEP})\n", 1,
                    "the routine replaced the run's process with another program"),
    "os._exit(0)": ("os._exit(0)\n", 1, "the routine called os._exit(0)"),
    "os._exit(3)": ("os._exit(3)\n", 1, "the routine called os._exit(3)"),
    "posix._exit(0)": ("import posix\nposix._exit(0)\n", 1,
                       "the routine ended the run's process (exit status 0) before its report"),
    "SIGKILL": ("os.kill(os.getpid(), signal.SIGKILL)\n", 1,
                "the run's process was killed by SIGKILL"),
    "segfault": ("import ctypes\nctypes.string_at(0)\n", 1, "killed by SIGSEGV"),
    "sys.exit(0)": ("sys.exit(0)\nrospy.logerr('never here')\n", 0, None),
    # a documented success: the thread is stopped with the run, and a warning says so
    "a thread left running": ("def spin():\n    while True:\n        time.sleep(0.01)\n"
                              "threading.Thread(target=spin, name='spinner', daemon=False).start()\n",
                              0, "mexone: warning: the routine left thread 'spinner' running: "
                                 "mexone stopped it"),
    "sys.exit(4)": ("sys.exit(4)\n", 1, "routine exited with status 4"),
    "a thread raises": ("threading.Thread(target=lambda: 1 / 0, name='worker').start()\n"
                        "rospy.sleep(0.5)\n", 1, "in thread 'worker', which the routine started"),
    "a thread calls os._exit": ("def bye():\n    os._exit(5)\nthreading.Thread(target=bye).start()\n"
                                "rospy.sleep(0.5)\n", 1, "the routine called os._exit(5)"),
    "a thread is os._exit": ("threading.Thread(target=os._exit, args=(6,), name='bye').start()\n"
                             "rospy.sleep(0.5)\n", 1, "os._exit(6), which would end the lab with "
                             "it: the routine was stopped there (end a routine by returning, or "
                             "with sys.exit(n)) (in thread 'bye', which the routine started)"),
    "a program left running": (f"subprocess.Popen({SLEEPER})\nrospy.sleep(0.5)\n", 1,
                               "the routine left process"),
    "a detached program": ("subprocess.run(['setsid', 'sh', '-c', '\"$0\" -c \"import time; "
                           "time.sleep(1000)\" \"$1\" &', sys.executable, TOKEN])\n"
                           "rospy.sleep(0.5)\n", 1, "the routine left a process running after the run"),
    "a program left running, then os._exit": (f"subprocess.Popen({SLEEPER})\nimport posix\n"
                                              "posix._exit(0)\n", 1, "exit status 0"),
}


def left_behind(token: str) -> list[str]:
    """Running processes whose command line names `token` (zombies have ended)."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        if token in cmdline and stat[stat.rindex(")") + 2] not in "ZX":
            out.append(f"{entry.name}: {cmdline}")
    return out


def my_children() -> set[int]:
    """This process's running children (the copies a routine forked here, its programs)."""
    out = set()
    for entry in Path("/proc").iterdir():
        try:
            stat = (entry / "stat").read_text() if entry.name.isdigit() else ""
        except OSError:
            continue
        if stat:
            fields = stat[stat.rindex(")") + 2:].split()
            if int(fields[1]) == os.getpid() and fields[0] not in "ZX":
                out.add(int(entry.name))
    return out


def run_routine(folder: Path, body: str, *options: str) -> tuple[subprocess.CompletedProcess, float]:
    path = folder / "hostile.py"
    path.write_text(f"TOKEN = {str(folder)!r}\n" + HEAD + body)
    start = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "mexone", "run", str(path), "--duration", "2",
                          *options], capture_output=True, text=True, timeout=120)
    return out, time.monotonic() - start


@pytest.mark.parametrize("name", list(CASES))
def test_a_hostile_routine_is_one_line_a_failure_and_leaves_nothing(tmp_path, name):
    body, status, said = CASES[name]
    out, seconds = run_routine(tmp_path, body, "--quiet")
    assert out.returncode == status, (out.stdout, out.stderr)
    assert "Traceback" not in out.stderr or name in ("a thread raises",)
    if said is None:
        assert out.stderr == ""
        assert "stayed standing" in out.stdout  # the report is there
    else:
        text = out.stdout + out.stderr
        assert said in text, text
        if "report" in said or "killed by" in said or "replaced" in said:  # the supervisor's
            lines = [line for line in out.stderr.splitlines() if said in line]
            assert len(lines) == 1 and lines[0].startswith("mexone: ")
    assert wait_until(lambda: not left_behind(str(tmp_path)), timeout=5), left_behind(str(tmp_path))
    assert seconds < 60  # a few seconds, and MuJoCo's start-up on a loaded machine


@pytest.mark.slow
def test_a_routine_that_spins_forever_is_stopped_and_leaves_nothing(tmp_path):
    out, seconds = run_routine(tmp_path, f"subprocess.Popen({SLEEPER})\nwhile True:\n    pass\n",
                               "--json")
    assert out.returncode == 1
    report = json.loads(out.stdout)
    assert "routine did not yield to the simulation for 5 s" in report["error"]
    assert "the routine left process" in report["error"]
    assert wait_until(lambda: not left_behind(str(tmp_path)), timeout=5), left_behind(str(tmp_path))


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL])
def test_a_signal_to_mexone_run_stops_the_run_which_reports_and_leaves_nothing(tmp_path, signum):
    """`mexone run` supervises the run: a SIGTERM or Ctrl-C to the command the user started
    stops the run (its report printed) and what the routine started; so does kill -9 of it
    (the run is told with SIGTERM: PR_SET_PDEATHSIG)."""
    path = tmp_path / "long.py"
    path.write_text(f"import subprocess, sys\nfrom mexone import rospy\nrospy.init_node('long')\n"
                    f"subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(1000)', "
                    f"{str(tmp_path)!r}])\nrospy.loginfo('ready')\nwhile True:\n"
                    f"    rospy.sleep(1.0)\n")
    proc = subprocess.Popen([sys.executable, "-m", "mexone", "run", str(path), "--duration",
                             "100000", "--rtf", "1"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:  # (SIGINT stays ignored in a background job's mexone, as nohup's: pytest may be one)
        ready = any("ready" in line for line in proc.stdout)
        assert ready, proc.communicate(timeout=30)
        proc.send_signal(signum)
        start = time.monotonic()
        out, err = proc.communicate(timeout=30)  # until the run, which holds the pipes, ends
        assert time.monotonic() - start < 5
    finally:
        proc.kill()
    # the program the routine left running is its error
    assert proc.returncode == (-signal.SIGKILL if signum == signal.SIGKILL else 1), err
    assert "stayed standing" in out and "the routine left process" in err, (out, err)
    assert wait_until(lambda: not left_behind(str(tmp_path)), timeout=5), left_behind(str(tmp_path))


# ----- in the lab's own process (the GUI's routines run there) ---------------------------------
IN_PROCESS = {
    "os._exit(0)": ("os._exit(0)\n", "the routine called os._exit(0)"),
    "os.execv": ("os.execv('/bin/true', ['true'])\n", "which would replace the lab's process"),
    "os.execlp": ("os.execlp('true', 'true')\n", "which would replace the lab's process"),
    "fork": ("os.fork()\nrospy.sleep(0.3)\n", "the routine forked the lab's process"),
    "fork, the copy spins": ("if os.fork() == 0:\n    while True:\n        pass\nrospy.sleep(0.3)\n",
                             "the routine left process"),
    "a program left running": (f"subprocess.Popen({SLEEPER})\nrospy.sleep(0.3)\n",
                               "the routine left process"),
    "a thread raises": ("threading.Thread(target=lambda: [][1]).start()\nrospy.sleep(0.3)\n",
                        "IndexError: list index out of range"),
}


@pytest.fixture(scope="module")
def lab():
    return Lab.create()


@pytest.mark.parametrize("name", list(IN_PROCESS))
def test_in_the_labs_process_a_hostile_routine_ends_itself_not_the_lab(tmp_path, lab, name):
    body, said = IN_PROCESS[name]
    path = tmp_path / "hostile.py"
    path.write_text(f"TOKEN = {str(tmp_path)!r}\n" + HEAD + body)
    threads, children = set(threading.enumerate()), my_children()
    runner = RoutineRunner(lab, path)
    start = lab.sim.time
    with pytest.raises(RoutineError) as raised:
        runner.run(1.0)
    assert runner.error is not None and said in runner.error, runner.error
    assert raised.value.details == runner.error
    assert lab.sim.time > start  # this process and its simulation are here to tell
    assert wait_until(lambda: not left_behind(str(tmp_path)), timeout=5), left_behind(str(tmp_path))
    assert wait_until(lambda: my_children() <= children, timeout=5)
    assert wait_until(lambda: set(threading.enumerate()) <= threads, timeout=5)


def test_a_gui_routine_that_calls_os_exit_and_forks_leaves_the_lab_running(tmp_path):
    from mexone.gui.app import GuiApp
    from mexone.physics import CompileOptions

    (tmp_path / "bye.py").write_text(HEAD + "if os.fork() == 0:\n    while True:\n        pass\n"
                                     "os._exit(0)\n")
    app = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 routine_dirs=[tmp_path])
    loop = threading.Thread(target=app.serve_forever, daemon=True)
    loop.start()
    children = my_children()
    try:
        app.panels["routines"].choice.value = "bye.py"
        app.do(app.panels["routines"].start)
        # it ended, with its error on the page
        assert wait_until(lambda: "os._exit(0)" in app.panels["routines"].console_view.content, timeout=20)
        assert "the routine called os._exit(0)" in app.panels["routines"].console_view.content
        assert "the routine left process" in app.panels["routines"].console_view.content
        t0 = app.lab.sim.time
        assert wait_until(lambda: app.lab.sim.time > t0 + 0.2, timeout=10)  # the lab goes on
        assert wait_until(lambda: my_children() <= children, timeout=5)
    finally:
        app.stop()
        loop.join(timeout=5)
