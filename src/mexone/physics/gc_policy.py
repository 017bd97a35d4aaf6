"""The garbage collector's policy while the lab's loop runs: no collection of Python's older
generations inside a control step.

CPython collects generation 0 after `threshold0` net allocations of container objects,
generation 1 after `threshold1` of those and generation 2 after `threshold2` of the generation-1
ones. A collection runs inside whatever allocated the object that tipped it: for the older
generations, with MuJoCo's, numpy's and a walking stack's objects alive, that is a few ms inside
some controller's update, a missed 2 ms deadline (benchmarks/RESULTS.md, the walking stack).

While a loop runs under `RealTimeGC` (Simulation.run does), the automatic collections are of
generation 0 only (the young objects: tens of microseconds); the older ones are collected at the
loop's idle moment (`idle()`: between ticks, before the pacing sleeps), where CPython itself chooses
which, by its own rules: generation 1 when its count is due, generation 2 when its count is due
and the long-lived objects not yet fully collected exceed a quarter of those alive (without that
rule a big process would pay a full collection, 0.5 s for 8 million objects, far more often than
CPython does). The same collections as CPython's, each at most one tick late: memory stays
bounded. When the outermost loop ends, the thresholds the process had are back. A process that
switched the collector off keeps it off: nothing is collected in its place.
"""

from __future__ import annotations

import gc
import threading
from types import TracebackType

__all__ = ["RealTimeGC", "REAL_TIME_GC"]

_OUT_OF_REACH = 1 << 30  # an older generation's threshold no loop reaches


class RealTimeGC:
    """The collector's policy for real-time loops (a context manager; nested and concurrent
    loops share it: the first to enter applies it, the last to leave restores the process's
    thresholds). One per process: `REAL_TIME_GC`."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._depth = 0
        self._saved: tuple[int, int, int] | None = None
        self.collected = [0, 0, 0]  # collections of each generation `idle()` ran (for tests)

    @property
    def active(self) -> bool:
        """True while a loop runs under the policy."""
        return self._depth > 0

    def __enter__(self) -> RealTimeGC:
        with self._lock:
            if self._depth == 0:
                self._saved = gc.get_threshold()
                gc.set_threshold(self._saved[0], _OUT_OF_REACH, _OUT_OF_REACH)
            self._depth += 1
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        with self._lock:
            self._depth -= 1
            if self._depth == 0 and self._saved is not None:
                saved, self._saved = self._saved, None
                if gc.get_threshold()[1:] == (_OUT_OF_REACH, _OUT_OF_REACH):  # nobody changed them
                    gc.set_threshold(*saved)

    def idle(self) -> None:
        """The loop's idle moment: if an older generation's count is due, hand CPython its own
        thresholds for one container allocation so that it collects what it would have (its
        rules, not a copy of them: the quarter rule for generation 2 has no Python API)."""
        saved = self._saved
        if saved is None or not gc.isenabled() or gc.get_count()[1] <= saved[1]:
            return  # CPython collects generation 1 once its count exceeds threshold1
        before = [stats["collections"] for stats in gc.get_stats()]
        gc.set_threshold(1, saved[1], saved[2])  # the next container allocation collects
        try:  # nothing else allocated meanwhile: one collection, the one CPython picks
            _Tip()  # 3.11 collects inside this allocation
            _checkpoint()  # 3.12+ at the next eval-breaker check: this call's start
        finally:
            gc.set_threshold(saved[0], _OUT_OF_REACH, _OUT_OF_REACH)
        after = [stats["collections"] for stats in gc.get_stats()]
        ran = [generation for generation in (1, 2) if after[generation] != before[generation]]
        if ran:
            self.collected[ran[-1]] += 1


class _Tip:
    """A container whose allocation lets CPython's collector run (no free list bypasses it)."""


def _checkpoint() -> None:
    """A Python call: its start runs a collection CPython 3.12+ scheduled."""


REAL_TIME_GC = RealTimeGC()
