"""`mexone sim --ros2` against a real rclpy node in its own process (client.py, none of mexone's
code in it), on PyPI's ROS 2 wheels.

The wheels install `std_msgs`, `sensor_msgs`, ... under ROS 1's Python names, so they live in an
environment of their own (scripts/test.sh makes `.venv-ros2`, MEXONE_ROS2_PYTHON names its
python); this process only starts the two. DDS traffic stays on this machine
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) in a domain of this test run's own (from its pid), so
parallel runs and other tests do not see each other.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import run_cli
from mexone.bus import msgs, ros_map
from mexone.robots.mex_one import params

HERE = Path(__file__).parent
SRC = HERE.parents[1] / "src"
G = 9.81
WHEELLESS = {"tf2_msgs", "control_msgs", "gazebo_msgs"}  # no ROS 2 wheel on PyPI (docs/ros2.md)


def ros2_python() -> str | None:
    """A Python with rclpy: MEXONE_ROS2_PYTHON, else this one if it has rclpy."""
    candidate = os.environ.get("MEXONE_ROS2_PYTHON") or sys.executable
    if shutil.which(candidate) is None and not Path(candidate).exists():
        return None
    ok = subprocess.run([candidate, "-c", "import rclpy, std_srvs.srv"], capture_output=True,
                        timeout=60).returncode == 0
    return candidate if ok else None


def ros2_env() -> dict[str, str]:
    # not ROS 1's (the session's ros_master fixture exports `mexone ros-env`'s: its genpy
    # control_msgs on PYTHONPATH would shadow the ROS 2 one)
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_") and k != "PYTHONPATH"}
    env.update({"ROS_DOMAIN_ID": str(1 + os.getpid() % 100),  # 1..100: this run's own
                "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1",
                "PYTHONPATH": os.pathsep.join([str(SRC), env.get("PYTHONPATH", "")]).rstrip(":")})
    return env


@pytest.fixture(scope="module")
def python():
    found = ros2_python()
    if found is None:
        pytest.skip("no Python with the ROS 2 wheels: pip install '.[ros2]' into a venv and "
                    "set MEXONE_ROS2_PYTHON (scripts/test.sh does)")
    return found


def controllers_with_a_trajectory_controller(folder: Path) -> Path:
    """Mex-One's controllers with the right arm under one joint_trajectory_controller, and an
    alternative for the neck's yaw (loaded inactive: the position controller claims the joint)."""
    import yaml

    from mexone.robots import mex_one

    config = yaml.safe_load(mex_one.controllers_path().read_text())
    ns = config["mex_rb"]
    gains = {}
    for joint in ("r_shoulder_pitch", "r_elbow"):
        gains[joint] = {k: ns[f"{joint}_position_controller"]["pid"][k] for k in ("p", "i", "d")}
        del ns[f"{joint}_position_controller"]
    ns["r_arm_controller"] = {"type": "effort_controllers/JointTrajectoryController",
                              "joints": list(gains), "gains": gains}
    ns["neck_yaw_effort_controller"] = {"type": "effort_controllers/JointEffortController",
                                        "joint": "neck_yaw"}
    path = folder / "controllers.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))  # the YAML order: which starts
    return path


@pytest.fixture(scope="module")
def acceptance(python, tmp_path_factory):
    """Run the simulator and the client once; every test below reads what the client saw."""
    controllers = controllers_with_a_trajectory_controller(tmp_path_factory.mktemp("ros2"))
    return sim_and_client(python, ros2_env(), "client.py", 180, "--controllers", str(controllers))


