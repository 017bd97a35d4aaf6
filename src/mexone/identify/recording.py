"""A bag -> what identification needs from it: measured joint positions on a clean time base,
the controller commands in order, and the base pose (which also says whether the robot was on a
stand).

Bags from real drivers are messy: joints in any order, several JointState publishers, stamps
that jitter by milliseconds. A stream published at a fixed rate (a driver's joint states, a
routine's commands) is put back on its regular grid (`regular_times`); with 10 ms of jitter on a
joint moving at 2 rad/s that is 20 mrad of error removed, 20 times the encoder noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mexone.control.spec import ControlConfig
from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.ranges import JOINT_VALUE, POSITION, VELOCITY, number_text
from mexone.record.reader import (
    COMMAND_TYPES,
    TRAJECTORY,
    BagContents,
    CommandMessage,
    StateMessage,
    read_bag,
)

__all__ = ["Recording", "BasePose", "Command", "read_recording", "regular_times", "MAX_JITTER",
           "STILL", "Grid", "fit_grid", "shared_regular_times"]

MAX_JITTER = 0.025  # s: a stream whose stamps stay this close (RMS) to a regular grid is regular
_MIN_REGULAR = 10  # messages: fewer say nothing about a rate
_TAIL = 6.0  # jitter's largest excursion in RMS multiples (Gaussian: 4 in 10 000); a stall is more
STILL = 1e-6  # m or unit quaternion: a base that moves less than this was on a stand
MAX_GAP = 5.0  # s without a joint-state sample (and 20 periods): a pause, or a stamp gone wrong
LIMIT_SLACK = 0.1  # of a joint's range: how far past its limits a recorded start may be
MAX_DURATION = 1800.0  # s of joint states: half an hour is plenty to fit (and ~300 MB to replay)


@dataclass(frozen=True)
class BasePose:
    """The root link's pose in the world at the start, from /tf, and whether it ever moved."""

    xyz: np.ndarray
    quat: np.ndarray  # w, x, y, z
    moved: float  # largest displacement over the bag (m)
    parent: str


@dataclass(frozen=True)
class Command:
    t: float  # s from the recording's start
    controller: str
    message: CommandMessage


@dataclass
class Recording:
    """One bag, ready to replay: times in seconds from the first joint-state sample."""

    bag: Path
    joints: list[str]  # measured joints, in the model's order
    t: dict[str, np.ndarray]  # per joint: sample times
    q: dict[str, np.ndarray]  # per joint: positions
    q0: dict[str, float]
    v0: dict[str, float]
    commands: list[Command]
    duration: float
    base: BasePose | None
    t0: float  # the bag time that is t = 0 here
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.bag.name

    @property
    def commanded(self) -> list[str]:
        return sorted({c.controller for c in self.commands})


@dataclass(frozen=True)
class Grid:
    """A fixed-rate stream's messages on their grid: message i was sent at start + period * k[i]."""

    k: np.ndarray
    period: float
    start: float

    def times(self) -> np.ndarray:
        return self.start + self.period * self.k


def fit_grid(t: np.ndarray, seq: np.ndarray | None = None) -> Grid | None:
    """The least-squares line through (index, stamp), or None for a stream that is not regular.

    The index is the message's sequence number when the publisher counted (ROS 1 headers), else
    its place in the stream, counting a gap of several periods as dropped messages when the jitter
    is small enough to see gaps."""
    t = np.asarray(t, dtype=float)
    n = len(t)
    if n < _MIN_REGULAR:
        return None
    if seq is not None and np.all(np.diff(seq) > 0):
        k = (seq - seq[0]).astype(float)
    else:
        diffs = np.diff(t)
        period = (t[-1] - t[0]) / (n - 1)
        spread = np.median(np.abs(diffs - np.median(diffs)))
        if period > 0 and spread < 0.25 * np.median(diffs):
            k = np.concatenate([[0.0], np.cumsum(np.maximum(1.0, np.round(diffs / np.median(diffs))))])
        else:
            k = np.arange(n, dtype=float)
    slope, intercept = np.polyfit(k, t, 1)
    residual = t - intercept - slope * k
    rms = float(np.sqrt(np.mean(residual**2)))
    if slope <= 0 or rms > MAX_JITTER or np.max(np.abs(residual)) > _TAIL * rms + 1e-3:
        return None  # irregular, or regular in another clock (wall-time commands, sim-time bag)
    return Grid(k, float(slope), float(intercept))


