"""A plain rclpy node, run as its own process by test_ros2.py: none of mexone's code is in it.

It talks to `mexone sim --ros2` as any ROS 2 user's node would and prints one JSON object of
what it measured; the test asserts on those numbers. argv[1]: the simulator's node name.
"""

from __future__ import annotations

import json
import math
import sys
import time

import rclpy
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import Log, Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import Empty
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from waiting import Waiter

SIM = sys.argv[1] if len(sys.argv) > 1 else "mexone"
NS = "/mex_rb"
JOINT = "neck_yaw"
CONTROLLER = f"{NS}/{JOINT}_position_controller"
GAIN = f"{JOINT}_position_controller.gains.{JOINT}.p"

rclpy.init()
node = rclpy.create_node("acceptance_client")
seen: dict[str, list] = {"clock": [], "joint_states": [], "imu": [], "l": [], "r": [],
                         "description": [], "rosout": []}


def keep(key):
    return lambda msg: seen[key].append((time.monotonic(), msg))


node.create_subscription(Clock, "/clock", keep("clock"),
                         QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
node.create_subscription(JointState, f"{NS}/joint_states", keep("joint_states"), 50)
node.create_subscription(Imu, f"{NS}/imu", keep("imu"), qos_profile_sensor_data)
node.create_subscription(WrenchStamped, f"{NS}/l_ankle_ft", keep("l"), qos_profile_sensor_data)
node.create_subscription(WrenchStamped, f"{NS}/r_ankle_ft", keep("r"), qos_profile_sensor_data)
node.create_subscription(String, "/robot_description", keep("description"),
                         QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
node.create_subscription(Log, "/rosout", keep("rosout"), QoSProfile(depth=100))
try:  # built from its official definition by `python -m mexone.ros2.interfaces` (no wheel)
    from tf2_msgs.msg import TFMessage

    seen["tf"] = []
    node.create_subscription(TFMessage, "/tf", keep("tf"), 100)
except ImportError:
    TFMessage = None
try:  # the same, for the controllers' state topics
    from control_msgs.msg import JointControllerState

    seen["state"] = []
    node.create_subscription(JointControllerState, f"{CONTROLLER}/state", keep("state"), 10)
except ImportError:
    JointControllerState = None
try:  # the same, for ros2_control's controller manager services
    from controller_manager_msgs import srv as cm
except ImportError:
    cm = None
commands = node.create_publisher(Float64MultiArray, f"{CONTROLLER}/commands", 10)
command_ros1 = node.create_publisher(Float64, f"{NS}/waist_yaw_position_controller/command", 10)
trajectory = node.create_publisher(JointTrajectory, f"{NS}/r_arm_controller/joint_trajectory", 10)
set_params = node.create_client(SetParameters, f"/{SIM}/set_parameters")
get_params = node.create_client(GetParameters, f"/{SIM}/get_parameters")
reset = node.create_client(Empty, "/reset_simulation")
out: dict[str, object] = {}


waiter = Waiter(node)  # tests/ros2/waiting.py
spin_until, call = waiter.spin_until, waiter.call


def sim_time(clock_msg) -> float:
    return clock_msg.clock.sec + clock_msg.clock.nanosec * 1e-9


def position(name: str) -> float | None:
    if not seen["joint_states"]:
        return None
    msg = seen["joint_states"][-1][1]
    return msg.position[list(msg.name).index(name)] if name in msg.name else None


def rosout_since(start: float) -> list[str]:
    return [m.msg for t, m in seen["rosout"] if t >= start and m.level >= Log.WARN]


def set_gain(value) -> tuple[bool, str]:
    kind = {float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}[type(value)]
    v = ParameterValue(type=kind)
    if kind == ParameterType.PARAMETER_DOUBLE:
        v.double_value = value
    else:
        v.string_value = value
    result = call(set_params, SetParameters.Request(parameters=[Parameter(name=GAIN, value=v)]))
    return result.results[0].successful, result.results[0].reason


# 1. what flows: description, clock, joint states, IMU, ankle wrenches over 2 s of sim time
spin_until(lambda: seen["description"] and len(seen["clock"]) > 10 and seen["joint_states"]
           and seen["imu"] and seen["l"] and seen["r"], 60)
for key in ("clock", "joint_states", "imu", "l", "r"):
    seen[key].clear()
spin_until(lambda: seen["clock"] and sim_time(seen["clock"][-1][1]) - sim_time(seen["clock"][0][1])
           >= 2.0, 30)
span = sim_time(seen["clock"][-1][1]) - sim_time(seen["clock"][0][1])
stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in seen["joint_states"]]
out["description"] = seen["description"][0][1].data if seen["description"] else ""
out["clock_sim_span"] = span
out["clock_count"] = len(seen["clock"])
clock_times = [sim_time(m) for _, m in seen["clock"]]
gaps = [b - a for a, b in zip(clock_times, clock_times[1:], strict=False) if b > a]
out["clock_min_gap"] = min(gaps) if gaps else None  # 1 ms when it is sent at 1 kHz of sim time
out["joint_states_rate"] = (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 else 0
out["imu_z"] = sum(m.linear_acceleration.z for _, m in seen["imu"]) / max(1, len(seen["imu"]))
out["imu_xy"] = max(math.hypot(m.linear_acceleration.x, m.linear_acceleration.y)
                    for _, m in seen["imu"])
if TFMessage is not None:
    spin_until(lambda: seen["tf"], 10)
    tf = seen["tf"][-1][1].transforms[0] if seen["tf"] else None
    out["tf"] = tf and {"parent": tf.header.frame_id, "child": tf.child_frame_id,
                        "z": tf.transform.translation.z, "w": tf.transform.rotation.w}
out["ankle_fz"] = sum(sum(m.wrench.force.z for _, m in seen[s]) / len(seen[s]) for s in "lr")

# 2. commands: ros2_control's name (Float64MultiArray) and the ROS 1 one (Float64)
target, waist = 0.3, -0.2
spin_until(lambda: commands.get_subscription_count() and command_ros1.get_subscription_count(), 20)
commands.publish(Float64MultiArray(data=[target]))
command_ros1.publish(Float64(data=waist))
spin_until(lambda: abs((position(JOINT) or 0) - target) <= 0.01 * target
           and abs((position("waist_yaw") or 0) - waist) <= 0.01 * abs(waist), 20)
out["commanded"] = target
out["reached"] = position(JOINT)
out["waist_reached"] = position("waist_yaw")

# 2b. joint_trajectory_controller's topic: two joints to a point 0.5 s ahead
goal = {"r_shoulder_pitch": 0.25, "r_elbow": -0.6}
spin_until(lambda: trajectory.get_subscription_count(), 20)
point = JointTrajectoryPoint(positions=list(goal.values()))
point.time_from_start.nanosec = 500_000_000
trajectory.publish(JointTrajectory(joint_names=list(goal), points=[point]))
spin_until(lambda: all(abs((position(j) or 0) - v) <= 0.01 * abs(v) for j, v in goal.items()), 20)
out["trajectory_goal"] = goal
out["trajectory_reached"] = {j: position(j) for j in goal}

# 3. hostile input: NaN, wrong lengths; then the sim still runs and holds the last good command
start = time.monotonic()
commands.publish(Float64MultiArray(data=[float("nan")]))
commands.publish(Float64MultiArray(data=[0.1, 0.2]))
command_ros1.publish(Float64(data=float("inf")))
spin_until(lambda: len(rosout_since(start)) >= 3, 10)
out["bad_command_warnings"] = rosout_since(start)
clock_before = sim_time(seen["clock"][-1][1])
spin_until(lambda: sim_time(seen["clock"][-1][1]) > clock_before + 0.2, 10)
out["still_running"] = sim_time(seen["clock"][-1][1]) > clock_before + 0.2
out["held_after_bad"] = position(JOINT)

# 4. a gain as a parameter; then a wrong type and a NaN, refused with a warning
if JointControllerState is not None:  # its first message may come after discovery settles
    spin_until(lambda: bool(seen["state"]), 10)
out["state_p_before"] = seen["state"][-1][1].p if JointControllerState and seen["state"] else None
out["gain_set"] = set_gain(77.5)
if JointControllerState is not None:
    start = time.monotonic()
    spin_until(lambda: any(t > start for t, _ in seen["state"]), 10)
    out["state_p_after"] = seen["state"][-1][1].p
got = call(get_params, GetParameters.Request(names=[GAIN]))
out["gain_read"] = got.values[0].double_value
start = time.monotonic()
out["gain_wrong_type"] = set_gain("stiff")
out["gain_nan"] = set_gain(float("nan"))
spin_until(lambda: len(rosout_since(start)) >= 2, 10)
out["gain_warnings"] = rosout_since(start)
out["gain_after_refusals"] = call(get_params, GetParameters.Request(names=[GAIN])).values[0] \
    .double_value

# 5. ros2_control's controller manager services (controller_manager_msgs, built like tf2_msgs)
if cm is not None:
    cm_clients: dict = {}

    def cm_call(name, request):
        """/controller_manager/<name>; its type is the request's service (ListControllers, ...)."""
        kind = getattr(cm, type(request).__name__.removesuffix("_Request"))
        if name not in cm_clients:
            cm_clients[name] = node.create_client(kind, f"/controller_manager/{name}")
        return call(cm_clients[name], request)

    def controllers():
        reply = cm_call("list_controllers", cm.ListControllers.Request())
        return {c.name: {"state": c.state, "type": c.type, "claimed": list(c.claimed_interfaces),
                         "required": list(c.required_command_interfaces)}
                for c in reply.controller}

    def switch(activate=(), deactivate=(), strictness=cm.SwitchController.Request.STRICT):
        start = time.monotonic()
        reply = cm_call("switch_controller", cm.SwitchController.Request(
            activate_controllers=list(activate), deactivate_controllers=list(deactivate),
            strictness=strictness))
        if not reply.ok:
            spin_until(lambda: rosout_since(start), 10)
        return [reply.ok, reply.message, rosout_since(start)]

    def hold_for(seconds):
        begin = sim_time(seen["clock"][-1][1])
        spin_until(lambda: sim_time(seen["clock"][-1][1]) >= begin + seconds, 20)

    ctrl, alt = f"{JOINT}_position_controller", f"{JOINT}_effort_controller"
    out["cm_list"] = controllers()
    hw = cm_call("list_hardware_interfaces", cm.ListHardwareInterfaces.Request())
    out["cm_hw"] = {"command": [i.name for i in hw.command_interfaces],
                    "claimed": [i.name for i in hw.command_interfaces if i.is_claimed],
                    "state": [i.name for i in hw.state_interfaces]}
    out["cm_types"] = list(cm_call("list_controller_types", cm.ListControllerTypes.Request()).types)
    # refusals: unknown, a joint two controllers would claim, an active one to unload
    out["cm_unknown"] = switch(activate=["no_such_controller"])
    out["cm_conflict"] = switch(activate=[alt])
    start = time.monotonic()
    out["cm_unload_active"] = cm_call("unload_controller",
                                      cm.UnloadController.Request(name=ctrl)).ok
    out["cm_load_unknown"] = cm_call("load_controller",
                                     cm.LoadController.Request(name="no_such_controller")).ok
    spin_until(lambda: len(rosout_since(start)) >= 2, 10)
    out["cm_refusal_warnings"] = rosout_since(start)
    out["cm_best_effort_again"] = switch(activate=[ctrl],
                                         strictness=cm.SwitchController.Request.BEST_EFFORT)[0]
    # deactivate: a command then does nothing; activate again: it reaches its target
    held = position(JOINT)
    out["cm_deactivate"] = switch(deactivate=[ctrl])
    out["cm_after_deactivate"] = controllers()[ctrl]
    commands.publish(Float64MultiArray(data=[0.0]))
    hold_for(0.5)
    out["cm_held"], out["cm_while_inactive"] = held, position(JOINT)
    out["cm_activate"] = switch(activate=[ctrl])
    out["cm_after_activate"] = controllers()[ctrl]
    commands.publish(Float64MultiArray(data=[0.1]))
    spin_until(lambda: abs((position(JOINT) or 0) - 0.1) <= 0.001, 20)
    out["cm_reached_after_activate"] = position(JOINT)
    # unload, load and configure the inactive alternative
    out["cm_unload"] = cm_call("unload_controller", cm.UnloadController.Request(name=alt)).ok
    out["cm_unloaded_listed"] = alt in controllers()
    out["cm_load"] = cm_call("load_controller", cm.LoadController.Request(name=alt)).ok
    out["cm_configure"] = cm_call("configure_controller",
                                  cm.ConfigureController.Request(name=alt)).ok
    out["cm_loaded_state"] = controllers().get(alt, {}).get("state")

# 6. reset: /clock starts again from 0
before = sim_time(seen["clock"][-1][1])
start = time.monotonic()
call(reset, Empty.Request())
spin_until(lambda: any(t >= start and sim_time(m) < before for t, m in seen["clock"]), 10)
after = [sim_time(m) for t, m in seen["clock"] if t >= start]
out["clock_before_reset"] = before
out["clock_after_reset"] = min(after) if after else None
print(json.dumps(out))
node.destroy_node()
rclpy.shutdown()
