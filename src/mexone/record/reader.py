"""Read a recorded bag back, with rosbags: the one reader of bags in mexone.

`read_bag` returns what a bag holds for joints -- every JointState message (names in any order,
header stamps and bag times both kept, so jitter can be judged later), every controller command
(Float64, Float64MultiArray, JointTrajectory) by topic, and the /tf transforms of the frames
asked for -- from bags written by mexone or by ROS itself (`rosbag record`, `ros2 bag record`).
`read_joint_series` turns it into per-joint series for plots and CSV.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from mexone.control.spec import controller_name
from mexone.errors import InputError
from mexone.ranges import number_text
from mexone.record.bag import typestore_for

__all__ = ["JointSeries", "read_joint_series", "FieldSeries", "read_field_series", "read_bag",
           "BagContents", "StateMessage", "CommandMessage", "TransformSample", "JOINT_STATE", "COMMAND_TYPES"]

log = logging.getLogger(__name__)

#: the joint states' type in a bag
JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT64, MULTI, TRAJECTORY = ("std_msgs/msg/Float64", "std_msgs/msg/Float64MultiArray",
                              "trajectory_msgs/msg/JointTrajectory")
#: the controllers' command types a bag's commands are read from
COMMAND_TYPES = (FLOAT64, MULTI, TRAJECTORY)
_TF = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")


@dataclass
class StateMessage:
    """One JointState as recorded: `t` is the bag's receive time, `stamp` the header's (None when
    the publisher left it zero); names in the publisher's order."""

    t: float
    stamp: float | None
    seq: int | None  # ROS 1 header sequence number (None for ROS 2)
    topic: str
    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray  # empty when the driver does not report it
    effort: np.ndarray
    index: int = 0  # 1, 2, ... on its topic (malformed messages left out still count)


@dataclass
class TrajectoryPoint:
    positions: np.ndarray
    velocities: np.ndarray
    time_from_start: float


@dataclass
class CommandMessage:
    """One command as recorded. `values`: the Float64 (one value) or Float64MultiArray data;
    trajectories keep their joints, points and header stamp."""

    t: float
    msgtype: str
    values: np.ndarray | None = None
    joint_names: tuple[str, ...] = ()
    points: list[TrajectoryPoint] = field(default_factory=list)
    stamp: float | None = None


@dataclass
class TransformSample:
    t: float
    parent: str
    child: str
    xyz: np.ndarray
    quat: np.ndarray  # w, x, y, z


@dataclass
class BagContents:
    path: Path
    states: list[StateMessage]
    commands: dict[str, list[CommandMessage]]  # topic -> messages in bag order
    transforms: list[TransformSample]
    topics: dict[str, str]  # every topic -> its message type
    warnings: list[str] = field(default_factory=list)  # one line each: what was left out and why


@dataclass
class JointSeries:
    """One joint's measured state and, where a position controller commanded it, the command
    (held between command messages, as the controller holds it)."""

    name: str
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    command: np.ndarray | None = None
    command_times: list[float] = field(default_factory=list)


@contextmanager
def _readable(path: Path | str) -> Iterator[Path]:
    """The bag, named as what it is (an MCAP named .bag is read as an MCAP, with a note); a
    killed recording's (BAG.active, or a truncated BAG) recovered into a temporary copy, with a
    one-line note saying how to repair the file itself."""
    from mexone.record.recover import (
        KIND_NAMES,
        bag_kind,
        bag_suffix,
        is_complete,
        killed_recording,
        misnamed,
        not_a_bag,
        recover,
    )

    path = Path(path)
    if path.is_dir():  # a rosbag2 folder
        yield path
        return
    source = path if path.is_file() and not path.name.endswith(".active") else \
        killed_recording(path)
    if source is None:
        raise InputError("no such file", file=path, hint="record one with --record FILE")
    kind = bag_kind(source)
    if kind is None:
        raise not_a_bag(source)
    wrong = misnamed(source)
    if wrong:
        log.warning(f"{source}: {wrong}; read as what it is (rename it "
                    f"{Path(source.name.removesuffix('.active')).stem}{kind})")
    complete = source is path and is_complete(source)
    if complete and not wrong:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="mexone-read-") as folder:
        copy = Path(folder) / (Path(source.name.removesuffix(".active")).stem + kind)
        if complete:
            copy.symlink_to(source.resolve())
        else:
            found = recover(source, copy)
            if not found.messages:
                raise InputError(f"starts as {KIND_NAMES[kind]}, but not one message can be read "
                                 "from it (damaged, or cut before its first chunk was written)",
                                 file=source, hint="record it again")
            bag = source.with_name(source.name.removesuffix(".active"))
            named = bag if bag_suffix(bag) == kind else bag.with_name(bag.stem + kind)
            rename = "" if named == bag else f"renamed {named.name}, "
            log.warning(f"{source}: an unfinished recording (killed?); read the "
                        f"{found.describe()} recovered from it; {rename}'mexone record --recover "
                        f"{named}' repairs it on disk")
        try:
            yield copy
        except InputError as exc:  # about the user's file, not our temporary copy
            raise InputError(exc.what, file=source, hint=exc.hint) from None


