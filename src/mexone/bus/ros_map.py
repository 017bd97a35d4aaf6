"""The one table of how bus topics meet a ROS graph, shared by the ROS 1 bridge, the ROS 2 bridge
and the Foxglove server: which bus types go out (and under which ROS type name, in ROS 1 and
ROS 2 spelling), which ROS types nodes may command, the ros2_control names a command topic also
answers to, and the QoS class each kind of message gets on ROS 2 (as ROS 2's drivers do).

Each front end converts messages its own way (genpy classes, rosidl classes, JSON); none keeps
a second copy of this mapping.
"""

from __future__ import annotations

from dataclasses import dataclass

from mexone.bus import msgs

__all__ = ["ros_type", "ros2_type", "can_send", "COMMAND_TYPES", "is_command", "Qos", "qos_of",
           "ros2_control_aliases", "package_of"]

# ROS types ROS nodes may publish to the simulator (commands): controllers' set points and
# trajectories, cmd_vel and goals
COMMAND_TYPES = frozenset({"std_msgs/Float64", "std_msgs/Float64MultiArray",
                           "trajectory_msgs/JointTrajectory", "geometry_msgs/Twist",
                           "geometry_msgs/PoseStamped"})


def ros_type(bus_type: type) -> str | None:
    """ROS 1 spelling, `sensor_msgs/Imu` (None: the type has no ROS counterpart)."""
    return msgs.ROS_TYPES.get(bus_type)


def ros2_type(bus_type: type) -> str | None:
    """ROS 2 spelling, `sensor_msgs/msg/Imu`."""
    name = ros_type(bus_type)
    if name is None:
        return None
    package, message = name.split("/")
    return f"{package}/msg/{message}"


def package_of(bus_type: type) -> str:
    return (ros_type(bus_type) or "").split("/")[0]


def can_send(bus_type: type) -> bool:
    """Whether a bridge publishes this bus type on ROS: every type with a ROS name (each bus
    message mirrors its ROS type's fields, or its bridge has a converter for it)."""
    return bus_type in msgs.ROS_TYPES


def is_command(bus_type: type) -> bool:
    """Whether ROS nodes may publish this bus type to the simulator."""
    return msgs.ROS_TYPES.get(bus_type) in COMMAND_TYPES


@dataclass(frozen=True)
class Qos:
    """A ROS 2 QoS class: reliable or best-effort, keep-last depth, transient-local or not."""

    reliable: bool = True
    depth: int = 10
    latched: bool = False
    why: str = ""


# as ROS 2's own publishers do: joint_state_broadcaster and controllers use the system default
# (reliable, depth 10); gazebo_ros' IMU, force-torque and contact plugins SensorDataQoS
# (best-effort, depth 5); image_transport's camera publishers reliable with a short queue (a
# slow reader gets the latest images); /clock ClockQoS (best-effort, depth 1); robot_state_
# publisher's /robot_description reliable and transient-local (late joiners get it)
STATE = Qos(True, 10, False, "states: reliable, depth 10 (joint_state_broadcaster)")
SENSOR = Qos(False, 5, False, "sensor data: best-effort, depth 5 (SensorDataQoS)")
CAMERA = Qos(True, 2, False, "images and clouds: reliable, depth 2 (image_transport)")
CLOCK = Qos(False, 1, False, "/clock: best-effort, depth 1 (ClockQoS)")
LATCHED = Qos(True, 1, True, "/robot_description: reliable, transient-local, depth 1")
COMMAND = Qos(True, 10, False, "commands: reliable, depth 10 (ros2_control's subscriptions)")
TF = Qos(True, 100, False, "/tf: reliable, depth 100 (tf2_ros' TransformBroadcaster)")

_QOS = {msgs.Imu: SENSOR, msgs.WrenchStamped: SENSOR, msgs.ContactsState: SENSOR,
        msgs.Image: CAMERA, msgs.CameraInfo: CAMERA, msgs.PointCloud2: CAMERA,
        msgs.Clock: CLOCK}


def qos_of(bus_type: type) -> Qos:
    """The QoS a bus topic of this type gets on ROS 2 (documented in docs/ros2.md)."""
    return _QOS.get(bus_type, STATE)


def ros2_control_aliases(topic: str, bus_type: type) -> list[tuple[str, str]]:
    """(ROS 2 topic, ROS type) names ros2_control's controllers would listen on, for a mexone
    command topic `<ns>/<ctrl>/command`: forward_command_controller's `commands`
    (std_msgs/Float64MultiArray, one value per joint) and joint_trajectory_controller's
    `joint_trajectory`. The ROS 1 name stays too."""
    if not topic.endswith("/command"):
        return []
    base = topic[: -len("command")]
    if bus_type in (msgs.Float64, msgs.Float64MultiArray):
        return [(base + "commands", "std_msgs/Float64MultiArray")]
    if bus_type is msgs.JointTrajectory:
        return [(base + "joint_trajectory", "trajectory_msgs/JointTrajectory")]
    return []
