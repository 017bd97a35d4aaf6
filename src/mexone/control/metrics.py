"""Tracking metrics of position-controlled joints: command vs actual, as a control student
reports them (RMS and max error, overshoot and settling time of each setpoint change)."""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from mexone.control.controllers.position import PositionController
from mexone.control.manager import ControllerManager
from mexone.physics.simulation import Simulation

__all__ = ["JointTracking", "TrackingRecorder", "SETTLE_BAND", "SAMPLE_RATE", "settling_time",
           "settle_band", "rise_time", "overshoot", "step_progress", "full_metrics", "CHUNK"]

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

    def as_json(self) -> dict[str, Any]:
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(self).items()}


class TrackingRecorder:
    """Samples every running position/trajectory controller's joints (setpoint, actual) at
    `rate` Hz of sim time and folds them into running statistics every CHUNK samples, so memory
    stays bounded however long the run (a 66,000 s run kept 13 M tuples before) and metrics()
    is quick. The numbers are those of the whole series: max error, overshoot, settling time
    and steps exactly; the RMS error up to float rounding (chunked sums). `history` s of the
    latest samples are kept for plots (history(joint))."""

    def __init__(self, sim: Simulation, manager: ControllerManager, rate: float = SAMPLE_RATE,
                 history: float = 0.0) -> None:
        self.manager = manager
        self.keep = int(round(history * rate)) + 1 if history > 0 else 0
        self.streams: dict[str, _JointStream] = {}
        self._layouts: dict[tuple[int, ...], _Layout] = {}  # by the tracked controllers' ids
        self._pending: list[tuple[float, _Layout, np.ndarray, np.ndarray]] = []  # not folded yet
        self.timer = sim.add_periodic(1.0 / rate, self.sample)

    def sample(self, sim: Simulation) -> None:
        tracked = [c for c in self.manager.controllers.values()
                   if c.running and c.tracks_position]
        if not tracked:
            return
        key = tuple(map(id, tracked))
        layout = self._layouts.get(key)
        if layout is None:
            layout = self._layouts[key] = _Layout.of(tracked)
        hw = self.manager.hw
        if layout.commanded:  # every setpoint is the position command: one read for all
            sp = hw.command.position[layout.rows]
        else:
            sp = np.concatenate([np.asarray(c.setpoint, dtype=float) for c in tracked])
        self._pending.append((sim.time, layout, sp, hw.position(layout.rows)))
        if len(self._pending) >= CHUNK:
            self._fold()

    def metrics(self) -> dict[str, JointTracking]:
        self._fold()
        return {joint: s.metrics(joint) for joint, s in self.streams.items()}

    def history(self, joint: str) -> np.ndarray:
        """The latest samples of `joint` (up to `history` s): rows of (t, setpoint, actual)."""
        self._fold()
        stream = self.streams.get(joint)
        return np.array(stream.recent if stream else [], dtype=float).reshape(-1, 3)

    def _fold(self) -> None:
        """Hand the pending samples to each joint's statistics, in time order."""
        if not self._pending:
            return
        groups: dict[int, tuple[_Layout, list[Any]]] = {}
        for row in self._pending:
            groups.setdefault(id(row[1]), (row[1], []))[1].append(row)
        self._pending = []
        parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
        for layout, rows in groups.values():
            t = np.array([r[0] for r in rows])
            sp, q = np.stack([r[2] for r in rows]), np.stack([r[3] for r in rows])
            for i, joint in enumerate(layout.joints):
                parts.setdefault(joint, []).append((t, sp[:, i], q[:, i]))
        for joint, chunks in parts.items():
            t, sp, q = (np.concatenate(c) for c in zip(*chunks, strict=True))
            if len(chunks) > 1:  # the joint changed controllers meanwhile (or has two)
                order = np.argsort(t, kind="stable")
                t, sp, q = t[order], sp[order], q[order]
            stream = self.streams.get(joint)
            if stream is None:
                stream = self.streams[joint] = _JointStream(self.keep)
            stream.fold(t, sp, q)