def regular_times(t: np.ndarray, seq: np.ndarray | None = None, late: bool = False) -> np.ndarray:
    """Stamps of a fixed-rate stream, de-jittered (see `fit_grid`). Streams that are not regular
    (a student's step commands) keep their stamps. `late`: the times are receive times, each
    late by a delay >= 0 (the network), so the grid is the line's lower edge (its 1st
    percentile), not its middle: with 10 ms of jitter the middle is 8 ms late."""
    return shared_regular_times([np.asarray(t, dtype=float)], late, [seq])[0]


def shared_regular_times(streams: list[np.ndarray], late: bool = False,
                         seqs: list[np.ndarray | None] | None = None) -> list[np.ndarray]:
    """Several streams de-jittered together where they share a grid -- one node publishing a
    command to every joint at each tick: the same period, and phases within a quarter period
    of each other. Twenty topics fitted as one: the grid is known sqrt(20) times better than
    from any of them, and the joints' commands keep their true order."""
    seqs = seqs or [None] * len(streams)
    grids = [fit_grid(t, s) for t, s in zip(streams, seqs, strict=True)]
    out = [np.asarray(t, dtype=float) for t in streams]
    done: set[int] = set()
    for i, g in enumerate(grids):
        if g is None or i in done:
            continue
        members = []
        for j in range(i, len(grids)):
            h = grids[j]
            if h is None or j in done or abs(h.period / g.period - 1) > 2e-3:
                continue
            shift = (h.start - g.start) / g.period  # grid periods from g's first message
            if abs(shift - round(shift)) < 0.25:
                members.append((j, round(shift)))
        k = np.concatenate([grids[j].k + shift for j, shift in members])
        t = np.concatenate([out[j] for j, _ in members])
        slope, intercept = np.polyfit(k, t, 1)
        edge = float(np.percentile(t - intercept - slope * k, 1)) if late else 0.0
        for j, shift in members:
            out[j] = intercept + edge + slope * (grids[j].k + shift)
            done.add(j)
    return out


def read_recording(path: Path, robot: RobotModel, config: ControlConfig,
                   joints: list[str] | None = None) -> Recording:
    """The bag's joint states, commands for `config`'s controllers and base pose; bad input is one
    line naming what is missing."""
    contents = read_bag(path, frames=(robot.base_link,))
    label = Path(path)
    if not contents.states:
        raise InputError("the bag has no sensor_msgs/JointState messages (no joint_states)",
                         file=label, hint=_topics_hint(contents, "record joint_states"))
    moving = {j.name for j in robot.moving_joints}
    recorded = sorted({n for s in contents.states for n in s.names})
    strangers = [n for n in recorded if n not in moving]
    if strangers and not joints:
        raise InputError(f"joints {', '.join(strangers)} are not in the model '{robot.name}'",
                         file=label, hint="give the model the bag was recorded from (--model), or "
                                          "list the joints to fit with --joints")
    if joints:
        missing = [j for j in joints if j not in recorded]
        if missing:
            raise InputError(f"the bag has no joint_states for {', '.join(missing)}", file=label,
                             hint="joints in the bag: " + ", ".join(recorded))
    notes = list(contents.warnings)
    measured = {n for n in recorded if n in moving}
    _check_states(contents, measured, label, notes)
    t, q, v = _joint_samples(contents, measured, label)
    empty = [j.name for j in robot.moving_joints if j.name in measured and j.name not in t]
    if not t:
        carried = any(len(s.position) for s in contents.states)
        raise InputError("every joint position in the bag is NaN or inf" if carried else
                         "the bag's JointStates carry names but no positions", file=label,
                         hint="record the joint positions: a joint_state_controller publishes them")
    if joints and any(j in empty for j in joints):
        raise InputError(f"the bag has no finite position of "
                         f"{', '.join(j for j in joints if j in empty)} (all NaN, inf or missing)",
                         file=label, hint="fit other joints: --joints")
    if empty:
        notes.append(f"{label.name}: every position of {', '.join(empty)} is NaN or inf; "
                     "not compared (they start at 0)")
    order = [j.name for j in robot.moving_joints if j.name in t]
    start = min(times[0] for times in t.values())
    commands = _commands(contents, config, start, _bag_clock(contents, label), label, notes)
    recording = Recording(label, order, {}, {}, {}, {}, commands, 0.0, None, start, notes)
    for name in order:
        keep = np.concatenate([[True], np.diff(t[name]) > 0])  # duplicates after de-jitter
        recording.t[name] = t[name][keep] - start
        recording.q[name] = q[name][keep]
        recording.q0[name] = float(q[name][0])
        recording.v0[name] = float(v[name][0]) if np.isfinite(v[name][0]) else 0.0
    _check_start(recording, robot)
    recording.duration = max(float(times[-1]) for times in recording.t.values())
    if recording.duration <= 0:
        raise InputError("the bag's joint states span no time", file=label,
                         hint="record at least a few seconds")
    if recording.duration > MAX_DURATION:
        raise InputError(f"the bag's joint states span {number_text(recording.duration)} s, "
                         f"more than {number_text(MAX_DURATION)} s", file=label,
                         hint="fit a shorter stretch: cut it with rosbag filter or ros2 bag convert")
    if not any(0 < c.t <= recording.duration for c in commands):
        raise InputError(f"no command was received while the joint states ran (0 to "
                         f"{number_text(recording.duration)} s; the commands: "
                         f"{number_text(commands[0].t)} to {number_text(commands[-1].t)} s)",
                         file=label, hint="record the commands and joint states of the same run")
    recording.base = _base_pose(contents, robot.base_link, start, label)
    unmeasured = [j.name for j in robot.moving_joints if j.name not in recorded]
    if unmeasured:
        recording.notes.append(f"{label.name}: no joint_states for {', '.join(unmeasured)}; "
                               "they start at 0 and are not compared")
    return recording


