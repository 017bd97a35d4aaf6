"""`mexone convert`: SDF <-> URDF keeps the robot where it was, to 1e-9, and refuses what
URDF cannot say. Poses are compared with a small SDF evaluator written here, independently of
mexone's own frame code."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from mexone.cli import main
from mexone.description.loader import load_model
from mexone.robots import mex_one

SDF = Path(__file__).parents[1] / "data" / "sdf"
FIXTURES = ["arm_editor/model.sdf", "sdf14_model_axes.sdf", "sdf17_relative_to.sdf",
            "joint_offset.sdf"]


# ----- an independent SDF evaluator --------------------------------------------------------------
def rot(r, p, y):
    cx, sx, cy, sy, cz, sz = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def pose_of(el):
    out = np.eye(4)
    text = el.findtext("pose")
    if text:
        v = [float(x) for x in text.split()]
        out[:3, :3] = rot(*v[3:])
        out[:3, 3] = v[:3]
    return out


class World:
    def __init__(self, path):
        root = etree.parse(str(path)).getroot()
        self.version = float(root.get("version"))
        self.model = root.find("model")
        self.named = {e.get("name"): e for e in self.model if e.tag in ("link", "joint", "frame")}

    def frame(self, name):
        if name in ("", "__model__", "world"):
            return np.eye(4)
        el = self.named[name]
        pose = el.find("pose")
        rel = pose.get("relative_to") if pose is not None else None
        if el.tag == "joint":
            rel = rel or el.findtext("child")
        elif el.tag == "frame":
            rel = rel or el.get("attached_to")
        return self.frame(rel or "") @ pose_of(el)

    def links(self):
        return {e.get("name"): self.frame(e.get("name")) for e in self.model.iterfind("link")}

    def attached(self, link, tag):
        """World poses of a link's <inertial>, <visual> or <collision> elements, in order."""
        el = self.named[link]
        return [self.frame(link) @ pose_of(x) for x in el.iterfind(tag)]

    def joints(self):
        out = {}
        for el in self.model.iterfind("joint"):
            frame = self.frame(el.get("name"))
            xyz = el.find("axis/xyz")
            if xyz is None:
                out[el.get("name")] = (frame[:3, 3], None)
                continue
            axis = np.array([float(v) for v in xyz.text.split()])
            flag = el.findtext("axis/use_parent_model_frame")
            if xyz.get("expressed_in"):
                axis = self.frame(xyz.get("expressed_in"))[:3, :3] @ axis
            elif not (self.version < 1.5 or (flag or "").strip() in ("1", "true")):
                axis = frame[:3, :3] @ axis
            out[el.get("name")] = (frame[:3, 3], axis / np.linalg.norm(axis))
        return out


def convert(src, dst):
    assert main(["convert", str(src), "-o", str(dst)]) == 0
    return dst


# ----- round trips -----------------------------------------------------------------------------
@pytest.mark.parametrize("fixture", FIXTURES)
def test_sdf_urdf_sdf_keeps_bodies_and_joint_axes(tmp_path, fixture):
    urdf = convert(SDF / fixture, tmp_path / "robot.urdf")
    back = convert(urdf, tmp_path / "back.sdf")
    a, b = World(SDF / fixture), World(back)
    model_pose = pose_of(a.model)  # only a world-welded base keeps the model pose
    for name in a.links():
        for tag in ("inertial", "visual", "collision"):
            for pa, pb in zip(a.attached(name, tag), b.attached(name, tag), strict=True):
                np.testing.assert_allclose(_weld(a, model_pose) @ pa, pb, atol=1e-9,
                                           err_msg=f"{name} {tag}")
    ja, jb = a.joints(), b.joints()
    assert set(ja) == set(jb)
    for name, (pos, axis) in ja.items():
        np.testing.assert_allclose(_weld(a, model_pose)[:3, :3] @ pos + _weld(a, model_pose)[:3, 3],
                                   jb[name][0], atol=1e-9, err_msg=name)
        if axis is not None and jb[name][1] is not None:
            np.testing.assert_allclose(_weld(a, model_pose)[:3, :3] @ axis, jb[name][1], atol=1e-9,
                                       err_msg=name)


