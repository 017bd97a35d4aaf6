"""A class's submissions graded in parallel (`mexone exercise grade NAME DIR --workers N`).

Each submission is graded by `grading.grade` in a worker process, not a thread: the teacher's
grader, matplotlib and the fork server of the isolated runs belong to one process each. Inside
a worker a submission runs isolated exactly as in a serial run. Results come back in the order of
the submissions whatever order they finish in, so the report and the CSV are the serial run's.

A signal (Ctrl-C) ends the workers at once (the runs they started die with them) and stops the
grading. A worker that dies otherwise (killed, out of memory) breaks its pool: the submissions
without a result are graded again by a new pool, those with one never twice.
"""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from mexone import signals
from mexone.errors import MexoneError
from mexone.exercises.exercise import Exercise
from mexone.exercises.grading import Result, grade, not_handed_in

__all__ = ["grade_all"]

POLL = 0.2  # s between two looks at the signals while the workers grade
POOLS = 3  # pools that may break (a worker killed) before the grading gives up


def _grade_one(exercise: Exercise, path: Path, local: bool, plots: Path | None,
               force: bool) -> Result:
    # a symlink is graded too: grade() refuses it unread, with its reason
    return grade(exercise, path, local=local, plots=plots, force=force) \
        if path.is_file() or path.is_symlink() else not_handed_in(exercise, path)


def grade_all(exercise: Exercise, submissions: dict[str, Path], workers: int = 1,
              local: bool = False, plots: Path | None = None,
              force: bool = False) -> Iterator[tuple[str, Result]]:
    """(student, result) for each of `submissions` (student -> file), in their order, graded by
    `workers` processes; a student's plots go to `plots`/student. A grader's error is raised
    when its student's turn comes, as a serial run raises it."""
    jobs = {student: (exercise, path, local, plots / student if plots else None, force)
            for student, path in submissions.items()}
    if workers <= 1 or len(jobs) <= 1:
        for student, job in jobs.items():
            yield student, _grade_one(*job)
        return
    done: dict[str, Future] = {}
    order = iter(jobs)
    turn = next(order, None)
    for _ in range(POOLS):
        todo = [student for student in jobs if student not in done]
        pool = ProcessPoolExecutor(min(workers, len(todo)), initializer=signals.leave_to_parent)
        stopped = True
        try:
            futures = {pool.submit(_grade_one, *jobs[student]): student for student in todo}
            pending = set(futures)
            broken = False
            while pending and not signals.requested() and not broken:
                finished, pending = wait(pending, timeout=POLL, return_when=FIRST_COMPLETED)
                for future in finished:
                    if isinstance(future.exception(), BrokenProcessPool):
                        broken = True  # graded again by the next pool
                    else:
                        done[futures[future]] = future
                while turn is not None and turn in done:
                    yield turn, done[turn].result()
                    turn = next(order, None)
            stopped = bool(pending) or broken
        finally:
            if stopped:  # a signal, an error, a dead worker or the caller stopped asking
                _end_workers(pool)
            pool.shutdown(wait=True, cancel_futures=True)
        signals.check()  # a signal: Stop, as a serial run's isolated run raises it
        if turn is None:
            return
    raise MexoneError(f"grading workers died {POOLS} times; {len(jobs) - len(done)} submissions "
                      "were not graded", hint="see the system's log (out of memory?), or grade "
                      "with fewer --workers")


def _end_workers(pool: ProcessPoolExecutor) -> None:
    """SIGTERM to every worker: it ends at once (signals.leave_to_parent), its runs with it."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        if process.is_alive():
            process.terminate()
