"""Mex-One's looks (issue 28): the visual shells changed nothing a figure was measured on."""

from __future__ import annotations

import json

import numpy as np
import pytest

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
