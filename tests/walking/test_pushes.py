"""The walking stack holds up (issue 39's acceptance): walking at 0.3 m/s it survives a 0.1 s
push of 6 N s at the torso, sideways either way and forward, at the phases of the stride that
were the hard ones (both feet down, the push towards the standing foot); and it steps down
the 2 cm step at the shipped rates (footsteps 100 Hz, COM planner 250 Hz, the rest 500 Hz),
the estimator in the loop. benchmarks/walking_stack.py scans the largest push survived."""

from __future__ import annotations

import math

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


@pytest.mark.slow
@pytest.mark.parametrize("angle, at", [(90, 5.0), (90, 5.1), (-90, 5.0), (0, 5.1), (0, 5.5)],
                         ids=["left-towards-the-standing-foot", "left-both-feet-down",
                              "right-the-swinging-foots-side", "forward-both-feet-down",
                              "forward-both-feet-down-later"])
def test_walking_at_0_3_m_s_it_survives_a_6_n_s_push(angle, at):
    """Steps lift every 0.4 s from 1.6 s, the right foot first: at 5.0 s the right foot is in
    the air (landing at 5.1 s) over the standing left one, at 5.1-5.2 s and 5.5-5.6 s both feet
    are down (forward there the steps needed more reach than 0.25 m: the push outran them)."""
    lab = _walking()
    force = 6.0 / 0.1
    direction = math.radians(angle)
    lab.sim.apply_wrench("torso", [force * math.cos(direction), force * math.sin(direction), 0.0],
                         duration=0.1, start=at)
    x0 = float(lab.sim.data.qpos[0])
    lowest = _lowest_until(lab, at + 3.0)
    assert lowest > FALLEN, f"fell (base at {lowest:.3f} m)"
    reports = {n: c.impl.report() for n, c in lab.manager.controllers.items() if hasattr(c, "impl")}
    assert reports["whole_body"]["stopped"] is None and reports["com_planner"]["stopped"] is None
    assert float(lab.sim.data.qpos[0]) - x0 > 0.6  # still walking forward, not just standing up
    if angle == 90 and at == 5.0:  # towards the standing foot: the steps came sooner
        assert reports["footsteps"]["hurried"] >= 1, reports["footsteps"]


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
