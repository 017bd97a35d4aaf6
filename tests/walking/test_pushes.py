"""The walking stack holds up (issue 39's acceptance): walking at 0.3 m/s it survives a 0.1 s
push of 6 N s at the torso, sideways either way and forward, at every tenth of a stride (the
hard ones: pushed towards the foot that has just landed); and it steps down
the 2 cm step at the shipped rates (footsteps 100 Hz, COM planner 250 Hz, the rest 500 Hz),
the estimator in the loop. benchmarks/walking_stack.py scans the largest push survived."""

from __future__ import annotations

import math
import os
import signal

import pytest

from mexone.lab import Lab
from mexone.physics.compile import Spawn
from mexone.physics.world import read_world
from mexone.robots import mex_one

FALLEN = 0.4  # m: the base lower than this is a fall (benchmarks/walking_stack.py's rule)
WALK = 1.0  # s: the footstep planner walks from here (its `settle`), the first lift 0.6 s later


def _walking(world=None, spawn: Spawn = Spawn()) -> Lab:
    """The shipped stack, commanded 0.3 m/s after it settled for a second (as
    benchmarks/walking_stack.py's `stack`)."""
    lab = Lab.create(controllers=mex_one.walking_path(), world=world, spawn=spawn)
    lab.sim.step(round(WALK / lab.sim.timestep))
    lab.manager.set_param("footsteps", "vx", 0.3)
    return lab


def _lowest_until(lab: Lab, until: float) -> float:
    lowest = math.inf
    while lab.sim.time < until:
        lab.sim.step(50)
        lowest = min(lowest, float(lab.sim.data.qpos[2]))
        if lowest < FALLEN:
            break
    return lowest


PHASES = [round(5.0 + 0.1 * k, 1) for k in range(8)]  # s: a stride, two steps of 0.4 s
PUSHES = [(angle, at) for angle in (90, -90, 0) for at in PHASES]
WATCH = 3.0  # s after the push it must still stand


def _pushed(lab: Lab, x0: float, angle: float, at: float, lowest_out: list | None = None) -> str:
    """The walk pushed 6 N s at `angle` degrees (0 forward, 90 left) at `at` s: "" if it stood
    for WATCH s and walks on, else what went wrong (`lowest_out`: the lowest base appended)."""
    force = 6.0 / 0.1
    direction = math.radians(angle)
    lab.sim.apply_wrench("torso", [force * math.cos(direction), force * math.sin(direction), 0.0],
                         duration=0.1, start=at)
    lowest = _lowest_until(lab, at + WATCH)
    if lowest_out is not None:
        lowest_out.append(lowest)
    if lowest <= FALLEN:
        return f"fell (base at {lowest:.3f} m)"
    reports = {n: c.impl.report() for n, c in lab.manager.controllers.items() if hasattr(c, "impl")}
    if reports["whole_body"]["stopped"] is not None or reports["com_planner"]["stopped"] is not None:
        return f"stopped: {reports['whole_body']['stopped']} {reports['com_planner']['stopped']}"
    if float(lab.sim.data.qpos[0]) - x0 < 0.6:  # still walking forward, not just standing up
        return f"stood but walked only {float(lab.sim.data.qpos[0]) - x0:.2f} m"
    if angle == 90 and at == 5.0 and reports["footsteps"]["hurried"] < 1:  # the steps came sooner
        return f"not hurried: {reports['footsteps']}"
    return ""


