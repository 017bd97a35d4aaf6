"""The model editor's core, driven as the page drives it: a 3-link arm built from three STL parts
in millimetres and saved; the files judged by check_urdf, `mexone check`, trimesh and the
simulator; undo that survives a restart; Mex-One's live check; a Gazebo model-editor SDF."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

from mexone.cli import main
from mexone.control.config import load_control_config
from mexone.description.model import Box, Cylinder, Mesh, Pose, Sphere
from mexone.description.urdf import read_urdf, write_urdf
from mexone.editor.parts import guess_unit, read_part, safe_name
from mexone.editor.save import save_controllers, save_package, save_sdf, save_urdf
from mexone.editor.session import EditSession
from mexone.editor.snapping import SNAP_RADIUS, Snap, nearest_snap
from mexone.errors import InputError, OutputExistsError
from mexone.lab import Lab
from mexone.robots import mex_one

DATA = Path(__file__).resolve().parents[1] / "data"
PARTS = {"arm_base": 1.0, "arm_upper": 0.5, "arm_fore": 0.3}  # link: mass in kg
HOLES = {"shoulder": ("arm_base", "arm_upper", (0.0, 0.1)), "elbow": ("arm_upper", "arm_fore", (0.15, 0.1))}


def hole_snap(session: EditSession, link: str, xz) -> int:
    """The index of the snap candidate on `link` that is the hole at (x, z) (metres)."""
    for i, (snap, point, _axis) in enumerate(session.snaps(link)):
        if snap.kind == "hole axis" and np.hypot(point[0] - xz[0], point[2] - xz[1]) < 1e-6:
            return i
    raise AssertionError(f"no hole at {xz} on {link}")


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """The arm as the issue builds it: import (units guessed: mm), masses, inertias from the
    meshes, collision cylinders, two revolute joints snapped to hole axes, motors; saved."""
    work = tmp_path_factory.mktemp("work")
    session = EditSession.open(work / "session", name="arm")
    for link in PARTS:
        path = DATA / "editor" / f"{link}.stl"
        assert read_part(path.name, path.read_bytes()).guess == "mm"
        assert session.import_part(path.name, path.read_bytes()) == link
    session.fix_to_world("arm_base")
    for link, mass in PARTS.items():
        session.compute_inertia(link, mass)
        session.fit_collision(link, "cylinder")
    for joint, (parent, child, xz) in HOLES.items():
        index = hole_snap(session, child, xz)
        _snap, point, axis = session.snaps(child)[index]
        session.add_joint(joint, parent, child, "revolute", point, axis)
        session.set_motor(joint)
    out = work / "out"
    out.mkdir()
    save_urdf(session, out / "arm.urdf")
    save_controllers(session, out / "controllers.yaml")
    return session, out


def test_the_saved_urdf_passes_check_urdf(arm):
    _session, out = arm
    if shutil.which("check_urdf") is None:
        pytest.skip("check_urdf (liburdfdom-tools) is not installed")
    result = subprocess.run(["check_urdf", str(out / "arm.urdf")], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "root Link: world has 1 child(ren)" in result.stdout
    assert "child(1):  arm_fore" in result.stdout


def test_the_saved_urdf_passes_mexone_check(arm, capsys):
    _session, out = arm
    assert main(["check", str(out / "arm.urdf"), "--controllers", str(out / "controllers.yaml")]) == 0
    assert "no problems found" in capsys.readouterr().out


def test_inertias_are_trimesh_s_for_those_meshes_and_masses(arm):
    _session, out = arm
    model = read_urdf(out / "arm.urdf")
    for link, mass in PARTS.items():
        mesh = trimesh.load(DATA / "editor" / f"{link}.stl")
        mesh.apply_scale(0.001)
        mesh.density = mass / mesh.volume
        inertial = model.links[link].inertial
        assert inertial.mass == pytest.approx(mass)
        frame = model.link_frames[link]  # the part's mesh frame is the assembly's
        com_world = (frame @ [*inertial.origin.xyz, 1.0])[:3]
        np.testing.assert_allclose(com_world, mesh.center_mass, atol=1e-9)
        rot = frame[:3, :3] @ inertial.origin.matrix[:3, :3]
        np.testing.assert_allclose(rot @ inertial.tensor @ rot.T, mesh.moment_inertia, rtol=1e-6, atol=1e-12)


def test_joints_sit_on_the_hole_axes(arm):
    session, _out = arm
    frames = session.world_frames()
    for joint, (_parent, child, xz) in HOLES.items():
        position = frames[child][:3, 3]
        assert position[[0, 2]] == pytest.approx(xz, abs=1e-9)
        axis = frames[child][:3, :3] @ np.asarray(session.model.joints[joint].axis)
        assert abs(axis[1]) == pytest.approx(1.0)  # through the plate: the bore's axis
        # the parts did not move: the upper arm's mesh is where the assembly put it
    mesh, origin = session.part_mesh("arm_upper")
    bounds = trimesh.transform_points(mesh.vertices, frames["arm_upper"] @ origin)
    np.testing.assert_allclose(bounds.min(axis=0), [-0.02, 0.01, 0.08], atol=1e-9)


def test_collision_cylinders_enclose_each_part(arm):
    session, out = arm
    model = read_urdf(out / "arm.urdf")
    for link in PARTS:
        (col,) = model.links[link].collisions
        assert isinstance(col.geometry, Cylinder)
        mesh, origin = session.part_mesh(link)
        local = trimesh.transform_points(mesh.vertices, np.linalg.inv(col.origin.matrix) @ origin)
        assert np.all(np.hypot(local[:, 0], local[:, 1]) <= col.geometry.radius + 1e-6)
        assert np.all(np.abs(local[:, 2]) <= col.geometry.length / 2 + 1e-6)
        # fitted, not oversized: the plate's length is the cylinder's length or its diameter
        assert max(col.geometry.length, 2 * col.geometry.radius) <= 1.3 * max(mesh.extents)


def test_the_saved_arm_holds_its_home_pose_with_its_controllers(arm):
    _session, out = arm
    lab = Lab.create(out / "arm.urdf", out / "controllers.yaml")
    lab.sim.run(3.0)
    held = lab.sim.joint_positions()
    assert np.all(np.abs(held) < 0.03), held  # sag under gravity: load / p, about 0.01 rad
    assert np.all(np.abs(lab.sim.data.qvel) < 1e-3)
    limp = Lab.create(out / "arm.urdf", False)  # the same arm without them falls
    limp.sim.run(1.0)
    assert np.max(np.abs(limp.sim.joint_positions())) > 0.3  # ten times the held sag


def test_controllers_yaml_carries_the_auto_gains(arm):
    session, out = arm
    config = load_control_config(out / "controllers.yaml")
    assert config.namespace == "arm"
    gains = {spec.joints[0]: spec.pid for spec in config.controllers.values() if spec.joints}
    assert gains == session.auto_gains()
    assert set(gains) == {"shoulder", "elbow"}


def test_saving_never_overwrites_without_force(arm):
    session, out = arm
    before = (out / "arm.urdf").read_text()
    session.set_color("arm_fore", (1, 0, 0, 1))
    with pytest.raises(OutputExistsError):
        save_urdf(session, out / "arm.urdf")
    assert (out / "arm.urdf").read_text() == before
    session.undo()


def test_the_ros_package_roslaunches(arm, tmp_path):
    session, _out = arm
    package = save_package(session, tmp_path / "my_arm")
    urdf = package / "urdf" / "arm.urdf"
    assert {p.name for p in (package / "meshes").iterdir()} == {f"{link}.stl" for link in PARTS}
    assert "package://my_arm/meshes/arm_base.stl" in urdf.read_text()
    with pytest.raises(OutputExistsError):
        save_package(session, package)
    if shutil.which("roslaunch") is None:
        pytest.skip("roslaunch is not installed")
    env = {"ROS_PACKAGE_PATH": str(tmp_path), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    dump = subprocess.run(["roslaunch", "--dump-params", "my_arm", "control.launch"], env=env,
                          capture_output=True, text=True, cwd=tmp_path)
    assert dump.returncode == 0, dump.stderr
    assert "/arm/shoulder_position_controller/pid/p:" in dump.stdout
    assert "/robot_description:" in dump.stdout
    result = subprocess.run(["check_urdf", str(urdf)], capture_output=True, text=True)
    assert result.returncode == 0


def test_the_sdf_saves_and_reads_back(arm):
    session, out = arm
    save_sdf(session, out / "arm.sdf")
    assert main(["check", str(out / "arm.sdf")]) in (0, 1)
    from mexone.description.loader import load_model

    back = load_model(out / "arm.sdf")
    assert set(back.joints) >= {"shoulder", "elbow"}
    assert back.links["arm_upper"].inertial.mass == pytest.approx(0.5)


def test_history_survives_a_restart_and_undo_redo_walk_it(arm, tmp_path):
    session, _out = arm
    shutil.copytree(session.folder, tmp_path / "copy")
    again = EditSession.open(tmp_path / "copy")
    assert again.index == session.index
    assert write_urdf(again.model) == write_urdf(session.model)
    assert again.undo() == "motor elbow: on"
    assert "elbow" not in {t.joint for t in again.model.transmissions}
    again.redo()
    assert again.model.transmissions == session.model.transmissions
    again.undo()
    again.set_joint("elbow", type="fixed")  # a new edit drops the redo branch
    assert not again.can_redo


def test_the_nearest_snap_within_the_radius_wins_and_none_beyond_it():
    face = Snap("face centre", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1e-4)
    edge = Snap("edge midpoint", (0.01, 0.0, 0.0), (1.0, 0.0, 0.0), 0.02)
    hole = Snap("hole axis", (0.1, 0.0, 0.0), (0.0, 1.0, 0.0), 0.005)
    rim = Snap("edge midpoint", (0.1049, 0.0, 0.0), (0.0, 0.0, 1.0), 0.002)  # on the hole's rim
    candidates = [(s, np.array(s.point), np.array(s.axis)) for s in (face, edge, hole, rim)]
    assert nearest_snap(candidates, (0.004, 0.0, 0.0)) == 0
    assert nearest_snap(candidates, (0.006, 0.003, 0.0)) == 1
    assert nearest_snap(candidates, (0.0, 0.0, SNAP_RADIUS * 0.99)) == 0
    assert nearest_snap(candidates, (0.0, 0.0, -SNAP_RADIUS * 1.01)) is None  # beyond: nothing
    assert nearest_snap(candidates, (0.05, 0.0, 0.0)) is None
    # a drop in a hole's mouth takes the hole, even right by a midpoint of its rim
    assert nearest_snap(candidates, (0.1045, 0.0, 0.0)) == 2
    assert nearest_snap(candidates, (0.1 + 0.005 + 0.014, 0.0, 0.0)) == 2  # 14 mm off its rim
    assert nearest_snap(candidates, (0.1 + 0.005 + 0.016, 0.0, 0.0)) is None
    assert nearest_snap(candidates[3:], (0.1045, 0.0, 0.0)) == 0  # the rim alone: reachable
    assert nearest_snap(candidates, (0.1, 0.014, 0.0)) == 2  # 14 mm along the axis
    assert nearest_snap(candidates, (0.1, 0.016, 0.0)) is None
    assert nearest_snap(candidates, (0.0, 0.0, 0.01), radius=0.005) is None


def test_a_gizmo_dropped_by_a_hole_snaps_the_joint_frame_onto_its_axis(tmp_path):
    session = EditSession.open(tmp_path / "work", name="two")
    for link in ("arm_upper", "arm_fore"):
        path = DATA / "editor" / f"{link}.stl"
        session.import_part(path.name, path.read_bytes())
    session.fix_to_world("arm_upper")
    face = next((p, a) for s, p, a in session.snaps("arm_fore") if s.kind == "face centre")
    session.add_joint("elbow", "arm_upper", "arm_fore", "revolute", *face)
    step, origin = session.index, session.joint("elbow").origin
    far = face[0] + np.array([0.0, -0.05, 0.0])  # 5 cm in front of the face: no snap
    assert session.snap_joint_near("elbow", far) is None
    assert session.index == step and session.joint("elbow").origin == origin
    hole = np.array([0.15, -0.01, 0.1])  # the forearm's hole, front end; axis -y
    snap = session.snap_joint_near("elbow", hole + [0.003, -0.004, 0.002])
    assert snap.kind == "hole axis" and session.index == step + 1  # one undoable step
    frame = session.world_frames()["arm_fore"]
    np.testing.assert_allclose(frame[:3, 3], hole, atol=1e-9)
    np.testing.assert_allclose(frame[:3, :3] @ session.joint("elbow").axis, (0.0, -1.0, 0.0), atol=1e-9)
    with pytest.raises(InputError, match="gizmo position NaN must be a finite number"):
        session.snap_joint_near("elbow", (np.nan, 0.0, 0.0))
    session.undo()
    assert session.joint("elbow").origin == origin


def test_units_and_names_of_imported_parts():
    assert guess_unit(150.0) == "mm"
    assert guess_unit(0.15) == "m"
    assert guess_unit(15.0) == "cm"
    assert safe_name("../../etc/passwd.stl") == "passwd"
    assert safe_name("Upper Arm.STL", taken={"upper_arm"}) == "upper_arm_2"
    with pytest.raises(InputError, match="not an STL"):
        read_part("x.exe", b"MZ")
    with pytest.raises(InputError, match="unreadable|no triangles"):
        read_part("x.stl", b"solid nothing\nendsolid\n")


def test_every_collision_shape_fits(tmp_path):
    session = EditSession.open(tmp_path / "s")
    data = (DATA / "editor" / "arm_upper.stl").read_bytes()
    link = session.import_part("arm_upper.stl", data, unit="mm")
    kinds = {"box": [Box], "sphere": [Sphere], "cylinder": [Cylinder],
             "capsule": [Cylinder, Sphere, Sphere], "mesh": [Mesh], "convex hull": [Mesh]}
    for shape, types in kinds.items():
        session.fit_collision(link, shape)
        assert [type(c.geometry) for c in session.model.links[link].collisions] == types
    hull = session.model.links[link].collisions[0].geometry
    assert (session.folder / hull.filename).is_file()
    assert not [f for f in session.findings() if f.severity == "error"]
    with pytest.raises(InputError):
        session.fit_collision(link, "teapot")


def test_bad_edits_are_refused_and_leave_no_step(arm, tmp_path):
    shutil.copytree(arm[0].folder, tmp_path / "copy")
    session = EditSession.open(tmp_path / "copy")
    index = session.index
    for bad in (lambda: session.add_joint("loop", "arm_fore", "arm_base", "revolute", (0, 0, 0), (0, 1, 0)),
                lambda: session.add_joint("x y", "arm_base", "arm_fore", "revolute", (0, 0, 0), (0, 1, 0)),
                lambda: session.set_inertial("arm_fore", -1, (0, 0, 0), (1, 0, 0, 1, 0, 1)),
                lambda: session.set_inertial("arm_fore", 1, (0, 0, float("nan")), (1, 0, 0, 1, 0, 1)),
                lambda: session.set_joint("elbow", axis=(0, 0, 0)),
                lambda: session.set_motor("nope"),
                lambda: session.set_surface("arm_fore", kp=0.0)):
        with pytest.raises(InputError):
            bad()
    assert session.index == index


def test_moving_a_mex_one_joint_frame_3cm_is_flagged_and_undo_clears_it(tmp_path, monkeypatch):
    session = EditSession.open(tmp_path / "mex", mex_one.urdf_path())
    assert session.findings() == []
    joint = session.model.joints["l_shoulder_pitch"]
    moved = Pose(tuple(np.add(joint.origin.xyz, (0.0, 0.03, 0.0))), joint.origin.rpy)
    session.move_joint_frame("l_shoulder_pitch", moved)
    flagged = [f for f in session.findings() if f.element == 'joint "l_shoulder_pitch"']
    assert [f.code for f in flagged] == ["joint-off-junction"]
    session.undo()
    assert session.findings() == []


def test_a_gazebo_model_editor_sdf_saves_as_convert_writes_it(tmp_path):
    source = DATA / "sdf" / "arm_editor"
    session = EditSession.open(tmp_path / "s", source)
    save_urdf(session, tmp_path / "editor.urdf")
    assert main(["convert", str(source), "-o", str(tmp_path / "convert.urdf")]) == 0
    # compared as models: convert writes a 1e-17 rounding residue as an explicit zero <origin>
    editor, convert = (write_urdf(read_urdf(tmp_path / f"{n}.urdf")) for n in ("editor", "convert"))
    assert editor == convert
    assert "model://arm_editor/meshes/part.stl" in editor


def test_editing_a_mex_one_joint_s_damping_changes_what_it_simulates_with(tmp_path):
    """Mex-One states its joints' damping twice (URDF <dynamics> and the <gazebo> block, which
    wins): an edit sets both, so the saved file says one thing and `check` finds no conflict."""
    from mexone.description.model import Dynamics

    session = EditSession.open(tmp_path / "mex", mex_one.urdf_path())
    assert "l_elbow" in session.model.gazebo_joints
    session.set_joint("l_elbow", dynamics=Dynamics(0.9, 0.05, 0.0))
    assert session.model.joint_dynamics("l_elbow").damping == pytest.approx(0.9)
    assert [f.code for f in session.findings() if f.code == "value-conflict"] == []
