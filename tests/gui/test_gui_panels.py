"""The page is panels behind one host interface: every piece is built through the registry,
none imports the app, the app stays the frame loop, the message plumbing and Load, and a panel
for another robot shows that robot's joints (no Mex-One default)."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

from helpers import built_panel
from mexone.gui import panels
from mexone.gui.joints import JointsPanel
from mexone.gui.plots import PlotPanel
from mexone.gui.stepresponse import StepResponse
from mexone.lab import AUTO, Lab

GUI = Path(panels.__file__).parent
MAX_APP_LINES = 300

ARM = """<?xml version="1.0"?>
<robot name="two_link_arm">
  <link name="world"/>
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
  <link name="upper"><inertial><origin xyz="0 0 -0.15"/><mass value="0.5"/><inertia ixx="0.004" iyy="0.004" izz="0.0005" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 -0.15"/><geometry><cylinder radius="0.02" length="0.3"/></geometry></visual></link>
  <link name="fore"><inertial><origin xyz="0 0 -0.1"/><mass value="0.3"/><inertia ixx="0.001" iyy="0.001" izz="0.0002" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 -0.1"/><geometry><cylinder radius="0.015" length="0.2"/></geometry></visual></link>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0 0 1"/></joint>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="15" velocity="5"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0 0 -0.3"/>
    <axis xyz="0 1 0"/><limit lower="-2.5" upper="0.5" effort="8" velocity="5"/></joint>
</robot>
"""


def _gui_modules():
    return sorted(p for p in GUI.glob("*.py") if p.name != "__init__.py")


def test_every_panel_is_built_through_the_registry():
    registered = set(panels.panel_types())
    assert {cls.name for cls in registered} >= {
        "simulation", "view", "joints", "plots", "step_response", "tools", "sensors", "routines",
        "physics", "topics", "controllers", "record", "load", "exercises", "walk_pad",
        "ik_handles", "walk_plan"}
    defined = set()
    for path in _gui_modules():
        module = importlib.import_module(f"mexone.gui.{path.stem}")
        defined |= {cls for _, cls in inspect.getmembers(module, inspect.isclass)
                    if issubclass(cls, panels.Panel) and cls is not panels.Panel
                    and cls.__module__ == module.__name__}
    assert defined <= registered  # no panel the registry does not know
    app = (GUI / "app.py").read_text()
    assert not [cls.__name__ for cls in defined if cls.__name__ in app]  # the app builds none itself


def test_no_panel_imports_the_app_and_the_app_stays_small():
    for path in _gui_modules():
        if path.name == "app.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):  # TYPE_CHECKING imports too
            names = [node.module] if isinstance(node, ast.ImportFrom) else \
                [a.name for a in node.names] if isinstance(node, ast.Import) else []
            assert "mexone.gui.app" not in names, path.name
    assert len((GUI / "app.py").read_text().splitlines()) <= MAX_APP_LINES


def test_no_gui_module_names_a_joint_of_mex_one():
    """A default that names one robot's joint is wrong for every other robot."""
    joints = Lab.create(controllers=False).sim.joint_names
    for path in _gui_modules():
        text = path.read_text()
        assert not [j for j in joints if f'"{j}"' in text or f"'{j}'" in text], path.name


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    viser = pytest.importorskip("viser")
    path = tmp_path_factory.mktemp("arm") / "arm.urdf"
    path.write_text(ARM)
    lab = Lab.create(model=path, controllers=AUTO)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield lab, server
    server.stop()


def test_panels_for_another_robot_show_that_robots_joints(arm):
    lab, server = arm
    joints = built_panel(JointsPanel, server, lab)
    assert [j for (_, j) in joints.sliders] == ["shoulder", "elbow"]
    labels = [f.handle.label for f in joints.host.fields.fields]
    assert labels == [f"{k} ({j})" for j in ("shoulder", "elbow") for k in "pid"]  # Gains
    assert joints.sliders[("elbow_position_controller", "elbow")].min == pytest.approx(-2.5)
    plots = built_panel(PlotPanel, server, lab)
    assert plots.chosen[:2] == [["shoulder/command", "shoulder/position"], ["shoulder/effort"]]
    step = built_panel(StepResponse, server, lab)
    assert tuple(step.joint.options) == ("shoulder", "elbow") and step.joint.value == "shoulder"
    joints.home()  # the page's Home: every held joint's setpoint to 0, through its topic
    lab.sim.step(1)
    assert list(lab.manager.setpoints()) == [0.0, 0.0]
