"""Tracking metrics of position-controlled joints: command vs actual, as a control student
reports them (RMS and max error; overshoot and settling time of each move the setpoint made).

A move is a setpoint change, and each next change in the same direction that comes while the
joint is still outside its settling band: a routine's staircase (`arms` sends 2 degrees every
0.1 s, ramping 30 degrees in 1.5 s) is one move of 30 degrees, not fifteen steps of 2 that
each "overshoot" by half and "never settle" because the next comes first. Overshoot is a
fraction of the whole move; settling counts from its last change. A move the next command (or
the end of the run) cut before the joint settled tells only that settling takes longer than
it was held (`unsettled_for`)."""

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
    overshoot: float  # worst over the moves, fraction of the move (0.1 = 10%)
    # worst over the moves that settled, s from a move's last change; None when a move held at
    # least that long never settled (then it takes more than `unsettled_for`)
    settling_time: float | None
    steps: int  # setpoint changes of at least MIN_STEP
    moves: int = 0  # the moves those changes made (a staircase is one)
    unsettled_for: float | None = None  # s: the longest a move was held without settling

    @property
    def settling_text(self) -> str:
        """The settling time as the report prints it: '0.120 s', or '> 0.100 s' when a move
        was cut (by the next command or the run's end) that long after its last change."""
        if self.settling_time is not None:
            return f"{self.settling_time:.3f} s"
        return f"> {self.unsettled_for:.3f} s" if self.unsettled_for is not None else "never"

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
                 history: float = 0.0):
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
class _Move:
    """One move's samples so far (see the module's docstring): from `start` to `target`, its
    latest setpoint change at sim time t0."""
    start: float
    target: float
    t0: float
    extreme: float = -np.inf  # furthest the joint went in the move's direction (sign * q)
    settled_at: float = 0.0  # time from t0 of the sample after the last one outside the band
    outside: bool = False  # the latest sample is outside the band

    @property
    def sign(self) -> float:
        return 1.0 if self.target > self.start else -1.0

    def continues(self, target: float) -> bool:
        """Whether a setpoint change to `target` continues this move: the same direction,
        before the joint settled."""
        return self.outside and (target - self.target) * self.sign > 0

    def extend(self, target: float, t0: float) -> None:
        self.target, self.t0, self.settled_at = target, t0, 0.0

    def fold(self, t: np.ndarray, q: np.ndarray) -> None:
        self.extreme = max(self.extreme, float((self.sign * q).max()))
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
        return _past(self.extreme, self.start, self.target)


def _past(extreme: float, start: float, target: float) -> float:
    """How far `extreme` (sign * q at its furthest) went past `target`, as a fraction of the
    move from `start`."""
    sign = 1.0 if target > start else -1.0
    return max((extreme - sign * target) / abs(target - start), 0.0)


@dataclass
class _Moves:
    """What the closed moves of a joint add up to."""
    worst: float = 0.0  # overshoot
    settled: float | None = None  # the longest settling among the moves that settled
    unsettled: float | None = None  # the longest hold of a move that did not settle

    def close(self, overshoot: float, settling: float | None, held: float) -> _Moves:
        """These figures with one more move's (a new _Moves: the open move is added to a copy)."""
        if settling is None:
            return _Moves(max(self.worst, overshoot), self.settled,
                          max(self.unsettled if self.unsettled is not None else 0.0, held))
        return _Moves(max(self.worst, overshoot),
                      max(self.settled if self.settled is not None else 0.0, settling),
                      self.unsettled)

    @property
    def settling_time(self) -> float | None:
        """The worst settling time of the moves held long enough to tell: a move cut before
        it settled tells nothing if it was held less than another took to settle."""
        if self.unsettled is None:
            return self.settled if self.settled is not None else 0.0
        if self.settled is not None and self.unsettled < self.settled:
            return self.settled
        return None


class _JointStream:
    """One joint's running tracking statistics (see TrackingRecorder)."""

    def __init__(self, keep: int):
        self.recent: deque[tuple[float, float, float]] = deque(maxlen=keep)
        self.n, self.sum_sq, self.max_abs = 0, 0.0, 0.0
        self.last_sp: float | None = None
        self.last_t = 0.0
        self.move: _Move | None = None  # the latest move's
        self.closed = _Moves()
        self.steps = self.moves = 0

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
            if k > 0:  # a setpoint change at a
                self.steps += 1
                if self.move is not None and self.move.continues(float(sp[a])):
                    self.move.extend(float(sp[a]), float(t[a]))
                else:
                    if self.move is not None:
                        self.closed = self._with_move(float(t[a]))
                    self.move = _Move(float(sp[a - 1] if a else before), float(sp[a]), float(t[a]))
                    self.moves += 1
            if self.move is not None and b > a:
                self.move.fold(t[a:b], q[a:b])
        self.last_sp, self.last_t = float(sp[-1]), float(t[-1])

    def _with_move(self, until: float) -> _Moves:
        m = self.move
        assert m is not None  # callers check
        return self.closed.close(m.overshoot, None if m.outside else m.settled_at, until - m.t0)

    def metrics(self, joint: str) -> JointTracking:
        moves = self._with_move(self.last_t) if self.move is not None else self.closed
        return JointTracking(joint, float(np.sqrt(self.sum_sq / self.n)), self.max_abs,
                             moves.worst, moves.settling_time, self.steps, self.moves,
                             moves.unsettled)


def full_metrics(joint: str, data: np.ndarray) -> JointTracking:
    """The tracking metrics of a whole series, rows of (t, setpoint, actual): what
    TrackingRecorder's running statistics equal (kept as their reference)."""
    t, sp, q = data.T
    error = sp - q
    changes = [int(c) for c in np.flatnonzero(np.abs(np.diff(sp)) >= MIN_STEP) + 1]
    closed = _Moves()
    moves = 0
    move: list[Any] | None = None  # [start, target, first sample, latest change's sample]

    def close(end: int) -> _Moves:
        assert move is not None
        start, target, first, last = move
        sign = 1.0 if target > start else -1.0
        over = _past(float((sign * q[first:end]).max()), start, target)
        settle = settling_time(t[last:end] - t[last], q[last:end], target, target - start)
        held = t[end] - t[last] if end < len(t) else t[-1] - t[last]
        return closed.close(over, settle, float(held))

    for c in changes:
        if move is not None:
            start, target = move[0], move[1]
            sign = 1.0 if target > start else -1.0
            outside = abs(q[c - 1] - target) > settle_band(target - start)
            if outside and (sp[c] - target) * sign > 0:
                move[1], move[3] = float(sp[c]), c
                continue
            closed = close(c)
        move, moves = [float(sp[c - 1]), float(sp[c]), c, c], moves + 1
    if move is not None:
        closed = close(len(t))
    return JointTracking(joint, float(np.sqrt(np.mean(error**2))), float(np.abs(error).max()),
                         closed.worst, closed.settling_time, len(changes), moves, closed.unsettled)


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
