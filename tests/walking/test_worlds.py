"""The shipped terrain worlds: SDF static boxes read as Blocks, compiled where they say, touched
by the robot; a bad box is one line at its line."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from mexone.errors import InputError
from mexone.physics.compile import compile_model
from mexone.physics.world import read_world
from mexone.robots import mex_one


def _height(model, x: float, y: float = 0.0) -> float:
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    geom = np.zeros(1, dtype=np.int32)
    dist = mujoco.mj_ray(model, data, np.array([x, y, 2.0]), np.array([0.0, 0.0, -1.0]),
                         np.array([1, 0, 0, 0, 0, 0], dtype=np.uint8), 1, -1, geom)
    return 2.0 - dist


@pytest.fixture(scope="module")
def robot():
    from mexone.description.loader import load_model

    return load_model(mex_one.urdf_path())


def test_the_slope_rises_five_degrees_and_comes_down(robot):
    world = read_world(mex_one.world_path("slope"))
    assert [b.name for b in world.blocks] == ["ramp_up", "plateau", "ramp_down"]
    model = compile_model(robot, world).model
    rise = 1.5 * math.tan(math.radians(5))
    assert _height(model, 0.5) == pytest.approx(0.0, abs=1e-9)
    assert _height(model, 1.75) == pytest.approx(rise / 2, abs=1e-6)  # half way up the ramp
    assert (_height(model, 1.8) - _height(model, 1.7)) / 0.1 == pytest.approx(math.tan(math.radians(5)))
    assert _height(model, 3.0) == pytest.approx(rise, abs=1e-6)
    assert _height(model, 4.25) == pytest.approx(rise / 2, abs=1e-6)
    assert _height(model, 5.5) == pytest.approx(0.0, abs=1e-9)


def test_the_step_is_two_centimetres_and_the_robot_stands_on_it(robot):
    world = read_world(mex_one.world_path("step"))
    from mexone.physics.compile import Spawn

    compiled = compile_model(robot, world, Spawn(xyz=(1.75, 0.0, 0.03)))
    model = compiled.model
    assert _height(model, 1.75) == pytest.approx(0.02, abs=1e-9)
    assert _height(model, 0.5) == pytest.approx(0.0, abs=1e-9)
    data = mujoco.MjData(model)
    for _ in range(300):  # the robot lands on the platform, not through it
        mujoco.mj_step(model, data)
    foot = model.body("l_foot").id
    assert data.xpos[foot][2] > 0.02 + 0.05


def test_a_box_of_no_size_is_one_line(tmp_path):
    text = mex_one.world_path("step").read_text().replace("<size>1.5 2 0.02</size>", "<size>1.5 0 0.02</size>", 1)
    path = tmp_path / "bad.world"
    path.write_text(text)
    with pytest.raises(InputError, match=r"bad.world:65: <size> box size 1.5 0 0.02 m: each must be > 0"):
        read_world(path)
