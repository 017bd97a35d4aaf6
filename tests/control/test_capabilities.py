"""Front ends ask a controller what it can do (its capabilities), never its kind string, class or
type name: a new controller type that holds a position is driven by the page's Home, the IK
handles and the step response without touching them."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mexone.control.controllers import CONTROLLER_TYPES, ControllerInterface
from mexone.control.spec import ControllerSpec
from mexone.lab import Lab

SRC = Path(__file__).resolve().parents[2] / "src" / "mexone"
KINDS = "position|velocity|effort|trajectory|state|python"
# `x.kind == "position"`, `kind in ("position", "trajectory")`, `kind != 'state'`, ...
KIND_COMPARISON = re.compile(
    rf"""(?<!for )kind\s*(==|!=|\bin\b|\bnot in\b)\s*[(\[{{]?\s*["']({KINDS})["']""")
# `type.endswith("JointPositionController")`: a type name's suffix standing for what it does
TYPE_SUFFIX = re.compile(r"""endswith\(\s*["'][A-Za-z_]*Controller["']""")


def test_no_front_end_compares_controller_kinds_or_type_names():
    found = []
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC)
        if rel.parts[0] == "control" or rel.parts[:3] == ("robots", "mex_one", "routines"):
            continue  # control/ keeps its own labels; shipped routines are ROS programs
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if KIND_COMPARISON.search(line) or TYPE_SUFFIX.search(line):
                found.append(f"{rel}:{number}: {line.strip()}")
    assert found == []


def test_the_greps_find_what_they_look_for():
    assert KIND_COMPARISON.search('if ctrl.kind == "position":')
    assert KIND_COMPARISON.search("c.kind in ('position', 'trajectory')")
    assert KIND_COMPARISON.search('if c.kind != "state"')
    assert not KIND_COMPARISON.search('if snap.kind == "hole axis"')
    assert not KIND_COMPARISON.search('for kind in ("position", "velocity"):')  # a loop
    assert TYPE_SUFFIX.search('str(params.get("type")).endswith("JointPositionController")')


EXPECTED = {  # type suffix -> (holds_position, takes_trajectories, tracks_position, drives_joints)
    "JointPositionController": (True, False, True, True),
    "JointGroupPositionController": (True, False, True, True),
    "JointTrajectoryController": (False, True, True, True),
    "JointVelocityController": (False, False, False, True),
    "JointGroupVelocityController": (False, False, False, True),
    "JointEffortController": (False, False, False, True),
    "JointGroupEffortController": (False, False, False, True),
    "JointStateController": (False, False, False, False),
}


@pytest.mark.parametrize("name", sorted(CONTROLLER_TYPES))
def test_each_shipped_type_declares_what_it_does(name):
    cls = CONTROLLER_TYPES[name].cls
    want = EXPECTED[name.split("/")[-1]]
    assert (cls.holds_position, cls.takes_trajectories, cls.tracks_position,
            cls.drives_joints) == want
    assert not cls.reloadable  # only a Python controller's code is imported again


def test_a_running_lab_answers_through_its_controllers():
    lab = Lab.create()
    manager = lab.manager
    held = [c for c in manager.controllers.values() if c.holds_position]
    assert held and all(c.tunable for c in held)  # Mex-One's PID position controllers
    assert [c.name for c in manager.controllers.values() if not c.drives_joints] == \
        ["joint_state_controller"]
    spec = manager.config.controllers["l_elbow_position_controller"]
    assert spec.controller_class.holds_position and spec.kind == "position"
    assert ControllerInterface.tunable.fget is not None  # a property: gains can come and go (ideal servo)


def test_a_python_controller_is_reloadable_and_names_its_file(tmp_path):
    from mexone.control.skeleton import skeleton_files

    for name, text in skeleton_files("my_pd").items():
        (tmp_path / name).write_text(text)
    lab = Lab.create(controllers=tmp_path / "controllers.yaml")
    runner = lab.manager.controllers["my_pd_controller"]
    assert runner.reloadable and not runner.holds_position and runner.drives_joints
    assert Path(runner.code_file).resolve() == (tmp_path / "my_pd.py").resolve()
    assert set(runner.declared_params()) == set(runner.params)
    spec: ControllerSpec = lab.manager.config.controllers["my_pd_controller"]
    assert spec.controller_class.reloadable
