"""mexone's bus messages <-> rospy messages: one table each way, keyed by the bus class (whose ROS
type name is `bus.msgs.ROS_TYPES`). The bridge forwards every bus topic whose type has a ROS
name: types whose fields mirror ROS's (the sensors' Imu, WrenchStamped, ContactsState, Image,
CameraInfo, PointCloud2, PointStamped, PolygonStamped) go field by field (`_generic`), so a new
message type needs a converter here only when its fields differ from ROS's. Stamps go through
integer nanoseconds: a float second would put them 1 ns off (robot_state_publisher then drops
them)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from mexone.bus import msgs, ros_map

__all__ = ["TO_ROS", "FROM_ROS", "ros_class", "to_ros", "from_ros", "ros_time", "bus_time",
           "can_send"]


def ros_class(bus_type: type):
    """The rospy class for a bus message class (Debian's, or mexone's generated ones)."""
    from roslib.message import get_message_class

    return get_message_class(msgs.ROS_TYPES[bus_type])


def ros_time(stamp: msgs.Time | int):
    """A rospy Time from a bus Time or integer nanoseconds, exactly."""
    import rospy

    if isinstance(stamp, int):
        return rospy.Time(*divmod(stamp, 1_000_000_000))
    return rospy.Time(stamp.secs, stamp.nsecs)


def bus_time(stamp) -> msgs.Time:
    return msgs.Time(int(stamp.secs), int(stamp.nsecs))


def _header(ros, header: msgs.Header) -> None:
    ros.seq, ros.stamp, ros.frame_id = header.seq, ros_time(header.stamp), header.frame_id


def _joint_state(m: msgs.JointState, cls):
    out = cls(name=list(m.name), position=list(m.position), velocity=list(m.velocity),
              effort=list(m.effort))
    _header(out.header, m.header)
    return out


def _tf(m: msgs.TFMessage, cls):
    from geometry_msgs.msg import TransformStamped

    out = cls()
    for t in m.transforms:
        ros = TransformStamped()
        _header(ros.header, t.header)
        ros.child_frame_id = t.child_frame_id
        tr, rot = ros.transform.translation, ros.transform.rotation
        tr.x, tr.y, tr.z = (float(v) for v in t.translation)
        rot.w, rot.x, rot.y, rot.z = (float(v) for v in t.rotation)
        out.transforms.append(ros)
    return out


def _controller_state(m: msgs.JointControllerState, cls):
    out = cls(set_point=m.set_point, process_value=m.process_value,
              process_value_dot=m.process_value_dot, error=m.error, time_step=m.time_step,
              command=m.command, p=m.p, i=m.i, d=m.d, i_clamp=m.i_clamp, antiwindup=m.antiwindup)
    _header(out.header, m.header)
    return out


def _trajectory_to_ros(m: msgs.JointTrajectory, cls):
    from trajectory_msgs.msg import JointTrajectoryPoint

    out = cls(joint_names=list(m.joint_names))
    _header(out.header, m.header)
    for p in m.points:
        out.points.append(JointTrajectoryPoint(
            positions=list(p.positions), velocities=list(p.velocities),
            accelerations=list(p.accelerations), effort=list(p.effort),
            time_from_start=_ros_duration(p.time_from_start)))
    return out


def _ros_duration(d: msgs.Duration):
    import rospy

    return rospy.Duration(d.secs, d.nsecs)


# bus class -> (bus message, rospy class) -> rospy message
TO_ROS: dict[type, Callable[[Any, type], Any]] = {
    msgs.Float64: lambda m, cls: cls(data=m.data),
    msgs.Float64MultiArray: lambda m, cls: cls(data=list(m.data)),
    msgs.JointState: _joint_state,
    msgs.Clock: lambda m, cls: cls(clock=ros_time(m.clock)),
    msgs.TFMessage: _tf,
    msgs.JointControllerState: _controller_state,
    msgs.JointTrajectory: _trajectory_to_ros,
}


def trajectory_from_ros(ros) -> msgs.JointTrajectory:
    points = [msgs.JointTrajectoryPoint(
        [float(v) for v in p.positions], [float(v) for v in p.velocities],
        [float(v) for v in p.accelerations], [float(v) for v in p.effort],
        msgs.Duration(int(p.time_from_start.secs), int(p.time_from_start.nsecs)))
        for p in ros.points]
    header = msgs.Header(ros.header.seq, bus_time(ros.header.stamp), ros.header.frame_id)
    return msgs.JointTrajectory(header, list(ros.joint_names), points)


# ROS type name -> rospy message -> bus message (what ROS nodes may command)
FROM_ROS: dict[str, Callable[[Any], Any]] = {
    "std_msgs/Float64": lambda r: msgs.Float64(float(r.data)),
    "std_msgs/Float64MultiArray": lambda r: msgs.Float64MultiArray([float(v) for v in r.data]),
    "trajectory_msgs/JointTrajectory": trajectory_from_ros,
}


def _generic_from_ros(ros, bus_type: type):
    """A ROS message into the bus class whose fields are ROS's own (the reverse of _generic):
    each field takes the type of the bus class's default for it."""
    default = bus_type()
    values = {}
    for f in dataclasses.fields(bus_type):
        value, like = getattr(ros, f.name), getattr(default, f.name)
        if isinstance(like, msgs.Time):
            values[f.name] = bus_time(value)
        elif dataclasses.is_dataclass(like):
            values[f.name] = _generic_from_ros(value, type(like))
        else:
            values[f.name] = type(like)(value)
    return bus_type(**values)


# geometry commands ROS nodes may send (cmd_vel, goals): fields as ROS's, copied generically
for _bus in (msgs.Twist, msgs.PoseStamped):
    FROM_ROS[msgs.ROS_TYPES[_bus]] = lambda r, _b=_bus: _generic_from_ros(r, _b)


def _generic(m, cls):
    """A bus message whose fields are ROS's own (names, order, nesting): copied field by field,
    nested messages built from the ROS class's slot types, stamps exact."""
    out = cls()
    for slot, slot_type in zip(cls.__slots__, cls._slot_types, strict=True):
        setattr(out, slot, _value(getattr(m, slot), slot_type))
    return out


def _value(value, slot_type: str):
    from roslib.message import get_message_class

    if isinstance(value, msgs.Time):
        return ros_time(value)
    if isinstance(value, msgs.Duration):
        return _ros_duration(value)
    if dataclasses.is_dataclass(value):
        return _generic(value, get_message_class(_full_type(slot_type)))
    if isinstance(value, (list, tuple)):
        base = slot_type.split("[", 1)[0]
        if "/" in base or base == "Header":
            return [_value(v, base) for v in value]
        return list(value)
    return value


def _full_type(slot_type: str) -> str:
    return "std_msgs/Header" if slot_type == "Header" else slot_type


def can_send(bus_type: type) -> bool:
    """Whether the bridge can publish this bus type on ROS (the shared table, `bus.ros_map`)."""
    return ros_map.can_send(bus_type)


def to_ros(msg, cls):
    return TO_ROS.get(type(msg), _generic)(msg, cls)


def from_ros(ros_msg):
    return FROM_ROS[ros_msg._type](ros_msg)
