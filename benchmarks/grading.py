"""Grading time for a class: `mexone exercise grade NAME FOLDER --csv -` over every exercise of
the shipped course, each on a folder of submissions (its reference and its starter), as a
teacher grades a class; the wall time of each command (interpreter start included).

    PYTHONPATH=src python benchmarks/grading.py [--repeat 1] [--only NAME ...]

The reference is the exercise's solution/ file if the course still carries it, else the
teacher's pack's (MEXONE_TEACHER_PACK=DIR: DIR/NAME/solution/FILE). Record the table, the
load (uptime) and the isolation the machine offered in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mexone.exercises import exercises, find_exercise


def _reference(ex) -> Path | None:
    if ex.solution.is_file():
        return ex.solution
    pack = os.environ.get("MEXONE_TEACHER_PACK")
    if pack and (Path(pack) / ex.name / "solution" / ex.file).is_file():
        return Path(pack) / ex.name / "solution" / ex.file
    return None


def _class_folder(ex, folder: Path) -> int:
    """A class of submissions for `ex`: its reference and its starter, one subfolder each."""
    count = 0
    for student, source in (("ada", _reference(ex)), ("bob", ex.starter)):
        if source is not None and source.is_file():
            (folder / student).mkdir(parents=True)
            shutil.copyfile(source, folder / student / ex.file)
            count += 1
    return count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="runs per exercise (the best kept)")
    parser.add_argument("--only", nargs="*", default=None, help="these exercises only")
    args = parser.parse_args()
    print(f"load: {os.getloadavg()[0]:.1f} {os.getloadavg()[1]:.1f} {os.getloadavg()[2]:.1f} "
          f"(1, 5, 15 min) on {os.cpu_count()} cores")
    total = 0.0
    print(f"{'exercise':<24} {'subs':>4} {'wall s':>7}  scores")
    for name in exercises():
        if args.only and name not in args.only:
            continue
        ex = find_exercise(name)
        best = None
        for _ in range(max(1, args.repeat)):
            with tempfile.TemporaryDirectory() as tmp:
                count = _class_folder(ex, Path(tmp) / "class")
                began = time.perf_counter()
                out = subprocess.run([sys.executable, "-m", "mexone", "exercise", "grade", name,
                                      str(Path(tmp) / "class"), "--csv", "-"],
                                     capture_output=True, text=True, check=False)
                wall = time.perf_counter() - began
            if out.returncode != 0:
                print(f"{name}: exit {out.returncode}: {out.stderr.strip()[-300:]}")
                break
            scores = " ".join(row.split(",")[1] for row in out.stdout.splitlines()[1:])
            best = wall if best is None else min(best, wall)
        if best is not None:
            total += best
            print(f"{name:<24} {count:>4} {best:7.1f}  {scores}", flush=True)
    print(f"{'the course':<24} {'':>4} {total:7.1f}")


if __name__ == "__main__":
    main()
