"""What each isolation layer of a student's jail costs (mexone.sandbox), on this machine:

- start: `spawn` of a Python that does nothing, to its end (interpreter start included), in
  each isolation the machine offers (MEXONE_SANDBOX=none, uid, namespaces);
- a graded run: exercises.isolate's run_trusted (the simulator: a fork) and run_jailed (a fork
  that confines itself) of a function that returns at once;
- inside: 200 000 system calls (os.getppid) and 20 000 opens of a file, in a jail and outside
  (seccomp's filter runs on every call, Landlock's rules on every open).

    PYTHONPATH=src python benchmarks/sandbox.py [--repeat 10] [--python /usr/bin/python3]

--python: the interpreter of the start and system-call rows (a jail of another uid runs only
a Python others may read: the system's, where this one lies in /root).

Record the table and the load (uptime) in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

CHILD = '''
import json, subprocess, sys, time
from mexone.sandbox import Jail, spawn, isolation
repeat = int(sys.argv[1])
print(json.dumps({"isolation": isolation().describe()}), flush=True)
spawn([sys.executable, "-c", "pass"], Jail()).wait(60)  # warm
began = time.perf_counter()
for _ in range(repeat):
    with spawn([sys.executable, "-I", "-S", "-c", "pass"], Jail()) as p:
        p.wait(60)
start = (time.perf_counter() - began) / repeat
code = ("import os, time\\nopen('f', 'w').close()\\nt = time.perf_counter()\\n"
        "for _ in range(200000): os.getppid()\\ns = time.perf_counter() - t\\n"
        "t = time.perf_counter()\\n"
        "for _ in range(20000): os.close(os.open('f', os.O_RDONLY))\\n"
        "print(s, time.perf_counter() - t)")
with spawn([sys.executable, "-I", "-S", "-c", code], Jail(), stdout=subprocess.PIPE) as p:
    calls, opens = (float(x) for x in p.popen.stdout.read().split())
print(json.dumps({"start": start, "calls": calls, "opens": opens}))
'''

BARE = ("import os, time\nopen('/tmp/mexone-bench-f', 'w').close()\nt = time.perf_counter()\n"
        "for _ in range(200000): os.getppid()\ns = time.perf_counter() - t\n"
        "t = time.perf_counter()\n"
        "for _ in range(20000): os.close(os.open('/tmp/mexone-bench-f', os.O_RDONLY))\n"
        "print(s, time.perf_counter() - t)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10)
    parser.add_argument("--python", default=sys.executable, help="the jails' interpreter")
    args = parser.parse_args()
    print(f"load: {' '.join(f'{x:.1f}' for x in os.getloadavg())} (1, 5, 15 min) on "
          f"{os.cpu_count()} cores")
    began = time.perf_counter()
    for _ in range(args.repeat):
        subprocess.run([args.python, "-I", "-S", "-c", "pass"], check=True)
    bare = (time.perf_counter() - began) / args.repeat
    calls, opens = (float(x) for x in subprocess.run([args.python, "-I", "-S", "-c", BARE],
                                                     capture_output=True, text=True,
                                                     check=True).stdout.split())
    print(f"{'isolation':<11} {'start ms':>9} {'getppid ns':>11} {'open us':>8}")
    print(f"{'(no jail)':<11} {bare * 1e3:9.1f} {calls / 2e5 * 1e9:11.0f} {opens / 2e4 * 1e6:8.2f}")
    for mode in ("none", "uid", "namespaces"):
        out = subprocess.run([args.python, "-c", CHILD, str(args.repeat)], capture_output=True,
                             text=True, env={**os.environ, "MEXONE_SANDBOX": mode})
        lines = out.stdout.splitlines()
        if out.returncode != 0 or len(lines) < 2:
            print(f"{mode:<11} failed: {out.stderr.strip()[-200:]}")
            continue
        row = json.loads(lines[1])
        print(f"{mode:<11} {row['start'] * 1e3:9.1f} {row['calls'] / 2e5 * 1e9:11.0f} "
              f"{row['opens'] / 2e4 * 1e6:8.2f}  ({json.loads(lines[0])['isolation']})")
    from mexone.exercises.isolate import prewarm, run_jailed, run_trusted

    prewarm()
    for run in (run_trusted, run_jailed):
        run(sum, [1])
        began = time.perf_counter()
        for _ in range(args.repeat):
            run(sum, [1, 2])
        print(f"{run.__name__:<11} {(time.perf_counter() - began) / args.repeat * 1e3:9.1f} ms "
              "a graded run of a function that returns at once")


if __name__ == "__main__":
    main()