def _bag_clock(contents: BagContents, label: Path):
    """Bag time -> the joint states' header-stamp clock. Commands (Float64) have no header, so
    their bag (receive) time is put on the states' clock with it: `rosbag record` of a simulator
    stores wall time while the stamps are sim time (an offset, and a rate when the sim runs slower
    than real time); a real driver's stamps are its own clock (an offset of the transport delay);
    in mexone's bags the two are the same. A line through every state's (receive time,
    de-jittered stamp), moved to its lower edge: the messages that arrived without delay."""
    pairs = []
    for (_, _), msgs in _streams(contents).items():
        stamped = [m for m in msgs if m.stamp is not None]
        if stamped:
            seqs = [m.seq for m in stamped]
            seq = np.array(seqs, dtype=float) if None not in seqs else None
            stamps = regular_times(np.array([m.stamp for m in stamped]), seq)
            pairs += [(m.t, s) for m, s in zip(stamped, stamps, strict=True)]
    if not pairs:
        return lambda x: np.asarray(x, dtype=float)
    pairs_a = np.array(pairs)
    t, stamp = pairs_a[:, 0], pairs_a[:, 1]
    t_mid, s_mid = float(np.median(t)), float(np.median(stamp))
    rate = np.polyfit(t - t_mid, stamp - s_mid, 1)[0] if len(pairs) >= _MIN_REGULAR else 1.0
    if not rate > 0:  # (NaN too: every message received at one time)
        raise InputError("the bag's receive times run against the joint states' header stamps "
                         f"(stamps per receive second: {number_text(rate)})", file=label,
                         hint="the bag's times were rewritten; record it again")
    rate = rate if 0.01 < rate < 100 else 1.0
    offset = float(np.percentile(stamp - s_mid - rate * (t - t_mid), 99))  # the earliest arrivals
    return lambda x: s_mid + offset + rate * (np.asarray(x, dtype=float) - t_mid)


def _streams(contents: BagContents) -> dict[tuple[str, tuple[str, ...]], list]:
    """JointState streams: one topic and one set of names (in any order: some drivers shuffle
    them), as one driver publishes them."""
    streams: dict[tuple[str, tuple[str, ...]], list] = {}
    for msg in contents.states:
        streams.setdefault((msg.topic, tuple(sorted(msg.names))), []).append(msg)
    return streams


def _topics_hint(contents: BagContents, what: str) -> str:
    topics = ", ".join(f"{t} [{k.rsplit('/', 1)[-1]}]" for t, k in sorted(contents.topics.items()))
    return f"{what}; the bag has: {topics or 'no topics'}"


def _check_states(contents: BagContents, wanted: set[str], label: Path, notes: list[str]) -> None:
    """Positions (and velocities, which start the replay) a robot can have: a finite value beyond
    `JOINT_VALUE` is a broken driver or a wrong unit, refused naming the message; NaN and inf
    are what drivers send for 'unknown': those samples are left out, with a note."""
    bad = 0
    first = ""
    bare = [m for m in contents.states if not len(m.position) and wanted.intersection(m.names)]
    for m in contents.states:
        for i, name in enumerate(m.names):
            if name not in wanted:
                continue
            for what, values, limit in (("position", m.position, JOINT_VALUE.high),
                                        ("velocity", m.velocity, VELOCITY.high)):
                if len(values) <= i:
                    continue
                value = float(values[i])
                if not np.isfinite(value):
                    if what == "position":
                        bad += 1
                        first = first or f"{name} in {_where(m)}"
                elif abs(value) > limit:
                    raise InputError(f"{_where(m)}: {name} {what} {number_text(value)} is not a "
                                     f"joint's (beyond +-{number_text(limit)})", file=label,
                                     hint="a broken driver or a wrong unit: fix or cut that "
                                          "stretch of the bag")
    if bad:
        notes.append(f"{label.name}: {bad} joint position(s) NaN or inf, left out (the first: "
                     f"{first})")
    if bare and len(bare) < len(contents.states):
        notes.append(f"{label.name}: {len(bare)} JointState message(s) with no positions, left "
                     f"out (the first: {_where(bare[0])})")


