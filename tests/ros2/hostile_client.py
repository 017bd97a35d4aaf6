"""A plain rclpy node, run as its own process by test_ros2_surfaces.py: none of mexone's code is
in it. It sends `mexone sim --ros2` what a hostile or careless ROS 2 user could (an empty
parameter name, 100 000 controller names, a NUL, a 100 000-character name) and prints one JSON
object of the answers and of /rosout's warnings. argv[1]: the simulator's node name."""

from __future__ import annotations

import json
import sys
import time

import rclpy
from rcl_interfaces.msg import Log, Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import QoSProfile
from waiting import Waiter

SIM = sys.argv[1] if len(sys.argv) > 1 else "mexone"
rclpy.init()
node = rclpy.create_node("hostile_client")
rosout: list[tuple[float, Log]] = []
node.create_subscription(Log, "/rosout", lambda m: rosout.append((time.monotonic(), m)),
                         QoSProfile(depth=1000))
out: dict[str, object] = {}


waiter = Waiter(node)  # tests/ros2/waiting.py
spin_until = waiter.spin_until


def call(client, request):
    return waiter.call(client, request, timeout=60.0)


def warnings_since(start: float) -> list[str]:
    spin_until(lambda: any(t >= start for t, _ in rosout), 3)
    return [m.msg for t, m in rosout if t >= start and m.level >= Log.WARN]


def double(value: float) -> ParameterValue:
    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)


set_params = node.create_client(SetParameters, f"/{SIM}/set_parameters")
for label, name in (("empty", ""), ("slash", "/"), ("nul", "physics.time\0step"),
                    ("long", "p" * 100_000)):
    start = time.monotonic()
    reply = call(set_params, SetParameters.Request(parameters=[Parameter(name=name,
                                                                         value=double(0.001))]))
    result = reply.results[0]
    out[f"param_{label}"] = [result.successful, result.reason, warnings_since(start)]

from controller_manager_msgs import srv as cm  # noqa: E402 - built by mexone.ros2.interfaces

switch_client = node.create_client(cm.SwitchController, "/controller_manager/switch_controller")
load_client = node.create_client(cm.LoadController, "/controller_manager/load_controller")
BEST_EFFORT = cm.SwitchController.Request.BEST_EFFORT
for label, names in (("many", [f"no_such_{i}" for i in range(100_000)]),
                     ("some", ["no_such_a", "nul\0name", "x" * 100_000])):
    start = time.monotonic()
    reply = call(switch_client, cm.SwitchController.Request(activate_controllers=names,
                                                            strictness=BEST_EFFORT))
    out[f"switch_{label}"] = [reply.ok, reply.message, warnings_since(start),
                              time.monotonic() - start]
for label, name in (("nul", "ctrl\0name"), ("long", "c" * 100_000)):
    start = time.monotonic()
    reply = call(load_client, cm.LoadController.Request(name=name))
    out[f"load_{label}"] = [reply.ok, warnings_since(start)]
print(json.dumps(out))
node.destroy_node()
rclpy.shutdown()