def read_bag(path: Path | str, frames: tuple[str, ...] = ()) -> BagContents:
    """Joint states, commands and the /tf transforms whose child frame is in `frames`."""
    with _readable(path) as readable:
        contents = _read(readable, frames)
    contents.path = Path(path)
    return contents


def _seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def _array(values) -> np.ndarray:
    return np.asarray(values, dtype=float).ravel()


def _reason(exc: BaseException) -> str:
    """A library's error as one short line (some span lines, some quote whole records)."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def _open(path: Path) -> AnyReader:
    try:
        reader = AnyReader([path], default_typestore=typestore_for(path.suffix == ".bag"))
        reader.open()
    except Exception as exc:  # rosbags raises its own error types for damaged or foreign files
        raise InputError(f"not a readable bag: {_reason(exc)}", file=path,
                         hint="give a .mcap or .bag recorded by mexone or ROS") from None
    return reader


def _malformed(msg, names: tuple[str, ...]) -> str | None:
    """Why a JointState breaks its own type's rule, or None: ROS wants one position, velocity and
    effort per name (or none of one kind), and each joint named once."""
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        return f"names {twice[0]} {names.count(twice[0])} times"
    for kind in ("position", "velocity", "effort"):
        count = len(getattr(msg, kind))
        if count not in (0, len(names)):
            return f"has {len(names)} names but {count} {kind} values (ROS: one per name, or none)"
    return None


def _read(path: Path, frames: tuple[str, ...]) -> BagContents:
    reader = _open(path)
    wanted = {f.strip("/") for f in frames}
    contents = BagContents(path, [], {}, [], {c.topic: c.msgtype for c in reader.connections})
    counts: dict[str, int] = {}  # JointState messages per topic
    bad: list[str] = []  # the malformed ones, left out
    try:
        for conn, stamp, raw in reader.messages():
            kind, t = conn.msgtype, stamp * 1e-9
            if kind == JOINT_STATE:
                msg = reader.deserialize(raw, kind)
                header = _seconds(msg.header.stamp)
                names = tuple(msg.name)
                index = counts[conn.topic] = counts.get(conn.topic, 0) + 1
                why = _malformed(msg, names)
                if why is not None:
                    bad.append(f"message {index} on {conn.topic} (t = {number_text(t)} s) {why}")
                    continue
                contents.states.append(StateMessage(
                    t, header if header > 0 else None, getattr(msg.header, "seq", None),
                    conn.topic, names, _array(msg.position), _array(msg.velocity),
                    _array(msg.effort), index))
            elif kind in (FLOAT64, MULTI):
                msg = reader.deserialize(raw, kind)
                contents.commands.setdefault(conn.topic, []).append(
                    CommandMessage(t, kind, _array(msg.data)))
            elif kind == TRAJECTORY:
                msg = reader.deserialize(raw, kind)
                points = [TrajectoryPoint(_array(p.positions), _array(p.velocities),
                                          _seconds(p.time_from_start)) for p in msg.points]
                header = _seconds(msg.header.stamp)
                contents.commands.setdefault(conn.topic, []).append(CommandMessage(
                    t, kind, joint_names=tuple(msg.joint_names), points=points,
                    stamp=header if header > 0 else None))
            elif kind in _TF and wanted:
                for tf in reader.deserialize(raw, kind).transforms:
                    if tf.child_frame_id.strip("/") in wanted:
                        tr, rot = tf.transform.translation, tf.transform.rotation
                        header = _seconds(tf.header.stamp)
                        contents.transforms.append(TransformSample(
                            header if header > 0 else t, tf.header.frame_id.strip("/"),
                            tf.child_frame_id.strip("/"), np.array([tr.x, tr.y, tr.z]),
                            np.array([rot.w, rot.x, rot.y, rot.z])))
    except InputError:
        raise
    except Exception as exc:  # a damaged chunk or a message that does not match its type
        raise InputError(f"cannot read the bag's messages: {_reason(exc)}", file=path,
                         hint="'mexone record --recover' repairs a truncated bag") from None
    finally:
        reader.close()
    if bad and not contents.states:
        raise InputError(f"every JointState message is malformed: {bad[0]}", file=path,
                         hint="fix the driver that published them")
    if bad:
        contents.warnings.append(f"{path.name}: left out {len(bad)} malformed JointState "
                                 f"message(s), the first: {bad[0]}")
    return contents


def read_joint_series(path: Path | str) -> dict[str, JointSeries]:
    """Per joint, for plots: every joint of the JointState messages (looked up by name in each
    message: drivers shuffle them), and each joint's `<joint>_position_controller/command` held
    between messages. What the reader left out is logged, one line each."""
    contents = read_bag(path)
    for warning in contents.warnings:
        log.warning(warning)
    states = contents.states
    if not states:
        raise InputError("the bag has no sensor_msgs/JointState messages", file=path,
                         hint="record a run that has a joint_state_controller")
    names = list(dict.fromkeys(n for s in states for n in s.names))
    where = [{n: i for i, n in enumerate(s.names)} for s in states]
    t = np.array([s.stamp if s.stamp is not None else s.t for s in states])
    out = {}
    for name in names:
        def column(field_name: str, name=name) -> np.ndarray:
            return np.array([getattr(s, field_name)[w[name]] if name in w and
                             len(getattr(s, field_name)) > w[name] else np.nan
                             for s, w in zip(states, where, strict=True)])

        series = JointSeries(name, t, column("position"), column("velocity"), column("effort"))
        topic = next((topic for topic, msgs in contents.commands.items()
                      if topic.endswith(f"/{controller_name(name)}/command")
                      and msgs[0].msgtype == FLOAT64), None)
        if topic is not None:
            ct = np.array([c.t for c in contents.commands[topic]])
            cv = np.array([c.values[0] if len(c.values) else np.nan
                           for c in contents.commands[topic]])
            idx = np.searchsorted(ct, t, side="right") - 1
            series.command = np.where(idx >= 0, cv[np.maximum(idx, 0)], 0.0)
            series.command_times = ct.tolist()
        out[name] = series
    return out


@dataclass
class FieldSeries:
    """One numeric field of one topic over time: `/mex_rb/imu/linear_acceleration/z`."""

    path: str
    t: np.ndarray
    values: np.ndarray


def _numeric_leaves(msg, prefix: str) -> Iterator[tuple[str, float]]:
    """(field path, value) for every scalar number in a message, as rqt_plot offers them;
    headers, strings and lists of messages are skipped, numeric arrays give one path per
    element."""
    if isinstance(msg, bool):
        return
    if isinstance(msg, int | float | np.integer | np.floating):
        yield prefix, float(msg)
        return
    if isinstance(msg, np.ndarray) and msg.dtype.kind in "iuf":
        for k, value in enumerate(msg.ravel().tolist()):
            yield f"{prefix}/{k}", float(value)
        return
    fields = getattr(msg, "__dataclass_fields__", None)
    if fields is None:
        return
    for name in fields:
        if name in ("header", "__msgtype__"):
            continue
        yield from _numeric_leaves(getattr(msg, name), f"{prefix}/{name}")


def read_field_series(path: Path | str, wanted: list[str]) -> list[FieldSeries]:
    """rqt_plot's topic paths: `/topic` (all its numeric fields) or `/topic/field/sub` (one
    field or a subtree). Time is the header stamp when the message has one, else the bag's."""
    with _readable(path) as readable:
        reader = _open(readable)
        try:
            topics = {c.topic: c for c in reader.connections}
            picks: dict[str, list[str]] = {}  # topic -> the field prefixes asked for
            for item in wanted:
                item = "/" + item.strip("/")
                topic = max((t for t in topics if item == t or item.startswith(t + "/")),
                            key=len, default=None)
                if topic is None:
                    raise InputError(f"the bag has no topic for '{item}'", file=path,
                                     hint="topics: " + ", ".join(sorted(topics)))
                picks.setdefault(topic, []).append(item[len(topic):])
            series: dict[str, tuple[list[float], list[float]]] = {}
            conns = [topics[t] for t in picks]
            for conn, stamp, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                header = getattr(msg, "header", None)
                t = _seconds(header.stamp) if header is not None else stamp * 1e-9
                for field_path, value in _numeric_leaves(msg, conn.topic):
                    sub = field_path[len(conn.topic):]
                    if any((sub == p or sub.startswith(p + "/")) if p
                           else "covariance" not in sub  # a whole topic: no matrices
                           for p in picks[conn.topic]):
                        times, values = series.setdefault(field_path, ([], []))
                        times.append(t)
                        values.append(value)
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"cannot read the bag's messages: {_reason(exc)}", file=path,
                             hint="'mexone record --recover' repairs a truncated bag") from None
        finally:
            reader.close()
    missing = [w for w in wanted if not any(p == "/" + w.strip("/") or p.startswith(
        "/" + w.strip("/") + "/") for p in series)]
    if missing:
        raise InputError(f"no numeric field at {', '.join(missing)} in the bag", file=path,
                         hint="give a topic or a field path such as /mex_rb/imu/linear_acceleration/z")
    return [FieldSeries(p, np.array(t), np.array(v)) for p, (t, v) in series.items()]
