"""Tracking metrics of position-controlled joints: command vs actual, as a control student
reports them (RMS and max error, overshoot and settling time of each setpoint change)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from mexone.control.manager import ControllerManager
from mexone.physics.simulation import Simulation

__all__ = ["JointTracking", "TrackingRecorder", "SETTLE_BAND", "SAMPLE_RATE", "settling_time",
           "settle_band", "rise_time", "overshoot", "step_progress"]

SAMPLE_RATE = 200.0  # Hz: 5 ms resolution for settling times
SETTLE_BAND = 0.02  # settled when within 2% of the step...
SETTLE_FLOOR = 0.005  # ...or 5 mrad, whichever is larger
MIN_STEP = 0.01  # rad: smaller setpoint changes count for errors, not for overshoot/settling


@dataclass(frozen=True)
class JointTracking:
    joint: str
    rms_error: float  # rad
    max_error: float  # rad
    overshoot: float  # worst over setpoint changes, fraction of the step (0.1 = 10%)
    settling_time: float | None  # worst over setpoint changes, s; None if one never settled
    steps: int  # setpoint changes of at least MIN_STEP

    def as_json(self) -> dict:
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(self).items()}


class TrackingRecorder:
    def __init__(self, sim: Simulation, manager: ControllerManager, rate: float = SAMPLE_RATE):
        self.manager = manager
        self.t: list[float] = []
        self.rows: dict[str, list[tuple[float, float]]] = {}
        self.timer = sim.add_periodic(1.0 / rate, self.sample)

    def sample(self, sim: Simulation) -> None:
        self.t.append(sim.time)
        for ctrl in self.manager.controllers.values():
            if ctrl.running and ctrl.kind in ("position", "trajectory"):
                q = ctrl.hw.position(ctrl.rows)
                for joint, sp, actual in zip(ctrl.joints, ctrl.setpoint, q, strict=True):
                    self.rows.setdefault(joint, []).append((sim.time, float(sp), float(actual)))

    def metrics(self) -> dict[str, JointTracking]:
        return {joint: _metrics(joint, np.array(rows)) for joint, rows in self.rows.items()}


def _metrics(joint: str, data: np.ndarray) -> JointTracking:
    t, sp, q = data.T
    error = sp - q
    changes = np.flatnonzero(np.abs(np.diff(sp)) >= MIN_STEP) + 1
    worst, settling = 0.0, 0.0
    bounds = list(changes) + [len(t)]
    for k, start in enumerate(changes):
        end = bounds[k + 1]
        step = sp[start] - sp[start - 1]
        worst = max(worst, overshoot(q[start:end], sp[start - 1], sp[start]))
        if settling is not None:
            settle = settling_time(t[start:end] - t[start], q[start:end], sp[start], step)
            settling = None if settle is None else max(settling, settle)
    return JointTracking(joint, float(np.sqrt(np.mean(error**2))), float(np.abs(error).max()),
                         worst, settling, len(changes))


def settle_band(step: float) -> float:
    """How close counts as settled after a step: 2% of the step, or 5 mrad if that is larger."""
    return max(SETTLE_BAND * abs(step), SETTLE_FLOOR)


def settling_time(t: np.ndarray, q: np.ndarray, target: float, step: float) -> float | None:
    """Time (from t[0]'s origin) after which q stays within the settling band of `target`;
    None if it is still outside at the end."""
    outside = np.flatnonzero(np.abs(q - target) > settle_band(step))
    if outside.size == 0:
        return 0.0
    if outside[-1] + 1 >= len(t):
        return None
    return float(t[outside[-1] + 1])


def step_progress(q: np.ndarray, start: float, target: float) -> np.ndarray:
    """How far along q is on each sample, from `start` (0) to `target` (1); all 1 for no step."""
    return (q - start) / (target - start) if target != start else np.ones_like(q, dtype=float)


def overshoot(q: np.ndarray, start: float, target: float) -> float:
    """How far q went past `target` after a step from `start`, as a fraction of the step."""
    return float(max(step_progress(q, start, target).max() - 1.0, 0.0))


def rise_time(t: np.ndarray, q: np.ndarray, start: float, target: float) -> float | None:
    """Time (from t[0]'s origin) q takes from 10% to 90% of the way from `start` to `target`;
    None if it never gets there."""
    progress = step_progress(q, start, target)
    low, high = np.flatnonzero(progress >= 0.1), np.flatnonzero(progress >= 0.9)
    if low.size == 0 or high.size == 0:
        return None
    return float(t[high[0]] - t[low[0]])
