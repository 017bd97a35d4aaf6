"""Pushes and new models on a running simulation (what gazebo_ros' apply_body_wrench,
apply_joint_effort and spawn_urdf_model need): impulses in sim time, exact ends, bodies that
touch the robot, and a robot that keeps its state and gains through a recompile."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from mexone.errors import InputError
from mexone.lab import Lab
from mexone.physics import Simulation, Spawn
from mexone.robots import mex_one

BOX = """<robot name="box"><link name="body"><inertial><mass value="2"/>
<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
<collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision></link></robot>"""


@pytest.fixture(scope="module")
def flying():
    """Mex-One holding its pose 2 m up: no ground force, so momentum changes by the impulse."""
    return Lab.create(spawn=Spawn((0, 0, 2.0)))


def test_a_wrench_gives_the_impulse_force_times_duration(flying):
    sim = flying.sim
    sim.reset()
    sim.step(20)
    mass = sim.model.body_subtreemass[sim.compiled.root_body]
    v0, _ = sim.link_velocity("pelvis")
    sim.apply_wrench("pelvis", (30.0, 0.0, 0.0), duration=0.1)
    sim.step(150)
    v1, _ = sim.link_velocity("pelvis")
    assert v1[0] - v0[0] == pytest.approx(30.0 * 0.1 / mass, rel=0.05)
    assert not sim.forces.active and not sim.data.xfrc_applied.any()


def test_a_wrench_ends_at_its_duration_to_the_step():
    sim = Simulation(mex_one.urdf_path())
    sim.apply_wrench("torso", (0, 5.0, 0), duration=0.012, frame="torso")
    sim.step(11)  # 11 steps of the 12 it lasts
    assert sim.data.xfrc_applied.any()
    sim.step(1)
    assert not sim.data.xfrc_applied.any() and not sim.forces.active


def test_joint_effort_for_a_duration_and_clear():
    sim = Simulation(mex_one.urdf_path())
    sim.apply_joint_effort("l_elbow", 2.0, duration=0.05)
    sim.apply_joint_effort("r_elbow", -1.0)  # until cleared
    dof_l = sim.compiled.dof_adr[sim.joint_names.index("l_elbow")]
    dof_r = sim.compiled.dof_adr[sim.joint_names.index("r_elbow")]
    sim.step(10)
    assert sim.data.qfrc_applied[dof_l] == 2.0 and sim.data.qfrc_applied[dof_r] == -1.0
    sim.step(50)
    assert sim.data.qfrc_applied[dof_l] == 0.0 and sim.data.qfrc_applied[dof_r] == -1.0
    assert sim.clear_joint_efforts("r_elbow") == 1
    sim.step(1)
    assert not sim.data.qfrc_applied.any()


def test_bad_pushes_are_one_line_errors():
    sim = Simulation(mex_one.urdf_path())
    with pytest.raises(InputError, match="no link named 'nose'"):
        sim.apply_wrench("nose", (1, 0, 0))
    with pytest.raises(InputError, match="finite"):
        sim.apply_wrench("pelvis", (np.nan, 0, 0))
    with pytest.raises(InputError, match="no moving joint"):
        sim.apply_joint_effort("pelvis_free", 1.0)
    assert not sim.forces.active


def test_a_spawned_box_lands_on_the_robot_and_the_robot_keeps_its_state(tmp_path):
    lab = Lab.create()
    sim = lab.sim
    lab.manager.command("l_elbow_position_controller", [-0.8])
    sim.step(500)
    before = sim.joint_positions()
    x, y, z = sim.link_pose("head")[0]
    (tmp_path / "box.urdf").write_text(BOX)
    sim.add_model(tmp_path / "box.urdf", "box", Spawn((x, y, z + 0.3), on_ground=False))
    assert np.allclose(sim.joint_positions(), before)
    touched = set()
    for _ in range(60):
        sim.step(10)
        for c in sim.data.contact:
            bodies = {sim.model.geom_bodyid[c.geom1], sim.model.geom_bodyid[c.geom2]}
            box = sim.body_id("box/body")
            if box in bodies:
                touched |= {sim.model.body(b).name for b in bodies - {box}}
    assert touched & set(sim.compiled.bodies), touched  # it hit a link of the robot
    assert sim.joint_positions()[sim.joint_names.index("l_elbow")] == pytest.approx(-0.8, abs=0.05)
    sim.remove_model("box")
    assert mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_BODY, "box/body") == -1
    with pytest.raises(InputError, match="no model named 'box'"):
        sim.remove_model("box")
