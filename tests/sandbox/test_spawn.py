"""sandbox.spawn: the limits hold in the new process, the secret never reaches it, it works in
its scratch folder, and kill() ends what it started."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from helpers import wait_until
from mexone.sandbox import Jail, Limits, spawn

PROBE = ("import json, os, resource; print(json.dumps([resource.getrlimit(resource.RLIMIT_CPU)[0], "
         "resource.getrlimit(resource.RLIMIT_AS)[0], os.getcwd(), "
         "'MEXONE_EXERCISE_SECRET' in os.environ]))")


def test_limits_scratch_and_no_secret(tmp_path, monkeypatch):
    import json

    monkeypatch.setenv("MEXONE_EXERCISE_SECRET", "teacher's")
    jail = Jail(scratch=tmp_path / "scratch", limits=Limits(cpu=7, memory_mb=900))
    with spawn([sys.executable, "-c", PROBE], jail, stdout=subprocess.PIPE) as proc:
        out = proc.popen.stdout.read()
        assert proc.wait(30) == 0
    cpu, memory, cwd, secret = json.loads(out)
    assert cpu == 7 and memory == 900 * 1024 * 1024
    assert cwd == str(tmp_path / "scratch") and not secret


def test_kill_ends_its_process_group():
    code = "import subprocess, time; subprocess.Popen(['sleep', '300']); print('up', flush=True); time.sleep(300)"
    proc = spawn([sys.executable, "-c", code], Jail(), stdout=subprocess.PIPE)
    assert proc.popen.stdout.readline() == b"up\n"
    pgid = proc.pid
    proc.kill()
    assert proc.returncode is not None
    assert wait_until(lambda: not _running_in_group(pgid), timeout=10), _running_in_group(pgid)
    assert not os.path.exists(proc.scratch)  # its own scratch folder went with it


def _running_in_group(pgid: int) -> list[int]:
    """Processes of group `pgid` that have not ended (zombies have: only their status waits)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2:].split()
            if int(fields[2]) == pgid and fields[0] not in "ZX":
                out.append(int(entry))
    return out
