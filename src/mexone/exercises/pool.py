"""A class's submissions graded in parallel: `mexone exercise grade NAME DIR --workers N` on local
processes, `--backend ray [--address ADDR]` on a Ray cluster.

Each submission is graded by `grading.grade` in a worker process, not a thread: the teacher's
grader, matplotlib and the fork server of the isolated runs belong to one process each. Inside
a worker a submission runs isolated exactly as in a serial run. Results come back in the order of
the submissions whatever order they finish in, so the report and the CSV are the serial run's.

A signal (Ctrl-C) ends the workers at once (the runs they started die with them) and stops the
grading. A worker that dies otherwise (killed, out of memory) breaks its pool: the submissions
without a result are graded again by a new pool, those with one never twice.

On Ray each submission is one task running the same `grading.grade` in a Ray worker process. A
worker that dies mid-submission has that task run again (Ray's task retries, `RETRIES`); a
task's result is taken once, so no submission is lost or counted twice. Ray's local workers
inherit this process's environment (the teacher's $MEXONE_EXERCISE_SECRET with it); a cluster's
take their nodes' (`ray start` run with the secret exported on each node).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from mexone import signals
from mexone.cluster import ray_session
from mexone.errors import MexoneError
from mexone.exercises import grading
from mexone.exercises.exercise import Exercise
from mexone.exercises.grading import Result
from mexone.exercises.isolate import prewarm

__all__ = ["grade_all", "BACKENDS"]

BACKENDS = ("local", "ray")  # where --workers run: this machine's processes, or a Ray cluster

POLL = 0.2  # s between two looks at the signals while the workers grade
POOLS = 3  # pools that may break (a worker killed) before the grading gives up
RETRIES = 3  # times Ray runs a submission again whose worker died (then: the grading stops)


def _grade_one(exercise: Exercise, path: Path, local: bool, plots: Path | None,
               force: bool) -> Result:
    # a symlink is graded too: grade() refuses it unread, with its reason. grading.grade looked
    # up at each call, not bound at import: whoever replaces it (a test) replaces it here too
    return grading.grade(exercise, path, local=local, plots=plots, force=force) \
        if path.is_file() or path.is_symlink() else grading.not_handed_in(exercise, path)


def _worker_ready() -> None:
    """A worker's start: signals left to its parent, and the runs' fork server started (MuJoCo
    and the lab imported once) before its first submission rather than during it."""
    signals.leave_to_parent()
    prewarm()


def grade_all(exercise: Exercise, submissions: dict[str, Path], workers: int = 1,
              local: bool = False, plots: Path | None = None, force: bool = False,
              backend: str = "local", address: str | None = None,
              progress: Callable[[int], None] | None = None) -> Iterator[tuple[str, Result]]:
    """(student, result) for each of `submissions` (student -> file), in their order, graded by
    `workers` processes (`backend` "local"), or by a Ray cluster's workers (`backend` "ray":
    the cluster at `address`, else a local one of `workers` CPUs); a student's plots go to
    `plots`/student. `progress(1)` is called as each submission finishes, in whatever order. A
    grader's error is raised when its student's turn comes, as a serial run raises it."""
    jobs = {student: (exercise, path, local, plots / student if plots else None, force)
            for student, path in submissions.items()}
    if backend == "ray":
        yield from _on_ray(jobs, workers, address, progress)
        return
    if workers <= 1 or len(jobs) <= 1:
        for student, job in jobs.items():
            result = _grade_one(*job)
            if progress:
                progress(1)
            yield student, result
        return
    done: dict[str, Future] = {}
    order = iter(jobs)
    turn = next(order, None)
    for _ in range(POOLS):
        todo = [student for student in jobs if student not in done]
        pool = ProcessPoolExecutor(min(workers, len(todo)), initializer=_worker_ready)
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
                        if progress:
                            progress(1)
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


def _on_ray(jobs: dict[str, tuple], workers: int, address: str | None,
            progress: Callable[[int], None] | None) -> Iterator[tuple[str, Result]]:
    """grade_all on Ray: one task per submission, retried when its worker dies; results taken
    in the submissions' order. A signal cancels the tasks in flight (their runs die with their
    workers) and stops the grading."""
    with ray_session(workers, address) as ray:
        from ray.exceptions import RayError, RayTaskError

        remote = ray.remote(max_retries=RETRIES, retry_exceptions=False)(_grade_one)
        refs = {remote.remote(*job): student for student, job in jobs.items()}
        finished: set[str] = set()
        pending = list(refs)
        by_student = {student: ref for ref, student in refs.items()}
        order = iter(jobs)
        turn = next(order, None)
        try:
            while turn is not None and not signals.requested():
                ready, pending = ray.wait(pending, num_returns=1, timeout=POLL) if pending \
                    else ([], pending)
                for ref in ready:
                    finished.add(refs[ref])
                    if progress:
                        progress(1)
                while turn is not None and turn in finished:
                    try:
                        result = ray.get(by_student[turn])
                    except RayTaskError as exc:  # the grader's own error, as serially
                        raise exc.cause from None
                    except RayError as exc:  # its workers died RETRIES + 1 times, a node lost
                        raise MexoneError(f"Ray could not grade {turn}: {type(exc).__name__} "
                                          f"({str(exc).splitlines()[0] if str(exc) else ''})",
                                          hint="see the Ray logs (out of memory?), or grade "
                                          "with fewer --workers") from None
                    yield turn, result
                    turn = next(order, None)
        finally:
            for ref in pending:  # a signal, an error or the caller stopped asking
                ray.cancel(ref, force=True)
        signals.check()  # a signal: Stop, as a serial run's isolated run raises it
