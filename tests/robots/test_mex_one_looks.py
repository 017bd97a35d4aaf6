"""Mex-One's looks (issue 28): the visual shells changed nothing a figure was measured on."""

from __future__ import annotations

import json
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from mexone.description.loader import load_model
from mexone.description.materials import display_rgba
from mexone.description.sdf import read_sdf, write_sdf
from mexone.physics.compile import GROUP_VISUAL
from mexone.robots import mex_one
from mexone.robots.mex_one import params
from robots.physics_snapshot import SNAPSHOT, snapshot


def _same(new, old, where: str) -> None:
    if isinstance(old, dict):
        assert sorted(new) == sorted(old), f"{where}: names differ"
        for key in old:
            _same(new[key], old[key], f"{where}/{key}")
    elif isinstance(old, list) and old and isinstance(old[0], (int, float)):
        np.testing.assert_allclose(new, old, rtol=1e-9, atol=1e-12, err_msg=where)
    elif isinstance(old, float):
        assert new == pytest.approx(old, rel=1e-9, abs=1e-12), where
    else:
        assert new == old, where


def test_compiled_physics_equals_the_snapshot_taken_before_the_shells():
    _same(snapshot(), json.loads(SNAPSHOT.read_text()), "mex_rb")


def _colours(robot) -> dict[str, list[tuple[float, ...]]]:
    """Per link, the colours its visuals are drawn in (the GUI's and MuJoCo's rule)."""
    return {name: [tuple(round(c, 3) for c in display_rgba(robot, name, v)) for v in link.visuals]
            for name, link in robot.links.items() if link.visuals}


def test_every_format_draws_the_shell_servo_and_kinect_colours(tmp_path):
    robot = load_model(mex_one.urdf_path())
    colours = _colours(robot)
    palette = {tuple(round(c, 3) for c in rgba) for rgba in params.MATERIALS.values()}
    assert {c for cs in colours.values() for c in cs} == palette
    assert len(colours["head"]) == 3 and len(colours["l_thigh"]) == 2  # several per link
    # the page and the video: the URDF's named colours, every visual its own
    assert [len(v) for v in colours.values()] == [
        len({p.material for p in params.looks()[name]}) for name in colours]
    # SDF export and back: the same visuals in the same colours
    sdf = tmp_path / "mex_rb.sdf"
    sdf.write_text(write_sdf(robot))
    assert _colours(read_sdf(sdf)) == colours
    # MJCF export (`mexone convert`, the simulator's own compile path): one geom per visual
    out = tmp_path / "mex_rb.xml"
    done = subprocess.run([sys.executable, "-m", "mexone", "convert", str(mex_one.urdf_path()),
                           "-o", str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    model = mujoco.MjModel.from_xml_path(str(out))
    for name, expected in colours.items():
        body = model.body(name).id
        drawn = [tuple(round(float(c), 3) for c in model.geom_rgba[g]) for g in range(model.ngeom)
                 if model.geom_bodyid[g] == body and model.geom_group[g] == GROUP_VISUAL]
        assert drawn == expected, name
