"""pyproject.toml's dependency ranges hold what the code needs and what is installed."""

from __future__ import annotations

import importlib.metadata as md
import tomllib
from pathlib import Path

import mujoco
import numpy as np
from packaging.requirements import Requirement
from packaging.version import Version

PROJECT = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())["project"]
REQUIRES = {Requirement(r).name.lower(): Requirement(r) for r in PROJECT["dependencies"]}


def test_every_dependency_installed_is_in_its_range():
    for name, requirement in REQUIRES.items():
        assert requirement.specifier.contains(md.version(name), prereleases=True), \
            f"{name} {md.version(name)} is outside {requirement.specifier}"


def test_the_mujoco_range_is_the_api_mexone_uses():
    """MuJoCo 4: nu counts control inputs, nactuator the actuators; mj_fullM takes (m, d, dst).
    MuJoCo 3 had neither, MuJoCo 5 may change them again: both ends are pinned."""
    spec = REQUIRES["mujoco"].specifier
    assert not spec.contains("3.5.0") and spec.contains("4.0.0") and not spec.contains("5.0.0")
    assert Version(mujoco.__version__) in spec
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint name="j"/><geom size=".1"/></body></worldbody>'
        '<actuator><position joint="j" kp="1"/><motor joint="j"/></actuator></mujoco>')
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    inertia = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, inertia)
    assert model.nactuator == 2 and inertia[0, 0] > 0


def test_python_range_is_mujocos():
    assert PROJECT["requires-python"] == md.metadata("mujoco")["Requires-Python"] == ">=3.11"
