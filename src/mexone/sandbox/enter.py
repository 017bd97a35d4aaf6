"""The first moments of a student's process (`python -I -S enter.py LIMITS PROGRAM...`): its
limits, then the program, which replaces this one. Run by path with no site and no package
imported, so nothing of mexone's or the parent's runs here."""

import contextlib
import json
import os
import resource
import sys


def enter(limits: str, argv: list[str]) -> None:
    cpu, memory_mb = json.loads(limits)
    cpu = max(1, int(cpu))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    with contextlib.suppress(ValueError, OSError):
        mem = int(memory_mb) * 1024 * 1024
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    with contextlib.suppress(ValueError, OSError):
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    os.execv(argv[0], argv)


if __name__ == "__main__":
    enter(sys.argv[1], sys.argv[2:])
