"""MJCF in: a MuJoCo robot (as Unitree and the Menagerie ship them) read through MjSpec into the
RobotModel gets the same check, simulation, controllers and topics as a URDF robot."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mexone.description.loader import load_model
from mexone.description.meshes import load_mesh, resolve_mesh
from mexone.lab import Lab

ENV = {k: v for k, v in os.environ.items() if k != "ROS_PACKAGE_PATH"}

MJCF = """<mujoco model="Hopper Arm">
  <compiler angle="degree" meshdir="assets"/>
  <default>
    <default class="visual"><geom contype="0" conaffinity="0" group="2"/></default>
    <default class="motor"><motor ctrlrange="-30 30" ctrllimited="true"/></default>
    <joint damping="0.5"/>
  </default>
  <asset><mesh name="shell" file="shell.stl" scale="0.001 0.001 0.001"/>
         <material name="blue" rgba="0 0 1 1"/></asset>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="base" pos="0 0 0.5">
      <freejoint/>
      <inertial pos="0 0 0" mass="4" diaginertia="0.05 0.05 0.05"/>
      <geom type="box" size="0.1 0.1 0.05"/>
      <geom class="visual" type="mesh" mesh="shell" pos="0.01 0 0.02" euler="0 0 30" material="blue"/>
      <body name="upper" pos="0 0 -0.05">
        <joint name="hip" axis="0 1 0" range="-90 90" pos="0 0 0.01"/>
        <inertial pos="0 0 -0.1" mass="1" diaginertia="0.004 0.004 0.001"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.03"/>
        <body name="lower" pos="0 0 -0.2">
          <joint name="knee" axis="0 1 0" range="0 120"/>
          <joint name="knee_twist" axis="0 0 1" range="-10 10"/>
          <inertial pos="0 0 -0.1" mass="0.8" diaginertia="0.003 0.003 0.001"/>
          <geom type="cylinder" size="0.025 0.1" pos="0 0 -0.1"/>
          <body name="toe" pos="0 0 -0.2">
            <joint name="toe" axis="0 1 0" range="-30 30"/>
            <inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>
            <geom type="sphere" size="0.03" friction="0.6"/>
          </body>
        </body>
      </body>
    </body>
    <body name="crate" pos="2 0 0.1"><geom type="box" size="0.1 0.1 0.1"/></body>
  </worldbody>
  <equality><joint name="toe_follows" joint1="toe" joint2="knee" polycoef="0.1 -0.5 0 0 0"/></equality>
  <actuator>
    <motor class="motor" name="hip_motor" joint="hip" gear="2"/>
    <motor class="motor" name="knee_motor" joint="knee"/>
  </actuator>
</mujoco>
"""


@pytest.fixture()
def mjcf(tmp_path) -> Path:
    import trimesh

    (tmp_path / "robot" / "assets").mkdir(parents=True)
    shell = trimesh.creation.box(extents=(150, 120, 60))  # millimetres, off-centre on purpose
    shell.apply_translation((40, -10, 5))
    shell.export(tmp_path / "robot" / "assets" / "shell.stl")
    path = tmp_path / "robot" / "hopper.xml"
    path.write_text(MJCF)
    return path


def mexone(*args, cwd: Path):
    out = subprocess.run([sys.executable, "-m", "mexone", *map(str, args)], cwd=cwd,
                         capture_output=True, text=True, timeout=120, env=ENV)
    assert "Traceback" not in out.stderr, out.stderr
    return out


def test_mjcf_reads_into_the_robot_model(mjcf):
    robot = load_model(mjcf)
    assert robot.name == "hopper_arm" and robot.root == "base" and not robot.fixed_to_world
    assert "crate" not in robot.links  # scenery beside the robot
    assert robot.mass == pytest.approx(4 + 1 + 0.8 + 0.1, abs=1e-5)
    hip, knee = robot.joints["hip"], robot.joints["knee"]
    assert hip.type == "revolute" and (hip.limit.lower, hip.limit.upper) == pytest.approx((-np.pi / 2, np.pi / 2))
    assert hip.limit.effort == pytest.approx(60.0)  # ctrlrange 30 x gear 2
    assert knee.limit.effort == pytest.approx(30.0) and hip.dynamics.damping == pytest.approx(0.5)
    assert robot.joints["knee_twist"].parent == "lower__knee"  # two joints in one body: a chain
    assert {t.joint for t in robot.transmissions} == {"hip", "knee"}
    mimic = robot.joints["toe"].mimic
    assert (mimic.joint, mimic.multiplier, mimic.offset) == ("knee", -0.5, 0.1)
    assert robot.gazebo_links["toe"].mu1 == pytest.approx(0.6)
    assert len(robot.links["upper"].collisions) == 3  # the capsule: a cylinder and two spheres
    shell = robot.links["base"].visuals[0]
    assert shell.rgba == (0, 0, 1, 1)


def test_mjcf_geometry_lands_where_mujoco_puts_it(mjcf):
    """The mesh's vertices, placed by our link frames, sit where MuJoCo's own model puts them."""
    robot = load_model(mjcf)
    model = mujoco.MjModel.from_xml_path(str(mjcf))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    g = next(i for i in range(model.ngeom) if model.geom_type[i] == mujoco.mjtGeom.mjGEOM_MESH)
    mesh = model.geom_dataid[g]
    verts = model.mesh_vert[model.mesh_vertadr[mesh]:model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
    theirs = verts @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
    shell = robot.links["base"].visuals[0]
    ours_local = load_mesh(resolve_mesh(shell.geometry.filename, robot.base_dir)).vertices * 0.001
    base = np.eye(4)
    base[:3, 3] = data.xpos[model.body("base").id]
    pose = base @ shell.origin.matrix
    ours = ours_local @ pose[:3, :3].T + pose[:3, 3]
    np.testing.assert_allclose(ours.min(axis=0), theirs.min(axis=0), atol=1e-6)
    np.testing.assert_allclose(ours.max(axis=0), theirs.max(axis=0), atol=1e-6)
    # a joint's axis and anchor: the knee's link frame is at the lower body's origin
    lower = robot.link_frames["lower"]
    np.testing.assert_allclose(lower[:3, 3] + base[:3, 3], data.xpos[model.body("lower").id], atol=1e-9)


def test_check_and_sim_take_mjcf_with_auto_controllers(mjcf):
    out = mexone("check", mjcf, cwd=mjcf.parent)
    assert out.returncode == 0, out.stdout
    assert "root Link: base has 1 child(ren)" in out.stdout
    run = mexone("sim", mjcf, "--controllers", "auto", "--fixed-base", "--headless", "--duration",
                 "1", cwd=mjcf.parent)
    assert run.returncode == 0, run.stderr
    lab = Lab.create(mjcf, "auto")
    assert lab.manager is not None and "hip_position_controller" in lab.manager.controllers
    assert "toe_position_controller" not in lab.manager.controllers  # the mimic follows
    assert "/hopper_arm/hip_position_controller/command" in lab.bus.topics  # ROS-named topics


def test_broken_mjcf_is_one_line_with_its_line(tmp_path):
    path = tmp_path / "bad.xml"
    path.write_text('<mujoco>\n<worldbody>\n<body name="a">\n<joint type="hinge" axis="0 0 0"/>\n'
                    '<geom size="0.1"/></body></worldbody></mujoco>')
    out = mexone("check", "bad.xml", cwd=tmp_path)
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert out.stderr.startswith("mexone: bad.xml:4: MuJoCo cannot read this MJCF: "), out.stderr
