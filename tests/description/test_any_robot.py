"""Real robot packages load as urdfdom loads them: fixed joints with a zero axis, $(find) and
package:// through one resolver, named and Gazebo materials, <mimic>."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from helpers import run_cli
from mexone.description.loader import load_model
from mexone.description.materials import display_rgba
from mexone.physics.compile import compile_model


def mexone(*args, cwd: Path, env=None) -> subprocess.CompletedProcess:
    """`mexone ARGS` in-process (one import of the verbs, not a Python start-up per call)."""
    code, stdout, stderr = run_cli(list(args), cwd=cwd, env=env)
    assert "Traceback" not in stderr, stderr
    return subprocess.CompletedProcess(args, code, stdout, stderr)


def test_fixed_joint_with_zero_axis_loads_as_urdfdom_loads_it(humanoid):
    text = humanoid.read_text()
    assert '<joint name="imu_joint" type="fixed">' in text and '<axis xyz="0 0 0"/>' in text
    robot = load_model(humanoid)
    assert robot.joints["imu_joint"].type == "fixed"
    compile_model(robot)  # MuJoCo builds it too
    tool = shutil.which("check_urdf")
    if tool is None:
        pytest.skip("check_urdf not installed (Debian liburdfdom-tools)")
    assert subprocess.run([tool, str(humanoid)], capture_output=True).returncode == 0


def test_a_moving_joint_with_zero_axis_is_still_refused(tmp_path):
    path = tmp_path / "r.urdf"
    path.write_text('<robot name="r"><link name="a"><inertial><mass value="1"/><inertia ixx="1" '
                    'ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link><link name="b">'
                    '<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" '
                    'izz="1"/></inertial></link>\n<joint name="j" type="revolute"><parent link="a"/>'
                    '<child link="b"/>\n<axis xyz="0 0 0"/><limit lower="-1" upper="1" effort="1" '
                    'velocity="1"/></joint></robot>')
    out = mexone("check", "r.urdf", cwd=tmp_path)
    assert out.returncode == 2 and out.stderr.startswith("mexone: r.urdf:3: <axis> has a zero axis")


def test_named_materials_and_gazebo_material_names_colour_the_robot(humanoid):
    robot = load_model(humanoid)
    pelvis, head, shank = (robot.links[n].visuals[0] for n in ("pelvis", "head", "l_shank"))
    assert pelvis.rgba == (0.9, 0.9, 0.9, 1.0)  # <material name="white"/> -> the robot's white
    assert shank.rgba == (0.2, 0.2, 0.2, 1.0)
    assert display_rgba(robot, "head", head)[:3] == (1.0, 0.51, 0.05)  # Gazebo/Orange wins
    model = compile_model(robot).model
    assert tuple(model.geom("l_shank/visual/0").rgba) == pytest.approx((0.2, 0.2, 0.2, 1.0))
    assert tuple(model.geom("head/visual/0").rgba[:3]) == pytest.approx((1.0, 0.51, 0.05))


def test_an_inline_material_can_be_named_again_later(tmp_path):
    path = tmp_path / "r.urdf"
    box = '<geometry><box size="0.1 0.1 0.1"/></geometry>'
    path.write_text(f'<robot name="r"><link name="a"><visual>{box}<material name="red"><color '
                    f'rgba="1 0 0 1"/></material></visual><visual>{box}<material name="red"/>'
                    '</visual></link></robot>')
    robot = load_model(path)
    assert [v.rgba for v in robot.links["a"].visuals] == [(1, 0, 0, 1), (1, 0, 0, 1)]


def test_package_uris_resolve_without_package_xml_by_folder_name(tmp_path):
    """A repository without package.xml: package://name is the ancestor folder called name, as
    Gazebo's model path finds it; the same resolver as $(find name)."""
    import trimesh

    root = tmp_path / "repo" / "robots" / "biped_description"
    (root / "meshes").mkdir(parents=True)
    (root / "urdf").mkdir()
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(root / "meshes" / "part.stl")
    (root / "urdf" / "r.urdf.xacro").write_text(
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="a"><inertial>'
        '<mass value="1"/><inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.002"/>'
        '</inertial><visual><geometry><mesh filename="package://biped_description/meshes/part.stl"/>'
        '</geometry></visual><collision><geometry>'
        '<mesh filename="$(find biped_description)/meshes/part.stl"/></geometry></collision>'
        '</link></robot>')
    out = mexone("check", "urdf/r.urdf.xacro", cwd=root)
    assert out.returncode == 0, out.stdout + out.stderr
    robot = load_model(root / "urdf" / "r.urdf.xacro")
    assert robot.links["a"].collisions[0].geometry.filename == str(root / "meshes" / "part.stl")


