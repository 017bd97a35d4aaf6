"""Controllers for a robot that has none: one JointPositionController per moving joint, with
gains from the robot's physics instead of a student's guesses.

For each joint, in the standing pose (the initial joint positions)::

    I   the inertia the joint moves about its axis: the composite rigid-body inertia of the links
        beyond it, or, for a joint between the robot and the ground it stands on (a leg), of the
        rest of the robot, which is what that joint lifts;
    w   the closed-loop bandwidth: the lower of what the time step allows (w dt <= 0.1, ten steps
        per radian of phase) and what the effort limit allows (an error of 0.1 rad saturates it);
    p = I w^2, d = 2 I w: a critically damped second-order loop of natural frequency w.

`auto_config` gives the ControlConfig `mexone sim --controllers auto` runs; `controllers_yaml`
writes the same gains with a comment per joint saying how each was derived, and
`transmissions_xacro` the <transmission> blocks ros_control needs, for a student to edit.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from mexone.control.spec import ControlConfig, ControllerSpec, PidGains, controller_name
from mexone.description.kinematics import link_frames_at, with_mimics
from mexone.description.meshes import geometry_bounds
from mexone.description.model import RobotModel, Transmission
from mexone.description.urdf import fmt
from mexone.errors import MexoneError

__all__ = ["JointTuning", "tune", "auto_config", "with_transmissions", "controllers_yaml",
           "transmissions_xacro", "STEP_BANDWIDTH", "SATURATION_ERROR", "POSITION_TYPE",
           "STATE_TYPE", "controller_name"]

STEP_BANDWIDTH = 0.1  # w dt: at most 0.1 rad of the loop's phase per physics step
SATURATION_ERROR = 0.1  # rad (or m): the error at which p alone reaches the effort limit
_SUPPORT_BAND = 0.01  # m: links this close to the lowest point carry the robot
_GRAVITY = 9.81
POSITION_TYPE = "effort_controllers/JointPositionController"
STATE_TYPE = "joint_state_controller/JointStateController"
STATE_RATE = 50.0


@dataclass(frozen=True)
class JointTuning:
    joint: str
    inertia: float  # kg m^2 about the axis (kg for a prismatic joint)
    moves: str  # which links that inertia is, in words
    omega: float  # rad/s
    omega_step: float  # what the time step allows
    omega_effort: float  # what the effort limit allows (inf: no limit)
    gravity: float  # |torque| the pose needs held against gravity, N m (N)
    gains: PidGains

    @property
    def sag(self) -> float:
        """Steady error under the standing gravity load (PD only)."""
        return self.gravity / self.gains.p if self.gains.p > 0 else math.inf

    def explain(self, step: float, effort: float) -> list[str]:
        prismatic = self.moves.startswith("mass")
        unit, load, error = ("kg", "N", "m") if prismatic else ("kg m^2", "N m", "rad")
        by_effort = ("no effort limit" if not math.isfinite(self.omega_effort) else
                     f"effort limit {fmt(effort)} allows {self.omega_effort:.3g} rad/s (an error "
                     f"of {SATURATION_ERROR:g} saturates it)")
        return [
            f"{self.joint}: moves {self.inertia:.4g} {unit} ({self.moves});",
            f"  bandwidth w = {self.omega:.3g} rad/s: the {step * 1000:g} ms step allows "
            f"{self.omega_step:.3g},",
            f"  the {by_effort};",
            f"  p = I w^2 = {self.gains.p:.4g}, d = 2 I w = {self.gains.d:.4g} (critically damped);",
            f"  standing on it alone loads it with {self.gravity:.3g} {load}: a steady error "
            f"of {self.sag:.2g} {error}.",
        ]


# ----- the physics ------------------------------------------------------------------------------
def _support(robot: RobotModel, frames: dict[str, np.ndarray]) -> set[str]:
    """Links whose collision geometry reaches the robot's lowest point: what it stands on."""
    lowest: dict[str, float] = {}
    for name, frame in frames.items():
        for col in robot.links[name].collisions:
            try:
                lower, upper = geometry_bounds(col.geometry, robot.base_dir)
            except MexoneError:
                continue
            corners = np.array([[x, y, z, 1.0] for x in (lower[0], upper[0])
                                for y in (lower[1], upper[1]) for z in (lower[2], upper[2])])
            z = float((frame @ col.origin.matrix @ corners.T)[2].min())
            lowest[name] = min(lowest.get(name, math.inf), z)
    if not lowest:
        return set()
    floor = min(lowest.values())
    return {name for name, z in lowest.items() if z <= floor + _SUPPORT_BAND}


