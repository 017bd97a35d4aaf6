"""The numbered examples run as they are (a newcomer's first contact must not be broken)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parents[1] / "examples").glob("[0-9][0-9]_*.py"))


@pytest.mark.parametrize("example", EXAMPLES, ids=[e.stem for e in EXAMPLES])
def test_example_runs(example, tmp_path):
    out = subprocess.run([sys.executable, str(example), str(tmp_path)], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert list(tmp_path.iterdir()) or "01_" in example.name  # outputs land where asked


def test_fall_and_stand_says_what_the_seed_saw(tmp_path):
    out = subprocess.run([sys.executable, str(EXAMPLES[0])], capture_output=True, text=True,
                         timeout=300)
    without, with_ = out.stdout.splitlines()
    assert float(without.split(" at ")[1].split()[0]) < 0.4  # fell
    assert float(with_.split(" at ")[1].split()[0]) > 0.59  # stands
