"""What a student's process sends is read as data against a schema: every value mexone sends
comes back equal, and any bytes at all -- a pickle, a forged class tag, an array whose header
lies about its size, nesting deep enough to blow the stack -- are refused with the error the
callers catch (never another exception, never an object of the sender's choosing)."""

from __future__ import annotations

import contextlib
import json
import math
import pickle
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mexone.sandbox import wire
from mexone.sandbox.wire import WireError


@dataclass
class Point:
    x: float
    y: float = 0.0


@dataclass
class Sample:
    t: list[float]
    points: list[Point]
    where: Path
    pose: np.ndarray
    label: str | None = None
    raw: bytes = b""
    extra: dict[str, int] = field(default_factory=dict)


@dataclass
class Other:
    x: float


plain_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=20)


@given(plain_json)
def test_plain_data_comes_back_equal(value):
    assert wire.loads(wire.dumps(value)) == value


@given(st.lists(st.floats(allow_nan=False), max_size=5),
       st.lists(st.tuples(st.floats(allow_nan=False), st.floats(allow_nan=False)), max_size=3),
       st.sampled_from(["float64", "float32", "int32", "uint8", "bool"]),
       st.lists(st.integers(0, 3), max_size=3), st.none() | st.text(), st.binary(max_size=20))
def test_a_dataclass_with_arrays_comes_back_equal(t, points, dtype, shape, label, raw):
    pose = (np.arange(int(np.prod(shape))) % 7).astype(dtype).reshape(shape)
    sent = Sample(t, [Point(x, y) for x, y in points], Path("/a/b"), pose, label, raw, {"n": 3})
    back = wire.loads(wire.dumps(sent), Sample)
    assert isinstance(back, Sample) and back.points == sent.points and back.t == t
    assert back.pose.dtype == pose.dtype and back.pose.shape == pose.shape
    assert np.array_equal(back.pose, pose) and back.raw == raw and back.where == Path("/a/b")


def test_nan_and_infinities_cross():
    back = wire.loads(wire.dumps([math.nan, math.inf, -math.inf]), list[float])
    assert math.isnan(back[0]) and back[1:] == [math.inf, -math.inf]


@pytest.mark.parametrize("data, schema, said", [
    (pickle.dumps(("ok", (0.0, None))), object, "not JSON"),
    (b'{"$": "Other", "x": 1.0}', Point, "a str 'Other', expected Point"),
    (b'{"x": 1.0, "os": "system"}', Point, "Point has no field 'os'"),
    (b'{"y": 1.0}', Point, "field 'x' is missing"),
    (b'{"x": "1.0"}', Point, "result.x: expected float"),
    (b'{"x": true}', Point, "result.x: expected float"),
    (b'[1, 2]', tuple[int, int, int], "2 items, expected 3"),
    (b'{"$a": ["object", [1], "AA=="]}', np.ndarray, "dtype"),
    (b'{"$a": ["float64", [1000000000000], "AA=="]}', np.ndarray, "with 1 bytes"),
    (b'{"$a": ["float64", [-1], ""]}', np.ndarray, "shape"),
    (b'{"$b": "not base64!"}', bytes, "not base64"),
    pytest.param(b'[' * 100_000 + b']' * 100_000, object, "result", id="a stack's worth of ["),
    (b'[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]'
     b']]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]', list[object], "nested too deeply"),
])
def test_what_does_not_fit_is_refused_in_one_line(data, schema, said):
    """Each refusal names where and what (the caller's one line)."""
    with pytest.raises(WireError) as caught:
        wire.loads(data, schema)
    assert said in str(caught.value) and "\n" not in str(caught.value)


def test_a_tag_picks_only_among_the_schemas_own_alternatives():
    assert isinstance(wire.loads(b'{"$": "Other", "x": 2}', Point | Other), Other)
    assert isinstance(wire.loads(b'{"x": 2}', Point | Other), Point)
    with pytest.raises(WireError):  # a class the schema does not name is never looked up
        wire.loads(b'{"$": "Popen", "args": ["sh"]}', Point | Other)


def test_more_than_the_limit_is_refused_before_it_is_parsed(monkeypatch):
    monkeypatch.setattr(wire, "MAX_BYTES", 100)
    with pytest.raises(WireError, match="more than"):
        wire.loads(b"[" + b"1," * 100 + b"1]")


def test_what_cannot_be_sent_is_said():
    with pytest.raises(WireError, match="cannot send a function"):
        wire.dumps({"f": lambda: None})


hostile_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
    | st.sampled_from(["$a", "$b", "$", "Point", "float64"]),
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.sampled_from(["$", "$a", "$b", "x", "y", "t", "points", "pose"])
                      | st.text(max_size=4), inner, max_size=4),
    max_leaves=25)
SCHEMAS = [object, float, int, str, bytes, Path, np.ndarray, list[float], tuple[int, ...],
           tuple[float, str], dict[str, float], Point | None, Sample, Point | Other]


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(hostile_json, st.sampled_from(SCHEMAS))
def test_any_json_is_read_or_refused_never_anything_else(raw, schema):
    try:
        value = wire.loads(json.dumps(raw), schema)
    except WireError as exc:
        assert "\n" not in str(exc)
        return
    if schema is Sample:
        assert isinstance(value, Sample)


@settings(max_examples=200)
@given(st.binary(max_size=64), st.sampled_from(SCHEMAS))
def test_any_bytes_are_read_or_refused_never_anything_else(data, schema):
    with contextlib.suppress(WireError):
        wire.loads(data, schema)
