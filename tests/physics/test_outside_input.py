"""A divergence right after an input from outside the lab (a ROS service call) names that input
as its cause, not the controller gains; with recover_outside (the ROS bridge sets it) the input
is undone, the world reset with a warning, and the run goes on (issue 30)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from mexone.lab import Lab
from mexone.physics import DivergenceError


@pytest.fixture(scope="module")
def lab():
    return Lab.create()


def _teleport(lab, undo=None) -> None:
    """What set_model_configuration did with l_elbow = 100 rad before it clamped: the limit's
    constraint flings the forearm beyond physics within a fraction of a second."""
    lab.sim.reset()
    lab.sim.step(100)
    lab.sim.set_joint_positions({"l_elbow": 100.0})
    lab.manager.hold({"l_elbow": 100.0})
    lab.sim.note_input("/gazebo/set_model_configuration (l_elbow 100)", undo)


def test_the_divergence_names_the_outside_input_not_the_gains(lab):
    lab.sim.recover_outside = False
    _teleport(lab)
    with pytest.raises(DivergenceError) as err:
        lab.sim.step(2000)
    text = err.value.one_line()
    assert "likely cause: the outside input /gazebo/set_model_configuration (l_elbow 100)" in text
    assert "gains" not in text


def test_with_recover_outside_the_input_is_undone_and_the_run_goes_on(lab, caplog):
    lab.sim.recover_outside = True
    undone = []
    _teleport(lab, undo=lambda: undone.append(True))
    start = lab.sim.steps
    with caplog.at_level(logging.WARNING, logger="mexone.physics"):
        lab.sim.step(2000)
    assert lab.sim.steps - start == 2000 and undone == [True]
    assert np.isfinite(lab.sim.data.qpos).all() and abs(lab.sim.joint_positions()).max() < 3.2
    [warning] = [r.getMessage() for r in caplog.records if "the world was reset" in r.getMessage()]
    assert "likely cause: the outside input /gazebo/set_model_configuration" in warning
    assert lab.sim.outside is None


def test_an_input_long_ago_is_not_blamed(lab):
    lab.sim.recover_outside = True
    lab.sim.reset()
    lab.sim.note_input("/gazebo/apply_body_wrench (long ago)")
    lab.sim.step(2100)  # 2.1 s of sim time: beyond OUTSIDE_WINDOW
    assert lab.sim.recent_input() is None
    lab.sim.set_joint_positions({"l_elbow": 100.0})
    lab.manager.hold({"l_elbow": 100.0})
    with pytest.raises(DivergenceError) as err:  # the robot's own divergence still ends the run
        lab.sim.step(2000)
    assert "outside input" not in err.value.one_line()
    lab.sim.recover_outside = False
