"""Controllers against closed forms: PD step response, integral clamp, antiwindup, effort
saturation, velocity control, trajectories; and bad commands never reach the physics."""

from __future__ import annotations

import logging

import mujoco
import numpy as np
import pytest

from mexone.bus.msgs import (
    Duration,
    Float64,
    Float64MultiArray,
    JointTrajectory,
    JointTrajectoryPoint,
)
from mexone.control import ControlConfig, PidArray, PidGains, parse_control_config
from mexone.description.urdf import read_urdf
from mexone.errors import InputError
from mexone.lab import Lab


@pytest.fixture
def inertia(turntable) -> float:
    return turntable[1]


def lab_with(tmp_path, turntable, yaml_text: str, **robot) -> Lab:
    write, _ = turntable
    return Lab.create(read_urdf(write(tmp_path, **robot)), parse_control_config(yaml_text))


def pid_yaml(p, d, i=0.0, clamp=0.0, antiwindup=False, ctype="effort_controllers/JointPositionController"):
    return f"""turntable:
  joint_state_controller: {{type: joint_state_controller/JointStateController, publish_rate: 50}}
  yaw_controller:
    type: {ctype}
    joint: yaw
    pid: {{p: {p}, i: {i}, d: {d}, i_clamp_min: {-clamp}, i_clamp_max: {clamp}, antiwindup: {str(antiwindup).lower()}}}
"""


def second_order(t, target, p, d, inertia):
    """I q'' + d q' + p q = p target, from rest at 0."""
    wn = np.sqrt(p / inertia)
    zeta = d / (2 * np.sqrt(p * inertia))
    wd = wn * np.sqrt(1 - zeta**2)
    return target * (1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2)
                                                   * np.sin(wd * t)))


def step_response(lab, target, seconds=1.5):
    lab.bus.publish("/turntable/yaw_controller/command", Float64(target))
    t0 = lab.sim.time
    out = []
    for _ in range(round(seconds / lab.sim.timestep)):
        lab.sim.step()
        out.append((lab.sim.time - t0, lab.sim.joint_positions()[0]))
    return np.array(out).T


@pytest.mark.parametrize("reduction", [1.0, 10.0])
def test_pd_step_response_matches_the_second_order_closed_form(tmp_path, reduction, turntable, inertia):
    p, d = 4.0, 0.15  # zeta ~ 0.27: a visible overshoot to compare
    lab = lab_with(tmp_path, turntable, pid_yaml(p, d), reduction=reduction)
    t, q = step_response(lab, 0.5)
    expected = second_order(t, 0.5, p, d, inertia)
    assert np.abs(q - expected).max() < 0.05 * 0.5
    overshoot = q.max() / 0.5 - 1
    zeta = d / (2 * np.sqrt(p * inertia))
    assert overshoot == pytest.approx(np.exp(-zeta * np.pi / np.sqrt(1 - zeta**2)), rel=0.05)


def test_mechanical_reduction_scales_actuator_effort_and_position(tmp_path, turntable):
    lab = lab_with(tmp_path, turntable, pid_yaml(4.0, 0.15), reduction=10.0)
    step_response(lab, 0.5, 0.2)
    data, model = lab.sim.data, lab.sim.model
    mujoco.mj_forward(model, data)
    assert data.actuator_length[0] == pytest.approx(10.0 * lab.sim.joint_positions()[0])
    assert data.qfrc_actuator[0] == pytest.approx(10.0 * data.actuator_force[0])  # MuJoCo's own
    assert lab.manager.hw.effort(np.array([0]))[0] == pytest.approx(data.qfrc_actuator[0])
    assert model.actuator_forcerange[0, 1] == pytest.approx(50.0 / 10.0)


def _steady_error(tmp_path, turntable, clamp, antiwindup=False, disturbance=1.0):
    lab = lab_with(tmp_path, turntable, pid_yaml(10.0, 1.0, i=20.0, clamp=clamp, antiwindup=antiwindup))
    lab.bus.publish("/turntable/yaw_controller/command", Float64(0.0))
    lab.sim.data.qfrc_applied[0] = disturbance  # a constant load torque on the joint
    lab.sim.step(8000)
    return lab.sim.joint_positions()[0]  # the load pushes it this far


def test_integral_clamp_limits_the_integral_term(tmp_path, turntable):
    assert _steady_error(tmp_path, turntable, clamp=0.0) == pytest.approx(0.1, rel=1e-3)  # no I in ROS
    assert _steady_error(tmp_path, turntable, clamp=0.5) == pytest.approx((1.0 - 0.5) / 10.0, rel=1e-3)
    assert abs(_steady_error(tmp_path, turntable, clamp=2.0)) < 1e-4  # the integral removes the error