@dataclass(frozen=True)
class _Layout:
    """The joints a set of tracked controllers hold, in their order, and their hardware rows."""
    joints: tuple[str, ...]
    rows: np.ndarray
    commanded: bool  # every controller's setpoint is its joints' position command

    @staticmethod
    def of(controllers: list[Any]) -> _Layout:
        return _Layout(tuple(j for c in controllers for j in c.joints),
                       np.concatenate([np.asarray(c.rows, dtype=int).reshape(-1)
                                       for c in controllers]),
                       all(getattr(type(c), "setpoint", None) is PositionController.setpoint
                           for c in controllers))


CHUNK = 1024  # samples (5 s) buffered before they are folded into the running statistics


@dataclass
class _Segment:
    """One setpoint change's samples so far: from `start` to `target`, from sim time t0."""
    start: float
    target: float
    t0: float
    peak: float = -np.inf  # highest step progress (1 = at the target)
    settled_at: float = 0.0  # time from t0 of the sample after the last one outside the band
    outside: bool = False  # the latest sample is outside the band

    def fold(self, t: np.ndarray, q: np.ndarray) -> None:
        self.peak = max(self.peak, float(step_progress(q, self.start, self.target).max()))
        out = np.flatnonzero(np.abs(q - self.target) > settle_band(self.target - self.start))
        if out.size == 0:
            if self.outside:
                self.settled_at, self.outside = float(t[0] - self.t0), False
        elif out[-1] + 1 < len(t):
            self.settled_at, self.outside = float(t[out[-1] + 1] - self.t0), False
        else:
            self.outside = True

    @property
    def overshoot(self) -> float:
        return max(self.peak - 1.0, 0.0)

    @property
    def settling(self) -> float | None:
        return None if self.outside else self.settled_at


class _JointStream:
    """One joint's running tracking statistics (see TrackingRecorder)."""

    def __init__(self, keep: int) -> None:
        self.recent: deque[tuple[float, float, float]] = deque(maxlen=keep)
        self.n, self.sum_sq, self.max_abs = 0, 0.0, 0.0
        self.last_sp: float | None = None
        self.segment: _Segment | None = None  # the latest setpoint change's
        self.worst = 0.0  # over the closed segments
        self.settling: float | None = 0.0  # None once one segment never settled
        self.steps = 0

    def fold(self, t: np.ndarray, sp: np.ndarray, q: np.ndarray) -> None:
        """The next samples, in time order."""
        if self.recent.maxlen:
            self.recent.extend(zip(t.tolist(), sp.tolist(), q.tolist(), strict=True))
        error = sp - q
        self.n += len(t)
        self.sum_sq += float(np.sum(error**2))
        self.max_abs = max(self.max_abs, float(np.abs(error).max()))
        before = sp[0] if self.last_sp is None else self.last_sp
        changes = np.flatnonzero(np.abs(np.diff(sp, prepend=before)) >= MIN_STEP)
        bounds = [0, *changes.tolist(), len(t)]
        for k in range(len(bounds) - 1):
            a, b = bounds[k], bounds[k + 1]
            if k > 0:  # a setpoint change at a: the previous segment ends
                self._close()
                self.segment = _Segment(float(sp[a - 1] if a else before), float(sp[a]),
                                        float(t[a]))
                self.steps += 1
            if self.segment is not None and b > a:
                self.segment.fold(t[a:b], q[a:b])
        self.last_sp = float(sp[-1])

    def _close(self) -> None:
        if self.segment is not None:
            self.worst = max(self.worst, self.segment.overshoot)
            if self.settling is not None:
                s = self.segment.settling
                self.settling = None if s is None else max(self.settling, s)

    def metrics(self, joint: str) -> JointTracking:
        worst, settling = self.worst, self.settling
        if self.segment is not None:  # the latest change is open to the end of the run
            worst = max(worst, self.segment.overshoot)
            s = self.segment.settling
            settling = None if settling is None or s is None else max(settling, s)
        return JointTracking(joint, float(np.sqrt(self.sum_sq / self.n)), self.max_abs, worst,
                             settling, self.steps)


def full_metrics(joint: str, data: np.ndarray) -> JointTracking:
    """The tracking metrics of a whole series, rows of (t, setpoint, actual): what
    TrackingRecorder's running statistics equal (kept as their reference)."""
    t, sp, q = data.T
    error = sp - q
    changes = np.flatnonzero(np.abs(np.diff(sp)) >= MIN_STEP) + 1
    worst = 0.0
    settling: float | None = 0.0
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