def sim_and_client(python, env: dict, client: str, timeout: float, *sim_args: str) -> dict:
    """`mexone sim --ros2 --headless SIM_ARGS` while the rclpy script `client` runs against it:
    the client's last line (JSON) with the simulator's stderr and exit status."""
    sim = subprocess.Popen([python, "-m", "mexone", "sim", "--ros2", "--headless", *sim_args],
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        done = subprocess.run([python, str(HERE / client), "mexone"], env=env,
                              capture_output=True, text=True, timeout=timeout)
    finally:
        sim.terminate()
        _, sim_err = sim.communicate(timeout=30)
    assert done.returncode == 0, done.stderr[-3000:] + sim_err[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1]) | {"sim_stderr": sim_err,
                                                                 "sim_status": sim.returncode}


def test_clock_joint_states_and_description_flow(acceptance):
    assert acceptance["description"].lstrip().startswith(("<?xml", "<robot"))
    assert 'name="mex_rb"' in acceptance["description"]
    assert acceptance["clock_sim_span"] >= 2.0
    # 1 kHz of sim time sent (gazebo_ros' rate): two consecutive ones arrive 1 ms of sim time
    # apart. Best-effort, depth 1 drops what a busy reader misses, so how many this client
    # takes depends on its machine's load: only a floor no loaded machine misses is asserted
    assert acceptance["clock_min_gap"] == pytest.approx(0.001, abs=1e-6)
    assert acceptance["clock_count"] / acceptance["clock_sim_span"] >= 50
    assert acceptance["joint_states_rate"] == pytest.approx(params.JOINT_STATE_RATE, rel=0.02)


def test_tf_has_world_to_base(acceptance):
    """/tf needs tf2_msgs, which has no wheel: built by `python -m mexone.ros2.interfaces`
    (scripts/test.sh does) from its official definition."""
    assert acceptance.get("tf"), "tf2_msgs is not built in the ROS 2 environment"
    tf = acceptance["tf"]
    assert (tf["parent"], tf["child"]) == ("world", "pelvis")  # the URDF root link
    assert 0.3 < tf["z"] < 1.0 and tf["w"] == pytest.approx(1.0, abs=0.01)  # standing upright


def test_imu_reads_plus_g_and_ankles_carry_the_weight_above_them(acceptance):
    assert acceptance["imu_z"] == pytest.approx(G, rel=0.01)
    assert acceptance["imu_xy"] < 0.05 * G
    feet = sum(p.mass for p in params.parts() if p.name.endswith("_foot"))
    robot = sum(p.mass for p in params.parts())
    assert acceptance["ankle_fz"] == pytest.approx((robot - feet) * G, rel=0.02)


def test_commands_reach_the_joints_within_one_percent(acceptance):
    """ros2_control's `<ctrl>/commands` (Float64MultiArray) and the ROS 1 `command`."""
    target = acceptance["commanded"]
    assert acceptance["reached"] == pytest.approx(target, rel=0.01)
    assert acceptance["waist_reached"] == pytest.approx(-0.2, rel=0.01)


def test_joint_trajectory_reaches_its_point(acceptance):
    """joint_trajectory_controller's `joint_trajectory` topic (trajectory_msgs/JointTrajectory)."""
    for joint, goal in acceptance["trajectory_goal"].items():
        assert acceptance["trajectory_reached"][joint] == pytest.approx(goal, rel=0.01)


def test_bad_commands_are_refused_on_rosout_and_the_sim_goes_on(acceptance):
    warnings = " | ".join(acceptance["bad_command_warnings"])
    assert "data is nan" in warnings and "data is inf" in warnings
    assert "2 values for a one-joint controller" in warnings
    assert acceptance["still_running"]
    assert acceptance["held_after_bad"] == pytest.approx(acceptance["commanded"], rel=0.01)
    assert "Traceback" not in acceptance["sim_stderr"]


def test_gain_parameter_sets_and_bad_values_are_refused(acceptance):
    assert acceptance["gain_set"] == [True, ""]
    assert acceptance["gain_read"] == 77.5
    # the controller's own state topic (control_msgs, built like tf2_msgs) shows the new gain
    assert acceptance["state_p_before"] == 15.0 and acceptance["state_p_after"] == 77.5
    ok, reason = acceptance["gain_wrong_type"]
    assert not ok and "must be a double" in reason
    ok, reason = acceptance["gain_nan"]
    assert not ok and "must be finite" in reason
    assert len(acceptance["gain_warnings"]) == 2
    assert acceptance["gain_after_refusals"] == 77.5  # a refused set changes nothing