def _weld(world, model_pose):
    welded = any(j.findtext("parent") == "world" for j in world.model.iterfind("joint"))
    return model_pose if welded else np.eye(4)


@pytest.mark.parametrize("fixture", FIXTURES[:3])
def test_link_frames_survive_when_joints_sit_at_link_origins(tmp_path, fixture):
    """Model-editor output has identity joint poses: then every link's world pose is kept.
    The root is the exception URDF forces: it has no pose of its own, so its frame becomes the
    model frame and its parts carry its pose (the seed's 3.3.2); they are compared above."""
    back = convert(convert(SDF / fixture, tmp_path / "r.urdf"), tmp_path / "r.sdf")
    a, b = World(SDF / fixture), World(back)
    weld = _weld(a, pose_of(a.model))
    root = load_model(SDF / fixture).base_link
    for name, pose in a.links().items():
        if name == root and not a.model.xpath("joint[parent='world']"):
            np.testing.assert_allclose(b.links()[name], np.eye(4), atol=1e-12)
            continue
        np.testing.assert_allclose(weld @ pose, b.links()[name], atol=1e-9, err_msg=name)


def test_link_frame_moves_onto_an_offset_joint(tmp_path):
    """URDF puts a child link's frame at its joint: the SDF joint pose becomes the new frame."""
    urdf = load_model(convert(SDF / "joint_offset.sdf", tmp_path / "o.urdf"))
    world = World(SDF / "joint_offset.sdf")
    np.testing.assert_allclose(urdf.link_frames["b"], world.frame("hinge"), atol=1e-12)


def test_sdf_only_properties_land_in_gazebo_blocks_and_dynamics(tmp_path):
    model = load_model(convert(SDF / "arm_editor/model.sdf", tmp_path / "arm.urdf"))
    link0 = model.gazebo_links["link_0"]
    assert (link0.self_collide, link0.mu1, link0.mu2, link0.kp, link0.kd) == (True, 0.61, 0.47, 1e7, 1)
    assert (link0.max_vel, link0.min_depth, link0.material) == (0.01, 0, "Gazebo/White")
    joint = model.joints["link_0_JOINT_0"]
    assert (joint.dynamics.damping, joint.dynamics.friction) == (0.04, 0.4)
    assert model.gazebo_joints["link_0_JOINT_0"] == joint.dynamics
    assert model.joints["link_1_JOINT_1"].type == "continuous"  # SDF's +-1e16 limits
    assert model.joints["link_1_JOINT_2"].type == "prismatic"
    inertial = model.links["link_0"].inertial  # the seed's Listing 3.2 numbers
    assert inertial.mass == 0.598008 and inertial.inertia[:4] == (0.005, 0, 0, 0.0045)


def test_world_welded_sdf_becomes_urdf_with_world_link(tmp_path):
    model = load_model(convert(SDF / "sdf14_model_axes.sdf", tmp_path / "old.urdf"))
    assert model.root == "world" and model.fixed_to_world
    assert model.joints["weld"].type == "revolute"


def test_converted_urdf_passes_the_real_check_urdf(tmp_path):
    tool = shutil.which("check_urdf")
    if tool is None:
        pytest.skip("check_urdf not installed (Debian liburdfdom-tools)")
    for fixture in FIXTURES:
        urdf = convert(SDF / fixture, tmp_path / (Path(fixture).stem + ".urdf"))
        out = subprocess.run([tool, str(urdf)], capture_output=True, text=True)
        assert out.returncode == 0, (fixture, out.stdout, out.stderr)


