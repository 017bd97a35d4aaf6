"""Run by test_ros2.py with the ROS 2 wheels' Python: mexone.ros2.cdr's hand-built bytes against
rclpy's own serializer (rosidl's C type support, through rmw_fastrtps), for property-generated
joint states and clocks. Prints one JSON object: the examples tried and the first mismatch."""

from __future__ import annotations

import json

from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from mexone.bus import msgs
from mexone.ros2 import cdr, convert

report: dict = {"joint_states": 0, "clocks": 0, "mismatch": None}
text = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"),
               max_size=12)
doubles = st.lists(st.floats(allow_nan=False), max_size=6)
encode = cdr.joint_state()  # one encoder throughout: its cache must follow changing names


def same(ours: bytes, theirs: bytes, cls, expected) -> bool:
    """The same message: it reads back equal, and every byte rclpy wrote is ours but padding
    (which Fast CDR leaves uninitialised, and which we write as 0); rclpy's buffer may be longer
    than the message."""
    try:
        back = deserialize_message(ours, cls)
    except Exception:  # noqa: BLE001 - rclpy cannot read our bytes: a mismatch
        return False
    return (back == expected and len(ours) <= len(theirs)
            and all(a == b or a == 0 for a, b in zip(ours, theirs, strict=False)))


@settings(derandomize=True, max_examples=300, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(0, 999_999_999), text, st.lists(text, max_size=6),
       doubles, doubles, doubles)
def joint_states(sec, nanosec, frame, names, position, velocity, effort):
    msg = msgs.JointState(msgs.Header(0, msgs.Time(sec, nanosec), frame), names, position,
                          velocity, effort)
    expected = convert.to_ros2(msg, JointState)
    ours, theirs = encode(msg), serialize_message(expected)
    report["joint_states"] += 1
    if not same(ours, theirs, JointState, expected) and report["mismatch"] is None:
        report["mismatch"] = {"message": repr(msg), "ours": ours.hex(), "rclpy": theirs.hex()}


@settings(derandomize=True, max_examples=100, deadline=None)
@given(st.integers(0, (2**31 - 1) * 10**9))
def clocks(t_ns):
    expected = Clock()
    expected.clock.sec, expected.clock.nanosec = divmod(t_ns, 10**9)
    ours, theirs = cdr.clock(t_ns), serialize_message(expected)
    report["clocks"] += 1
    if not same(ours, theirs, Clock, expected) and report["mismatch"] is None:
        report["mismatch"] = {"clock": t_ns, "ours": ours.hex(), "rclpy": theirs.hex()}


joint_states()
clocks()
print(json.dumps(report))
