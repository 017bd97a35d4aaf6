"""Students per machine: N real sessions through a real JupyterHub on this machine, each a Unix
user with their own Jupyter server and `mexone sim` started by the launcher entry (through
jupyter-server-proxy), each with its page's traffic open (a websocket client reading everything
the lab sends, through the hub's proxy and the student's server, as a browser tab would). Prints
each lab's real-time factor (from the sim time its page shows), CPU share and memory, and the
students' Jupyter servers' cost. Needs root and tests/hub's configurable-http-proxy (npm, as
scripts/test.sh installs it); the students' venv is brought up to date with this checkout.

    python benchmarks/hub_class.py [--students 20] [--seconds 30]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent / "tests" / "hub")]

from classroom import Classroom, class_names, labs_of, missing, pids_of, students_venv  # noqa: E402
from lab_cost import Page, cpu_seconds, rss_mb  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--students", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=30.0)
    args = parser.parse_args()
    why = missing()
    if why:
        sys.exit(f"hub_class: {why}")
    sys.path.insert(0, str(HERE.parent / "tests"))  # wheelenv, to build this checkout's wheel
    students_venv()
    names = class_names(*(f"s{i:02d}" for i in range(args.students)))
    room = Classroom(names).start()
    try:
        pages = []
        for name in names:
            token = room.spawn(name)
            url = f"ws://127.0.0.1:{room.port}/user/{name}/mexone/index.html"
            page = Page(url, {"Authorization": f"token {token}"})
            page.start()
            pages.append(page)
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and any(len(p.samples) < 3 and not p.error for p in pages):
            time.sleep(1.0)
        labs = {name: labs_of(name)[0] for name in names}
        servers = {name: [pid for pid in pids_of(labs[name].uid) if pid != labs[name].pid]
                   for name in names}
        time.sleep(5.0)
        load = os.getloadavg()
        t0 = time.monotonic()
        c0 = {n: cpu_seconds(lab.pid) for n, lab in labs.items()}
        s0 = {n: sum(cpu_seconds(p) for p in servers[n]) for n in names}
        time.sleep(args.seconds)
        t1 = time.monotonic()
        rows = []
        for page, name in zip(pages, names, strict=True):
            lab = labs[name]
            rows.append({"student": name, "rtf": page.rtf(t0),
                         "lab_cpu_percent": 100 * (cpu_seconds(lab.pid) - c0[name]) / (t1 - t0),
                         "lab_rss_mb": rss_mb(lab.pid),
                         "server_cpu_percent": 100 * (sum(cpu_seconds(p) for p in servers[name])
                                                      - s0[name]) / (t1 - t0),
                         "server_rss_mb": sum(rss_mb(p) for p in servers[name]),
                         "error": page.error})
        for page in pages:
            page.stop.set()
        summary = {
            "students": args.students, "load_before": load, "load_after": os.getloadavg(),
            "min_rtf": min(r["rtf"] for r in rows),
            "median_rtf": statistics.median(r["rtf"] for r in rows),
            "lab_cpu_percent": statistics.mean(r["lab_cpu_percent"] for r in rows),
            "lab_rss_mb": statistics.mean(r["lab_rss_mb"] for r in rows),
            "server_cpu_percent": statistics.mean(r["server_cpu_percent"] for r in rows),
            "server_rss_mb": statistics.mean(r["server_rss_mb"] for r in rows),
            "errors": [r["error"] for r in rows if r["error"]],
        }
        for row in rows:
            print(json.dumps(row), file=sys.stderr)
        print(json.dumps(summary))
    finally:
        room.stop()


if __name__ == "__main__":
    main()