def test_ros_package_path_wins_over_the_folders_above(tmp_path, monkeypatch):
    from mexone.description.packages import find_package

    for where in ("a", "b"):
        folder = tmp_path / where / "biped_description"
        folder.mkdir(parents=True)
        (folder / "package.xml").write_text("<package><name>biped_description</name></package>")
    near = tmp_path / "b" / "biped_description"
    assert find_package("biped_description", near) == near
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "a"))
    assert find_package("biped_description", near) == tmp_path / "a" / "biped_description"


def _xacro_package(folder: Path, name: str) -> None:
    """A ROS package in `folder` named `name` (package.xml), with a xacro macro and a mesh."""
    import trimesh

    (folder / "urdf").mkdir(parents=True)
    (folder / "meshes").mkdir()
    (folder / "package.xml").write_text(f"<package format='2'><name>{name}</name></package>")
    trimesh.creation.box(extents=(0.1, 0.2, 0.3)).export(folder / "meshes" / "part.stl")
    (folder / "urdf" / "parts.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:macro name="part" '
        'params="n"><link name="${n}"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" '
        'ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial><visual><geometry><mesh filename='
        f'"package://{name}/meshes/part.stl"/></geometry></visual></link></xacro:macro></robot>')


def _robot_including(name: str) -> str:
    return ('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
            f'<xacro:include filename="$(find {name})/urdf/parts.xacro"/><xacro:part n="a"/>'
            '</robot>')


