"""The seed's chapter 4 checks on Mex-One, done by the machine, plus any-URDF loading."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
from lxml import etree

from mexone.control.hardware import SimHardware, build_actuators
from mexone.description.check import check_model
from mexone.description.loader import load_model
from mexone.lab import Lab
from mexone.physics import CompileOptions, DivergenceError, Simulation, Spawn
from mexone.physics.monitor import RunMonitor
from mexone.robots import mex_one

ROBOTS = Path(__file__).parents[1] / "data" / "robots"
def fall(seconds=5.0, spawn=Spawn()):
    """Stand Mex-One on the ground with no controllers and let go (the seed's 4.2.3)."""
    sim = Simulation(mex_one.urdf_path(), spawn=spawn)
    monitor = RunMonitor(sim)
    anchors = []

    def tick(s):
        monitor.tick(s)
        anchors.append(_anchor_error(s))

    sim.run(seconds, on_tick=tick, tick=0.01)
    return sim, monitor, max(anchors)


def _anchor_error(sim) -> float:
    """How far each child link's frame is from where its parent says the joint is (m)."""
    model, data = sim.model, sim.data
    worst = 0.0
    for body in range(2, model.nbody):
        parent = model.body_parentid[body]
        expected = data.xpos[parent] + data.xmat[parent].reshape(3, 3) @ model.body_pos[body]
        worst = max(worst, float(np.linalg.norm(data.xpos[body] - expected)))
    return worst


@pytest.mark.slow
def test_fall_without_controllers_stays_assembled_and_comes_to_rest():
    sim, monitor, anchor = fall()
    summary = monitor.summary()
    assert summary.base_height < 0.4  # it fell: the pelvis dropped from 0.60 m
    assert summary.max_link_speed > 1.0  # ...with real speed
    assert anchor < 1e-3  # stays assembled
    assert summary.at_rest and summary.rest_time < 5.0
    assert np.isfinite(sim.data.qpos).all() and not summary.diverged
    q = sim.joint_positions()
    lower = np.array([sim.robot.joints[j].limit.lower for j in sim.joint_names])
    upper = np.array([sim.robot.joints[j].limit.upper for j in sim.joint_names])
    assert np.all(q > lower - 0.05) and np.all(q < upper + 0.05)  # limits hold on impact


@pytest.mark.slow
def test_two_runs_are_bit_identical():
    a, _, _ = fall(2.0)
    b, _, _ = fall(2.0)
    assert np.array_equal(a.data.qpos, b.data.qpos) and np.array_equal(a.data.qvel, b.data.qvel)


def test_standing_spawn_touches_the_ground_without_penetration():
    sim = Simulation(mex_one.urdf_path())
    assert sim.base_height == pytest.approx(0.60, abs=1e-9)
    sim.step(20)
    depths = [sim.data.contact[i].dist for i in range(sim.data.ncon)]
    assert depths and min(depths) > -1e-3


def _fold_left_arm(self_collide: bool) -> tuple[float, set[str]]:
    sim = Simulation(mex_one.urdf_path(), options=CompileOptions(
        self_collision=None if self_collide else False, fixed_base=True))
    sim.apply_joint_effort("l_shoulder_roll", -4.0)  # push the left arm in towards the body
    touched = set()
    for _ in range(150):
        sim.step(10)
        for i in range(sim.data.ncon):
            c = sim.data.contact[i]
            touched |= {sim.model.geom(c.geom1).name.split("/")[0], sim.model.geom(c.geom2).name.split("/")[0]}
    return float(sim.joint_positions()[sim.joint_names.index("l_shoulder_roll")]), touched


def test_self_collision_stops_a_folded_arm_at_the_body():
    angle, touched = _fold_left_arm(self_collide=True)
    assert angle > -0.2 and "torso" in touched | {"pelvis"} and touched & {"l_upper_arm", "l_forearm"}
    through, touched = _fold_left_arm(self_collide=False)  # the seed's Fig. 4.8
    assert through < -0.45 and not touched & {"torso", "pelvis"}


def _broken_head(tmp_path, edit) -> Path:
    root = etree.parse(str(mex_one.urdf_path())).getroot()
    edit(root.find("link[@name='head']"), root)
    path = tmp_path / "broken.urdf"
    path.write_bytes(etree.tostring(root))
    return path


def test_misplaced_com_and_overlarge_inertia_are_diagnosed(tmp_path, monkeypatch):
    """The seed's Fig. 4.7: caught by check before it runs, and never a silent explosion."""
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(mex_one.package_dir()))

    def edit(head, root):
        head.find("inertial/origin").set("xyz", "0.5 0 0")
        for key in ("ixx", "iyy", "izz"):
            head.find("inertial/inertia").set(key, "50")

    path = _broken_head(tmp_path, edit)
    codes = {f.code for f in check_model(load_model(path))}
    assert {"com-outside", "inertia-too-large"} <= codes
    sim = Simulation(path)
    try:
        sim.run(3.0)
    except DivergenceError as exc:
        assert "head" in str(exc) and "mexone check" in str(exc)
    else:
        assert np.isfinite(sim.data.qpos).all()
        assert sim.link_speeds().max() < 50


