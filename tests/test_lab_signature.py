"""Lab.create means what its signature says: every accepted type of every parameter does what the
docstring promises (one test each), and any other type is an ArgumentTypeError -- a TypeError
and a one-line MexoneError naming the parameter -- raised before anything loads."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mexone.control import ControlConfig
from mexone.control.config import load_control_config
from mexone.description.loader import load_model
from mexone.errors import ArgumentTypeError, InputError, MexoneError
from mexone.lab import AUTO, Lab
from mexone.physics.compile import CompileOptions, Spawn
from mexone.physics.world import World
from mexone.robots import mex_one

YAML = """turntable:
  joint_state_controller: {type: joint_state_controller/JointStateController, publish_rate: 50}
  yaw_controller:
    type: effort_controllers/JointPositionController
    joint: yaw
    pid: {p: 4.0, i: 0.0, d: 0.15}
"""


@pytest.fixture(scope="module")
def files(tmp_path_factory, turntable) -> tuple[Path, Path]:
    """(the turntable's URDF, its controller YAML)."""
    folder = tmp_path_factory.mktemp("lab")
    urdf = turntable[0](folder)
    yaml = folder / "controllers.yaml"
    yaml.write_text(YAML)
    return urdf, yaml


def running(lab: Lab) -> set[str]:
    return {name for name, c in lab.manager.controllers.items() if c.running}


# ----- model ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def builtin() -> Lab:
    return Lab.create()


def test_model_none_is_the_builtin_robot_with_its_controllers(builtin):
    assert builtin.sim.robot.name == "mex_rb"
    assert running(builtin) == set(load_control_config(mex_one.controllers_path()).controllers)


@pytest.mark.parametrize("kind", ["RobotModel", "str", "Path"])
def test_model_as_robot_model_str_or_path(files, kind):
    urdf, _ = files
    model = {"RobotModel": load_model(urdf), "str": str(urdf), "Path": urdf}[kind]
    lab = Lab.create(model)
    assert lab.sim.robot.name == "turntable" and lab.manager is None  # no YAML of its own


# ----- controllers ------------------------------------------------------------------------------
def test_controllers_true_is_the_builtin_robots_yaml():
    lab = Lab.create(controllers=True)
    assert running(lab) == set(load_control_config(mex_one.controllers_path()).controllers)


def test_controllers_true_for_another_robot_says_what_to_pass(files):
    with pytest.raises(ArgumentTypeError, match="pass its controller YAML, a ControlConfig, or 'auto'"):
        Lab.create(files[0], controllers=True)


def test_controllers_false_lets_the_builtin_robot_go_limp():
    lab = Lab.create(controllers=False)
    assert lab.manager is None and "No controllers" in lab.no_controllers


def test_controllers_none_for_another_robot_is_none_with_a_note(files):
    lab = Lab.create(files[0], controllers=None)
    assert lab.manager is None and "no controller YAML was given" in lab.no_controllers


def test_controllers_auto(files):
    lab = Lab.create(files[0], controllers=AUTO)
    assert running(lab) == {"joint_state_controller", "yaw_position_controller"}


@pytest.mark.parametrize("kind", ["str", "Path", "ControlConfig"])
def test_controllers_as_path_or_control_config(files, kind):
    urdf, yaml = files
    given_ = {"str": str(yaml), "Path": yaml, "ControlConfig": load_control_config(yaml)}[kind]
    lab = Lab.create(urdf, controllers=given_)
    assert running(lab) == {"joint_state_controller", "yaw_controller"}


# ----- the other parameters ---------------------------------------------------------------------
@pytest.mark.parametrize("world, step", [(None, 0.001), (World(step=0.002), 0.002)])
def test_world(files, world, step):
    assert Lab.create(files[0], world=world).sim.timestep == step


def test_spawn_and_options(files):
    lab = Lab.create(files[0], spawn=Spawn(joints=(("yaw", 0.5),)), options=CompileOptions(armature=0.1))
    assert lab.sim.joint_positions()[0] == pytest.approx(0.5)
    assert lab.sim.model.dof_armature.max() == pytest.approx(0.1)


@pytest.mark.parametrize("rtf", [None, 0, 2, 0.5])
def test_target_rtf_none_int_or_float(files, rtf):
    assert Lab.create(files[0], target_rtf=rtf).sim.target_rtf == rtf


@pytest.mark.parametrize("period", [None, 0.005, 1])
def test_control_period_none_float_or_int(files, period):
    lab = Lab.create(files[0], controllers=files[1], control_period=period)
    assert lab.manager.control_period == (period or lab.sim.timestep)


@pytest.mark.parametrize("namespace, expected", [(None, "/turntable"), ("/bench", "/bench"), ("arm", "/arm")])
def test_namespace(files, namespace, expected):
    assert Lab.create(files[0], controllers=files[1], namespace=namespace).namespace == expected


@pytest.mark.parametrize("start", [None, ["yaw_controller"], ("joint_state_controller",), []])
def test_start_none_list_or_tuple(files, start):
    lab = Lab.create(files[0], controllers=files[1], start=start)
    assert running(lab) == ({"joint_state_controller", "yaw_controller"} if start is None else set(start))


@pytest.mark.parametrize("container", [list, tuple])
def test_edits_list_or_tuple(files, container):
    seen = []
    Lab.create(files[0], edits=container([lambda spec, robot: seen.append(robot.name)]))
    assert seen == ["turntable"]


# ----- wrong types ------------------------------------------------------------------------------
WRONG = [
    ("model", 3), ("model", True), ("model", b"robot.urdf"), ("model", ["robot.urdf"]),
    ("controllers", 3), ("controllers", 1.5), ("controllers", ["controllers.yaml"]),
    ("controllers", {"yaw_controller": {}}), ("world", "empty.world"), ("world", 0.001),
    ("spawn", None), ("spawn", (0, 0, 0.6)), ("options", None), ("options", {"fixed_base": True}),
    ("target_rtf", "1"), ("target_rtf", True), ("control_period", "0.01"), ("control_period", [0.01]),
    ("namespace", 3), ("namespace", Path("/arm")), ("start", "yaw_controller"), ("start", [1]),
    ("start", {"yaw_controller"}), ("edits", lambda spec, robot: None), ("edits", [3]),
    ("edits", "edit"),
]


def _id(name: str, value: object) -> str:
    """A test id the same in every process (pytest-xdist's workers must collect the same)."""
    return f"{name}={'a function' if callable(value) else repr(value)}"[:40]


@pytest.mark.parametrize("name, value", WRONG, ids=[_id(n, v) for n, v in WRONG])
def test_a_wrong_type_is_a_type_error_naming_the_parameter(name, value):
    with pytest.raises(ArgumentTypeError) as error:
        Lab.create(**{name: value})
    assert isinstance(error.value, TypeError) and isinstance(error.value, MexoneError)
    text = str(error.value)
    assert text.startswith(f"Lab.create: {name} must be ") and "\n" not in text


@pytest.mark.parametrize("name, value", [("target_rtf", -1), ("target_rtf", math.nan),
                                         ("control_period", 0), ("control_period", math.inf),
                                         ("model", ""), ("controllers", "")])
def test_a_value_out_of_range_is_an_input_error(name, value):
    with pytest.raises(InputError, match=f"Lab.create: {name}"):
        Lab.create(**{name: value})


VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=True),
                   st.text(max_size=12), st.binary(max_size=4), st.lists(st.integers(), max_size=2),
                   st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


@settings(derandomize=True, max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(["model", "controllers", "world", "spawn", "options", "target_rtf",
                             "control_period", "namespace", "start", "edits"]), value=VALUES)
def test_any_value_builds_a_lab_or_says_why_in_one_line(files, name, value):
    """Never a bare TypeError from deep inside (os.fspath, float(), iteration), never a crash."""
    kwargs = {"model": files[0]} if name != "model" else {}
    try:
        Lab.create(**kwargs, **{name: value})
    except MexoneError as error:
        assert "\n" not in str(error) and str(error)
    except (AttributeError, ValueError, KeyError) as error:  # pragma: no cover - the failure
        pytest.fail(f"{name}={value!r}: {type(error).__name__}: {error}")


def test_control_config_is_the_type_the_package_exports():
    assert ControlConfig is type(load_control_config(mex_one.controllers_path()))