def test_controller_manager_lists_controllers_and_interfaces(acceptance):
    """ros2_control's /controller_manager/list_controllers and list_hardware_interfaces
    (controller_manager_msgs, built from its official definitions like tf2_msgs)."""
    assert "cm_list" in acceptance, "controller_manager_msgs is not built in the ROS 2 environment"
    listed = acceptance["cm_list"]
    neck = listed["neck_yaw_position_controller"]
    assert neck == {"state": "active", "type": "effort_controllers/JointPositionController",
                    "claimed": ["neck_yaw/effort"], "required": ["neck_yaw/effort"]}
    assert listed["neck_yaw_effort_controller"]["state"] == "inactive"
    assert listed["neck_yaw_effort_controller"]["claimed"] == []
    assert listed["r_arm_controller"]["claimed"] == ["r_shoulder_pitch/effort", "r_elbow/effort"]
    assert listed["joint_state_controller"] == {
        "state": "active", "type": "joint_state_controller/JointStateController", "claimed": [],
        "required": []}
    joints = {h.name for h in params.hinges()}  # Mex-One's, every one with a transmission
    assert set(acceptance["cm_hw"]["command"]) == {f"{j}/{i}" for j in joints
                                                   for i in ("position", "velocity", "effort")}
    claimed = {c for entry in listed.values() if entry["state"] == "active"
               for c in entry["claimed"]}
    assert set(acceptance["cm_hw"]["claimed"]) == claimed and "neck_yaw/effort" in claimed
    assert "effort_controllers/JointTrajectoryController" in acceptance["cm_types"]


def test_controller_manager_refuses_bad_requests_on_rosout(acceptance):
    ok, message, warnings = acceptance["cm_unknown"]
    assert not ok and "no_such_controller" in message and any("no_such_controller" in w
                                                               for w in warnings)
    ok, message, warnings = acceptance["cm_conflict"]
    assert not ok and "driven by 'neck_yaw_position_controller'" in message
    assert any("switch_controller" in w and "neck_yaw" in w for w in warnings)
    assert acceptance["cm_unload_active"] is False and acceptance["cm_load_unknown"] is False
    assert any("it is running" in w for w in acceptance["cm_refusal_warnings"])
    assert acceptance["cm_best_effort_again"] is True  # already active: fine under BEST_EFFORT
    assert acceptance["still_running"] and "Traceback" not in acceptance["sim_stderr"]


def test_switch_controller_deactivates_and_restores(acceptance):
    ok, message, _ = acceptance["cm_deactivate"]
    assert ok and "deactivated neck_yaw_position_controller" in message
    assert acceptance["cm_after_deactivate"]["state"] == "inactive"
    assert acceptance["cm_after_deactivate"]["claimed"] == []
    # a command to an inactive controller does nothing: the neck stays where it was, not at 0
    assert acceptance["cm_while_inactive"] == pytest.approx(acceptance["cm_held"], abs=0.02)
    assert abs(acceptance["cm_while_inactive"]) > 0.2
    assert acceptance["cm_activate"][0] is True
    assert acceptance["cm_after_activate"] == {**acceptance["cm_list"][
        "neck_yaw_position_controller"]}
    assert acceptance["cm_reached_after_activate"] == pytest.approx(0.1, abs=0.001)


def test_controller_manager_unload_load_configure(acceptance):
    assert acceptance["cm_unload"] is True and acceptance["cm_unloaded_listed"] is False
    assert acceptance["cm_load"] is True and acceptance["cm_configure"] is True
    assert acceptance["cm_loaded_state"] == "inactive"


