"""`_x:=v` sets the routine's private ~x under the name its init_node gives, as rosrun does
(rospy sets the private parameters at init_node, under the node's final name: anonymous's, or
`__name:=`'s), not under the routine's file name. tests/ros1/test_routine_params.py holds the
same cases against Debian's rospy."""

from __future__ import annotations

import json

import pytest

from mexone.errors import InputError
from mexone.lab import Lab
from mexone.routines.runner import RoutineRunner, parse_param_args

# the routine the ROS 1 test also runs with Debian's rospy (`import rospy` there)
ROUTINE = """import json
{import_line}
rospy.init_node("other_name", anonymous={anonymous})
report(json.dumps([rospy.get_name(), rospy.get_param("~x", None), rospy.get_param("~dur", None),
                   rospy.has_param("/params_file/x"), rospy.get_param("/g", None)]))
"""
CASES = [  # (arguments, init_node's anonymous)
    (["_x:=3", "_dur:=[1, 2.5]", "g:=global"], False),
    (["_x:=hello"], True),
    (["_x:=3", "__name:=renamed"], True),  # __name turns anonymous off, as rospy
]


def routine_text(anonymous: bool, import_line: str, report: str) -> str:
    return report + ROUTINE.format(import_line=import_line, anonymous=anonymous)


def expected(args: list[str], anonymous: bool) -> list:
    """What rospy gives (tests/ros1 checks this against Debian's rospy)."""
    values = parse_param_args(args)
    name = "/" + values.get("__name", "other_name")
    return [name if "__name" in values or not anonymous else name + "_", values.get("_x"),
            values.get("_dur"), False, values.get("g")]


def seen(got: list, anonymous: bool) -> list:
    """An anonymous name's suffix differs (rospy: pid and time, mexone: thread): its prefix."""
    name = got[0]
    if anonymous and not name.endswith("renamed"):
        name = name[:name.index("other_name_") + len("other_name_")]
    return [name, *got[1:]]


@pytest.fixture(scope="module")
def lab():
    return Lab.create()


@pytest.mark.parametrize("args,anonymous", CASES)
def test_private_params_land_under_the_init_node_name(lab, tmp_path, args, anonymous):
    path = tmp_path / "params_file.py"
    path.write_text(routine_text(anonymous, "from mexone import rospy",
                                 "def report(text):\n    rospy.set_param('/seen', text)\n"))
    runner = RoutineRunner(lab, path, parse_param_args(args))
    runner.run(0.05)
    got = json.loads(runner.params["/seen"])
    assert seen(got, anonymous) == expected(args, anonymous)
    assert "/params_file/x" not in runner.params  # moved, not copied
    assert runner.param("x") == got[1]  # where `mexone run` reads ~duration and ~phases


def test_declared_duration_is_read_under_the_node_name(lab, tmp_path):
    path = tmp_path / "timed.py"  # the file's name is not the node's
    path.write_text("from mexone import rospy\nrospy.init_node('walker')\n"
                    "rospy.set_param('~duration', 0.2)\nrospy.sleep(0.01)\n")
    runner = RoutineRunner(lab, path)
    start = lab.sim.time
    runner.run(None, hold=True)  # to its declared duration, as `mexone run`
    assert runner.declared_duration() == 0.2
    assert lab.sim.time - start == pytest.approx(0.2, abs=2 * lab.sim.timestep)


@pytest.mark.parametrize("arg", ["__ns:=/robot", "__log:=x", "__name:=/a/b", "__name:=9lives"])
def test_remappings_routines_do_not_take_are_one_line_errors(arg):
    with pytest.raises(InputError) as info:
        parse_param_args([arg])
    assert arg.split(":=")[0] in info.value.one_line() and "\n" not in info.value.one_line()