def test_xacro_find_walks_up_to_the_package_xml_that_names_the_package(tmp_path):
    """A ROS 1 checkout: the folder is 'op3_description-master', its package.xml says
    'op3_description'; $(find op3_description) and package://op3_description find it."""
    root = tmp_path / "op3_description-master"
    _xacro_package(root, "op3_description")
    robot_file = root / "urdf" / "robot.urdf.xacro"
    robot_file.write_text(_robot_including("op3_description"))
    out = mexone("check", robot_file, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    robot = load_model(robot_file)
    assert robot.links["a"].visuals[0].geometry.filename == "package://op3_description/meshes/part.stl"
    assert compile_model(robot).model.mesh_vertnum.sum() == 8  # the box, found by package://


def test_xacro_find_uses_ros_package_path(tmp_path):
    """The robot's file outside any package; its parts in a workspace on ROS_PACKAGE_PATH."""
    _xacro_package(tmp_path / "ws" / "src" / "deep" / "parts_pkg", "biped_parts")
    robot_file = tmp_path / "elsewhere" / "robot.urdf.xacro"
    robot_file.parent.mkdir()
    robot_file.write_text(_robot_including("biped_parts"))
    out = mexone("check", robot_file, cwd=tmp_path)
    assert out.returncode == 2 and "cannot find package 'biped_parts'" in out.stderr
    assert "ROS_PACKAGE_PATH (not set)" in out.stderr and out.stderr.count("\n") == 1
    out = mexone("check", robot_file, cwd=tmp_path,
                 env={"ROS_PACKAGE_PATH": str(tmp_path / "ws" / "src")})
    assert out.returncode == 0, out.stdout + out.stderr
    out = mexone("sim", robot_file, "--headless", "--duration", "0.1", "--no-controllers",
                 cwd=tmp_path, env={"ROS_PACKAGE_PATH": str(tmp_path / "ws" / "src")})
    assert out.returncode == 0, out.stdout + out.stderr


def test_findings_on_a_xacro_robot_carry_no_line_of_the_expanded_document(tmp_path):
    """xacro's output has other lines than its source: a finding names the element, not a line
    that points somewhere else in the .xacro."""
    import json

    root = tmp_path / "op3_description"
    _xacro_package(root, "op3_description")
    robot_file = root / "urdf" / "robot.urdf.xacro"
    robot_file.write_text(_robot_including("op3_description").replace(
        "</robot>", '<link name="b"><visual><geometry><mesh filename="package://op3_description'
                    '/meshes/gone.stl"/></geometry></visual></link><joint name="j" type="fixed">'
                    '<parent link="a"/><child link="b"/></joint></robot>'))
    out = mexone("check", robot_file, cwd=tmp_path)
    assert out.returncode == 1
    missing = [line for line in out.stdout.splitlines() if "[mesh-missing]" in line]
    assert missing == ['  error: link "b": visual mesh file '
                       f"'{root / 'meshes' / 'gone.stl'}' does not exist (check the filename and "
                       "path) [mesh-missing]"]
    out = mexone("check", robot_file, "--json", cwd=tmp_path)
    finding = next(f for f in json.loads(out.stdout)["findings"] if f["code"] == "mesh-missing")
    assert finding["line"] is None and finding["file"] == str(robot_file)


# ----- check that people trust on real robots ---------------------------------------------------
def _check(path: Path, *args) -> tuple[int, list[dict]]:
    import json

    out = mexone("check", path, "--json", *args, cwd=path.parent)
    return out.returncode, json.loads(out.stdout)["findings"]


def _add_links(path: Path, xml: str) -> None:
    path.write_text(path.read_text().replace("</robot>", xml + "</robot>"))


def test_a_1_g_dummy_link_with_its_com_off_is_info_not_an_error(humanoid):
    _add_links(humanoid, '<link name="logo_link"><inertial><origin xyz="0.3 0 0"/><mass value="0.001"/>'
                         '<inertia ixx="1e-7" ixy="0" ixz="0" iyy="1e-7" iyz="0" izz="1e-7"/></inertial>'
                         '<visual><geometry><box size="0.05 0.05 0.001"/></geometry></visual></link>'
                         '<joint name="logo_joint" type="fixed"><parent link="torso"/>'
                         '<child link="logo_link"/></joint>')
    code, findings = _check(humanoid)
    assert code == 0
    logo = [f for f in findings if f["element"] == 'link "logo_link"']
    assert [(f["code"], f["severity"]) for f in logo] == [("com-outside", "info")]
    # the same offset on a heavy link is an error with its file and line
    humanoid.write_text(humanoid.read_text().replace('<mass value="0.001"/>', '<mass value="5"/>'))
    code, findings = _check(humanoid)
    logo = next(f for f in findings if f["element"] == 'link "logo_link"')
    assert code == 1 and logo["severity"] == "error"
    assert logo["file"] == str(humanoid) and logo["line"] == humanoid.read_text().count(
        "\n", 0, humanoid.read_text().index('<link name="logo_link">')) + 1


def test_collision_pad_inside_its_visual_is_not_misplaced(humanoid):
    box = '<inertial><mass value="0.2"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>'
    _add_links(humanoid, f'<link name="tip">{box}<visual><geometry><box size="0.02 0.02 0.06"/>'
                         '</geometry></visual><collision><origin xyz="0 0 -0.025"/><geometry><box '
                         'size="0.018 0.018 0.008"/></geometry></collision></link>'
                         '<joint name="tip_joint" type="fixed"><parent link="l_hand"/><child link="tip"/>'
                         '</joint>'
                         f'<link name="chest">{box}<visual><geometry><box size="0.1 0.1 0.1"/></geometry>'
                         '</visual><collision><origin xyz="0.04 0 0.03"/><geometry><box '
                         'size="0.2 0.14 0.18"/></geometry></collision></link>'
                         '<joint name="chest_joint" type="fixed"><parent link="torso"/>'
                         '<child link="chest"/></joint>'
                         f'<link name="away">{box}<visual><geometry><box size="0.05 0.05 0.05"/></geometry>'
                         '</visual><collision><origin xyz="0.2 0 0.3"/><geometry><box '
                         'size="0.05 0.05 0.05"/></geometry></collision></link>'
                         '<joint name="away_joint" type="fixed"><parent link="torso"/>'
                         '<child link="away"/></joint>')
    _, findings = _check(humanoid)
    misplaced = [f["element"] for f in findings if f["code"] == "collision-misplaced"]
    assert misplaced == ['link "away"']  # the seed's Fig. 4.6 still is


def test_capital_names_are_one_summary_line(humanoid):
    text = humanoid.read_text()
    for name in ("l_hand", "r_hand", "l_wrist", "r_wrist", "l_forearm"):
        text = text.replace(f'"{name}"', f'"{name.upper()}"')
    humanoid.write_text(text)
    code, findings = _check(humanoid)
    capitals = [f for f in findings if f["code"] == "name-capitals"]
    assert code == 0 and len(capitals) == 1 and capitals[0]["severity"] == "info"
    assert capitals[0]["element"] == "5 links and joints"


def test_controller_findings_name_the_yaml_and_its_line(humanoid, tmp_path):
    (tmp_path / "c.yaml").write_text("biped:\n  knee:\n    type: effort_controllers/JointPositionController\n"
                                     "    joint: l_knee\n    pid: {p: 10}\n")
    out = mexone("check", humanoid, "--controllers", tmp_path / "c.yaml", cwd=tmp_path)
    line = next(x for x in out.stdout.splitlines() if "controller-no-transmission" in x)
    assert line.strip().startswith(f"{tmp_path / 'c.yaml'}:2: error:")
    code, findings = _check(humanoid, "--controllers", tmp_path / "c.yaml")
    found = next(f for f in findings if f["code"] == "controller-no-transmission")
    assert (found["file"], found["line"]) == (str(tmp_path / "c.yaml"), 2)


def test_a_missing_mesh_names_file_and_line_in_check_and_sim(humanoid):
    humanoid.write_text(humanoid.read_text().replace(
        '<visual><origin xyz="0 0 0.1"/><geometry><box size="0.16 0.16 0.18"/>',
        '<visual><origin xyz="0 0 0.1"/>\n<geometry><mesh filename="gone.stl"/>'))
    line = humanoid.read_text().splitlines().index(
        next(x for x in humanoid.read_text().splitlines() if "gone.stl" in x)) + 1
    code, findings = _check(humanoid)
    missing = next(f for f in findings if f["code"] == "mesh-missing")
    assert code == 1 and missing["line"] == line - 1  # the <visual> that names it
    out = mexone("sim", humanoid, "--headless", "--duration", "0.01", cwd=humanoid.parent)
    assert out.returncode == 2 and out.stderr.startswith(f"mexone: {humanoid}:{line - 1}: mesh file")


# ----- convert faithfully ----------------------------------------------------------------------
def test_mjcf_export_to_another_folder_runs_the_same_robot_in_plain_mujoco(tmp_path,
                                                                          humanoid_with_mesh):
    import mujoco
    import numpy as np

    urdf = humanoid_with_mesh
    (tmp_path / "export").mkdir()
    out = mexone("convert", urdf, "-o", tmp_path / "export" / "biped.xml", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "lint error" not in out.stdout
    text = (tmp_path / "export" / "biped.xml").read_text()
    assert 'file="../ws/src/biped_description/meshes/pelvis.stl"' in text  # relative to OUT
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "export" / "biped.xml"))  # MuJoCo's loader
    assert model.nu > 0 and model.nmesh >= 1
    data = mujoco.MjData(model)
    start = data.qpos.copy()
    mujoco.mj_step(model, data, 3000)  # 3 s, no mexone: the actuators hold it by themselves
    assert abs(data.qpos[2] - start[2]) < 0.01
    assert np.abs(data.qpos[7:] - start[7:]).max() < 0.02