def test_mex_one_urdf_sdf_urdf_is_the_same_robot(tmp_path):
    sdf = convert(mex_one.urdf_path(), tmp_path / "mex.sdf")
    again = load_model(convert(sdf, tmp_path / "mex.urdf"))
    original = load_model(mex_one.urdf_path())
    # SDF has no massless link: the Kinect's optical frames fold into its link, as sdformat
    # lumps them (the camera still names its frame_id), and the robot weighs what it weighed
    from mexone.description.convert import merge_massless

    urdf = original
    original, merged = merge_massless(original)
    assert sorted(merged) == ["kinect_depth_optical_frame", "kinect_link", "kinect_rgb_optical_frame"]
    assert list(again.links) == list(original.links)
    assert again.mass == pytest.approx(urdf.mass, abs=1e-9)
    # the Kinect (on the massless kinect_link) is now on the head, in the same place
    before = next(s for s in urdf.sensors if s.name == "kinect")
    after = next(s for s in again.sensors if s.name == "kinect")
    assert (after.link, after.frame) == ("head", "kinect_depth_optical_frame")
    np.testing.assert_allclose(again.link_frames["head"] @ after.pose.matrix,
                               urdf.link_frames["kinect_link"] @ before.pose.matrix, atol=1e-9)
    for name, frame in original.link_frames.items():
        np.testing.assert_allclose(again.link_frames[name], frame, atol=1e-12, err_msg=name)
    for name, joint in original.joints.items():
        other = again.joints[name]
        assert (other.type, other.parent, other.child, other.limit) == \
            (joint.type, joint.parent, joint.child, joint.limit)
        np.testing.assert_allclose(other.axis, joint.axis, atol=1e-12)
        assert again.joint_dynamics(name) == original.joint_dynamics(name)
    for name, props in original.gazebo_links.items():
        got = again.gazebo_links[name]
        assert (got.self_collide, got.mu1, got.mu2, got.kp, got.kd, got.material) == \
            (props.self_collide, props.mu1, props.mu2, props.kp, props.kd, props.material)
    assert again.ros_namespace == "/mex_rb"


def test_xacro_input(tmp_path):
    src = tmp_path / "legs.urdf.xacro"
    src.write_text("""<?xml version="1.0"?>
<robot name="legs" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:property name="len" value="0.3"/>
  <xacro:macro name="leg" params="side y">
    <link name="${side}_leg">
      <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.001"/></inertial>
      <collision><origin xyz="0 0 ${-len/2}"/><geometry><cylinder radius="0.03" length="${len}"/></geometry></collision>
    </link>
    <joint name="${side}_hip" type="revolute">
      <parent link="base"/><child link="${side}_leg"/><origin xyz="0 ${y} 0"/>
      <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="2"/>
    </joint>
  </xacro:macro>
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <xacro:leg side="left" y="0.1"/>
  <xacro:leg side="right" y="${-0.1}"/>
</robot>""")
    model = load_model(convert(src, tmp_path / "legs.urdf"))
    assert set(model.links) == {"base", "left_leg", "right_leg"}
    assert model.joints["right_hip"].origin.xyz == (0, -0.1, 0)
    assert model.links["left_leg"].collisions[0].geometry.length == 0.3


def test_relative_mesh_paths_follow_the_output(tmp_path):
    src = tmp_path / "src"
    (src / "meshes").mkdir(parents=True)
    shutil.copy(SDF / "arm_editor/meshes/part.stl", src / "meshes/part.stl")
    (src / "r.urdf").write_text("""<robot name="r"><link name="a">
      <inertial><mass value="1"/><inertia ixx="0.004" ixy="0" ixz="0" iyy="0.004" iyz="0" izz="0.0003"/></inertial>
      <visual><geometry><mesh filename="meshes/part.stl" scale="0.001 0.001 0.001"/></geometry></visual>
      </link></robot>""")
    (tmp_path / "out").mkdir()
    model = load_model(convert(src / "r.urdf", tmp_path / "out" / "r.urdf"))
    assert model.links["a"].visuals[0].geometry.filename == "../src/meshes/part.stl"
    assert [f.code for f in __import__("mexone.description.check", fromlist=["x"]).check_model(model)] == []


def test_refuses_to_overwrite_without_force(tmp_path, capsys):
    out = tmp_path / "mine.urdf"
    out.write_text("my work")
    assert main(["convert", str(SDF / "joint_offset.sdf"), "-o", str(out)]) == 2
    assert out.read_text() == "my work"
    assert "pass --force" in capsys.readouterr().err
    assert main(["convert", str(SDF / "joint_offset.sdf"), "-o", str(out), "--force"]) == 0
    assert out.read_text().startswith("<?xml")


def test_unknown_output_format(tmp_path, capsys):
    assert main(["convert", str(SDF / "joint_offset.sdf"), "-o", str(tmp_path / "x.dae")]) == 2
    assert "name the output .urdf, .sdf or .xml (MJCF)" in capsys.readouterr().err
