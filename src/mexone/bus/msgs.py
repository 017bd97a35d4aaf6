"""Message dataclasses with the field names of their ROS counterparts, so routines port by
changing imports. Times are rospy-like Time/Duration values in sim time."""

from __future__ import annotations

from dataclasses import dataclass, field

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
    "ROS_TYPES",
]


@dataclass(frozen=True, order=True)
class _Stamp:
    """Seconds and nanoseconds, as ROS keeps time."""

    secs: int = 0
    nsecs: int = 0

    @classmethod
    def from_sec(cls, seconds: float):
        secs, nsecs = divmod(round(seconds * 1e9), 1_000_000_000)  # round first: 1.9999999999 -> 2
        return cls(int(secs), int(nsecs))

    @classmethod
    def from_nsec(cls, nanoseconds: int):
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

    def __sub__(self, other):
        if isinstance(other, Time):
            return Duration.from_sec(self.to_sec() - other.to_sec())
        return Time.from_sec(self.to_sec() - other.to_sec())


@dataclass
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


# class -> ROS type name (for topic listings, the ROS bridge and bag files)
ROS_TYPES: dict[type, str] = {
    Float64: "std_msgs/Float64",
    Float64MultiArray: "std_msgs/Float64MultiArray",
    JointState: "sensor_msgs/JointState",
    Clock: "rosgraph_msgs/Clock",
    JointTrajectory: "trajectory_msgs/JointTrajectory",
    TFMessage: "tf2_msgs/TFMessage",
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