def test_antiwindup_against_the_control_toolbox_recurrence():
    """Error +1 for 10 s, then -1: without antiwindup the integral winds up to 10 and the term
    stays saturated until it unwinds below i_max/i; with it, it turns at once."""
    gains = [PidGains(p=0, i=2.0, i_clamp_min=-1.0, i_clamp_max=1.0, antiwindup=aw)
             for aw in (False, True)]
    pid = PidArray(gains)
    dt = 0.001
    for _ in range(10_000):
        pid.integral(np.ones(2), dt)
    assert pid.i_error == pytest.approx([10.0, 0.5], rel=1e-6)
    leave = [None, None]
    for k in range(1, 20_000):
        term = pid.integral(-np.ones(2), dt)
        for j in range(2):
            if leave[j] is None and term[j] < 1.0 - 1e-9:
                leave[j] = k * dt
    assert leave[0] == pytest.approx(10.0 - 0.5, abs=2 * dt)  # wound up: 9.5 s to unwind
    assert leave[1] == pytest.approx(0.0, abs=2 * dt)


def test_effort_saturates_at_the_urdf_limit(tmp_path, turntable, inertia):
    lab = lab_with(tmp_path, turntable, """turntable:
  yaw_effort: {type: effort_controllers/JointEffortController, joint: yaw}
""", effort=2.0)
    lab.bus.publish("/turntable/yaw_effort/command", Float64(100.0))
    lab.sim.step(100)
    assert lab.sim.joint_efforts()[0] == pytest.approx(2.0)
    # q = 1/2 (tau / I) t^2
    assert lab.sim.joint_positions()[0] == pytest.approx(0.5 * 2.0 / inertia * 0.1**2, rel=0.02)


def test_velocity_controller_reaches_the_commanded_speed(tmp_path, turntable, inertia):
    lab = lab_with(tmp_path, turntable, """turntable:
  yaw_velocity: {type: effort_controllers/JointVelocityController, joint: yaw, pid: {p: 2.0, d: 0.0}}
""")
    lab.bus.publish("/turntable/yaw_velocity/command", Float64(1.5))
    lab.sim.step(1000)
    # first order: I v' = p (v_cmd - v): v = v_cmd (1 - exp(-p t / I))
    expected = 1.5 * (1 - np.exp(-2.0 * 1.0 / inertia))
    assert lab.sim.joint_velocities()[0] == pytest.approx(expected, rel=0.01)


def test_ideal_servo_teleports_only_when_asked(tmp_path, turntable):
    lab = lab_with(tmp_path, turntable, """turntable:
  yaw_controller: {type: position_controllers/JointPositionController, joint: yaw, ideal_servo: true}
""")
    lab.bus.publish("/turntable/yaw_controller/command", Float64(0.7))
    lab.sim.step(2)
    assert lab.sim.joint_positions()[0] == pytest.approx(0.7)
    with pytest.raises(InputError, match="has no PID gains"):
        lab_with(tmp_path, turntable, """turntable:
  yaw_controller: {type: position_controllers/JointPositionController, joint: yaw}
""")


def test_gazebo_differences_are_warned_once(tmp_path, caplog, turntable):
    with caplog.at_level(logging.WARNING, logger="mexone"):
        lab_with(tmp_path, turntable, pid_yaml(2.0, 0.1, i=0.5, ctype="position_controllers/JointPositionController"))
    text = caplog.text
    assert "Gazebo 7 ignored this pid" in text and "gives no integral action" in text


def test_bad_commands_are_refused_or_clamped_and_never_reach_physics(tmp_path, caplog, turntable):
    lab = lab_with(tmp_path, turntable, pid_yaml(4.0, 0.5))
    topic = "/turntable/yaw_controller/command"
    with caplog.at_level(logging.WARNING, logger="mexone"):
        lab.bus.publish(topic, Float64(float("nan")))
        lab.bus.publish(topic, Float64(float("inf")))
        lab.sim.step(10)
        assert np.isfinite(lab.sim.data.qpos).all() and np.isfinite(lab.sim.data.ctrl).all()
        lab.bus.publish(topic, Float64(5.0))  # the limit is 3 rad
        lab.sim.step(1)  # subscribers only buffer: the next control update applies it
    assert "not finite; ignored" in caplog.text
    assert "clamped: yaw 5 -> 3" in caplog.text
    assert lab.manager.controllers["yaw_controller"].setpoint[0] == 3.0


def test_wrong_message_type_on_a_command_topic(tmp_path, turntable):
    lab = lab_with(tmp_path, turntable, pid_yaml(4.0, 0.5))
    with pytest.raises(InputError, match="carries std_msgs/Float64, not std_msgs/Float64MultiArray"):
        lab.bus.publish("/turntable/yaw_controller/command", Float64MultiArray([1.0]))


