"""Two robots in one world, each with its own controller manager (what spawn_urdf_model with a
-robot_namespace gives a robot with transmissions, as gazebo_ros_control does): commands on one
namespace move only that robot's joints, the first robot keeps its run-time gains across the
recompile, and deleting the second stops its controllers and leaves the first untouched."""

from __future__ import annotations

import pytest

from mexone.bus.msgs import Float64, JointState
from mexone.control.config import load_control_config
from mexone.control.hardware import SimHardware, build_actuators
from mexone.control.manager import ControllerManager
from mexone.lab import Lab
from mexone.physics.compile import Spawn
from mexone.robots import mex_one


def joints(lab: Lab, topic: str) -> dict[str, float]:
    got: list[JointState] = []
    sub = lab.bus.subscribe(topic, JointState, got.append)
    lab.sim.run(0.05)
    sub.unregister()
    return dict(zip(got[-1].name, got[-1].position, strict=True))


def test_two_robots_are_commanded_independently_and_the_second_can_go():
    lab = Lab.create()
    sim = lab.sim
    lab.manager.set_gains("l_elbow_position_controller",
                              lab.manager.controllers["l_elbow_position_controller"]
                              .gains[0].__class__(p=80.0, d=1.0))
    kp_before = sim.model.actuator_biasprm[sim.model.actuator("l_elbow").id, 1]
    robot = lab.sim.robot
    sim.add_model(robot, "robot2", Spawn((0.0, 1.5, 0.0)), edits=[build_actuators])
    assert sim.model.actuator_biasprm[sim.model.actuator("l_elbow").id, 1] == kp_before
    model = sim.model
    bodies = {i: model.body(model.geom_bodyid[i]).name for i in range(model.ngeom)}
    solid = [g for g in range(model.ngeom) if model.geom_contype[g] and bodies[g] != "world"]
    first = [g for g in solid if not bodies[g].startswith("robot2/")]
    other = [g for g in solid if bodies[g].startswith("robot2/")]

    def touch(a: int, b: int) -> bool:  # MuJoCo's contype/conaffinity rule
        return bool(model.geom_contype[a] & model.geom_conaffinity[b]
                    or model.geom_contype[b] & model.geom_conaffinity[a])
    assert first and other and all(touch(a, b) for a in first for b in other)  # robots meet
    plain_first = sum(touch(a, b) for a in first for b in first if a < b)
    plain_other = sum(touch(a, b) for a in other for b in other if a < b)
    # each keeps its own selfCollide rules (Mex-One's links all have it): as many pairs
    assert plain_first == plain_other  # touch within each robot
    config = load_control_config(mex_one.controllers_path())
    second = ControllerManager(sim, lab.bus, config, SimHardware(sim, robot, "robot2/"), "/robot2")
    assert second.start_default() == []
    sim.run(0.5)
    lab.bus.publish("/mex_rb/l_elbow_position_controller/command", Float64(-0.5))
    lab.bus.publish("/robot2/l_elbow_position_controller/command", Float64(-1.0))
    lab.bus.publish("/robot2/neck_yaw_position_controller/command", Float64(0.6))
    sim.run(2.0)
    first, other = joints(lab, "/mex_rb/joint_states"), joints(lab, "/robot2/joint_states")
    assert first["l_elbow"] == pytest.approx(-0.5, abs=0.03)
    assert other["l_elbow"] == pytest.approx(-1.0, abs=0.03)
    assert other["neck_yaw"] == pytest.approx(0.6, abs=0.03)
    assert first["neck_yaw"] == pytest.approx(0.0, abs=0.03)
    pelvis2 = sim.data.xpos[sim.model.body("robot2/pelvis").id]
    assert pelvis2[1] == pytest.approx(1.5, abs=0.1) and pelvis2[2] > 0.5  # standing, held
    second.close()
    sim.remove_model("robot2")
    assert sim.model.nactuator == 2 * len(robot.actuated_joints)
    lab.bus.publish("/mex_rb/l_elbow_position_controller/command", Float64(-0.2))
    sim.run(1.5)
    assert joints(lab, "/mex_rb/joint_states")["l_elbow"] == pytest.approx(-0.2, abs=0.03)
