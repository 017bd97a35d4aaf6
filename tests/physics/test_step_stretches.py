"""Simulation.step's stretches of single steps (a control due at every step, as a controller at
the physics rate is) against one step per call, which never takes them: the same calls at the
same sim times and the same physics to the bit, whatever the control does between two steps
(pushes, efforts, timers added and removed, a reset, a new physics step)."""

from __future__ import annotations

import math

import numpy as np

from mexone.physics import Simulation
from mexone.robots import mex_one


class Meddler:
    """A control due at every step (now and then a few steps later) that changes what the loop
    planned: every rule that ends a stretch, at awkward moments."""

    def __init__(self, log: list) -> None:
        self.wake_ns = -math.inf
        self.k = 0
        self.log = log
        self.timers: list = []

    def update(self, sim: Simulation) -> None:
        self.k += 1
        k, step = self.k, round(sim.timestep * 1e9)
        self.log.append(("update", sim.time_ns, sim.steps))
        self.wake_ns = sim.time_ns + (3 * step + 1 if k % 97 == 0 else step)
        if k % 41 == 0:
            sim.apply_wrench("pelvis", [20.0, 5.0, 0.0], duration=0.004)
        if k % 67 == 0:
            sim.apply_joint_effort(sim.joint_names[3], -2.0, duration=0.0021)
        if k % 59 == 0:
            self.timers.append(sim.add_periodic(
                0.0012, lambda s: self.log.append(("timer", s.time_ns, s.steps))))
        if k % 83 == 0 and self.timers:
            sim.remove_periodic(self.timers.pop(0))
        if k == 150:
            sim.reset()


def _run(chunks: list[int]) -> tuple[bytes, list]:
    sim = Simulation(mex_one.urdf_path())
    log: list = []
    sim.add_periodic(0.0037, lambda s: log.append(("steady", s.time_ns, s.steps)))
    sim.add_control(Meddler(log))
    for n in chunks:
        sim.step(n)
    state = np.concatenate((sim.data.qpos, sim.data.qvel, sim.data.qfrc_applied,
                            sim.data.xfrc_applied.ravel(), [sim.time_ns, sim.steps]))
    return state.tobytes(), log


def test_stretches_of_single_steps_run_the_same_calls_and_physics_as_one_step_a_call():
    chunks = [1, 7, 50, 333, 49, 51, 700, 309]
    one_by_one = _run([1] * sum(chunks))
    stretched = _run(chunks)
    assert len(one_by_one[1]) > 1000  # the control ran at (nearly) every step
    assert stretched[1] == one_by_one[1]
    assert stretched[0] == one_by_one[0]
