"""When a bridge publishes /clock, in sim time: the one rule the ROS 1 and ROS 2 bridges share.

/clock goes out every 1/frequency s of sim time (gazebo_ros' pub_clock_frequency), but no more
than `wall_rate` messages per wall second: faster than real time the timer's period grows with
the measured sim rate. A period that long is also kept on a multiple of QUANTUM_NS of sim time,
where the run loop's ticks (`mexone sim --headless --rtf 0`: every 10 ms) end MuJoCo's batched
mj_step anyway, so the timer never splits a batch: a 1 ms timer made the first ROS 2 bridge cost
1.8x, and an unaligned one (94 ms, say) cut one batch in nine in ROS 1's.
"""

from __future__ import annotations

from mexone.physics.simulation import NS, Periodic

__all__ = ["QUANTUM_NS", "clock_period_ns", "respace"]

QUANTUM_NS = 10_000_000  # sim ns: the run loop's flat-out tick, a batch boundary anyway


def clock_period_ns(sim_rate: float, frequency: float, wall_rate: float, longest: float) -> int:
    """The /clock timer's period (sim ns): 1/frequency s, or sim_rate/wall_rate s when that is
    longer (sim_rate: sim s per wall s, measured; wall_rate: messages per wall second at most),
    at most `longest` s; past QUANTUM_NS, a multiple of it."""
    shortest = 1.0 / frequency
    period_ns = round(min(max(shortest, sim_rate / wall_rate), max(shortest, longest)) * NS)
    if period_ns > QUANTUM_NS:
        period_ns = round(period_ns / QUANTUM_NS) * QUANTUM_NS
    return period_ns


def respace(timer: Periodic, now_ns: int, period_ns: int) -> None:
    """Give a /clock timer (from its own callback, at sim time now_ns) its next period; a
    period of QUANTUM_NS or more also puts its next firing on a multiple of QUANTUM_NS."""
    timer.period_ns = period_ns
    if period_ns >= QUANTUM_NS:
        timer.next_ns = -(-(now_ns + period_ns) // QUANTUM_NS) * QUANTUM_NS
