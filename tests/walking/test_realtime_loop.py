"""The walking stack in the lab's real-time loop (Simulation.run): no collection of Python's older
generations runs inside a part's update (they run between ticks, physics/gc_policy.py), the
process's collector thresholds are back when the loop ends, and a walk's memory stays bounded
(nothing a part keeps grows with every update)."""

from __future__ import annotations

import gc

from mexone.lab import Lab
from mexone.physics.gc_policy import REAL_TIME_GC
from mexone.robots import mex_one


class _Cycle:
    def __init__(self) -> None:
        self.me = self


def _tracked() -> int:
    gc.collect()
    return len(gc.get_objects())


def test_a_walk_in_the_loop_collects_old_generations_between_updates_only_and_stays_bounded():
    lab = Lab.create(controllers=mex_one.walking_path())
    lab.sim.run(1.0)
    lab.manager.set_param("footsteps", "vx", 0.3)
    inside = [""]
    collections: list[tuple[int, str]] = []
    for name, runner in lab.manager.controllers.items():
        impl = getattr(runner, "impl", None)
        if impl is None:
            continue

        def marked(state, t, dt, update=impl.update, name=name):
            inside[0] = name
            _Cycle()  # garbage only a collection frees, as a student's part may leave
            try:
                return update(state, t, dt)
            finally:
                inside[0] = ""

        impl.update = marked

    def watch(phase, info):
        if phase == "start":
            collections.append((info["generation"], inside[0]))

    saved = gc.get_threshold()
    gc.set_threshold(200, 2, 3)  # collections often enough to see each generation in seconds
    # (the shipped parts leave next to nothing to collect: the cycles above make the work)
    gc.callbacks.append(watch)
    try:
        lab.sim.run(1.5)  # up to speed
        before, idle_before = _tracked(), list(REAL_TIME_GC.collected)
        collections.clear()
        lab.sim.run(3.0)  # 1500 estimator and whole-body updates, 750 of the COM planner's
        after = _tracked()
        assert gc.get_threshold() == (200, 2, 3)  # the loop's end put them back
    finally:
        gc.callbacks.remove(watch)
        gc.set_threshold(*saved)
    assert lab.sim.data.qpos[2] > 0.5 and lab.sim.data.qpos[0] > 0.3  # it walked
    in_updates = [(g, part) for g, part in collections if part]
    assert in_updates and {g for g, _ in in_updates} == {0}  # young ones only inside the parts
    assert {0, 1} <= {g for g, _ in collections}  # the older ones ran, between ticks (generation
    # 2 only where CPython would run it: a quarter of the long-lived objects new, tests/physics/
    # test_gc_policy.py; this walk keeps too little for that)
    assert REAL_TIME_GC.collected[1] > idle_before[1]
    # bounded: a part that kept one object per update would add 1500 here
    assert after - before < 300, (before, after)
