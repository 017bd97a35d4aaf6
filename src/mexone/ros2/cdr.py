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
import sys
from array import array

__all__ = ["clock", "joint_state", "ENCODERS"]

_ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE: the payload's offsets count from after it
_STAMP = struct.Struct("<iI")
_UINT32 = struct.Struct("<I")
_SWAP = sys.byteorder != "little"


def clock(t_ns: int) -> bytes:
    """rosgraph_msgs/Clock at `t_ns` of sim time."""
    return _ENCAPSULATION + _STAMP.pack(*divmod(t_ns, 1_000_000_000))


def _string(out: bytearray, text: str) -> None:
    out += b"\x00" * (-len(out) % 4)
    data = text.encode()
    out += _UINT32.pack(len(data) + 1) + data + b"\x00"


def _doubles(out: bytearray, values) -> None:
    """A float64 sequence: its length (4-aligned), then the values (8-aligned if any)."""
    out += b"\x00" * (-len(out) % 4)
    out += _UINT32.pack(len(values))
    if values:
        out += b"\x00" * (-len(out) % 8)
        data = array("d", values)
        if _SWAP:
            data.byteswap()
        out += data.tobytes()


class _JointStateEncoder:
    """sensor_msgs/JointState from the bus message; the frame id and names change rarely, so
    their bytes are kept between messages."""

    def __init__(self) -> None:
        self._key: tuple[str, list[str]] | None = None
        self._prefix = b""

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
        stamp = msg.header.stamp
        out = bytearray(_STAMP.pack(stamp.secs, stamp.nsecs))  # offset 0 of the payload
        out += self._prefix
        for values in (msg.position, msg.velocity, msg.effort):
            _doubles(out, values)
        return _ENCAPSULATION + out


def joint_state() -> _JointStateEncoder:
    """An encoder (bus JointState -> bytes) with its own cache, one per topic."""
    return _JointStateEncoder()


# ROS type -> a factory of encoders from the bus message to CDR bytes
ENCODERS = {"sensor_msgs/JointState": joint_state}