def test_watchdog_stops_an_exploding_robot_and_names_the_cause(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(mex_one.package_dir()))

    def edit(head, root):
        root.find("gazebo[@reference='neck_pitch']/axis/dynamics/damping").text = "-50"
        root.find("joint[@name='neck_pitch']/dynamics").set("damping", "-50")

    sim = Simulation(_broken_head(tmp_path, edit), options=CompileOptions(fixed_base=True))
    sim.set_joint_positions({"neck_pitch": 0.1})
    with pytest.raises(DivergenceError) as caught:
        sim.run(5.0)
    message = str(caught.value)
    assert "simulation diverged" in message and "dynamics-negative" in message
    assert 'joint "neck_pitch"' in message


def test_any_urdf_fixed_base_arm_with_relative_meshes():
    sim = Simulation(ROBOTS / "arm" / "arm.urdf")
    assert not sim.compiled.free and sim.joint_names == ["shoulder", "elbow"]
    assert sim.model.nmesh == 3  # STL and OBJ visuals loaded
    sim.set_joint_positions({"shoulder": 0.3})
    sim.run(2.0)
    assert np.isfinite(sim.data.qpos).all()
    # the mechanicalReduction 50 motor: joint effort = 50 x actuator effort, limit 20 N m
    sim = Simulation(ROBOTS / "arm" / "arm.urdf", edits=[build_actuators])
    hw = SimHardware(sim)
    hw.command.effort[hw.rows(["shoulder"])] = 100.0
    hw.write()
    sim.step(1)
    assert sim.joint_efforts()[0] == pytest.approx(20.0)


def test_any_urdf_floating_quadruped_with_package_meshes():
    sim = Simulation(ROBOTS / "quadruped_description" / "urdf" / "quadruped.urdf",
                     spawn=Spawn(xyz=(0, 0, 0.2)))
    assert sim.compiled.free and len(sim.joint_names) == 4 and sim.model.nmesh == 5
    monitor = RunMonitor(sim)
    sim.run(3.0, on_tick=monitor.tick)
    summary = monitor.summary()
    assert summary.at_rest and not summary.diverged
    assert 0.0 < summary.base_height < 0.4


