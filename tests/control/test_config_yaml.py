"""Controller YAML as a person writes it: every float is a float, booleans are booleans, a key
given twice is an error, and aliases are fine until they explode."""

from __future__ import annotations

import time

import pytest

from mexone import yamlio
from mexone.control.config import parse_control_config
from mexone.errors import InputError

KNEE = """mex_rb:
  knee:
    type: effort_controllers/JointPositionController
    joint: l_knee
    pid: {{{pid}}}
"""


@pytest.mark.parametrize("text, value", [("1.0e9", 1e9), ("1e9", 1e9), ("1E+3", 1e3), (".5", 0.5),
                                         ("-2.5e-3", -2.5e-3), ("100", 100.0), ("1_000.5", 1000.5)])
def test_every_float_a_person_writes(text, value):
    """YAML 1.1 reads 1.0e9 and 1e9 as strings: `p: 1.0e9` was refused as 'not a number'."""
    config = parse_control_config(KNEE.format(pid=f"p: {text}"))
    assert config.controllers["knee"].pid.p == value


def test_strings_stay_strings():
    assert yamlio.load("a: '1e9'\nb: 1e9x\nc: e9\nd: 1.2.3\n") == {"a": "1e9", "b": "1e9x", "c": "e9",
                                                                  "d": "1.2.3"}


@pytest.mark.parametrize("text, value", [("true", True), ("false", False), ("yes", True), ("off", False)])
def test_antiwindup_takes_booleans_as_rosparam_reads_them(text, value):
    config = parse_control_config(KNEE.format(pid=f"p: 1, antiwindup: {text}"))
    assert config.controllers["knee"].pid.antiwindup is value


@pytest.mark.parametrize("text", ["'no'", '"false"', "1", "maybe"])
def test_antiwindup_refuses_what_is_not_a_boolean(text):
    """bool('no') is True: a quoted 'no' turned anti-windup on."""
    with pytest.raises(InputError, match="is not a boolean"):
        parse_control_config(KNEE.format(pid=f"p: 1, antiwindup: {text}"))


def test_duplicate_key_names_both_lines():
    with pytest.raises(InputError) as caught:
        parse_control_config("mex_rb:\n  knee: {type: x}\n  hip: {type: y}\n  knee: {type: z}\n", None)
    assert str(caught.value) == ("<yaml>:4: duplicate key 'knee' (first on line 2) (YAML would silently "
                                 "keep the second; remove one)")


def test_merge_keys_and_shared_aliases_are_fine():
    text = """defaults: &gains {p: 100.0, d: 1.0}
mex_rb:
  knee:
    type: effort_controllers/JointPositionController
    joint: l_knee
    pid: {<<: *gains, d: 2.0}
  hip:
    type: effort_controllers/JointPositionController
    joint: l_hip_pitch
    pid: *gains
"""
    doc = yamlio.load(text)
    assert doc["mex_rb"]["knee"]["pid"] == {"p": 100.0, "d": 2.0}
    assert doc["mex_rb"]["hip"]["pid"] == {"p": 100.0, "d": 1.0}


def test_alias_bomb_is_refused_before_it_expands():
    lines = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 12)]
    start = time.monotonic()
    with pytest.raises(InputError, match="YAML aliases expand to over 1,000,000 values"):
        yamlio.load("\n".join(lines), "bomb.yaml")
    assert time.monotonic() - start < 1.0  # 9^12 values, never built