def _check_start(recording: Recording, robot: RobotModel) -> None:
    """The first recorded pose within the model's joint limits (give or take `LIMIT_SLACK` of
    each range): started beyond them the replay flies apart, and the bag is of another robot or
    another unit."""
    for name, q0 in recording.q0.items():
        joint = robot.joints[name]
        limit = joint.limit
        if joint.type not in ("revolute", "prismatic") or limit is None or limit.upper <= limit.lower:
            continue
        slack = LIMIT_SLACK * (limit.upper - limit.lower)
        if not limit.lower - slack <= q0 <= limit.upper + slack:
            raise InputError(f"{name} starts at {number_text(q0)}, beyond its limits "
                             f"[{number_text(limit.lower)}, {number_text(limit.upper)}] in the "
                             "model", file=recording.bag,
                             hint="give the model the bag was recorded from with --model; positions "
                                  "in degrees?")


def _where(m: StateMessage) -> str:
    return f"message {m.index} on {m.topic} (t = {number_text(m.t)} s)"


def _check_times(times: np.ndarray, msgs: list[StateMessage], label: Path) -> None:
    """A stream's times (de-jittered stamps) may wobble by jitter, not run backwards or jump."""
    if len(times) < 2:
        return
    latest = np.maximum.accumulate(times)
    behind = np.flatnonzero(latest - times > MAX_JITTER)  # further back than any jitter goes
    if behind.size:
        back = int(behind[0])
        later = msgs[int(np.argmax(times[:back] >= latest[back]))]
        m = msgs[back]
        raise InputError(f"the header stamps on {m.topic} run backwards in the order the bag "
                         f"received them: message {m.index} is stamped {number_text(times[back])} "
                         f"s, after message {later.index} at {number_text(latest[back])} s",
                         file=label, hint="a driver stamps joint states as it reads the joints, "
                                          "a recorder receives them in that order: were the "
                                          "stamps or the bag's times rewritten?")
    step = np.diff(times)
    gap = int(np.argmax(step))
    if step[gap] > max(MAX_GAP, 20 * float(np.median(step))):
        m = msgs[gap + 1]
        raise InputError(f"a gap of {number_text(step[gap])} s in the joint states on {m.topic} "
                         f"before message {m.index} (stamped {number_text(times[gap + 1])} s)",
                         file=label, hint="fit the stretches of the bag either side of it "
                                          "separately, or fix the stamps")


def _joint_samples(contents: BagContents, wanted: set[str], label: Path):
    """Per joint: de-jittered times, positions and velocities, from every JointState stream (a
    stream: one topic and one set of names, as one driver publishes them)."""
    streams = _streams(contents)
    t: dict[str, list] = {}
    q: dict[str, list] = {}
    v: dict[str, list] = {}
    for (_, names), msgs in streams.items():
        stamps = np.array([m.stamp if m.stamp is not None else m.t for m in msgs])
        seqs = [m.seq for m in msgs]
        seq = np.array(seqs, dtype=float) if None not in seqs else None
        times = regular_times(stamps, seq, late=any(m.stamp is None for m in msgs))
        _check_times(times, msgs, label)
        for name in names:
            if name not in wanted:
                continue
            where = [m.names.index(name) for m in msgs]
            pos = np.array([m.position[i] if len(m.position) > i else np.nan
                            for m, i in zip(msgs, where, strict=True)])
            vel = np.array([m.velocity[i] if len(m.velocity) > i else np.nan
                            for m, i in zip(msgs, where, strict=True)])
            good = np.isfinite(pos)
            t.setdefault(name, []).append(times[good])
            q.setdefault(name, []).append(pos[good])
            v.setdefault(name, []).append(vel[good])
    out_t, out_q, out_v = {}, {}, {}
    for name in wanted:
        if name not in t or not sum(len(x) for x in t[name]):
            continue
        times = np.concatenate(t[name])
        order = np.argsort(times, kind="stable")
        out_t[name] = times[order]
        out_q[name] = np.concatenate(q[name])[order]
        out_v[name] = np.concatenate(v[name])[order]
    return out_t, out_q, out_v


