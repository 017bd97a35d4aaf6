"""The built-in Mex-One: committed files equal the generator's, the model is what DESIGN.md
section 2 promises, and the real urdfdom check_urdf accepts it."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
import trimesh
import yaml

from mexone.control.config import load_control_config
from mexone.control.lint import lint_controllers
from mexone.description.check import check_model, format_tree
from mexone.description.loader import load_model
from mexone.description.materials import display_rgba
from mexone.description.meshes import load_mesh, resolve_mesh
from mexone.robots import mex_one
from mexone.robots.mex_one import generate, params

JOINTS = {f"{s}_{j}" for s in "lr" for j in ("hip_yaw", "hip_roll", "hip_pitch", "knee",
                                                 "ankle_pitch", "ankle_roll", "shoulder_pitch",
                                                 "shoulder_roll", "elbow")} | {
    "waist_yaw", "neck_yaw", "neck_pitch"}
AXES = {"yaw": (0, 0, 1), "roll": (1, 0, 0), "pitch": (0, 1, 0), "knee": (0, 1, 0),
        "elbow": (0, 1, 0)}


@pytest.fixture(scope="module")
def model():
    return load_model(mex_one.urdf_path())


def test_committed_files_match_the_generator(tmp_path):
    written = generate.generate(tmp_path)
    for new in written:
        old = mex_one.package_dir() / new.relative_to(tmp_path)
        assert old.exists(), f"{old} is generated but not committed"
        if new.suffix == ".stl":
            a, b = trimesh.load(old), trimesh.load(new)
            assert a.vertices.shape == b.vertices.shape, f"{old.name} drifted"
            np.testing.assert_allclose(a.vertices, b.vertices, atol=1e-4, err_msg=old.name)
        else:
            assert old.read_text() == new.read_text(), (
                f"{old} drifted from params.py: run python -m mexone.robots.mex_one.generate")


def test_real_check_urdf_accepts_it_and_prints_our_tree(model):
    tool = shutil.which("check_urdf")
    if tool is None:
        pytest.skip("check_urdf not installed (Debian liburdfdom-tools)")
    out = subprocess.run([tool, str(mex_one.urdf_path())], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == format_tree(model)


def test_21_dof_with_stable_names_axes_and_one_controller_each(model):
    assert model.name == "mex_rb" and model.root == "pelvis" and not model.fixed_to_world
    assert {j.name for j in model.moving_joints} == JOINTS
    fixed = {j.name: j.child for j in model.joints.values() if not j.moving}
    assert fixed == {"kinect_joint": "kinect_link",  # the Kinect's frames, for TF
                     "kinect_rgb_optical_frame_joint": "kinect_rgb_optical_frame",
                     "kinect_depth_optical_frame_joint": "kinect_depth_optical_frame"}
    for joint in model.moving_joints:
        kind = joint.name.split("_")[-1]
        assert joint.axis == AXES[kind], joint.name
        assert joint.limit.lower < 0 < joint.limit.upper or joint.name.endswith(("knee", "elbow"))
        assert joint.limit.lower <= 0 <= joint.limit.upper, "home (all zero) must be reachable"
        assert joint.limit.effort > 0 and joint.limit.velocity > 0
        assert joint.dynamics.damping > 0 and joint.dynamics.friction > 0
        assert model.joint_dynamics(joint.name) == joint.dynamics  # Listing 3.11 agrees
        tx = model.transmission_for(joint.name)
        assert tx.hardware_interface == "hardware_interface/EffortJointInterface"
        assert tx.mechanical_reduction == 1.0
    assert len(model.actuated_joints) == 21
    assert model.ros_namespace == "/mex_rb"


def test_published_scale_height_and_mass(model):
    assert model.mass == pytest.approx(15.0, abs=0.5)
    # height: lowest and highest collision point at home, all joints 0
    zs = []
    for name, frame in model.link_frames.items():
        for col in model.links[name].collisions:
            half = col.geometry.half_extents()
            centre = frame @ col.origin.matrix
            corners = np.array([[x, y, z, 1] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
            zs.extend((centre @ (corners * np.append(half, 1)).T)[2])
    assert max(zs) - min(zs) == pytest.approx(1.05, abs=1e-3)
    assert -min(zs) == pytest.approx(params.PELVIS_HEIGHT, abs=1e-9)  # soles at z = 0


FRAMES = {"kinect_link", "kinect_rgb_optical_frame", "kinect_depth_optical_frame"}  # no body


def test_every_link_is_physical(model):
    assert set(model.links) - FRAMES == {p.name for p in params.parts()}
    for link in (model.links[p.name] for p in params.parts()):
        inertial = link.inertial
        assert inertial.mass > 0
        moments = np.linalg.eigvalsh(inertial.tensor)
        assert moments[0] > 0
        assert moments[0] + moments[1] >= moments[2]
        assert link.visuals and link.collisions
        gz = model.gazebo_links[link.name]
        assert gz.self_collide is True and gz.mu1 > 0 and gz.mu2 > 0 and gz.kp > 0 and gz.kd > 0
        # the visuals' named colours are what every renderer shows: no Gazebo script paints a
        # link's servo and shell one colour
        assert gz.material is None
        materials = [v.material for v in link.visuals]
        assert len(set(materials)) == len(materials)  # one visual per material
        for vis in link.visuals:
            assert vis.rgba == params.MATERIALS[vis.material]
            assert display_rgba(model, link.name, vis) == vis.rgba


def test_box_inertia_matches_the_closed_form(model):
    pelvis = model.links["pelvis"].inertial
    x, y, z = 0.12, 0.18, 0.08
    m = pelvis.mass
    np.testing.assert_allclose(np.diag(pelvis.tensor),
                               [m / 12 * (y * y + z * z), m / 12 * (x * x + z * z),
                                m / 12 * (x * x + y * y)], rtol=1e-5)


def _bounds(boxes) -> tuple[np.ndarray, np.ndarray]:
    boxes = np.array(boxes).reshape(-1, 3)
    return boxes.min(axis=0), boxes.max(axis=0)


def test_meshes_are_millimetre_stl_wrapping_the_collisions(model):
    for link in (model.links[p.name] for p in params.parts()):
        seen = []
        for i, vis in enumerate(link.visuals):
            assert vis.geometry.scale == (0.001, 0.001, 0.001)
            stem = link.name if i == 0 else f"{link.name}_{vis.material}"
            assert vis.geometry.filename == f"package://mex_rb/meshes/{stem}.stl"
            path = resolve_mesh(vis.geometry.filename, model.base_dir)
            assert path.read_bytes()[:5] != b"solid"  # binary STL
            mesh = load_mesh(path)
            assert trimesh.Trimesh(mesh.vertices, mesh.faces).is_watertight, path.name  # closed
            seen.append(mesh.bounds / 1000.0)
        lo, hi = _bounds(seen)
        c_lo, c_hi = _bounds([(np.asarray(c.origin.xyz) - c.geometry.half_extents(),
                               np.asarray(c.origin.xyz) + c.geometry.half_extents())
                              for c in link.collisions])
        # the shell wraps the collision primitives; it only reaches further to cover a joint's
        # servo in the gap the primitives leave (the knee's: 5 cm) or to draw a hand
        assert np.all(np.abs(lo - c_lo) <= 0.051) and np.all(np.abs(hi - c_hi) <= 0.051), link.name
    # the robot is drawn as tall as it collides: soles on the ground, the Kinect's top at 1.05 m
    for name, side in (("l_foot", 0), ("head", 1)):
        meshes = [load_mesh(resolve_mesh(v.geometry.filename, model.base_dir))
                  for v in model.links[name].visuals]
        drawn = _bounds([m.bounds / 1000.0 for m in meshes])[side][2]
        cols = model.links[name].collisions
        collides = _bounds([(np.asarray(c.origin.xyz) - c.geometry.half_extents(),
                             np.asarray(c.origin.xyz) + c.geometry.half_extents())
                            for c in cols])[side][2]
        assert drawn == pytest.approx(collides, abs=1e-4), name


def test_visual_triangles_are_few_enough_for_software_gl(model):
    faces = sum(len(load_mesh(resolve_mesh(v.geometry.filename, model.base_dir)).faces)
                for link in model.links.values() for v in link.visuals)
    from mexone.gui.scene import SHADOW_TRIANGLES

    assert 10_000 < faces <= SHADOW_TRIANGLES  # round shells, and the page keeps its shadow


def test_controller_yaml_follows_listing_3_17(model):
    raw = yaml.safe_load(mex_one.controllers_path().read_text())
    assert list(raw) == ["mex_rb"]
    config = load_control_config(mex_one.controllers_path())
    assert config.namespace == "mex_rb"
    jsc = config.controllers["joint_state_controller"]
    assert jsc.type == "joint_state_controller/JointStateController" and jsc.publish_rate == 50
    for joint in JOINTS:
        spec = config.controllers[f"{joint}_position_controller"]
        assert spec.joints == (joint,) and spec.pid.p > 0 and spec.pid.d > 0
    assert len(config.controllers) == 22


def test_shipped_model_and_controllers_lint_clean(model):
    config = load_control_config(mex_one.controllers_path())
    findings = check_model(model) + lint_controllers(model, config)
    assert [f for f in findings if f.severity != "info"] == []


def test_world_has_ground_sun_gravity_and_1ms_step():
    from lxml import etree

    world = etree.parse(str(mex_one.world_path())).getroot().find("world")
    assert world.findtext("gravity").split() == ["0", "0", "-9.81"]
    assert float(world.findtext("physics/max_step_size")) == 0.001
    assert world.find("light[@name='sun']") is not None
    assert world.find("model[@name='ground_plane']/link/collision/geometry/plane") is not None


def test_the_shipped_empty_world_is_the_default_world():
    from dataclasses import replace

    from mexone.physics.world import default_world, read_world

    shipped = read_world(mex_one.world_path())
    assert replace(shipped, source=None) == default_world()
