"""A corpus of readable but wrong inputs: what `check` reports (exit 1) and whether `sim` agrees.

Each file in tests/data/findings is small and self-contained; expected.yaml holds the exact
finding lines (file:line: severity: element: message [code]) and, for URDFs, sim's verdict.
The verbs run in-process (the CLI's `main`): one import, not a Python start-up per case.
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest
import yaml

from helpers import run_cli
from mexone.cli import build_parser

FINDINGS = Path(__file__).parents[1] / "data" / "findings"
EXPECTED = yaml.safe_load((FINDINGS / "expected.yaml").read_text())


def mexone(*args: str) -> subprocess.CompletedProcess:
    """`mexone ARGS` in the corpus's folder, without the machine's ROS_PACKAGE_PATH."""
    build_parser()  # the verbs' imports, once, before any case's clock starts
    start = time.monotonic()
    code, stdout, stderr = run_cli(list(args), cwd=FINDINGS)
    assert time.monotonic() - start < 10, f"{args} took over 10 s"
    assert "Traceback" not in stderr
    return subprocess.CompletedProcess(args, code, stdout, stderr)


def test_corpus_is_complete():
    files = {p.name for p in FINDINGS.iterdir()} - {"expected.yaml"}
    assert files == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_check_reports_exactly_these_findings(name):
    expected = EXPECTED[name]
    out = mexone("check", "--controllers", name) if name.endswith(".yaml") else mexone("check", name)
    found = [line.strip() for line in out.stdout.splitlines()
             if line.startswith("  ") and line.strip().startswith(f"{name}:")]
    assert found == expected["findings"]
    assert out.returncode == expected["exit"]
    assert out.stderr == ""


@pytest.mark.parametrize("name", sorted(n for n, e in EXPECTED.items() if "sim" in e))
def test_sim_agrees_with_check(name):
    expected = EXPECTED[name]["sim"]
    out = mexone("sim", "--headless", "--duration", "0.05", name)
    if expected == 0:
        assert out.returncode == 0, out.stderr
        assert "0.050 s simulated" in out.stdout
    else:
        assert out.returncode == 2
        assert out.stderr.strip() == expected and out.stderr.count("\n") == 1
    # what sim refuses, check must have called an error
    if expected != 0:
        assert any(": error: " in line for line in EXPECTED[name]["findings"])
