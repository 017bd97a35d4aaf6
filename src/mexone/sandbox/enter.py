"""The first moments of a jail spawned by `spawn`: ``python -I -S enter.py PLAN FDS PROGRAM...``
confines itself as PLAN says (confine.jail: this process stays outside as the jail's relay)
and the jail's first process becomes PROGRAM. ``enter.py --probe`` prints what the machine
offers (confine.probe, in this throwaway process). Run by path with no site and no package
imported, so nothing of mexone's or the parent's runs here."""

import os
import sys


def main(argv: list[str]) -> None:
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import confine  # type: ignore[import-not-found]  # this folder's, by path: no package

    if argv[:1] == ["--probe"]:
        import json

        print(json.dumps(confine.probe()), flush=True)
        return
    plan = confine.Plan.loads(argv[0])
    keep = tuple(int(fd) for fd in argv[1].split(",") if fd)
    program = argv[2:]
    confine.jail(plan, keep)
    try:
        os.execv(program[0], program)
    except OSError as exc:
        os.write(2, f"mexone sandbox: cannot start {program[0]}: {exc.strerror}\n".encode())
        os._exit(127)


if __name__ == "__main__":
    main(sys.argv[1:])
