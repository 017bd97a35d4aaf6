"""The bridges' /clock timer (bus.clock, shared by ROS 1 and ROS 2) never splits MuJoCo's batched
stepping: flat out, `mexone sim --headless` steps 10 ms per mj_step call between its ticks, and a
/clock timer on those boundaries leaves every call 10 steps (an unaligned one cut one in nine)."""

from __future__ import annotations

import collections

import mujoco
import pytest

from mexone.bus.clock import QUANTUM_NS, clock_period_ns, respace
from mexone.lab import Lab
from mexone.physics.simulation import NS


@pytest.mark.parametrize("rate,frequency,wall,longest,period_ms", [
    (1.0, 1000.0, 1000.0, 0.2, 1),  # real time: gazebo_ros' 1 kHz in sim time
    (0.5, 1000.0, 1000.0, 0.2, 1),
    (18.96, 1000.0, 200.0, 0.2, 90),  # flat out: ~200 a wall second, on a 10 ms boundary
    (35.0, 1000.0, 200.0, 0.2, 180),
    (500.0, 1000.0, 200.0, 0.2, 200),  # at most `longest`
    (3.0, 100.0, 200.0, 2.0, 20),  # pub_clock_frequency 100 Hz: never shorter than 10 ms
    (0.0, 2.0, 200.0, 0.2, 500),  # never shorter than 1/frequency, even past `longest`
])
def test_clock_period(rate, frequency, wall, longest, period_ms):
    assert clock_period_ns(rate, frequency, wall, longest) == period_ms * 1_000_000


def _chunks(respaced) -> collections.Counter:
    """Steps per mj_step call of a flat-out run (ticks every 10 ms) with a /clock-like timer
    whose callback `respaced(timer, sim)` sets its next period, as the bridges do."""
    lab = Lab.create()
    sim = lab.sim
    timer = sim.add_periodic(0.001, lambda s: respaced(timer, s))
    sim.run(0.05, tick=0.01)  # the first firings, at 1 ms, before the rate is known
    real, chunks = mujoco.mj_step, collections.Counter()

    def counted(model, data, nstep=1):
        chunks[nstep] += 1
        return real(model, data, nstep)

    mujoco.mj_step = counted
    try:
        sim.run(2.0, tick=0.01)
    finally:
        mujoco.mj_step = real
    assert sim.timestep * NS * 10 == QUANTUM_NS
    return chunks


def test_a_clock_timer_splits_no_batch():
    rate, wall = 18.96, 200.0  # sim s per wall s, /clock messages per wall s: 94.8 ms apart

    def shared(timer, sim):
        respace(timer, sim.time_ns, clock_period_ns(rate, 1000.0, wall, 0.2))

    def unaligned(timer, sim):  # the rule before: the period alone
        timer.period_ns = round(rate / wall * NS)

    assert _chunks(shared) == {10: 200}
    before = _chunks(unaligned)
    assert before[10] < 200 and sum(before.values()) > 200  # it split about one call in nine
