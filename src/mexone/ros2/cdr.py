"""The two messages a ROS 2 reader gets most often, serialized by hand into ROS 2's wire format
(CDR, little-endian, as rmw_fastrtps writes it) and published as bytes (rclpy's publish_raw).

Why: the generic path (one rclpy object per message, then rclpy's Python -> C conversion, then
Fast DDS' serialization) costs more than the rest of the bridge together, flat out at 50 joint
states and ~15 clocks per simulated second (benchmarks/RESULTS.md, "ROS 2 bridge"). Here a
JointState is its stamp, a cached prefix (frame id and joint names, the same every message)
and the three float64 arrays' bytes; a Clock is 12 bytes. The bytes are exactly what
`rclpy.serialization.serialize_message` gives for the same message (tests/ros2/cdr_check.py
compares them), so a reader cannot tell the difference.
"""

from __future__ import annotations

import struct

__all__ = ["clock", "joint_state", "ENCODERS"]

_ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE: the payload's offsets count from after it
_STAMP = struct.Struct("<iI")
_UINT32 = struct.Struct("<I")


def clock(t_ns: int) -> bytes:
    """rosgraph_msgs/Clock at `t_ns` of sim time."""
    return _ENCAPSULATION + _STAMP.pack(*divmod(t_ns, 1_000_000_000))


def _string(out: bytearray, text: str) -> None:
    out += b"\x00" * (-len(out) % 4)
    data = text.encode()
    out += _UINT32.pack(len(data) + 1) + data + b"\x00"


def _doubles_format(offset: int, counts: tuple[int, ...]) -> struct.Struct:
    """float64 sequences from payload offset `offset`: each its uint32 length (4-aligned), then
    its values (8-aligned when there are any), padding as CDR puts it."""
    fmt = ["<"]
    for n in counts:
        pad = -offset % 4
        fmt.append(f"{pad}xI")
        offset += pad + 4
        if n:
            pad = -offset % 8
            fmt.append(f"{pad}x{n}d")
            offset += pad + 8 * n
    return struct.Struct("".join(fmt))


class _JointStateEncoder:
    """sensor_msgs/JointState from the bus message; the frame id and names change rarely, so
    their bytes are kept between messages."""

    def __init__(self) -> None:
        self._key: tuple[str, list[str]] | None = None
        self._prefix = b""
        self._tails: dict[tuple[int, ...], struct.Struct] = {}

    def __call__(self, msg) -> bytes:
        frame, names = msg.header.frame_id, msg.name
        if self._key is None or self._key[0] != frame or self._key[1] != names:
            prefix = bytearray(8)  # the stamp's place: offsets count from the payload's start
            _string(prefix, frame)
            prefix += b"\x00" * (-len(prefix) % 4)
            prefix += _UINT32.pack(len(names))
            for name in names:
                _string(prefix, name)
            self._key, self._prefix = (frame, list(names)), bytes(prefix[8:])
            self._tails = {}
        position, velocity, effort = msg.position, msg.velocity, msg.effort
        counts = (len(position), len(velocity), len(effort))
        tail = self._tails.get(counts)
        if tail is None:
            tail = self._tails[counts] = _doubles_format(8 + len(self._prefix), counts)
        stamp = msg.header.stamp
        return b"".join((_ENCAPSULATION, _STAMP.pack(stamp.secs, stamp.nsecs), self._prefix,
                         tail.pack(counts[0], *position, counts[1], *velocity, counts[2],
                                   *effort)))


def joint_state() -> _JointStateEncoder:
    """An encoder (bus JointState -> bytes) with its own cache, one per topic."""
    return _JointStateEncoder()


# ROS type -> a factory of encoders from the bus message to CDR bytes
ENCODERS = {"sensor_msgs/JointState": joint_state}
