"""A class graded with `mexone exercise grade NAME DIR --workers N`: wall time for each N over the
same folder (a mix of right, wrong, broken and missing submissions), the speed-up and the
parallel efficiency against N = 1, and whether every CSV is the serial one.

    python benchmarks/grade_class.py [--students 12] [--workers 1 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def make_class(folder: Path, students: int) -> None:
    from mexone.exercises import find_exercise

    ex = find_exercise("home_hold")
    kinds = [ex.solution.read_text(), ex.starter.read_text(), "mex_rb: [unclosed\n", None]
    for i in range(students):
        text = kinds[i % len(kinds)]
        if text is None:
            (folder / f"s{i:03d}").mkdir()  # handed in nothing
        else:
            (folder / f"s{i:03d}.yaml").write_text(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--students", type=int, default=12)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "class"
        folder.mkdir()
        make_class(folder, args.students)
        rows, csvs = [], {}
        for n in args.workers:
            out = Path(tmp) / f"grades-{n}.csv"
            load = os.getloadavg()[0]
            start = time.monotonic()
            subprocess.run([sys.executable, "-m", "mexone", "exercise", "grade", "home_hold",
                            str(folder), "--csv", str(out), "--workers", str(n)], check=True,
                           stdout=subprocess.DEVNULL)
            rows.append({"workers": n, "seconds": round(time.monotonic() - start, 1),
                         "load_before": round(load, 1)})
            csvs[n] = out.read_text()
        base = rows[0]["seconds"]
        for row in rows:
            row["speed_up"] = round(base / row["seconds"], 2)
            row["efficiency"] = round(row["speed_up"] * rows[0]["workers"] / row["workers"], 2)
            row["same_csv"] = csvs[row["workers"]] == csvs[rows[0]["workers"]]
            print(json.dumps({"students": args.students, **row}))


if __name__ == "__main__":
    main()
