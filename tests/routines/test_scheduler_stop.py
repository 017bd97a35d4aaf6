"""The scheduler after stop(): a routine still running its own code (not waiting) no longer
gates the simulation, and asking for the horizon then never raises (it crashed the GUI's
simulation thread when the page stopped a routine stuck in a loop)."""

from __future__ import annotations

import math
import threading

from mexone.routines.runtime import RoutineContext, Scheduler


def test_horizon_after_stop_with_a_routine_that_never_waited():
    scheduler = Scheduler(poll=0.01)
    entered, release = threading.Event(), threading.Event()

    def routine():
        scheduler.enter(RoutineContext(lab=None, scheduler=scheduler, params={},
                                       log=lambda level, text: None))
        entered.set()
        try:
            while not release.is_set():  # its own code: it never calls scheduler.wait
                release.wait(0.01)
        except BaseException:  # noqa: BLE001 - stop() interrupts a routine running its own code
            pass
        scheduler.leave()

    thread = threading.Thread(target=routine, daemon=True)
    thread.start()
    assert entered.wait(10)
    assert scheduler.horizon() is None  # running: the simulation waits for it
    scheduler.stop()
    assert scheduler.horizon() == math.inf
    release.set()
    thread.join(10)