def _in_forks(lab: Lab, x0: float, pushes: list[tuple[int, float]], at_once: int = 2,
              push_one=_pushed) -> dict:
    """Each push on a fork of the warmed-up walk (the whole lab's state, no copy to keep in
    step), `at_once` at a time: {push: "" or what went wrong}; `push_one(lab, x0, angle, at)`:
    what each fork runs ("" when it stood)."""
    from mexone.control.watchdog import GUARD

    results: dict = {}
    running: dict[int, tuple[tuple[int, float], int]] = {}
    todo = list(pushes)
    while todo or running:
        while todo and len(running) < at_once:
            push = todo.pop(0)
            read, write = os.pipe()
            with GUARD.lock:  # the controller watchdog's lock free in the child
                pid = os.fork()
            if pid == 0:  # the child: one push, its verdict down the pipe
                GUARD.running = False  # its watchdog thread was not forked: the next update starts one
                os.close(read)
                signal.alarm(600)  # a hung child dies rather than hangs the suite
                try:
                    verdict = push_one(lab, x0, *push)
                except BaseException as exc:  # noqa: BLE001 - reported by the parent
                    verdict = f"raised {exc!r}"
                os.write(write, (verdict or "ok").encode()[:4000])
                os._exit(0)
            os.close(write)
            running[pid] = (push, read)
        pid, status = os.wait()
        push, read = running.pop(pid)
        with os.fdopen(read, "rb") as pipe:
            said = pipe.read().decode()
        results[push] = "" if said == "ok" else (said or f"the child ended with status {status}")
    return results


@pytest.fixture(scope="module")
def pushed_over_a_stride() -> dict:
    """6 N s at each tenth of a stride, left, right and forward, each on a fork of one walk
    that went on to just before the first push (one warm-up for all 24)."""
    lab = _walking()
    x0 = float(lab.sim.data.qpos[0])
    lab.sim.step(round((PHASES[0] - 0.05 - lab.sim.time) / lab.sim.timestep))
    return _in_forks(lab, x0, PUSHES)


# not met yet: none on this grid (pushed right at 5.3 s fell until a landing waited for its
# foot's touchdown: benchmarks/RESULTS.md; `walking_stack.py --phases fine` scans a finer grid)
NOT_YET: set[tuple[int, float]] = set()


@pytest.mark.slow
@pytest.mark.parametrize("angle, at", [pytest.param(a, t, marks=pytest.mark.xfail(
    strict=True, reason="see NOT_YET")) if (a, t) in NOT_YET else (a, t) for a, t in PUSHES],
                         ids=[f"{ {90: 'left', -90: 'right', 0: 'forward'}[a]}-at-{t:g}s" for a, t in PUSHES])
def test_walking_at_0_3_m_s_it_survives_a_6_n_s_push_at_every_phase(pushed_over_a_stride, angle, at):
    """Steps lift every 0.4 s from 1.6 s, the right foot first: over 5.0-5.7 s the right foot is
    in the air until 5.1 s, both feet down 5.1-5.2 s, the left in the air 5.2-5.5 s, both down
    5.5-5.6 s, the right in the air from 5.6 s. The hard ones: pushed towards the foot that has
    just landed (left at 5.5-5.7 s, right at 5.1-5.2 s), which must step again further out."""
    verdict = pushed_over_a_stride[(angle, at)]
    assert verdict == "", verdict


@pytest.mark.slow
def test_it_steps_down_the_2_cm_step_at_the_shipped_rates():
    """From the platform's far end (x 2.2 m, its edge at 2.5 m) down onto the floor."""
    import yaml

    parts = next(iter(yaml.safe_load(mex_one.walking_path().read_text()).values()))
    rates = {n: e.get("update_rate") for n, e in parts.items() if n != "joint_state_controller"}
    assert rates == {"estimator": 500, "footsteps": 100, "com_planner": 250, "whole_body": 500}
    lab = _walking(read_world(mex_one.world_path("step")), Spawn(xyz=(2.2, 0.0, 0.02)))
    sim = lab.sim
    sim.step(500)
    on_top = float(sim.data.qpos[2])
    lowest = _lowest_until(lab, 7.0)
    assert lowest > 0.5, f"fell or crouched (base at {lowest:.3f} m)"
    feet = [sim.data.xpos[sim.model.body(name).id].copy() for name in ("l_foot", "r_foot")]
    assert min(float(f[0]) for f in feet) > 2.6, feet  # both feet off the platform
    assert min(float(f[2]) for f in feet) == pytest.approx(0.06, abs=0.005)  # a sole on the floor
    assert float(sim.data.qpos[2]) == pytest.approx(on_top - 0.02, abs=0.01)  # 2 cm down
