"""Controllers without hand-written transmissions: `--controllers auto`, `mexone controllers`,
initial joint positions (-J, --pose), and what a robot without controllers says."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from helpers import run_cli
from mexone.control.autotune import STEP_BANDWIDTH, controllers_yaml, tune
from mexone.control.config import load_control_config
from mexone.description.loader import load_model
from mexone.lab import Lab
from mexone.physics import Spawn

CROUCH = {"l_hip_pitch": -0.3, "l_knee": 0.6, "l_ankle_pitch": -0.3,
          "r_hip_pitch": -0.3, "r_knee": 0.6, "r_ankle_pitch": -0.3,
          "l_elbow": -0.5, "r_elbow": -0.5}
J_CROUCH = [arg for name, value in CROUCH.items() for arg in ("-J", name, str(value))]


def mexone(*args, cwd: Path, env=None) -> subprocess.CompletedProcess:
    """`mexone ARGS` in-process (one import of the verbs, not a Python start-up per call)."""
    code, stdout, stderr = run_cli(list(args), cwd=cwd, env=env)
    assert "Traceback" not in stderr, stderr
    return subprocess.CompletedProcess(args, code, stdout, stderr)


def test_the_fixture_is_a_real_humanoid(humanoid):
    robot = load_model(humanoid)
    assert len(robot.moving_joints) >= 20 and robot.mass >= 30
    assert not robot.transmissions


def test_auto_gains_hold_a_humanoid_crouching_for_10_s(humanoid):
    lab = Lab.create(humanoid, "auto", spawn=Spawn(joints=tuple(CROUCH.items())))
    sim = lab.sim
    start = sim.joint_positions()
    for name, value in CROUCH.items():  # the pose is there from t = 0, not reached later
        assert start[sim.joint_names.index(name)] == pytest.approx(value)
    height = sim.base_height
    sim.run(10.0)
    error = np.abs(sim.joint_positions() - start)
    assert error.max() < 0.02, sim.joint_names[int(error.argmax())]
    assert sim.base_height == pytest.approx(height, abs=0.02)  # standing, not lying


def test_without_controllers_the_same_humanoid_collapses(humanoid):
    """The standing test above can fail: unpowered, the crouch folds within a second."""
    lab = Lab.create(humanoid, False, spawn=Spawn(joints=tuple(CROUCH.items())))
    height = lab.sim.base_height
    lab.sim.run(1.0)
    assert lab.sim.base_height < height - 0.1


def test_gains_follow_the_physics(humanoid):
    robot = load_model(humanoid)
    gains = {t.joint: t for t in tune(robot, 0.001)}
    knee, wrist, hip_yaw = gains["l_knee"], gains["l_wrist"], gains["l_hip_yaw"]
    # a leg joint lifts the body above it; a wrist turns only the hand
    assert knee.inertia > 10 and wrist.inertia < 0.01
    assert "above it" in knee.moves and "beyond it" in wrist.moves
    for t in gains.values():  # critically damped: d^2 = 4 I p
        assert t.gains.d ** 2 == pytest.approx(4 * t.inertia * t.gains.p, rel=2e-3)
        assert t.omega <= STEP_BANDWIDTH / 0.001 + 1e-9
    # the hand's bandwidth is the time step's, the knee's the effort limit's (0.1 rad saturates)
    assert wrist.omega == pytest.approx(100.0)
    assert knee.gains.p == pytest.approx(150 / 0.1, rel=1e-3)
    assert hip_yaw.gravity == pytest.approx(0.0, abs=1e-6)  # a vertical axis carries no weight
    # a 10x smaller step allows 10x the bandwidth where the step was the limit
    fine = {t.joint: t for t in tune(robot, 0.0001)}["l_wrist"]
    assert fine.omega == pytest.approx(min(1000.0, fine.omega_effort)) and fine.omega > 400


def test_controllers_verb_writes_a_yaml_and_xacro_that_run(humanoid):
    package = humanoid.parent.parent
    (package / "config").mkdir()
    out = mexone("controllers", humanoid, "-o", package / "config" / "controllers.yaml",
                 *J_CROUCH, cwd=package)
    assert out.returncode == 0, out.stderr
    text = (package / "config" / "controllers.yaml").read_text()
    config = load_control_config(package / "config" / "controllers.yaml")
    assert len(config.controllers) == 26 and config.namespace == "biped"
    assert "# l_knee: moves" in text and "critically damped" in text
    assert yaml.safe_load(text)["biped"]["l_knee_position_controller"]["pid"]["p"] > 0  # plain YAML
    # the student's robot: the URDF plus the written transmissions, through xacro and $(find)
    (package / "urdf" / "biped.urdf.xacro").write_text(
        '<robot name="biped" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:include filename="$(find biped_description)/urdf/biped.urdf"/>'
        '<xacro:include filename="$(find biped_description)/config/controllers_transmissions.xacro"/>'
        '</robot>')
    robot = load_model(package / "urdf" / "biped.urdf.xacro")
    assert len(robot.transmissions) == 25 and robot.ros_namespace == "/biped"
    run = mexone("sim", "urdf/biped.urdf.xacro", "--controllers", "config/controllers.yaml",
                 *J_CROUCH, "--headless", "--duration", "2", cwd=package)
    assert run.returncode == 0, run.stderr
    assert "base height 0.91" in run.stdout  # crouching (lying it would be ~0.1)
    again = mexone("controllers", humanoid, "-o", package / "config" / "controllers.yaml",
                   cwd=package)
    assert again.returncode == 2 and "--force" in again.stderr  # never overwritten silently


def test_sim_says_when_a_robot_has_no_transmissions(humanoid):
    out = mexone("sim", humanoid, "--headless", "--duration", "0.01", cwd=humanoid.parent)
    assert out.returncode == 0
    notes = [line for line in out.stderr.splitlines() if "transmission" in line]
    assert len(notes) == 1 and "--controllers auto" in notes[0]
    quiet = mexone("sim", humanoid, "--headless", "--duration", "0.01", "--no-controllers",
                   cwd=humanoid.parent)
    assert "transmission" not in quiet.stderr


def test_no_controllers_note_names_the_reason(humanoid):
    assert "--controllers auto" in Lab.create(humanoid).no_controllers
    assert "--no-controllers" in Lab.create(humanoid, False).no_controllers
    assert "--no-controllers" not in Lab.create(humanoid).no_controllers


def test_pose_file_and_J(humanoid, tmp_path):
    pose = tmp_path / "standing.yaml"
    pose.write_text("".join(f"{k}: {v}\n" for k, v in {**CROUCH, "l_knee": 0.4}.items()))
    out = mexone("sim", humanoid, "--controllers", "auto", "--pose", pose, "-J", "r_knee", "0.2",
                 "--headless", "--duration", "0.5", "--json", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    lab = Lab.create(humanoid, "auto", spawn=Spawn(joints=(("l_knee", 0.4), ("r_knee", 0.2))))
    q = dict(zip(lab.sim.joint_names, lab.sim.joint_positions(), strict=True))
    assert q["l_knee"] == pytest.approx(0.4) and q["r_knee"] == pytest.approx(0.2)
    lab.sim.run(0.5)
    lab.sim.reset()  # a reset returns to the initial pose, as Gazebo's reset to the spawn
    assert lab.sim.joint_positions()[lab.sim.joint_names.index("l_knee")] == pytest.approx(0.4)


@pytest.mark.parametrize(("args", "message"), [
    (["-J", "l_kne", "0.3"], "initial position for 'l_kne', which is not a moving joint"),
    (["-J", "l_knee", "9"], "initial position 9 of 'l_knee' is outside its limits [0, 2.5]"),
    (["-J", "l_knee", "nan"], "-J l_knee nan: nan must be a finite number"),
    (["--pose", "bad.yaml"], "bad.yaml:2: position of 'r_knee' is 'high', not a finite number"),
])
def test_bad_initial_positions_are_one_line(humanoid, tmp_path, args, message):
    (tmp_path / "bad.yaml").write_text("l_knee: 0.4\nr_knee: high\n")
    out = mexone("sim", humanoid, "--controllers", "auto", *args, "--headless", "--duration",
                 "0.1", cwd=tmp_path)
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and message in out.stderr, out.stderr


def test_the_yaml_says_how_each_gain_was_derived(humanoid):
    robot = load_model(humanoid)
    text = controllers_yaml(robot, 0.001, "biped")
    blocks = text.split("\n\n")[1:]
    assert len(blocks) == 25
    for block in blocks:
        assert "bandwidth w =" in block and "p = I w^2 =" in block and "pid: {p:" in block


def test_run_warns_when_a_routine_commands_a_topic_nobody_hears(humanoid, tmp_path):
    """The seed's routine names /mex_rb/...; this robot's controllers listen on /biped/...:
    'mexone run' says so and lists the topics that would move it, instead of a silent 0."""
    routine = tmp_path / "wave.py"
    routine.write_text(
        "from mexone import rospy\nfrom mexone.msgs import Float64\nrospy.init_node('wave')\n"
        "pubs = [rospy.Publisher(t, Float64, queue_size=1) for t in\n"
        "        ('/mex_rb/l_elbow_position_controller/command',\n"
        "         '/biped/r_elbow_position_controller/command')]\n"
        "rate = rospy.Rate(10)\nfor _ in range(5):\n"
        "    for pub in pubs:\n        pub.publish(Float64(-0.4))\n    rate.sleep()\n")
    args = ("run", routine, "--model", humanoid, "--controllers", "auto", "--duration", "1")
    out = mexone(*args, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    warnings = [line for line in out.stdout.splitlines() if "has no subscriber" in line]
    assert len(warnings) == 1  # once, and not for the topic that is heard
    assert warnings[0].startswith("[WARN] [0.000]: /mex_rb/l_elbow_position_controller/command")
    assert "command topics are: /biped/waist_yaw_position_controller/command, " in warnings[0]
    assert warnings[0].count("_position_controller/command") == 26
    quiet = mexone(*args, "--json", cwd=tmp_path)
    report = __import__("json").loads(quiet.stdout)
    assert report["notices"] == [warnings[0].split(": ", 1)[1]]
    # --json: stdout is the report alone; the routine's log, this warning once, goes to stderr
    assert quiet.stderr.count("/mex_rb/l_elbow_position_controller/command has no subscriber") == 1
    assert report["joints"]["r_elbow"]["max_error"] > 0.1  # the heard one moved its joint
