"""Test helpers: a real recording as editable records, written back as a ROS 1 bag or an MCAP,
so tests can mutate what a careless driver or an attacker might put in one -- NaN, inf and huge
values, names dropped or repeated, stamps running backwards -- and the bytes themselves."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mexone.record.bag import typestore_for
from mexone.record.reader import FLOAT64, JOINT_STATE, read_bag

__all__ = ["Record", "TF", "records_of", "write", "STATE", "COMMAND"]

STATE, COMMAND, TF = JOINT_STATE, FLOAT64, "tf2_msgs/msg/TFMessage"
CHUNK = 16 * 1024  # bytes


@dataclass
class Record:
    """One message: `t` the bag's receive time (s); `stamp` the header's (0: none).
    JointState: names, position, velocity, effort. Float64: value. TF: parent, child, xyz, quat
    (w, x, y, z)."""

    t: float
    topic: str
    msgtype: str
    stamp: float = 0.0
    seq: int = 0
    names: list[str] = field(default_factory=list)
    position: list[float] = field(default_factory=list)
    velocity: list[float] = field(default_factory=list)
    effort: list[float] = field(default_factory=list)
    value: float = 0.0
    parent: str = ""
    child: str = ""
    xyz: list[float] = field(default_factory=list)
    quat: list[float] = field(default_factory=list)


def records_of(bag: Path, seconds: float, commanded: tuple[str, ...] | None = None,
               base_link: str = "pelvis") -> list[Record]:
    """The bag's joint states, Float64 commands (of `commanded` joints' controllers, or all) and
    /tf of `base_link` during its first `seconds`, in receive order."""
    contents = read_bag(bag, frames=(base_link,))
    out: list[Record] = []
    for seq, s in enumerate(contents.states):
        out.append(Record(s.t, s.topic, STATE, s.stamp or 0.0, seq, list(s.names),
                          s.position.tolist(), s.velocity.tolist(), s.effort.tolist()))
    for topic, messages in contents.commands.items():
        joint = topic.rsplit("/", 2)[-2].removesuffix("_position_controller")
        if commanded is not None and joint not in commanded:
            continue
        out += [Record(m.t, topic, COMMAND, value=float(m.values[0])) for m in messages
                if m.msgtype == FLOAT64]
    out += [Record(tf.t, "/tf", TF, tf.t, parent=tf.parent, child=tf.child, xyz=tf.xyz.tolist(),
                   quat=tf.quat.tolist()) for tf in contents.transforms]
    out = [r for r in out if r.t <= seconds]
    out.sort(key=lambda r: r.t)
    return copy.deepcopy(out)


def _message(record: Record, types, ros1: bool):
    def time(t: float):
        ns = int(round(t * 1e9))
        return types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)

    def header(frame: str = ""):
        extra = {"seq": record.seq} if ros1 else {}
        return types["std_msgs/msg/Header"](stamp=time(record.stamp), frame_id=frame, **extra)

    def array(values):
        return np.asarray(values, dtype=np.float64).reshape(-1)

    if record.msgtype == STATE:
        return types[STATE](header=header(), name=list(record.names), position=array(record.position),
                            velocity=array(record.velocity), effort=array(record.effort))
    if record.msgtype == COMMAND:
        return types[COMMAND](data=float(record.value))
    x, y, z = record.xyz
    w, qx, qy, qz = record.quat
    stamped = types["geometry_msgs/msg/TransformStamped"](
        header=header(record.parent), child_frame_id=record.child,
        transform=types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
            rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=w)))
    return types[TF](transforms=[stamped])


def write(records: list[Record], path: Path, ros1: bool | None = None) -> Path:
    """The records as a ROS 1 bag (`ros1`, default: a .bag name) or an MCAP laid out as rosbag2
    writes it, in the order given (receive times need not increase)."""
    ros1 = path.suffix == ".bag" if ros1 is None else ros1
    store = typestore_for(ros1)
    stamp = [max(0, int(round(r.t * 1e9))) for r in records]
    if ros1:
        from rosbags.rosbag1 import Writer

        with Writer(path) as writer:
            writer.chunk_threshold = CHUNK  # small chunks: a cut bag keeps most of them
            connections: dict[str, object] = {}
            for r, ns in zip(records, stamp, strict=True):
                if r.topic not in connections:
                    connections[r.topic] = writer.add_connection(r.topic, r.msgtype, typestore=store)
                writer.write(connections[r.topic], ns,
                             store.serialize_ros1(_message(r, store.types, True), r.msgtype))
        return path
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter

    with path.open("wb") as handle:
        writer = McapWriter(handle, compression=CompressionType.NONE, chunk_size=CHUNK)
        writer.start(profile="ros2", library="mexone tests")
        channels: dict[str, int] = {}
        for r, ns in zip(records, stamp, strict=True):
            if r.topic not in channels:
                text, _ = store.generate_msgdef(r.msgtype, ros_version=2)
                schema = writer.register_schema(r.msgtype, "ros2msg", text.encode())
                channels[r.topic] = writer.register_channel(r.topic, "cdr", schema)
            writer.add_message(channels[r.topic], log_time=ns, publish_time=ns,
                               data=bytes(store.serialize_cdr(_message(r, store.types, False),
                                                              r.msgtype)))
        writer.finish()
    return path