def _finite(m: CommandMessage) -> bool:
    if m.msgtype == TRAJECTORY:
        return all(np.isfinite(p.positions).all() and np.isfinite(p.velocities).all()
                   and np.isfinite(p.time_from_start) for p in m.points)
    return m.values is not None and bool(np.isfinite(m.values).all())


def _some(names: list[str], most: int = 3) -> str:
    """A few names, then how many more: one line stays readable."""
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def _commands(contents: BagContents, config: ControlConfig, start: float, clock,
              label: Path, notes: list[str]) -> list[Command]:
    """Commands on `<ns>/<controller>/command` for the controllers of `config`, in time order:
    bag times put on the states' clock (`clock`), then t = 0 at `start`. A command with NaN or
    inf in it is left out, with a note: the controllers ignored it when the bag was recorded."""
    out: list[Command] = []
    chosen = []
    dropped: dict[str, int] = {}
    for topic, msgs in contents.commands.items():
        parts = topic.rstrip("/").split("/")
        if len(parts) < 2 or parts[-1] != "command" or parts[-2] not in config.controllers:
            continue
        if config.controllers[parts[-2]].joints == ():
            continue
        finite = [m for m in msgs if _finite(m)]
        if len(finite) < len(msgs):
            dropped[topic] = len(msgs) - len(finite)
        if finite:
            chosen.append((parts[-2], finite))
    if dropped and not chosen:
        raise InputError(f"every command for the controllers is NaN or inf (on "
                         f"{_some(sorted(dropped))})", file=label,
                         hint="nothing drove the joints: record a run with real commands")
    if dropped:
        notes.append(f"{label.name}: {sum(dropped.values())} command(s) with NaN or inf left out "
                     f"(as the controllers ignored them), on {_some(sorted(dropped))}")
    received = [clock(np.array([m.t for m in msgs])) for _, msgs in chosen]
    for (name, msgs), times in zip(chosen, shared_regular_times(received, late=True), strict=True):
        out += [Command(float(ti) - start, name, m) for ti, m in zip(times, msgs, strict=True)]
    if not out:
        expected = [f"<ns>/{n}/command" for n, c in config.controllers.items() if c.joints][:3]
        commanded = [t for t, k in contents.topics.items() if k in COMMAND_TYPES]
        hint = (f"command topics in the bag: {', '.join(sorted(commanded))}; the controllers YAML "
                f"expects e.g. {', '.join(expected)} (give the YAML that ran with --controllers)"
                if commanded else _topics_hint(contents, "record the controllers' command topics"))
        raise InputError("the bag has no commands for the controllers (no controller commands)",
                         file=label, hint=hint)
    out.sort(key=lambda c: c.t)
    return out


def _base_pose(contents: BagContents, base: str, start: float, label: Path) -> BasePose | None:
    samples = [s for s in contents.transforms if s.child == base]
    if not samples:
        return None
    parents = {s.parent for s in samples}
    parent = sorted(parents)[0]
    samples = [s for s in samples if s.parent == parent]
    for s in samples:
        where = f"/tf of {base} at t = {number_text(s.t)} s"
        if not (np.isfinite(s.xyz).all() and np.all(np.abs(s.xyz) <= POSITION.high)):
            raise InputError(f"{where}: translation ({', '.join(map(number_text, s.xyz))}) is "
                             f"not a place (beyond +-{number_text(POSITION.high)} m or not finite)",
                             file=label, hint="fix the transform's publisher, or drop /tf from "
                                              "the bag and say --base fixed or free")
        size = float(np.max(np.abs(s.quat))) if np.isfinite(s.quat).all() else 0.0
        if not 1e-6 < size < 1e6:  # (before any norm: 1e300 squared overflows)
            raise InputError(f"{where}: rotation ({', '.join(map(number_text, s.quat))}) is not "
                             "a quaternion (zero, huge or not finite)", file=label,
                             hint="fix the transform's publisher, or drop /tf from the bag and "
                                  "say --base fixed or free")
    times = np.array([s.t for s in samples])
    first = samples[int(np.argmin(np.abs(times - start)))]
    unit = first.quat / np.linalg.norm(first.quat)
    xyz = np.array([s.xyz for s in samples])
    quat = np.array([s.quat / np.linalg.norm(s.quat) for s in samples])
    quat *= np.where(quat @ unit < 0, -1.0, 1.0)[:, None]
    moved = max(float(np.max(np.linalg.norm(xyz - first.xyz, axis=1))),
                float(np.max(np.linalg.norm(quat - unit, axis=1))))
    return BasePose(first.xyz.copy(), unit, moved, parent)
