"""Every verb explains itself; the console script is installed."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from mexone.cli import build_parser

VERBS = sorted(build_parser()._subparsers._group_actions[0].choices)


def test_console_script_is_installed():
    exe = shutil.which("mexone")
    assert exe, "pip install . must put 'mexone' on PATH"
    out = subprocess.run([exe, "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    for verb in VERBS:
        assert verb in out.stdout


@pytest.mark.parametrize("verb", VERBS)
def test_verb_help(verb, capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args([verb, "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    assert f"usage: mexone {verb}" in text and len(text.splitlines()) > 5


def test_no_verb_is_a_usage_error():
    out = subprocess.run([shutil.which("mexone")], capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr == ("mexone: the following arguments are required: <verb> "
                          "(see 'mexone --help')\n")


def test_bad_option_value_is_one_line():
    out = subprocess.run([shutil.which("mexone"), "run", "joint_steps", "--duration", "-1"],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr == ("mexone: run: argument --duration: -1 must be a finite number >= 0.001 "
                          "and <= 1e+09; s of sim time (see 'mexone run --help')\n")


@pytest.mark.parametrize("verb", ["sim", "check", "run", "record", "render", "sweep", "identify",
                                  "controllers", "convert"])
def test_every_verb_that_reads_a_robot_names_mjcf(verb, capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args([verb, "--help"])
    assert "MJCF" in capsys.readouterr().out
