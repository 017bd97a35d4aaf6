"""Grading time for a class: `mexone exercise grade NAME FOLDER --csv -` over every exercise of
the shipped course, each on a folder of submissions (its reference and its starter), as a
teacher grades a class; the wall time of each command (interpreter start included).

    PYTHONPATH=src python benchmarks/grading.py [--repeat 1] [--only NAME ...] [--ab OTHER_SRC]

--ab OTHER_SRC pairs each run with one of another mexone (e.g. main's src, exported with
`git archive`), alternating them exercise by exercise so both see the same load; the ratio is
this one's wall time over the other's.

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
    parser.add_argument("--ab", type=Path, default=None, help="another mexone's src to pair with")
    args = parser.parse_args()
    print(f"load: {os.getloadavg()[0]:.1f} {os.getloadavg()[1]:.1f} {os.getloadavg()[2]:.1f} "
          f"(1, 5, 15 min) on {os.cpu_count()} cores")
    sources = {"this": str(Path(__file__).resolve().parents[1] / "src")}
    if args.ab is not None:
        sources["other"] = str(args.ab.resolve())
    totals = dict.fromkeys(sources, 0.0)
    header = " ".join(f"{k + ' s':>8}" for k in sources)
    print(f"{'exercise':<24} {'subs':>4} {header}{'  ratio' if args.ab else ''}  scores")
    for name in exercises():
        if args.only and name not in args.only:
            continue
        ex = find_exercise(name)
        best: dict[str, float] = {}
        scores = ""
        for _ in range(max(1, args.repeat)):
            for label, src in sources.items():
                with tempfile.TemporaryDirectory() as tmp:
                    count = _class_folder(ex, Path(tmp) / "class")
                    began = time.perf_counter()
                    out = subprocess.run([sys.executable, "-m", "mexone", "exercise", "grade",
                                          name, str(Path(tmp) / "class"), "--csv", "-"],
                                         capture_output=True, text=True, check=False,
                                         env={**os.environ, "PYTHONPATH": src})
                    wall = time.perf_counter() - began
                if out.returncode != 0:
                    print(f"{name} ({label}): exit {out.returncode}: {out.stderr.strip()[-300:]}")
                    continue
                if label == "this":
                    scores = " ".join(row.split(",")[1] for row in out.stdout.splitlines()[1:])
                best[label] = min(best.get(label, wall), wall)
        if len(best) == len(sources):
            for label in sources:
                totals[label] += best[label]
            shown = " ".join(f"{best[k]:8.1f}" for k in sources)
            ratio = f"  {best['this'] / best['other']:5.2f}" if args.ab else ""
            print(f"{name:<24} {count:>4} {shown}{ratio}  {scores}", flush=True)
    shown = " ".join(f"{totals[k]:8.1f}" for k in sources)
    ratio = f"  {totals['this'] / totals['other']:5.2f}" if args.ab and totals["other"] else ""
    print(f"{'the course':<24} {'':>4} {shown}{ratio}")
    print(f"load after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
