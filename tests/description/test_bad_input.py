"""A corpus of broken files, each with the exact one-line error it must give (exit 2)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

BROKEN = Path(__file__).parents[1] / "data" / "broken"
EXPECTED = yaml.safe_load((BROKEN / "expected.yaml").read_text())


def test_corpus_is_complete():
    files = {p.name for p in BROKEN.iterdir()} - {"expected.yaml"}
    assert files == set(EXPECTED)
    assert len(files) >= 20


# messages that name ROS_PACKAGE_PATH must not depend on the machine's
ENV = {k: v for k, v in os.environ.items() if k != "ROS_PACKAGE_PATH"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_broken_file_gives_its_one_line_error(name):
    args = ["check", "--controllers", name] if name.endswith(".yaml") else ["check", name]
    start = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "mexone", *args], cwd=BROKEN,
                         capture_output=True, text=True, timeout=60, env=ENV)
    assert time.monotonic() - start < 10
    assert out.returncode == 2
    assert out.stderr.strip() == EXPECTED[name]
    assert "Traceback" not in out.stderr and out.stderr.count("\n") == 1


def test_missing_file():
    out = subprocess.run([sys.executable, "-m", "mexone", "check", "nowhere.urdf"],
                         capture_output=True, text=True)
    assert (out.returncode, out.stderr) == (2, "mexone: nowhere.urdf: no such file (check the path)\n")

