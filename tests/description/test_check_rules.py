"""Every lint rule of `mexone check`, proven by a deliberately broken Mex-One."""

from __future__ import annotations

import copy
import json

import pytest
from lxml import etree

from mexone.cli import main
from mexone.control.config import parse_control_config
from mexone.control.lint import lint_controllers
from mexone.description.check import check_model
from mexone.description.loader import load_model
from mexone.robots import mex_one


@pytest.fixture(autouse=True)
def _find_package(monkeypatch):
    # the broken copies live in tmp folders: let package://mex_rb resolve like ROS would
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(mex_one.package_dir()))


def broken(tmp_path, edit, name="broken.urdf"):
    root = etree.parse(str(mex_one.urdf_path())).getroot()
    edit(root)
    path = tmp_path / name
    path.write_bytes(etree.tostring(root))
    return path


def findings_of(path, controllers=None):
    model = load_model(path)
    return check_model(model) + (lint_controllers(model, controllers) if controllers else [])


def link(root, name):
    return root.find(f"link[@name='{name}']")


def joint(root, name):
    return root.find(f"joint[@name='{name}']")


def set_attr(path_el, **attrs):
    for key, value in attrs.items():
        path_el.set(key, value)


def shift_joint_keep_body(root):
    """Move the elbow 0.3 m down but the forearm's body with it up: same look, wrong pivot."""
    joint(root, "l_elbow").find("origin").set("xyz", "0 0 -0.47")
    for el in link(root, "l_forearm").iter("origin"):
        x, y, z = (float(v) for v in el.get("xyz").split())
        el.set("xyz", f"{x} {y} {z + 0.3}")
    visual = link(root, "l_forearm").find("visual")
    etree.SubElement(visual, "origin", xyz="0 0 0.3", rpy="0 0 0")


def shift_frame_keep_parts(root, name="l_shoulder_pitch", dy=0.03):
    """Move a joint's frame 3 cm sideways, its child's parts staying where they were (what the
    editor's gizmo does): the pivot is now beside the shoulder, off where the parts meet."""
    el = joint(root, name)
    x, y, z = (float(v) for v in el.find("origin").get("xyz").split())
    el.find("origin").set("xyz", f"{x} {y + dy} {z}")
    child = el.find("child").get("link")
    holders = list(link(root, child)) + [j for j in root.findall("joint")
                                         if j.find("parent").get("link") == child]
    for item in holders:
        origin = item.find("origin")
        if origin is None:
            origin = etree.SubElement(item, "origin", xyz="0 0 0", rpy="0 0 0")
        x, y, z = (float(v) for v in origin.get("xyz", "0 0 0").split())
        origin.set("xyz", f"{x} {y - dy} {z}")


def garbage_mesh(root, tmp_path):
    (tmp_path / "bad.stl").write_bytes(b"this is not a mesh")
    link(root, "head").find("visual/geometry/mesh").set("filename", "bad.stl")


def duplicate(root, kind, name):
    root.append(copy.deepcopy(root.find(f"{kind}[@name='{name}']")))


CASES = {
    "mass-nonpositive": ('link "pelvis"',
                         lambda r: link(r, "pelvis").find("inertial/mass").set("value", "0")),
    "inertia-not-positive": ('link "head"',
                             lambda r: link(r, "head").find("inertial/inertia").set("ixx", "-0.01")),
    "inertia-triangle": ('link "head"', lambda r: set_attr(
        link(r, "head").find("inertial/inertia"), ixx="0.0001", iyy="0.0001", izz="0.01")),
    "inertia-too-large": ('link "head"', lambda r: set_attr(  # the seed's Fig. 4.7
        link(r, "head").find("inertial/inertia"), ixx="5", iyy="5", izz="5")),
    "com-outside": ('link "head"',
                    lambda r: link(r, "head").find("inertial/origin").set("xyz", "0.3 0 0")),
    "collision-misplaced": ('link "head"',  # the seed's Fig. 4.6
                            lambda r: link(r, "head").find("collision/origin").set("xyz", "0.2 0 0.3")),
    "joint-misplaced": ('joint "l_elbow"', shift_joint_keep_body),
    "joint-off-junction": ('joint "l_shoulder_pitch"', shift_frame_keep_parts),
    "mesh-missing": ('link "head"', lambda r: link(r, "head").find("visual/geometry/mesh").set(
        "filename", "package://mex_rb/meshes/nope.stl")),
    "mesh-units": ('link "torso"',
                   lambda r: link(r, "torso").find("visual/geometry/mesh").set("scale", "1 1 1")),
    "effort-limit": ('joint "l_elbow"',  # the seed's Listing 3.9
                     lambda r: joint(r, "l_elbow").find("limit").set("effort", "-1")),
    "velocity-limit": ('joint "l_elbow"',
                       lambda r: joint(r, "l_elbow").find("limit").set("velocity", "0")),
    "limit-range": ('joint "l_knee"', lambda r: set_attr(joint(r, "l_knee").find("limit"),
                                                         lower="1", upper="-1")),
    "dynamics-negative": ('joint "l_knee"',
                          lambda r: joint(r, "l_knee").find("dynamics").set("damping", "-0.5")),
    "name-capitals": ('robot "Mex_RB"', lambda r: r.set("name", "Mex_RB")),
    "duplicate-name": ('joint "l_knee"', lambda r: duplicate(r, "joint", "l_knee")),
    "gazebo-unknown-reference": ('<gazebo reference="hed">',
                                 lambda r: r.find("gazebo[@reference='head']").set("reference", "hed")),
    "multiple-roots": ('robot "mex_rb"', lambda r: etree.SubElement(r, "link", name="loose")),
    "loop": ('joint "extra"', lambda r: r.append(etree.fromstring(
        '<joint name="extra" type="fixed"><parent link="torso"/><child link="l_foot"/></joint>'))),
    "transmission-unknown-joint": ('transmission "l_elbow_transmission"', lambda r: r.find(
        "transmission[@name='l_elbow_transmission']/joint").set("name", "nope")),
    "transmission-fixed-joint": ('transmission "neck_pitch_transmission"',
                                 lambda r: joint(r, "neck_pitch").set("type", "fixed")),
    "transmission-reduction": ('transmission "l_elbow_transmission"', lambda r: setattr(r.find(
        "transmission[@name='l_elbow_transmission']/actuator/mechanicalReduction"), "text", "0")),
    "inertial-missing": ('link "head"',
                         lambda r: link(r, "head").remove(link(r, "head").find("inertial"))),
}


