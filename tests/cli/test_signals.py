"""Signals: a Ctrl-C or SIGTERM during start-up is one line and exit 130/143 for every verb (it
used to be a KeyboardInterrupt traceback and exit -2); a file being finished waits for nothing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import weakref
from pathlib import Path

import pytest

from mexone import signals
from mexone.robots import mex_one

VERBS = {
    "sim": ["sim", "--headless", "--duration", "5"],
    "run": ["run", "home", "--duration", "5"],
    "record": ["record", "-o", "r.mcap", "--duration", "5"],
    "plot": ["plot", "r.mcap", "-o", "p.png"],
    "render": ["render", "arms", "-o", "r.mp4", "--duration", "1"],
    "sweep": ["sweep", "--joint", "l_elbow", "--p", "10", "--duration", "0.3", "-o", "sw"],
    "check": ["check"],
    "convert": ["convert", str(mex_one.urdf_path()), "-o", "x.sdf"],
    "bench": ["bench", "--quick"],
}


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # even if pytest runs as a background job


def catches(pid: int, signum: int) -> bool:
    """Whether mexone (not the forked pytest it was before exec) has a handler for signum
    (Linux: SigCgt in /proc/PID/status)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        command = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except FileNotFoundError:
        return False
    mask = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt")), 16)
    return b"mexone" in command and bool(mask >> (signum - 1) & 1)


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux /proc")
def test_a_signal_during_start_up_is_one_line_and_128_plus_n(tmp_path):
    """The signal goes in as soon as mexone's handlers are installed (Python does not catch
    SIGTERM, so SigCgt showing it is that moment), while the verbs' modules are still loading."""
    started = {}
    for k, (verb, args) in enumerate(VERBS.items()):  # both signals take the same path
        signum = (signal.SIGINT, signal.SIGTERM)[k % 2]
        started[verb, signum] = subprocess.Popen(
            [sys.executable, "-m", "mexone", *args], cwd=tmp_path, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    deadline = time.monotonic() + 60
    pending = dict(started)
    while pending and time.monotonic() < deadline:
        for key, proc in list(pending.items()):
            if catches(proc.pid, signal.SIGTERM) or proc.poll() is not None:
                proc.send_signal(key[1])
                del pending[key]
        time.sleep(0.002)
    assert not pending, f"never installed its handlers: {sorted(pending)}"
    for (verb, signum), proc in started.items():
        out, err = proc.communicate(timeout=60)
        name = signal.Signals(signum).name
        assert (proc.returncode, err) == (128 + signum, f"mexone: interrupted by {name}\n"), \
            (verb, name, proc.returncode, err)


def test_finishing_defers_a_signal_until_the_file_is_done(monkeypatch):
    """In a library user's process (no CLI handlers): Ctrl-C during a bag's closing waits, then
    reaches the user's own handler."""
    monkeypatch.setattr(signals, "_state", signals._State())  # as if the CLI never ran here
    saved = {s: signal.getsignal(s) for s in signals.SIGNALS}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    done = []
    try:
        with pytest.raises(KeyboardInterrupt), signals.finishing():
            signal.raise_signal(signal.SIGINT)
            done.append("closed")  # reached: the signal did not cut the block short
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        for signum, handler in saved.items():
            signal.signal(signum, handler)
    assert done == ["closed"]


def test_uninterrupted_is_cheap_enough_for_every_message():
    # our cost: this thread's own CPU time (0.2-0.3 us here), not the wall time a stalled host
    # or another job on the core adds
    start = time.thread_time()
    for _ in range(100_000):
        with signals.uninterrupted:
            pass
    assert (time.thread_time() - start) / 100_000 < 5e-6  # s per message


@pytest.fixture
def cli_handlers(monkeypatch):
    """mexone's handlers installed in this process, as the CLI installs them; restored after."""
    monkeypatch.setattr(signals, "_state", signals._State())
    saved = {s: signal.getsignal(s) for s in signals.SIGNALS}
    signals.stop_on_signals()
    try:
        yield
    finally:
        for signum, handler in saved.items():
            signal.signal(signum, handler)


def _signal_self(signum: int) -> list[bool]:
    """Send signum to this process and spin a few bytecodes so the handler runs right here;
    return whether the stop was seen afterwards (a handler that raised never gets there)."""
    os.kill(os.getpid(), signum)
    for _ in range(1000):
        if signals.requested():
            break
    return [signals.requested()]


def test_a_signal_inside_del_or_a_weakref_callback_is_not_lost(cli_handlers, capsys):
    """The bug: SIGTERM landed in WeakValueDictionary's callback, the handler's KeyboardInterrupt
    was printed as 'Exception ignored' and dropped, and `mexone sim` ran on for 40 minutes."""
    seen: list[bool] = []

    class Dropped:
        def __del__(self):
            seen.extend(_signal_self(signal.SIGTERM))

    Dropped()  # __del__ runs now, and the handler inside it
    assert seen == [True]  # the handler ran inside __del__ and did not raise there
    assert signals.requested() and signals.exit_code() == 143
    with pytest.raises(signals.Stop):
        signals.check()  # the stop is raised where mexone's code asks for it

    signals._state.first = None  # again, through a weakref callback, as in the report
    cache = weakref.WeakValueDictionary()

    class Value:
        pass

    cache["page"] = value = Value()
    ref = weakref.ref(value, lambda _ref: seen.extend(_signal_self(signal.SIGINT)))
    del value  # the callbacks run now
    assert ref() is None and "page" not in cache
    assert seen == [True, True] and signals.exit_code() == 130
    assert "Exception ignored" not in capsys.readouterr().err


def test_a_second_signal_within_the_grace_is_the_same_stop(cli_handlers):
    signals._on_signal(signal.SIGINT, None)
    signals._on_signal(signal.SIGTERM, None)  # a double stop: recorded once, nothing raised
    assert signals.exit_code() == 130


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, preexec_fn=_default_sigint)


