"""Physics that used to pass silently: a robot spawned inside the ground, energy from nowhere,
absurd world steps, meshes MuJoCo cannot read, <mimic>."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time

import mujoco
import numpy as np
import pytest
import trimesh

from mexone.description.urdf import read_urdf
from mexone.errors import InputError, MexoneError
from mexone.physics import DivergenceError, Simulation, Spawn
from mexone.robots import mex_one

ENV = {k: v for k, v in os.environ.items() if k != "ROS_PACKAGE_PATH"}


def mexone(*args: str, cwd=None):
    start = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "mexone", *args], cwd=cwd, capture_output=True,
                         text=True, timeout=60, env=ENV)
    assert time.monotonic() - start < 10
    assert "Traceback" not in out.stderr
    return out


# ----- spawning inside the ground ----------------------------------------------------------------
def test_spawn_inside_the_ground_is_lifted_with_a_warning():
    """`sim -z -0.5` shot Mex-One 96 m into the air and exited 0."""
    out = mexone("sim", "--headless", "--no-controllers", "-z", "-0.5", "--duration", "0.5", "--json")
    assert out.returncode == 0
    assert out.stderr == ("mexone: warning: spawn z -0.5 puts 'mex_rb' 0.500 m inside the ground; "
                          "lifted so its lowest point is on the ground (it would be shot into the air)\n")
    import json

    summary = json.loads(out.stdout)
    assert summary["max_link_speed"] < 5 and summary["base_height"] < 1.0


def test_lifted_spawn_stands_where_a_ground_spawn_stands():
    lifted = Simulation(mex_one.urdf_path(), spawn=Spawn((0, 0, -0.5)))
    standing = Simulation(mex_one.urdf_path())
    assert lifted.base_height == pytest.approx(standing.base_height)


def test_spawn_lowest_point_counts_the_rotation(tmp_path):
    """z is the height of the lowest point of the robot as spawned: a box on its edge stands
    on the edge, not half inside the ground."""
    path = tmp_path / "box.urdf"
    path.write_text("""<robot name="box"><link name="box"><inertial><mass value="1"/>
      <inertia ixx="0.0017" ixy="0" ixz="0" iyy="0.0017" iyz="0" izz="0.0017"/></inertial>
      <collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link></robot>""")
    sim = Simulation(read_urdf(path), spawn=Spawn(rpy=(np.pi / 4, 0, 0)))
    assert sim.base_height == pytest.approx(0.05 * np.sqrt(2))


def test_a_non_finite_spawn_is_refused():
    with pytest.raises(InputError, match="is not finite"):
        Simulation(mex_one.urdf_path(), spawn=Spawn((0, 0, float("nan"))))


# ----- the energy watchdog -----------------------------------------------------------------------
def test_energy_gain_without_a_motor_is_a_divergence():
    """Started 0.5 m inside the ground the robot leaves at 47 m/s, under the 50 m/s limit."""
    sim = Simulation(mex_one.urdf_path())
    sim.data.qpos[2] -= 0.5  # past the spawn's lift: the state a too-stiff contact can make
    mujoco.mj_forward(sim.model, sim.data)
    with pytest.raises(DivergenceError) as caught:
        sim.run(1.0)
    message = str(caught.value)
    assert message.startswith("simulation diverged at t = 0.010 s: the robot gained ")
    assert "J with no motor or force driving it" in message
    assert "likely cause: it started inside the ground or another body" in message


def test_a_passive_fall_and_a_lifted_pendulum_are_no_divergence(tmp_path):
    drop = Simulation(mex_one.urdf_path(), spawn=Spawn((0, 0, 1.0)))
    drop.run(2.0)  # falls, hits the ground, collapses: energy only leaves
    path = tmp_path / "pendulum.urdf"
    path.write_text("""<robot name="p"><link name="world"/>
      <joint name="weld" type="fixed"><parent link="world"/><child link="pivot"/><origin xyz="0 0 2"/></joint>
      <link name="pivot"/>
      <joint name="swing" type="continuous"><parent link="pivot"/><child link="rod"/><axis xyz="0 1 0"/>
        <limit effort="10" velocity="100"/></joint>
      <link name="rod"><inertial><origin xyz="0 0 -0.5"/><mass value="1"/>
        <inertia ixx="0.0834" ixy="0" ixz="0" iyy="0.0834" iyz="0" izz="0.0002"/></inertial></link></robot>""")
    sim = Simulation(read_urdf(path))
    sim.set_joint_positions({"swing": np.pi})  # upside down: 9.8 J above home, as the user wants
    sim.data.qpos[sim.compiled.qpos_adr[0]] += 1e-3  # so it falls
    sim.run(3.0)
    sim.reset()
    sim.run(0.5)


# ----- worlds ------------------------------------------------------------------------------------
def _world(tmp_path, step: str) -> str:
    text = mex_one.world_path().read_text().replace(
        "<max_step_size>0.001</max_step_size>", f"<max_step_size>{step}</max_step_size>")
    (tmp_path / "w.world").write_text(text)
    return "w.world"


def test_a_half_second_step_is_refused(tmp_path):
    out = mexone("sim", "--headless", "--world", _world(tmp_path, "0.5"), cwd=tmp_path)
    assert out.returncode == 2
    assert out.stderr == ("mexone: w.world:8: <max_step_size> 0.5 s must be a finite number >= 1e-05 "
                          "and <= 0.01 s (Gazebo's default is 0.001)\n")


def test_a_2_ms_step_is_fine(tmp_path):
    out = mexone("sim", "--headless", "--duration", "0.1", "--world", _world(tmp_path, "0.002"),
                 cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("mex_rb: 0.100 s simulated")


# ----- meshes MuJoCo cannot read itself ----------------------------------------------------------
def _mesh_robot(tmp_path, mesh: str) -> str:
    (tmp_path / "robot.urdf").write_text(f"""<robot name="m"><link name="ball">
      <inertial><mass value="1"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
      <collision><geometry><mesh filename="{mesh}"/></geometry></collision></link></robot>""")
    return "robot.urdf"


@pytest.mark.parametrize("kind", ["ascii", "over_200k_faces"])
def test_check_and_sim_agree_on_stl_meshes(tmp_path, kind):
    """MuJoCo refuses ASCII STL and over 200,000 faces; mexone reads those itself (trimesh)."""
    if kind == "ascii":
        trimesh.creation.icosphere(subdivisions=2, radius=0.05).export(tmp_path / "ball.stl",
                                                                       file_type="stl_ascii")
    else:
        ball = trimesh.creation.uv_sphere(radius=0.05, count=(236, 236))
        assert len(ball.faces) > 200_000
        ball.export(tmp_path / "ball.stl")
    name = _mesh_robot(tmp_path, "ball.stl")
    check = mexone("check", name, cwd=tmp_path)
    assert check.returncode == 0, check.stdout
    sim = mexone("sim", "--headless", "--duration", "0.2", name, cwd=tmp_path)
    assert sim.returncode == 0, sim.stderr
    assert "at rest" in sim.stdout


# ----- mimic -------------------------------------------------------------------------------------
def test_mimic_joint_follows_its_leader(tmp_path):
    path = tmp_path / "gripper.urdf"
    finger = """<inertial><origin xyz="0 0 -0.05"/><mass value="0.1"/>
      <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.00001"/></inertial>"""
    path.write_text(f"""<robot name="gripper"><link name="world"/>
      <joint name="weld" type="fixed"><parent link="world"/><child link="palm"/><origin xyz="0 0 1"/></joint>
      <link name="palm"/>
      <joint name="left" type="revolute"><parent link="palm"/><child link="l"/><origin xyz="0.05 0 0"/>
        <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="1" velocity="5"/></joint>
      <link name="l">{finger}</link>
      <joint name="right" type="revolute"><parent link="palm"/><child link="r"/><origin xyz="-0.05 0 0"/>
        <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="1" velocity="5"/>
        <mimic joint="left" multiplier="-1" offset="0.1"/></joint>
      <link name="r">{finger}</link></robot>""")
    sim = Simulation(read_urdf(path))
    sim.set_joint_positions({"left": 0.8, "right": -0.7})
    sim.run(1.0)
    left, right = sim.joint_positions()
    assert abs(left) > 0.05  # it swung
    assert right == pytest.approx(0.1 - left, abs=2e-3)


def test_a_world_s_gravity_and_real_time_factor_are_checked_by_their_ranges(tmp_path):
    from mexone.physics.world import read_world

    text = mex_one.world_path().read_text()
    for old, new, message in (
            ("<real_time_factor>1</real_time_factor>", "<real_time_factor>1e300</real_time_factor>",
             "1e+300 must be a finite number >= 0 and <= 100"),
            ("<gravity>0 0 -9.81</gravity>", "<gravity>0 0 -1e300</gravity>", "(0, 0, -1e+300) m/s^2: each component")):
        (tmp_path / "w.world").write_text(text.replace(old, new, 1))
        with pytest.raises(MexoneError, match=re.escape(message)):
            read_world(tmp_path / "w.world")
