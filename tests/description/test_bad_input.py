"""A corpus of broken files, each with the exact one-line error it must give (exit 2).

The corpus runs in-process (the CLI's `main`): one import of the verbs, not one per file; a
missing file runs as a process, as a user meets it."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from helpers import run_cli
from mexone.cli import build_parser

BROKEN = Path(__file__).parents[1] / "data" / "broken"
EXPECTED = yaml.safe_load((BROKEN / "expected.yaml").read_text())


def test_corpus_is_complete():
    files = {p.name for p in BROKEN.iterdir()} - {"expected.yaml"}
    assert files == set(EXPECTED)
    assert len(files) >= 20


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_broken_file_gives_its_one_line_error(name):
    args = ["check", "--controllers", name] if name.endswith(".yaml") else ["check", name]
    build_parser()  # the verbs' imports, once, before any case's clock starts
    start = time.monotonic()
    # messages that name ROS_PACKAGE_PATH must not depend on the machine's (run_cli unsets it)
    code, _, err = run_cli(args, cwd=BROKEN)
    assert time.monotonic() - start < 10
    assert code == 2
    assert err.strip() == EXPECTED[name]
    assert "Traceback" not in err and err.count("\n") == 1


def test_missing_file():
    out = subprocess.run([sys.executable, "-m", "mexone", "check", "nowhere.urdf"],
                         capture_output=True, text=True)
    assert (out.returncode, out.stderr) == (2, "mexone: nowhere.urdf: no such file (check the path)\n")

