"""A class graded with `mexone exercise grade NAME DIR`: serially, by `--workers N` local processes
and as Ray tasks (`--backend ray`), over the same folder of a class's usual submissions (right,
wrong, raising, NaN, syntax error, spinning, sleeping in its update, sleeping at import, nothing
handed in). Prints wall time, speed-up and parallel efficiency against the serial run, whether
each CSV is the serial one byte for byte and every student is in it once, and the load.

    python benchmarks/grade_class.py [--students 100] [--workers 2] [--no-ray]

gravity_compensation is the cheapest exercise a student hands in Python for (about 1 s of
simulation per run): a crash or a hang is then one a student's Python can make.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EXERCISE = "gravity_compensation"
RETURN = "        return self.kp"  # the starter's update's last line, which the kinds edit


def kinds() -> list[tuple[str, str | None]]:
    """(kind, the file's text or None: nothing handed in), one class's worth of each."""
    from mexone.exercises import find_exercise

    ex = find_exercise(EXERCISE)
    starter = ex.starter.read_text()
    assert RETURN in starter, "the starter changed: update RETURN"

    def update(body: str) -> str:
        return starter.replace(RETURN, body + "\n" + RETURN)

    return [("right", ex.solution.read_text()), ("wrong", starter),
            ("raises", update("        raise RuntimeError('a bug')")),
            ("nan", starter.replace(RETURN, "        return float('nan') * self.kp")),
            ("syntax", "def update(self:\n"),
            ("right", ex.solution.read_text()),
            ("spins", update("        while True: pass")),  # one line: a deterministic report
            ("sleeps", update("        import time\n        time.sleep(600)")),
            ("wrong", starter), ("missing", None)]


def make_class(folder: Path, students: int) -> dict[str, str]:
    """`students` submissions cycling through kinds(), and once per 50 one that sleeps at
    import (the import's time limit ends it). Returns student -> kind."""
    table = kinds()
    made = {}
    for i in range(students):
        kind, text = table[i % len(table)]
        if i % 50 == 49:
            kind, text = "sleeps at import", "import time\ntime.sleep(600)\n"
        student = f"s{i:03d}"
        made[student] = kind
        if text is None:
            (folder / student).mkdir()
        else:
            (folder / f"{student}.py").write_text(text)
    return made


def grade(folder: Path, out: Path, more: list[str]) -> dict:
    load = os.getloadavg()[0]
    start = time.monotonic()
    subprocess.run([sys.executable, "-m", "mexone", "exercise", "grade", EXERCISE, str(folder),
                    "--csv", str(out), "--force", *more], check=True, stdout=subprocess.DEVNULL)
    seconds = time.monotonic() - start
    return {"run": " ".join(more) or "serial", "seconds": round(seconds, 1),
            "per_submission": round(seconds / len(list(folder.iterdir())), 2),
            "load_before": round(load, 1), "load_after": round(os.getloadavg()[0], 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--students", type=int, default=100)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-ray", action="store_true", help="local processes only")
    args = parser.parse_args()
    os.environ.setdefault("MEXONE_EXERCISE_SECRET", "grade_class.py's secret, not a course's")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "class"
        folder.mkdir()
        made = make_class(folder, args.students)
        runs = [[], ["--workers", str(args.workers)]]
        if not args.no_ray:
            runs.append(["--backend", "ray", "--workers", str(args.workers)])
        csvs: list[str] = []
        rows: list[dict] = []
        for i, more in enumerate(runs):
            out = Path(tmp) / f"grades-{i}.csv"
            row = grade(folder, out, more)
            csvs.append(out.read_text())
            with out.open() as handle:
                students = [r["student"] for r in csv.DictReader(handle)]
            base = rows[0]["seconds"] if rows else row["seconds"]
            workers = 1 if i == 0 else args.workers
            row.update(speed_up=round(base / row["seconds"], 2),
                       efficiency=round(base / row["seconds"] / workers, 2),
                       same_csv=csvs[i] == csvs[0],
                       each_once=sorted(students) == sorted(made) and len(set(students)) == len(made))
            rows.append(row)
            print(json.dumps({"students": args.students, **row}), flush=True)
        print(json.dumps({"kinds": {k: list(made.values()).count(k) for k in set(made.values())}}))


if __name__ == "__main__":
    main()