def test_unknown_joint_and_conflicting_controllers(tmp_path, turntable):
    with pytest.raises(InputError, match="names joint 'pitch', which the robot does not have"):
        lab_with(tmp_path, turntable, """turntable:
  c: {type: effort_controllers/JointPositionController, joint: pitch, pid: {p: 1}}
""")
    config = parse_control_config(pid_yaml(4.0, 0.5) + """  yaw_effort: {type: effort_controllers/JointEffortController, joint: yaw}
""")
    # alternatives for one joint: the first starts, the other loads stopped (was: the sim exited)
    lab = Lab.create(read_urdf(turntable[0](tmp_path)), config)
    assert {c.name: c.state for c in lab.manager.list_controllers()} == {
        "joint_state_controller": "running", "yaw_controller": "running", "yaw_effort": "stopped"}
    lab.manager.switch(start=["yaw_effort"], stop=["yaw_controller"])  # one switch swaps them
    assert lab.manager.controllers["yaw_effort"].running
    with pytest.raises(InputError, match="joint 'yaw' is driven by 'yaw_controller'"):
        Lab.create(read_urdf(turntable[0](tmp_path)), config, start=["yaw_controller", "yaw_effort"])


def test_switch_stop_start_and_list(tmp_path, turntable):
    config = parse_control_config(pid_yaml(4.0, 0.5) + """  yaw_effort: {type: effort_controllers/JointEffortController, joint: yaw}
""")
    lab = Lab.create(read_urdf(turntable[0](tmp_path)), ControlConfig(config.namespace, {
        k: v for k, v in config.controllers.items() if k != "yaw_effort"}, {}, None))
    manager = lab.manager
    manager.config = config
    manager.switch(start=["yaw_effort"], stop=["yaw_controller"])
    states = {c.name: c.state for c in manager.list_controllers()}
    assert states == {"joint_state_controller": "running", "yaw_controller": "stopped",
                      "yaw_effort": "running"}
    lab.bus.publish("/turntable/yaw_effort/command", Float64(0.5))
    lab.sim.step(10)
    assert lab.sim.joint_efforts()[0] == pytest.approx(0.5)


def test_trajectory_controller_interpolates(tmp_path, turntable):
    lab = lab_with(tmp_path, turntable, """turntable:
  arm_trajectory:
    type: effort_controllers/JointTrajectoryController
    joints: [yaw]
    gains: {yaw: {p: 40.0, d: 2.0}}
""")
    traj = lab.manager.controllers["arm_trajectory"]
    msg = JointTrajectory(joint_names=["yaw"], points=[
        JointTrajectoryPoint(positions=[1.0], time_from_start=Duration.from_sec(1.0)),
        JointTrajectoryPoint(positions=[1.0], velocities=[0.0], time_from_start=Duration.from_sec(2.0)),
        JointTrajectoryPoint(positions=[0.0], velocities=[0.0], time_from_start=Duration.from_sec(3.0)),
    ])
    lab.bus.publish("/turntable/arm_trajectory/command", msg)
    lab.sim.step(1)  # the update before this step (t = 0) takes the buffered trajectory
    assert traj.sample(0.5)[0][0] == pytest.approx(0.5)  # linear: no velocities given
    assert traj.sample(2.5)[0][0] == pytest.approx(0.5)  # cubic Hermite midpoint
    assert traj.sample(2.25)[0][0] == pytest.approx(1 - (3 * 0.25**2 - 2 * 0.25**3))
    lab.sim.step(3499)
    assert lab.sim.joint_positions()[0] == pytest.approx(0.0, abs=0.01)  # holds the last point


def test_group_controller_takes_an_array(tmp_path, turntable):
    lab = lab_with(tmp_path, turntable, """turntable:
  group: {type: effort_controllers/JointGroupEffortController, joints: [yaw]}
""")
    lab.bus.publish("/turntable/group/command", Float64MultiArray([0.25]))
    lab.sim.step(5)
    assert lab.sim.joint_efforts()[0] == pytest.approx(0.25)


def test_state_topic_publishes_only_while_someone_listens(tmp_path, turntable):
    """control_msgs/JointControllerState on <ctrl>/state: set point, measured value, error, the
    torque commanded and the gains, at 100 Hz of sim time, and nothing while nobody listens."""
    from mexone.bus.msgs import JointControllerState

    lab = Lab.create(read_urdf(turntable[0](tmp_path)), parse_control_config(pid_yaml(4.0, 0.5)))
    topic = "/turntable/yaw_controller/state"
    assert lab.bus.topics[topic].count == 0
    lab.sim.step(100)
    assert lab.bus.topics[topic].count == 0  # nobody listened: nothing built
    heard: list[JointControllerState] = []
    sub = lab.bus.subscribe(topic, JointControllerState, heard.append)
    lab.manager.command("yaw_controller", [0.3])
    lab.sim.step(1000)
    assert len(heard) == pytest.approx(100, abs=2)
    last = heard[-1]
    q = lab.sim.joint_positions()[0]
    assert last.set_point == 0.3 and last.process_value == pytest.approx(q, abs=1e-3)
    assert last.error == pytest.approx(0.3 - last.process_value) and (last.p, last.d) == (4.0, 0.5)
    assert heard[0].command != 0.0  # the torque the PID applied when it started moving
    sub.unregister()
    lab.sim.step(100)
    assert len(heard) == pytest.approx(100, abs=2)
