"""A value stated twice (URDF and <gazebo>, two <gazebo> blocks, a repeated URDF element) is a
`mexone check` finding naming both lines and the winner, and the model uses that winner."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexone.cli import main
from mexone.description.check import check_model
from mexone.description.conflicts import CONFLICT_CODE
from mexone.description.loader import load_model
from mexone.physics.compile import compile_model
from mexone.robots import mex_one

_INERTIAL = ('<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
             'ixz="0" iyz="0"/></inertial>')


def robot(joint_extra: str = "", after: str = "") -> str:
    """Two links and a revolute joint `j`; `joint_extra` goes inside the joint, `after` after it.
    Every element sits on its own line so a line number names one statement."""
    return "\n".join([
        '<robot name="r">',
        f'<link name="a">{_INERTIAL}</link>',
        f'<link name="b">{_INERTIAL}</link>',
        '<joint name="j" type="revolute">',
        '<parent link="a"/>',
        '<child link="b"/>',
        '<limit lower="-1" upper="1" effort="10" velocity="1"/>',
        joint_extra,
        "</joint>",
        after,
        "</robot>",
    ]) + "\n"


def line_of(text: str, needle: str, nth: int = 0) -> int:
    lines = [i for i, line in enumerate(text.splitlines(), start=1) if needle in line]
    return lines[nth]


def gazebo(ref: str, *tags: str) -> str:
    return "\n".join([f'<gazebo reference="{ref}">', *tags, "</gazebo>"])


def joint_dynamics(**values: str) -> str:
    return "\n".join(["<axis>", "<dynamics>", *(f"<{k}>{v}</{k}>" for k, v in values.items()),
                      "</dynamics>", "</axis>"])


def conflicts(path):
    return [f for f in check_model(load_model(path)) if f.code == CONFLICT_CODE]


def write(tmp_path, text: str):
    path = tmp_path / "r.urdf"
    path.write_text(text)
    return path


def test_urdf_damping_overridden_by_gazebo_is_reported_with_both_lines(tmp_path, capsys):
    text = robot('<dynamics damping="0.52"/>', gazebo("j", joint_dynamics(damping="0.2")))
    path = write(tmp_path, text)
    assert main(["check", str(path)]) == 1
    out = capsys.readouterr().out
    urdf_line, gazebo_line = line_of(text, 'damping="0.52"'), line_of(text, "<damping>0.2")
    finding = next(line for line in out.splitlines() if CONFLICT_CODE in line)
    assert f"{path}:{urdf_line}" in finding and f"{path}:{gazebo_line}" in finding
    assert "0.2 wins" in finding and 'joint "j"' in finding and "damping" in finding
    assert "no problems found" not in out
    # and the simulation uses the winner, as Gazebo does
    compiled = compile_model(load_model(path))
    assert compiled.model.dof_damping[compiled.dof_adr[0]] == pytest.approx(0.2)


CASES = {
    # name: (text, needle of the losing line, needle of the winning line, winner)
    "joint friction vs gazebo": (
        robot('<dynamics friction="0.3"/>', gazebo("j", joint_dynamics(friction="0.05"))),
        'friction="0.3"', "<friction>0.05", "0.05"),
    "gazebo damping in two blocks": (
        robot("", gazebo("j", joint_dynamics(damping="0.7")) + "\n"
              + gazebo("j", joint_dynamics(damping="0.9"))),
        "<damping>0.7", "<damping>0.9", "0.9"),
    "link mu1 in two blocks": (
        robot("", gazebo("b", "<mu1>0.4</mu1>") + "\n" + gazebo("b", "<mu1>0.8</mu1>")),
        "<mu1>0.4", "<mu1>0.8", "0.8"),
    "link kp twice in one block": (
        robot("", gazebo("b", "<kp>1000</kp>", "<kp>5000</kp>")), "<kp>1000", "<kp>5000", "5000"),
    "link kd in two blocks": (
        robot("", gazebo("b", "<kd>1</kd>") + "\n" + gazebo("b", "<kd>10</kd>")),
        "<kd>1<", "<kd>10<", "10"),
    "implicitSpringDamper": (
        robot("", gazebo("j", "<implicitSpringDamper>true</implicitSpringDamper>") + "\n"
              + gazebo("j", "<implicitSpringDamper>0</implicitSpringDamper>")),
        "<implicitSpringDamper>true", "<implicitSpringDamper>0", "0"),
    "stopErp": (
        robot("", gazebo("j", "<stopErp>0.2</stopErp>", "<stopCfm>0</stopCfm>") + "\n"
              + gazebo("j", "<stopErp>0.8</stopErp>")),
        "<stopErp>0.2", "<stopErp>0.8", "0.8"),
    "selfCollide": (
        robot("", gazebo("b", "<selfCollide>true</selfCollide>") + "\n"
              + gazebo("b", "<selfCollide>false</selfCollide>")),
        "<selfCollide>true", "<selfCollide>false", "false"),
    "two <dynamics> in a joint (urdfdom reads the first)": (
        robot('<dynamics damping="0.1"/>\n<dynamics damping="0.6"/>'),
        'damping="0.6"', 'damping="0.1"', "0.1"),
    "two <limit> in a joint": (
        robot('<limit lower="-2" upper="1" effort="10" velocity="1"/>'),
        'lower="-2"', 'lower="-1"', "-1"),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_each_kind_of_conflict_names_both_lines_and_the_winner(tmp_path, case):
    text, loser, winner, value = CASES[case]
    path = write(tmp_path, text)
    found = conflicts(path)
    assert len(found) == 1, [f.one_line() for f in found]
    message = found[0].one_line(str(path))
    assert f"{path}:{line_of(text, loser)}" in message
    assert f"{path}:{line_of(text, winner)}" in message
    assert f"{value} wins" in message
    assert found[0].line == line_of(text, loser)  # the line that changes nothing when edited
    assert main(["check", str(path)]) == 1


def test_the_model_uses_the_reported_winner(tmp_path):
    model = load_model(write(tmp_path, CASES["link kp twice in one block"][0]))
    assert model.gazebo_links["b"].kp == 5000  # Gazebo applies the later tag
    model = load_model(write(tmp_path, CASES["two <dynamics> in a joint (urdfdom reads the first)"][0]))
    assert model.joint_dynamics("j").damping == 0.1


def test_a_later_gazebo_block_keeps_what_it_does_not_restate(tmp_path):
    text = robot('<dynamics damping="0.5" friction="0.3"/>',
                 gazebo("j", joint_dynamics(damping="0.5", friction="0.3")) + "\n"
                 + gazebo("j", joint_dynamics(friction="0.3")))
    model = load_model(write(tmp_path, text))
    assert model.joint_dynamics("j").damping == 0.5 and model.joint_dynamics("j").friction == 0.3
    assert conflicts(tmp_path / "r.urdf") == []


@settings(derandomize=True, max_examples=40, deadline=None)
@given(first=st.sampled_from(["0.5", "0.50", "5e-1", "0.7", "1", "1.0"]),
       second=st.sampled_from(["0.5", "0.50", "5e-1", "0.7", "1", "1.0"]),
       tag=st.sampled_from(["mu1", "mu2", "kp", "kd", "maxVel", "minDepth"]))
def test_same_value_written_differently_is_no_conflict(tmp_path_factory, first, second, tag):
    text = robot("", gazebo("b", f"<{tag}>{first}</{tag}>") + "\n"
                 + gazebo("b", f"<{tag}>{second}</{tag}>"))
    path = write(tmp_path_factory.mktemp("c"), text)
    found = conflicts(path)
    assert bool(found) == (float(first) != float(second))
    attr = {"maxVel": "max_vel", "minDepth": "min_depth"}.get(tag, tag)
    assert getattr(load_model(path).gazebo_links["b"], attr) == float(second)


def test_mex_one_states_each_value_once(monkeypatch):
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(mex_one.package_dir()))
    model = load_model(mex_one.urdf_path())
    assert model.gazebo_joints  # it does write <dynamics> and <gazebo> damping, the same
    assert conflicts(mex_one.urdf_path()) == []