def _mass_properties(robot: RobotModel, frames: dict[str, np.ndarray],
                     links: Iterable[str]) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(mass, COM in world, inertia tensor about the COM in world) of each link with mass."""
    out = []
    for name in links:
        inertial = robot.links[name].inertial
        if inertial is None or inertial.mass <= 0 or name not in frames:
            continue
        pose = frames[name] @ inertial.origin.matrix
        rot = pose[:3, :3]
        out.append((inertial.mass, pose[:3, 3], rot @ inertial.tensor @ rot.T))
    return out


def tune(robot: RobotModel, timestep: float, positions: Mapping[str, float] | None = None,
         floating: bool | None = None) -> list[JointTuning]:
    """Gains for every moving joint that no <mimic> drives, in the pose `positions`."""
    positions = with_mimics(robot, positions or {})
    frames = link_frames_at(robot, positions)
    floating = (not robot.fixed_to_world) if floating is None else floating
    support = _support(robot, frames) if floating else set()
    everything = set(frames)
    omega_step = STEP_BANDWIDTH / timestep
    subtrees = {name: set(robot.walk(name)) for name in everything} if support else {}
    gravity = np.array([0.0, 0.0, -_GRAVITY])
    out = []
    for joint in robot.moving_joints:
        if joint.mimic is not None or joint.parent not in frames:
            continue  # (not in frames: a tree beside the root's, as an editor's loose parts)
        distal = set(robot.walk(joint.child))
        if support and support & distal:  # a leg: it lifts the body, not the other legs
            moved = {name for name in everything - distal
                     if joint.child in subtrees[name] or not subtrees[name] & support}
            moves = "the robot above it, which stands on it"
        else:
            moved, moves = distal, "the links beyond it"
        parent = frames[joint.parent] @ joint.origin.matrix
        axis = parent[:3, :3] @ (np.asarray(joint.axis) / np.linalg.norm(joint.axis))
        anchor = parent[:3, 3]
        inertia, torque = 0.0, 0.0
        for mass, com, tensor in _mass_properties(robot, frames, moved):
            arm = com - anchor
            if joint.type == "prismatic":
                inertia += mass
                torque += float(axis @ (mass * gravity))
            else:
                inertia += mass * float(np.sum(np.cross(axis, arm) ** 2)) + float(axis @ tensor @ axis)
                torque += float(axis @ np.cross(arm, mass * gravity))
        if joint.type == "prismatic":
            moves = "mass of " + moves
        effort = joint.limit.effort if joint.limit and joint.limit.effort > 0 else math.inf
        inertia = max(inertia, 1e-9)
        omega_effort = math.sqrt(effort / (SATURATION_ERROR * inertia)) if math.isfinite(effort) \
            else math.inf
        omega = min(omega_step, omega_effort)
        gains = PidGains(p=_round(inertia * omega**2), d=_round(2 * inertia * omega))
        out.append(JointTuning(joint.name, inertia, moves, omega, omega_step, omega_effort,
                               abs(torque), gains))
    return out


def _round(value: float) -> float:
    """Four significant digits: the YAML reads like a person wrote it."""
    return float(f"{value:.4g}")


# ----- what the rest of mexone runs ---------------------------------------------------------------
def with_transmissions(robot: RobotModel) -> RobotModel:
    """A copy of the robot with a SimpleTransmission on every moving joint that no <mimic>
    drives and that has none (EffortJointInterface, reduction 1)."""
    have = {t.joint for t in robot.transmissions}
    added = [Transmission(f"{j.name}_tran", j.name, actuator=f"{j.name}_motor")
             for j in robot.moving_joints if j.name not in have and j.mimic is None]
    return replace(robot, transmissions=[*robot.transmissions, *added])


def auto_config(robot: RobotModel, timestep: float, positions: Mapping[str, float] | None = None,
                floating: bool | None = None, namespace: str | None = None) -> ControlConfig:
    """A joint_state_controller and one position controller per tuned joint."""
    config = ControlConfig(namespace=namespace)
    config.controllers["joint_state_controller"] = ControllerSpec(
        "joint_state_controller", STATE_TYPE, publish_rate=STATE_RATE)
    for t in tune(robot, timestep, positions, floating):
        name = controller_name(t.joint)
        config.controllers[name] = ControllerSpec(name, POSITION_TYPE, (t.joint,), t.gains)
    return config


def controllers_yaml(robot: RobotModel, timestep: float, namespace: str,
                     positions: Mapping[str, float] | None = None, floating: bool | None = None,
                     source: str | None = None) -> str:
    """The ros_control YAML of `auto_config`, each gain with how it was derived."""
    tunings = tune(robot, timestep, positions, floating)
    pose = ", ".join(f"{k} {fmt(v)}" for k, v in (positions or {}).items()) or "every joint at 0"
    lines = [f"# ros_control controllers for '{robot.name}'" + (f" ({source})" if source else ""),
             "# written by 'mexone controllers': gains from the robot's physics in the standing pose",
             f"# ({pose}); tune them from here. For each joint: the inertia it moves about its",
             "# axis I, the bandwidth w the time step and effort limit allow, p = I w^2 and",
             "# d = 2 I w (critically damped). Load with: rosparam load <this file>",
             f"{namespace.strip('/')}:",
             "  joint_state_controller:",
             f"    type: {STATE_TYPE}",
             f"    publish_rate: {STATE_RATE:g}"]
    for t in tunings:
        joint = robot.joints[t.joint]
        effort = joint.limit.effort if joint.limit else 0.0
        lines.append("")
        lines += ["  # " + text for text in t.explain(timestep, effort)]
        lines += [f"  {controller_name(t.joint)}:",
                  f"    type: {POSITION_TYPE}",
                  f"    joint: {t.joint}",
                  f"    pid: {{p: {t.gains.p:g}, i: 0.0, d: {t.gains.d:g}}}"]
    return "\n".join(lines) + "\n"


def transmissions_xacro(robot: RobotModel, namespace: str, yaml_name: str | None = None,
                        include: str = "$(find PKG)/config/controllers_transmissions.xacro") -> str:
    """The <transmission> of every joint the YAML drives (and the gazebo_ros_control plugin if
    the robot has none), as a xacro a student includes from the robot's own; `include` is this
    file's name as that include says it (`$(find pkg)/path` inside a ROS package)."""
    lines = ['<?xml version="1.0"?>',
             f"<!-- ros_control transmissions for '{robot.name}', written by 'mexone controllers'"
             + (f" with {yaml_name}" if yaml_name else "") + ".",
             f'     Include it from the robot\'s xacro: <xacro:include filename="{include}"/> -->',
             '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">']
    have = {t.joint for t in robot.transmissions}
    for joint in robot.moving_joints:
        if joint.mimic is not None or joint.name in have:
            continue
        lines += [f'  <transmission name="{joint.name}_tran">',
                  "    <type>transmission_interface/SimpleTransmission</type>",
                  f'    <joint name="{joint.name}">',
                  "      <hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface>",
                  "    </joint>",
                  f'    <actuator name="{joint.name}_motor">',
                  "      <mechanicalReduction>1</mechanicalReduction>",
                  "    </actuator>",
                  "  </transmission>"]
    if robot.ros_namespace is None:
        lines += ['  <gazebo>',
                  '    <plugin name="gazebo_ros_control" filename="libgazebo_ros_control.so">',
                  f"      <robotNamespace>/{namespace.strip('/')}</robotNamespace>",
                  "      <robotSimType>gazebo_ros_control/DefaultRobotHWSim</robotSimType>",
                  "    </plugin>",
                  "  </gazebo>"]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
