"""What a ROS request may carry before it reaches the physics: each field against its range in
`mexone.ranges` (the one home), so a service call, an action goal or a command from the graph
is refused with one line naming the field instead of ending the simulation.

Every check raises `InputError`; the service handlers turn it into success=False (or ok=False,
or a rejected goal) with the same line on /rosout."""

from __future__ import annotations

import math

import numpy as np

from mexone.errors import InputError
from mexone.ranges import FORCE, LENGTH, POSITION, SPEED, SPIN, TIMEOUT, Range, number_text

__all__ = ["vector", "position", "quaternion", "twist", "force", "offset", "seconds", "timeout", "names"]


def vector(v, rng: Range, what: str) -> np.ndarray:
    """A geometry_msgs Vector3 or Point as 3 floats, each within `rng`."""
    return np.array([rng.check(getattr(v, axis), f"{what}.{axis}") for axis in "xyz"])


def _length(values: np.ndarray, rng: Range, what: str) -> np.ndarray:
    """Each component and the vector's length within `rng` (a diagonal is as fast as an axis)."""
    rng.check(float(np.linalg.norm(values)), f"|{what}|")
    return values


def position(p, what: str) -> np.ndarray:
    """A place in the world (spawn, set_model_state)."""
    return vector(p, POSITION, what)


def quaternion(q, what: str, zero_is_identity: bool = True) -> np.ndarray:
    """(w, x, y, z), normalised. A message's default quaternion is all zeros: with
    `zero_is_identity` that means no rotation, as a ROS user means it."""
    values = np.array([q.w, q.x, q.y, q.z], dtype=float)
    if not np.isfinite(values).all():
        raise InputError(f"{what} ({', '.join(number_text(v) for v in values)}) is not finite",
                         hint="send a unit quaternion, w = 1 for no rotation")
    norm = float(np.linalg.norm(values))  # finite: each component is at most 1.8e308
    if not math.isfinite(norm):
        values = values / np.abs(values).max()
        norm = float(np.linalg.norm(values))
    if norm < 1e-9:
        if zero_is_identity:
            return np.array([1.0, 0, 0, 0])
        raise InputError(f"{what} is zero", hint="use w = 1 for no rotation")
    return values / norm


def twist(t, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Linear (m/s) and angular (rad/s) velocity: beyond the watchdog's limits they would be a
    divergence the moment they were set."""
    return (_length(vector(t.linear, SPEED, f"{what}.linear"), SPEED, f"{what}.linear"),
            _length(vector(t.angular, SPIN, f"{what}.angular"), SPIN, f"{what}.angular"))


def force(v, what: str) -> np.ndarray:
    return vector(v, FORCE, what)


def offset(v, what: str) -> np.ndarray:
    """A point or offset within a robot (a wrench's reference point)."""
    return vector(v, LENGTH, what)


def seconds(value: float, what: str) -> float:
    """A finite number of seconds (rospy's Duration.to_sec(), or a float field)."""
    number = float(value)
    if not math.isfinite(number):
        raise InputError(f"{what} {number_text(number)} is not finite")
    return number


def timeout(value: float, what: str = "timeout") -> float:
    return TIMEOUT.check(value, what)


def names(values, what: str) -> list[str]:
    """A list of names, each once."""
    out = list(values)
    repeated = sorted({n for n in out if out.count(n) > 1})
    if repeated:
        raise InputError(f"{what} names {', '.join(repeated)} more than once")
    return out
