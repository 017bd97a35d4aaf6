"""Message dataclasses with the field names of their ROS counterparts, so routines port by
changing imports. Times are rospy-like Time/Duration values in sim time."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Self, overload

__all__ = [
    "Time",
    "Duration",
    "Header",
    "Float64",
    "Float64MultiArray",
    "JointState",
    "Clock",
    "JointTrajectoryPoint",
    "JointTrajectory",
    "TransformStamped",
    "TFMessage",
    "Vector3",
    "Point",
    "Point32",
    "Quaternion",
    "Wrench",
    "WrenchStamped",
    "Imu",
    "ContactState",
    "ContactsState",
    "RegionOfInterest",
    "Image",
    "CameraInfo",
    "PointField",
    "PointCloud2",
    "PointStamped",
    "Polygon",
    "PolygonStamped",
    "Twist",
    "Pose",
    "PoseStamped",
    "PoseArray",
    "Path",
    "ROS_TYPES",
]


@dataclass(frozen=True, order=True)
class _Stamp:
    """Seconds and nanoseconds, as ROS keeps time."""

    secs: int = 0
    nsecs: int = 0

    @classmethod
    def from_sec(cls, seconds: float) -> Self:
        secs, nsecs = divmod(round(seconds * 1e9), 1_000_000_000)  # round first: 1.9999999999 -> 2
        return cls(int(secs), int(nsecs))

    @classmethod
    def from_nsec(cls, nanoseconds: int) -> Self:
        secs, nsecs = divmod(int(nanoseconds), 1_000_000_000)
        return cls(secs, nsecs)

    def to_sec(self) -> float:
        return self.secs + self.nsecs * 1e-9

    def to_nsec(self) -> int:
        return self.secs * 1_000_000_000 + self.nsecs


@dataclass(frozen=True, order=True)
class Duration(_Stamp):
    pass


@dataclass(frozen=True, order=True)
class Time(_Stamp):
    def __add__(self, other: Duration) -> Time:
        return Time.from_sec(self.to_sec() + other.to_sec())

    @overload
    def __sub__(self, other: Time) -> Duration: ...
    @overload
    def __sub__(self, other: Duration) -> Time: ...

    def __sub__(self, other: Time | Duration) -> Time | Duration:
        if isinstance(other, Time):
            return Duration.from_sec(self.to_sec() - other.to_sec())
        return Time.from_sec(self.to_sec() - other.to_sec())


@dataclass(slots=True)
class Header:
    seq: int = 0
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Float64:
    data: float = 0.0


@dataclass
class Float64MultiArray:
    data: list[float] = field(default_factory=list)


@dataclass
class JointState:
    header: Header = field(default_factory=Header)
    name: list[str] = field(default_factory=list)
    position: list[float] = field(default_factory=list)
    velocity: list[float] = field(default_factory=list)
    effort: list[float] = field(default_factory=list)


@dataclass
class Clock:
    clock: Time = field(default_factory=Time)


@dataclass
class JointTrajectoryPoint:
    positions: list[float] = field(default_factory=list)
    velocities: list[float] = field(default_factory=list)
    accelerations: list[float] = field(default_factory=list)
    effort: list[float] = field(default_factory=list)
    time_from_start: Duration = field(default_factory=Duration)


@dataclass
class JointTrajectory:
    header: Header = field(default_factory=Header)
    joint_names: list[str] = field(default_factory=list)
    points: list[JointTrajectoryPoint] = field(default_factory=list)


@dataclass
class TransformStamped:
    header: Header = field(default_factory=Header)  # frame_id: the parent frame
    child_frame_id: str = ""
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # w, x, y, z


@dataclass
class TFMessage:
    transforms: list[TransformStamped] = field(default_factory=list)


# ----- geometry and sensors (sensor_msgs, geometry_msgs, gazebo_msgs) ------------------------------
@dataclass(slots=True)
class Vector3:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Point:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Point32:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass(slots=True)
class Quaternion:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


@dataclass(slots=True)
class Wrench:
    force: Vector3 = field(default_factory=Vector3)
    torque: Vector3 = field(default_factory=Vector3)


@dataclass(slots=True)
class WrenchStamped:
    header: Header = field(default_factory=Header)
    wrench: Wrench = field(default_factory=Wrench)


@dataclass(slots=True)
class Imu:
    header: Header = field(default_factory=Header)
    orientation: Quaternion = field(default_factory=Quaternion)
    orientation_covariance: list[float] = field(default_factory=lambda: [0.0] * 9)
    angular_velocity: Vector3 = field(default_factory=Vector3)
    angular_velocity_covariance: list[float] = field(default_factory=lambda: [0.0] * 9)
    linear_acceleration: Vector3 = field(default_factory=Vector3)
    linear_acceleration_covariance: list[float] = field(default_factory=lambda: [0.0] * 9)


@dataclass(slots=True)
class ContactState:
    info: str = ""
    collision1_name: str = ""
    collision2_name: str = ""
    wrenches: list[Wrench] = field(default_factory=list)
    total_wrench: Wrench = field(default_factory=Wrench)
    contact_positions: list[Vector3] = field(default_factory=list)
    contact_normals: list[Vector3] = field(default_factory=list)
    depths: list[float] = field(default_factory=list)


@dataclass(slots=True)
class ContactsState:
    header: Header = field(default_factory=Header)
    states: list[ContactState] = field(default_factory=list)


@dataclass
class RegionOfInterest:
    x_offset: int = 0
    y_offset: int = 0
    height: int = 0
    width: int = 0
    do_rectify: bool = False


@dataclass
class Image:
    header: Header = field(default_factory=Header)
    height: int = 0
    width: int = 0
    encoding: str = ""
    is_bigendian: int = 0
    step: int = 0
    data: bytes = b""


@dataclass
class CameraInfo:
    header: Header = field(default_factory=Header)
    height: int = 0
    width: int = 0
    distortion_model: str = "plumb_bob"
    D: list[float] = field(default_factory=lambda: [0.0] * 5)  # noqa: N815 - ROS field names
    K: list[float] = field(default_factory=lambda: [0.0] * 9)  # noqa: N815
    R: list[float] = field(default_factory=lambda: [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0])  # noqa: N815
    P: list[float] = field(default_factory=lambda: [0.0] * 12)  # noqa: N815
    binning_x: int = 0
    binning_y: int = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


@dataclass
class PointField:
    INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = 1, 2, 3, 4, 5, 6, 7, 8
    name: str = ""
    offset: int = 0
    datatype: int = 7
    count: int = 1


@dataclass
class PointCloud2:
    header: Header = field(default_factory=Header)
    height: int = 0
    width: int = 0
    fields: list[PointField] = field(default_factory=list)
    is_bigendian: bool = False
    point_step: int = 0
    row_step: int = 0
    data: bytes = b""
    is_dense: bool = False


@dataclass
class PointStamped:
    header: Header = field(default_factory=Header)
    point: Point = field(default_factory=Point)


@dataclass
class Polygon:
    points: list[Point32] = field(default_factory=list)


@dataclass
class PolygonStamped:
    header: Header = field(default_factory=Header)
    polygon: Polygon = field(default_factory=Polygon)


@dataclass
class Twist:
    """A velocity: linear m/s and angular rad/s (cmd_vel: x forward, y left, z turn left)."""

    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class Pose:
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseStamped:
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass
class PoseArray:
    """geometry_msgs/PoseArray: poses in one frame (a walk's footsteps)."""

    header: Header = field(default_factory=Header)
    poses: list[Pose] = field(default_factory=list)


@dataclass
class Path:
    """nav_msgs/Path: a path as stamped poses (a walk's planned ZMP and COM), as rviz draws it."""

    header: Header = field(default_factory=Header)
    poses: list[PoseStamped] = field(default_factory=list)


# class -> ROS type name (for topic listings, the ROS bridge and bag files)
#: each message class -> its ROS type name ("sensor_msgs/JointState")
ROS_TYPES: dict[type, str] = {
    Float64: "std_msgs/Float64",
    Float64MultiArray: "std_msgs/Float64MultiArray",
    JointState: "sensor_msgs/JointState",
    Clock: "rosgraph_msgs/Clock",
    JointTrajectory: "trajectory_msgs/JointTrajectory",
    TFMessage: "tf2_msgs/TFMessage",
    Imu: "sensor_msgs/Imu",
    WrenchStamped: "geometry_msgs/WrenchStamped",
    ContactsState: "gazebo_msgs/ContactsState",
    Image: "sensor_msgs/Image",
    CameraInfo: "sensor_msgs/CameraInfo",
    PointCloud2: "sensor_msgs/PointCloud2",
    PointStamped: "geometry_msgs/PointStamped",
    PolygonStamped: "geometry_msgs/PolygonStamped",
    Twist: "geometry_msgs/Twist",
    PoseStamped: "geometry_msgs/PoseStamped",
    PoseArray: "geometry_msgs/PoseArray",
    Path: "nav_msgs/Path",
}


# ----- controller state (ros_controllers' `state` topics) ------------------------------------
@dataclass
class JointControllerState:
    """control_msgs/JointControllerState: what a single-joint controller aims at and gets."""

    header: Header = field(default_factory=Header)
    set_point: float = 0.0
    process_value: float = 0.0
    process_value_dot: float = 0.0
    error: float = 0.0
    time_step: float = 0.0
    command: float = 0.0
    p: float = 0.0
    i: float = 0.0
    d: float = 0.0
    i_clamp: float = 0.0
    antiwindup: bool = False


__all__.append("JointControllerState")
ROS_TYPES[JointControllerState] = "control_msgs/JointControllerState"
