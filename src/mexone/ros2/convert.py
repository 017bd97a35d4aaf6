"""mexone's bus messages <-> rclpy (rosidl) messages. Each bus message carries its ROS type's
field names, so one generic copy serves every type; the differences from ROS 1 are ROS 2's own:
no `seq` in headers, stamps as builtin_interfaces (sec, nanosec), byte arrays as array('B').
Which bus type maps to which ROS type is the shared table, `mexone.bus.ros_map`."""

from __future__ import annotations

import array
import dataclasses
import importlib
import logging
import math
from collections.abc import Callable
from typing import Any

from mexone.bus import msgs, ros_map
from mexone.errors import InputError

log = logging.getLogger("mexone.ros2")

__all__ = ["ros2_class", "to_ros2", "from_ros2", "message_class"]

_CLASSES: dict[str, type | None] = {}


def message_class(name: str):
    """The rclpy class of `pkg/Name` or `pkg/msg/Name`, None when its wheel is not installed."""
    package, *_, message = name.split("/")
    key = f"{package}/{message}"
    if key not in _CLASSES:
        try:
            module = importlib.import_module(f"{package}.msg")
            cls = getattr(module, message)
        except (ImportError, AttributeError):
            cls = None
        if cls is not None and not hasattr(type(cls), "__import_type_support__"):
            # ROS 1's package of that name (genpy) earlier on the path: `mexone ros-env` puts
            # mexone's own there, for --ros; rclpy cannot use it
            log.warning("%s on this Python's path is a ROS 1 package (%s), not ROS 2's: its "
                        "topics are left out (remove ROS 1's folders from PYTHONPATH for --ros2)",
                        package, getattr(module, "__file__", "?"))
            cls = None
        _CLASSES[key] = cls
    return _CLASSES[key]


def ros2_class(bus_type: type):
    return message_class(ros_map.ros_type(bus_type) or "")


# a plan per ROS class: (field, how, nested class) -- built once, so a message costs a loop
_PLANS: dict[type, list[tuple[str, str, Any]]] = {}


def _plan(cls) -> list[tuple[str, str, Any]]:
    plan = _PLANS.get(cls)
    if plan is None:
        plan = []
        for name, kind in cls.get_fields_and_field_types().items():
            inner = kind[len("sequence<"):-1] if kind.startswith("sequence<") else kind
            inner = inner.split("[", 1)[0]
            if inner == "builtin_interfaces/Time" or inner == "builtin_interfaces/Duration":
                plan.append((name, "stamp", message_class(inner)))
            elif "/" in inner:
                how = "list" if kind.startswith("sequence<") or kind.endswith("]") else "msg"
                plan.append((name, how, message_class(inner)))
            elif inner in ("uint8", "octet") and (kind.startswith("sequence<") or "[" in kind):
                plan.append((name, "bytes", None))
            elif kind.startswith("sequence<") or kind.endswith("]"):
                plan.append((name, "array", inner))
            else:
                plan.append((name, "plain", inner))
        _PLANS[cls] = plan
    return plan


def to_ros2(msg, cls):
    """A bus message as an instance of `cls` (its rclpy class), field by field."""
    out = cls()
    for name, how, inner in _plan(cls):
        value = getattr(msg, name, None)
        if value is None:
            continue  # a ROS 2 field the bus message lacks keeps its default
        if how == "stamp":
            value = inner(sec=int(value.secs), nanosec=int(value.nsecs))
        elif how == "msg":
            value = to_ros2(value, inner)
        elif how == "list":
            value = [to_ros2(v, inner) for v in value]
        elif how == "bytes":
            value = array.array("B", bytes(value))
        elif how == "array":
            # array('d') is what rosidl's C conversion copies in one go (a list goes item by item)
            value = array.array("d", value) if inner == "double" else list(value)
        setattr(out, name, value)
    return out


def _bus_from(ros, bus_type: type):
    """The reverse: a rclpy message into the bus dataclass whose fields are ROS's own."""
    default = bus_type()
    values = {}
    for f in dataclasses.fields(bus_type):
        if not hasattr(ros, f.name):
            continue  # seq: ROS 2 headers have none
        value, like = getattr(ros, f.name), getattr(default, f.name)
        if isinstance(like, msgs.Time | msgs.Duration):
            values[f.name] = type(like)(int(value.sec), int(value.nanosec))
        elif dataclasses.is_dataclass(like):
            values[f.name] = _bus_from(value, type(like))
        elif isinstance(like, list) and f.name == "points":
            values[f.name] = [_bus_from(p, msgs.JointTrajectoryPoint) for p in value]
        elif isinstance(like, list):
            values[f.name] = [_finite(v, f.name) if isinstance(v, float) else v for v in value]
        elif isinstance(like, float):
            values[f.name] = _finite(float(value), f.name)
        else:
            values[f.name] = type(like)(value)
    return bus_type(**values)


def _finite(value: float, field: str) -> float:
    if not math.isfinite(value):
        raise InputError(f"{field} is {value}: commands must be finite numbers")
    return value


def from_ros2(ros_msg, bus_type: type):
    """A command from the graph as the bus message the topic carries (finite numbers only)."""
    return _bus_from(ros_msg, bus_type)


def commands_to(bus_type: type) -> Callable[[Any], Any]:
    """ros2_control's `commands` (Float64MultiArray) as the bus topic's own type: a
    single-joint controller takes exactly one value."""
    if bus_type is msgs.Float64:
        def one(ros):
            if len(ros.data) != 1:
                raise InputError(f"{len(ros.data)} values for a one-joint controller: send "
                                 "exactly one")
            return msgs.Float64(_finite(float(ros.data[0]), "data"))
        return one
    return lambda ros: from_ros2(ros, bus_type)