def test_urdf_sdf_urdf_keeps_massless_links_massless(tmp_path, humanoid):
    from mexone.description.loader import load_model as load

    before = load(humanoid).mass
    assert mexone("convert", humanoid, "-o", tmp_path / "b.sdf", cwd=tmp_path).returncode == 0
    out = mexone("convert", tmp_path / "b.sdf", "-o", tmp_path / "b.urdf", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    after = load(tmp_path / "b.urdf")
    assert after.mass == pytest.approx(before, abs=1e-9)  # not 1 kg more per frame link
    assert "imu_link" not in after.links  # merged into torso, as sdformat merges it


def test_convert_counts_lint_errors_as_check_does(tmp_path):
    import trimesh

    src = tmp_path / "src"
    (src / "meshes").mkdir(parents=True)
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(src / "meshes" / "part.stl")
    (src / "r.urdf").write_text(
        '<robot name="r"><link name="a"><inertial><origin xyz="1 0 0"/><mass value="1"/><inertia '
        'ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.002"/></inertial><visual><geometry>'
        '<mesh filename="meshes/part.stl"/></geometry></visual><collision><geometry>'
        '<mesh filename="meshes/part.stl"/></geometry></collision></link></robot>')
    check = mexone("check", src / "r.urdf", cwd=tmp_path)
    errors = check.stdout.count(": error: ")
    assert errors == 1  # the COM one metre away
    (tmp_path / "out").mkdir()
    for name in ("r.urdf", "r.sdf", "r.xml"):
        out = mexone("convert", src / "r.urdf", "-o", tmp_path / "out" / name, cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        assert f"; {errors} lint error(s), run 'mexone check {src / 'r.urdf'}'" in out.stdout
