"""The collector's real-time policy (physics/gc_policy.py): while a loop runs, the automatic
collections are of the young generation only; the older ones are collected in the loop's idle
moment when CPython's counts say they are due; the process's thresholds are back when the
outermost loop ends; a process that switched the collector off keeps it off."""

from __future__ import annotations

import gc
import weakref

import pytest

from mexone.physics.gc_policy import RealTimeGC


class _Cycle:
    def __init__(self) -> None:
        self.me = self


@pytest.fixture
def thresholds():
    """The process's collector state, put back after the test whatever it did."""
    saved, enabled = gc.get_threshold(), gc.isenabled()
    gc.set_threshold(100, 3, 4)
    yield (100, 3, 4)
    gc.set_threshold(*saved)
    (gc.enable if enabled else gc.disable)()


def test_nested_loops_share_the_policy_and_the_outermost_restores_the_thresholds(thresholds):
    policy = RealTimeGC()
    with policy:
        young, middle, old = gc.get_threshold()
        assert young == 100 and middle > 1e6 and old > 1e6  # the older ones out of reach
        with policy:
            assert policy.active
        assert policy.active and gc.get_threshold()[1] > 1e6  # the inner loop's end restores nothing
    assert not policy.active
    assert gc.get_threshold() == thresholds


def test_the_older_generations_wait_for_the_idle_moment_and_are_collected_there(thresholds):
    policy = RealTimeGC()
    seen: list[int] = []

    def watch(phase, info):
        if phase == "start":
            seen.append(info["generation"])

    gc.callbacks.append(watch)
    try:
        with policy:
            gc.collect(2)  # every count from zero
            survivor = _Cycle()
            gc.collect(0)  # a young collection: the cycle, still referenced, into generation 1
            garbage = weakref.ref(survivor)
            del survivor  # now garbage that only a collection of generation 1 frees
            seen.clear()
            policy.idle()
            assert garbage() is not None  # one young collection, threshold1 = 3: not due
            held = [[] for _ in range(2000)]  # 20 automatic collections' worth of allocations
            assert set(seen) == {0} and len(seen) >= 3  # every one of them young only
            assert garbage() is not None and gc.get_count()[1] >= 3
            policy.idle()  # due: generation 1 collected here, the cycle freed
            assert garbage() is None and policy.collected == [0, 1, 0]
            del held
    finally:
        gc.callbacks.remove(watch)


def test_generation_two_is_collected_when_its_count_is_due(thresholds):
    policy = RealTimeGC()
    with policy:
        gc.collect(2)  # the counts from zero
        for _ in range(thresholds[2]):  # threshold2 collections of generation 1 in the idle
            for _ in range(thresholds[1]):
                gc.collect(0)
            policy.idle()
        assert policy.collected == [0, thresholds[2] - 1, 1]


def test_a_process_that_switched_the_collector_off_keeps_it_off(thresholds):
    policy = RealTimeGC()
    gc.disable()
    with policy:
        for _ in range(10):
            gc.collect(0)
        policy.idle()
        assert not gc.isenabled()
    assert policy.collected == [0, 0, 0] and not gc.isenabled()
