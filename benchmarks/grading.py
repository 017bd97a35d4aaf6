"""Grading time for a class: `mexone exercise grade NAME FOLDER --csv -` over every exercise of
the shipped course, each on a folder of submissions (its reference and its starter, or
`--students N` of them in turn), as a teacher grades a class; the wall time of each command
(interpreter start included) and its CPU time (the command and every process it waited for:
the grader, the isolated runs, their workers).

    PYTHONPATH=src python benchmarks/grading.py [--repeat 1] [--only NAME ...] [--students 2]
        [--ab OTHER_SRC]

--ab OTHER_SRC pairs each run with one of another mexone (e.g. an older commit's src, checked
out with `git worktree add`), alternating them exercise by exercise so both see the same load;
the ratios are this one's wall and CPU time over the other's.

The reference is the exercise's solution/ file if the course still carries it, else the
teacher's pack's (MEXONE_TEACHER_PACK=DIR: DIR/NAME/solution/FILE). Record the table, the
load (uptime) and the isolation the machine offered in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import resource
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


def _class_folder(ex, folder: Path, students: int = 2) -> int:
    """A class of `students` submissions for `ex`, one subfolder each: its reference and its
    starter in turn."""
    sources = [s for s in (_reference(ex), ex.starter) if s is not None and s.is_file()]
    for k in range(students if sources else 0):
        (folder / f"s{k:02d}").mkdir(parents=True)
        shutil.copyfile(sources[k % len(sources)], folder / f"s{k:02d}" / ex.file)
    return students if sources else 0


CPUACCT = Path("/sys/fs/cgroup/cpuacct")  # cgroup v1's CPU accounting (root may make groups)


class _CpuMeter:
    """CPU seconds of a command and of every process it starts, however they end (a jailed run
    in a namespace of its own, a fork server killed rather than waited for): a cgroup of its
    own where this process may make one (root, cgroup v1 cpuacct), else wait4's RUSAGE_CHILDREN
    delta, which counts only the processes their parents waited for (say which in the table)."""

    def __init__(self) -> None:
        self.group: Path | None = CPUACCT / f"mexone-grading-{os.getpid()}"
        try:
            self.group.mkdir(exist_ok=True)
        except OSError:
            self.group = None
        self.how = "cgroup cpuacct" if self.group else "RUSAGE_CHILDREN (waited-for only)"

    def _used(self) -> float:
        if self.group is not None:
            return int((self.group / "cpuacct.usage").read_text()) * 1e-9
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime

    def run(self, command: list[str], env: dict[str, str]
            ) -> tuple[subprocess.CompletedProcess, float, float]:
        """-> (its result, wall s, CPU s: user + system of it and what it started)."""
        procs = None if self.group is None else self.group / "cgroup.procs"

        def join() -> None:  # in the child, before exec: it and its descendants counted
            if procs is not None:
                procs.write_text(str(os.getpid()))

        cpu, began = self._used(), time.perf_counter()
        out = subprocess.run(command, capture_output=True, text=True, check=False, env=env,
                             preexec_fn=join)  # noqa: PLW1509 - one thread here
        return out, time.perf_counter() - began, self._used() - cpu

    def close(self) -> None:
        if self.group is not None:
            with contextlib.suppress(OSError):
                self.group.rmdir()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="runs per exercise (the best kept)")
    parser.add_argument("--only", nargs="*", default=None, help="these exercises only")
    parser.add_argument("--students", type=int, default=2, help="submissions per exercise")
    parser.add_argument("--ab", type=Path, default=None, help="another mexone's src to pair with")
    args = parser.parse_args()
    print(f"load: {' '.join(f'{x:.1f}' for x in os.getloadavg())} (1, 5, 15 min) on "
          f"{os.cpu_count()} cores")
    secret = os.environ.get("MEXONE_EXERCISE_SECRET") or "benchmark-secret-not-a-real-one"
    sources = {"this": str(Path(__file__).resolve().parents[1] / "src")}
    if args.ab is not None:
        sources["other"] = str(args.ab.resolve())
    totals = {k: [0.0, 0.0] for k in sources}
    meter = _CpuMeter()
    print(f"CPU time by {meter.how}")
    header = " ".join(f"{k + ' wall':>10} {k + ' cpu':>10}" for k in sources)
    ratios = "  wall x   cpu x" if args.ab else ""
    print(f"{'exercise':<24} {'subs':>4} {header}{ratios}  scores (this)")
    for name in exercises():
        if args.only and name not in args.only:
            continue
        ex = find_exercise(name)
        best: dict[str, list[float]] = {}
        scores = ""
        for _ in range(max(1, args.repeat)):
            for label, src in sources.items():
                with tempfile.TemporaryDirectory() as tmp:
                    count = _class_folder(ex, Path(tmp) / "class", args.students)
                    out, wall, cpu = meter.run([sys.executable, "-m", "mexone", "exercise", "grade",
                                             name, str(Path(tmp) / "class"), "--csv", "-"],
                                            {**os.environ, "PYTHONPATH": src,
                                             "MEXONE_EXERCISE_SECRET": secret})
                if out.returncode != 0:
                    print(f"{name} ({label}): exit {out.returncode}: {out.stderr.strip()[-300:]}")
                    continue
                if label == "this":
                    scores = " ".join(row.split(",")[1] for row in out.stdout.splitlines()[1:])
                was = best.get(label, [wall, cpu])
                best[label] = [min(was[0], wall), min(was[1], cpu)]
        if len(best) == len(sources):
            for label in sources:
                totals[label] = [a + b for a, b in zip(totals[label], best[label], strict=True)]
            print(f"{name:<24} {count:>4} {_row(best, bool(args.ab))}  {scores}", flush=True)
    print(f"{'the class':<24} {'':>4} {_row(totals, bool(args.ab))}")
    print(f"load after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    meter.close()


def _row(times: dict[str, list[float]], ab: bool) -> str:
    """Wall and CPU s per source, and this over the other's."""
    shown = " ".join(f"{w:10.1f} {c:10.1f}" for w, c in times.values())
    if not ab or not all(times["other"]):
        return shown
    return (f"{shown}  {times['this'][0] / times['other'][0]:6.2f} "
            f"{times['this'][1] / times['other'][1]:6.2f}")


if __name__ == "__main__":
    main()