def test_a_later_second_signal_ends_a_stop_that_hangs_unless_a_file_is_being_closed():
    hung = ("import os, signal, time\nfrom mexone import signals\nsignals.stop_on_signals()\n"
            "{hold}os.kill(os.getpid(), signal.SIGTERM)\ntime.sleep(signals.GRACE + 0.2)\n"
            "os.kill(os.getpid(), signal.SIGINT)\ntime.sleep(0.5)\nprint('survived', flush=True)\n")
    ended = _python(hung.format(hold=""))
    assert ended.returncode == 143 and ended.stdout == ""
    assert ended.stderr == "mexone: stopping took too long; ended by a second SIGINT\n"
    closing = _python(hung.format(hold="signals.hold('x.mcap')\n"))
    assert closing.returncode == 0 and closing.stdout == "survived\n"
    assert closing.stderr == ("mexone: still stopping: closing x.mcap, one moment "
                              "(kill -9 abandons it)\n")


def test_a_signal_the_parent_ignored_stays_ignored():
    code = ("import os, signal\nsignal.signal(signal.SIGHUP, signal.SIG_IGN)\n"
            "from mexone import signals\nsignals.stop_on_signals()\n"
            "print(signal.getsignal(signal.SIGHUP) is signal.SIG_IGN, "
            "signal.getsignal(signal.SIGTERM) is signals._on_signal)\n")
    assert _python(code).stdout == "True True\n"


def test_a_forked_child_gets_the_default_dispositions(cli_handlers):
    """fork copies the handlers; a sweep's worker with ours would record SIGTERM and run on."""
    signals._on_signal(signal.SIGTERM, None)  # the parent is stopping
    pid = os.fork()
    if pid == 0:  # the child: default SIGTERM, no stop recorded
        ok = signal.getsignal(signal.SIGTERM) is signal.SIG_DFL and not signals.requested()
        os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    assert signal.getsignal(signal.SIGTERM) is signals._on_signal and signals.requested()