def test_reset_restarts_clock_at_zero(acceptance):
    assert acceptance["clock_before_reset"] > 1.0
    assert acceptance["clock_after_reset"] == pytest.approx(0.0, abs=0.05)


def test_sim_stops_cleanly(acceptance):
    assert acceptance["sim_status"] in (0, 143, -15)


def _left_out(stderr: str) -> str:
    """The start-up line naming what has no message package (docs/ros2.md), or ""."""
    return next((line for line in stderr.splitlines() if "not on ROS 2" in line), "")


def test_what_the_built_packages_carry_is_not_said_missing(acceptance):
    """With tf2_msgs, control_msgs and controller_manager_msgs built (scripts/test.sh builds
    them), the start-up line names only gazebo_msgs' contacts, which no build adds."""
    line = _left_out(acceptance["sim_stderr"])
    assert "(gazebo_msgs)" in line and "contact" in line
    assert not any(p in line for p in ("tf2_msgs", "control_msgs", "interfaces"))


def test_missing_message_packages_are_named_at_start_up(python, tmp_path):
    """As right after `pip install ".[ros2]"` (the built packages hidden, nothing deleted): one
    line at start-up names each package, what it would carry, and the build; was: nothing,
    and /tf silently absent."""
    import docblocks
    from mexone.ros2 import interfaces

    env = ros2_env()
    env["PYTHONPATH"] = f"{docblocks.hide_modules(tmp_path, interfaces.PACKAGES)}:{env['PYTHONPATH']}"
    done = subprocess.run([python, "-m", "mexone", "sim", "--ros2", "--headless", "--duration",
                           "0.2"], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    line = _left_out(done.stderr)
    assert line.startswith("mexone: not on ROS 2 (their message packages have no wheel on PyPI)")
    for carries, package in (("/tf", "tf2_msgs"), ("_position_controller/state", "control_msgs"),
                             ("/controller_manager/", "controller_manager_msgs"),
                             ("_contact", "gazebo_msgs")):
        assert carries in line and f"({package})" in line, (package, line)
    assert line.endswith("python -m mexone.ros2.interfaces (the ros2-build extra) builds "
                         "tf2_msgs, control_msgs, controller_manager_msgs (docs/ros2.md)")
    assert done.stderr.count("not on ROS 2") == 1  # one line, not one per package


def test_ros1_and_ros2_together_are_refused_in_one_line():
    code, out, err = run_cli(["sim", "--ros", "--ros2", "--headless", "--duration", "0.01"])
    assert code == 2 and err.count("\n") == 1 and "--ros and --ros2" in err


def test_ros1_refuses_ros2s_messages_in_one_line(python):
    """In an environment with the ROS 2 wheels, --ros says why it cannot work (same names)."""
    done = subprocess.run([python, "-m", "mexone", "sim", "--ros", "--headless"], env=ros2_env(),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert "ROS 2's message packages" in done.stderr and done.stderr.count("\n") == 1


def test_one_table_serves_both_bridges():
    """The ROS 1 converters take exactly the shared table's command types; every bus type with a
    ROS name has a ROS 2 class unless its package has no wheel (then documented)."""
    from mexone.ros1 import convert

    assert set(convert.FROM_ROS) == set(ros_map.COMMAND_TYPES)
    assert {ros_map.package_of(t) for t in msgs.ROS_TYPES} - WHEELLESS <= {
        "std_msgs", "sensor_msgs", "geometry_msgs", "trajectory_msgs", "nav_msgs", "rosgraph_msgs"}
    docs = (HERE.parents[1] / "docs" / "ros2.md").read_text()
    for package in WHEELLESS:
        assert package in docs
    assert ros_map.ros2_control_aliases("/ns/c/command", msgs.Float64) == [
        ("/ns/c/commands", "std_msgs/Float64MultiArray")]
    assert ros_map.ros2_control_aliases("/ns/c/command", msgs.JointTrajectory) == [
        ("/ns/c/joint_trajectory", "trajectory_msgs/JointTrajectory")]


def test_building_messages_without_tools_is_one_line(monkeypatch, tmp_path):
    from mexone.errors import MexoneError
    from mexone.ros2 import interfaces

    monkeypatch.setenv("PATH", str(tmp_path))  # no cmake, no compiler
    with pytest.raises(MexoneError) as caught:
        interfaces.build(tmp_path, log=lambda _line: None)
    assert "needs 'cmake'" in caught.value.one_line() and "ros2-build" in caught.value.one_line()
    assert (interfaces.SHARE / "tf2_msgs" / "msg" / "TFMessage.msg").read_text().strip() == \
        "geometry_msgs/TransformStamped[] transforms"  # the official definition, field for field


def test_hand_built_cdr_is_what_rclpy_serializes(python):
    """The bridge sends joint states and /clock as CDR bytes it builds itself (cdr.py, for speed):
    byte for byte rclpy's own serialization (rosidl's type support), for generated messages."""
    done = subprocess.run([python, str(HERE / "cdr_check.py")], env=ros2_env(),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["mismatch"] is None, report["mismatch"]
    assert report["joint_states"] >= 300 and report["clocks"] >= 100


# ----- hostile requests (issue 36): hostile_client.py, a plain rclpy node ----------------------------
@pytest.fixture(scope="module")
def hostile(python):
    """The simulator and hostile_client.py once; the tests below read its answers."""
    env = ros2_env()
    env["ROS_DOMAIN_ID"] = str(101 + os.getpid() % 100)  # apart from the acceptance run's
    return sim_and_client(python, env, "hostile_client.py", 240)


def test_a_parameter_without_a_name_is_refused(hostile):
    ok, reason, warnings = hostile["param_empty"]
    assert not ok and "parameter name '' is not a parameter's name" in reason  # was a success
    assert any("parameter refused" in w for w in warnings)
    for case in ("param_slash", "param_nul", "param_long"):
        ok, reason, _ = hostile[case]
        assert not ok and len(reason) < 1000, (case, reason[:200])


def test_switch_controller_is_bounded_and_says_what_it_skipped(hostile):
    ok, message, warnings, seconds = hostile["switch_many"]
    assert not ok and "100000" in message and "at most 1000" in message, message[:300]
    assert len(message) < 1000 and seconds < 10  # was ok, a 1.5 MB message, 3.4 s
    ok, message, warnings, _ = hostile["switch_some"]
    assert not ok and "nothing to switch" in message and len(message) < 1000, message[:300]
    assert "nul\\x00name" in message or "nul" in message  # escaped, or cut at the NUL by rcl
    assert "xxxxxxxxxx..." in message and "(100000 characters)" in message  # not 100 000 x


def test_echoed_names_are_printable_and_bounded(hostile):
    for case in ("load_nul", "load_long"):
        ok, warnings = hostile[case]
        assert not ok and warnings and all(len(w) < 1500 for w in warnings), (case, warnings)
        assert all(w.isprintable() for w in warnings)
    assert len(hostile["sim_stderr"]) < 20_000 and "Traceback" not in hostile["sim_stderr"]


def test_a_huge_or_nul_controller_type_is_not_echoed_raw(tmp_path):
    import yaml

    from mexone.robots import mex_one

    config = yaml.safe_load(mex_one.controllers_path().read_text())
    for name, kind in (("long", "x" * 100_000), ("nul", "my\0type/Cls")):
        config["mex_rb"]["weird"] = {"type": kind, "joints": ["neck_yaw"]}
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(config))
        code, _, err = run_cli(["sim", "--headless", "--duration", "0.01", "--controllers", path])
        assert code == 2 and err.count("\n") == 1 and len(err) < 2000, err[:300]
        assert err.isprintable() or err[:-1].isprintable()