def test_the_shipped_model_is_clean():
    assert findings_of(mex_one.urdf_path()) == []


@pytest.mark.parametrize("code", sorted(CASES))
def test_rule_fires_on_its_broken_model(tmp_path, code):
    element, edit = CASES[code]
    path = broken(tmp_path, edit)
    found = [(f.code, f.element) for f in findings_of(path)]
    assert (code, element) in found, found


def test_unreadable_mesh(tmp_path):
    path = broken(tmp_path, lambda r: garbage_mesh(r, tmp_path))
    found = [(f.code, f.element) for f in findings_of(path)]
    assert ("mesh-unreadable", 'link "head"') in found


def test_mesh_already_in_metres_but_scaled(tmp_path):
    path = broken(tmp_path, lambda r: link(r, "head").find("visual/geometry/mesh").set(
        "scale", "0.000001 0.000001 0.000001"))
    assert "mesh-units" in {f.code for f in findings_of(path)}


def test_cycle_without_a_root(tmp_path):
    path = tmp_path / "cycle.urdf"
    path.write_text("""<robot name="c">
      <link name="a"/><link name="b"/>
      <joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>
      <joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint></robot>""")
    assert "loop" in {f.code for f in findings_of(path)}


CONTROLLERS = """
mex_rb:
  joint_state_controller: {type: joint_state_controller/JointStateController, publish_rate: 50}
  ghost_controller: {type: effort_controllers/JointPositionController, joint: l_wing, pid: {p: 1}}
  elbow_controller:
    type: position_controllers/JointPositionController
    joint: l_elbow
    pid: {p: 2.0, i: 0.5, d: 0.1}
"""


def test_controller_rules(tmp_path):
    tx = "transmission[@name='l_knee_transmission']"
    path = broken(tmp_path, lambda r: r.remove(r.find(tx)))
    config = parse_control_config(CONTROLLERS + """
  knee_controller: {type: effort_controllers/JointPositionController, joint: l_knee, pid: {p: 1}}
""")
    found = {(f.code, f.element) for f in findings_of(path, config)}
    assert ("controller-unknown-joint", 'controller "ghost_controller"') in found
    assert ("controller-no-transmission", 'controller "knee_controller"') in found
    assert ("controller-interface", 'controller "elbow_controller"') in found
    assert ("position-controller-pid", 'controller "elbow_controller"') in found
    assert ("pid-integral-unclamped", 'controller "elbow_controller"') in found


def test_cli_exit_codes_and_json(tmp_path, capsys):
    assert main(["check"]) == 0
    assert capsys.readouterr().out.rstrip().endswith("no problems found")
    path = broken(tmp_path, CASES["com-outside"][1])
    assert main(["check", str(path), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["robot"] == "mex_rb" and report["root"] == "pelvis"
    assert (report["links"], report["joints"], report["actuated"]) == (25, 24, 21)  # + Kinect frames
    assert report["mass"] == pytest.approx(15.0)
    assert {"code": "com-outside", "severity": "error", "element": 'link "head"'}.items() <= \
        report["findings"][0].items()
    assert set(report) == {"robot", "root", "links", "joints", "actuated", "mass", "sensors", "findings"}


def test_findings_name_file_and_line(tmp_path, capsys):
    path = broken(tmp_path, CASES["effort-limit"][1])
    assert main(["check", str(path)]) == 1
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if "[effort-limit]" in x)
    assert line.strip().startswith(f"{path}:") and 'joint "l_elbow"' in line