def test_mjcf_export_is_the_simulated_robot(tmp_path):
    xml = tmp_path / "mex.xml"
    out = subprocess.run([sys.executable, "-m", "mexone", "convert", str(mex_one.urdf_path()),
                          "-o", str(xml), "--controllers", str(mex_one.controllers_path())],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    plain = mujoco.MjModel.from_xml_path(str(xml))
    data = mujoco.MjData(plain)
    sim = Lab.create().sim  # with its controllers: the export carries their actuators and gains
    assert plain.nu == sim.model.nu > 0
    assert (plain.nbody, plain.njnt, plain.nu, plain.npair) == \
        (sim.model.nbody, sim.model.njnt, sim.model.nu, sim.model.npair)
    for field in ("body_mass", "body_inertia", "body_pos", "body_ipos", "jnt_range",
                  "dof_damping", "dof_frictionloss", "geom_size", "geom_friction", "pair_friction",
                  "pair_solref", "actuator_gear", "actuator_forcerange", "actuator_biasprm"):
        np.testing.assert_allclose(getattr(plain, field), getattr(sim.model, field), rtol=1e-5,
                                   atol=1e-12, err_msg=field)
    live = sim.model.actuator_gainprm[:, 0] > 0  # integral terms that act (the rest: clamped to 0)
    np.testing.assert_allclose(plain.actuator_gainprm[live], sim.model.actuator_gainprm[live])
    assert (plain.opt.timestep, plain.opt.cone, plain.opt.impratio, plain.opt.integrator) == \
        (sim.model.opt.timestep, sim.model.opt.cone, sim.model.opt.impratio, sim.model.opt.integrator)
    # the feet touch the ground exactly, and the XML prints 6 digits: start both 1 cm up
    plain.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
    data.qpos[2] += 0.01
    sim.data.qpos[2] += 0.01
    mujoco.mj_step(plain, data, 1000)
    sim.step(1000)
    np.testing.assert_allclose(data.qpos, sim.data.qpos, atol=1e-6)


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mexone", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


def test_sim_headless_json():
    out = run_cli("sim", "--headless", "--duration", "1", "--json", "-P", "0.3", "-z", "0.05")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert {"sim_time", "wall_time", "rtf", "base_height", "max_link_speed", "at_rest",
            "diverged"} <= set(report)
    assert report["sim_time"] == pytest.approx(1.0) and report["diverged"] is False
    assert report["rtf"] > 0 and report["base_height"] < 0.6


BAD = {
    "missing_mesh.urdf": ('<robot name="r"><link name="a"><inertial><mass value="1"/>'
                          '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>'
                          '<visual><geometry><mesh filename="meshes/gone.stl"/></geometry></visual>'
                          '</link></robot>', "mesh file"),
    "floating.urdf": ('<robot name="r"><link name="a"><inertial><mass value="1"/>'
                      '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
                      '<link name="b"/><joint name="free_j" type="floating"><parent link="a"/>'
                      '<child link="b"/></joint></robot>', "joint 'free_j' is floating"),
    "massless.urdf": ('<robot name="r"><link name="a"><inertial><mass value="1"/>'
                      '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
                      '<link name="b"/><joint name="j" type="continuous"><parent link="a"/>'
                      '<child link="b"/><limit effort="1" velocity="1"/></joint></robot>',
                      "link 'b' moves (joint 'j') but has no mass"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_models_the_simulator_cannot_build_fail_in_one_line(tmp_path, name):
    text, expected = BAD[name]
    (tmp_path / name).write_text(text)
    out = run_cli("sim", name, "--headless", "--duration", "0.1", cwd=tmp_path)
    assert out.returncode == 2, out
    assert out.stderr.startswith(f"mexone: {name}") and expected in out.stderr
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr


def test_convert_to_mjcf_does_not_overwrite(tmp_path):
    target = tmp_path / "keep.xml"
    target.write_text("mine")
    out = run_cli("convert", str(mex_one.urdf_path()), "-o", str(target))
    assert out.returncode == 2 and target.read_text() == "mine"


def test_collada_meshes_load_through_trimesh(tmp_path):
    """MuJoCo reads no .dae; Gazebo models often use it: the compile step converts it."""
    import shutil

    arm = tmp_path / "arm"
    shutil.copytree(ROBOTS / "arm", arm)
    urdf = (arm / "arm.urdf").read_text().replace("meshes/fore.stl", "meshes/fore.dae")
    (arm / "arm.urdf").write_text(urdf)
    sim = Simulation(arm / "arm.urdf")
    mesh = sim.model.mesh("fore/visual_mesh/0")
    verts = sim.model.mesh_vert[mesh.vertadr[0]:mesh.vertadr[0] + mesh.vertnum[0]]
    np.testing.assert_allclose(verts.max(axis=0) - verts.min(axis=0), [0.1, 0.1, 0.3], atol=1e-5)
