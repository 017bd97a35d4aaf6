"""Signals: a Ctrl-C or SIGTERM during start-up is one line and exit 130/143 for every verb (it
used to be a KeyboardInterrupt traceback and exit -2); a file being finished waits for nothing."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
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
    start = time.perf_counter()
    for _ in range(100_000):
        with signals.uninterrupted:
            pass
    assert (time.perf_counter() - start) / 100_000 < 5e-6  # s per message
