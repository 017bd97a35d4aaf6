"""What crosses a jail's boundary as data: JSON read against a schema (a type annotation),
never a pickle.

`dumps(value)` writes plain data, dataclasses (their fields and their class's name under "$"),
numpy arrays (dtype, shape and the raw bytes in base64, under "$a") and bytes (base64 under "$b").
`loads(data, schema)` reads it back only as `schema` says: `float`, `int`, `bool`, `str`,
`bytes`, `None`, `Path`, `numpy.ndarray`, `list[X]`, `tuple[X, ...]`, `tuple[X, Y]`,
`dict[str, X]`, `X | Y`, a dataclass (its fields' annotations, recursively) or `object` (plain
JSON only). A class is never looked up by a name the sender chose: a dataclass is read only where
the schema names it, the "$" tag only picks among the schema's own alternatives. Whatever does
not fit is a SchemaError naming where (`result[2].position: expected float, got str`).
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import types
import typing
from collections.abc import Sequence
from pathlib import Path

__all__ = ["dumps", "loads", "plain", "read", "SchemaError", "MAX_BYTES", "PLAIN"]

MAX_BYTES = 64 << 20  # the largest message read (a run's samples are under 1 MB)
MAX_DEPTH = 64
PLAIN = object  # the schema of plain JSON: dicts, lists, strings, numbers, booleans, None
_DTYPES = ("float64", "float32", "int64", "int32", "int8", "uint8", "bool")


class SchemaError(ValueError):
    """What was received does not fit its schema (or is not JSON)."""


def _plain(value: object, depth: int = 0) -> object:
    if depth > MAX_DEPTH:
        raise SchemaError("nested too deeply")
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value
    if isinstance(value, bytes | bytearray | memoryview):
        return {"$b": base64.b64encode(bytes(value)).decode()}
    if isinstance(value, Path):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = {"$": type(value).__name__}
        for f in dataclasses.fields(value):
            out[f.name] = _plain(getattr(value, f.name), depth + 1)
        return out
    if isinstance(value, dict):
        return {str(k): _plain(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_plain(v, depth + 1) for v in value]
    numpy = _numpy()
    if numpy is not None:
        if isinstance(value, numpy.ndarray):
            dtype = value.dtype.name if value.dtype.name in _DTYPES else "float64"
            data = numpy.asarray(value, dtype=dtype).tobytes()  # C order, any layout, 0-d too
            return {"$a": [dtype, list(value.shape), base64.b64encode(data).decode()]}
        if isinstance(value, numpy.generic):
            return _plain(value.item(), depth)
    raise SchemaError(f"cannot send a {type(value).__name__}")


def plain(value: object) -> object:
    """`value` as the plain data `dumps` writes (SchemaError for what cannot be sent)."""
    return _plain(value)


def dumps(value: object) -> bytes:
    """`value` as JSON bytes (NaN and infinities as JSON's common extension)."""
    try:
        return json.dumps(_plain(value), separators=(",", ":")).encode()
    except SchemaError:
        raise
    except (TypeError, ValueError, RecursionError) as exc:
        raise SchemaError(f"cannot send it: {exc}") from None


def loads(data: bytes | str, schema: object = PLAIN, where: str = "result") -> object:
    """`data` read as `schema` says (SchemaError if it does not fit)."""
    if len(data) > MAX_BYTES:
        raise SchemaError(f"{where}: {len(data)} bytes, more than {MAX_BYTES >> 20} MB")
    try:
        raw = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise SchemaError(f"{where}: not JSON ({type(exc).__name__})") from None
    return read(raw, schema, where)


def read(raw: object, schema: object, where: str = "result", depth: int = 0) -> object:
    """Decoded JSON `raw` checked and built as `schema` says."""
    if depth > MAX_DEPTH:
        raise SchemaError(f"{where}: nested too deeply")
    origin = typing.get_origin(schema)
    args = typing.get_args(schema)
    if schema is typing.Any or schema is object:
        return _check_plain(raw, where, depth)
    if schema is None or schema is type(None):
        if raw is not None:
            raise _expected("None", raw, where)
        return None
    if origin in (typing.Union, types.UnionType):
        tag = raw.get("$") if isinstance(raw, dict) else None
        errors = []
        for option in args:
            if tag is not None and dataclasses.is_dataclass(option) and option.__name__ != tag:
                continue
            try:
                return read(raw, option, where, depth)
            except SchemaError as exc:
                errors.append(exc)
        if errors and len(errors) == 1:
            raise errors[0]
        raise SchemaError(f"{where}: {_shown(raw)} is none of {_names(args)}")
    if schema is float:
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise _expected("float", raw, where)
        return float(raw)
    if schema is int:
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise _expected("int", raw, where)
        return raw
    if schema is bool:
        if not isinstance(raw, bool):
            raise _expected("bool", raw, where)
        return raw
    if schema is str:
        if not isinstance(raw, str):
            raise _expected("str", raw, where)
        return raw
    if schema is bytes:
        return _bytes(raw, where)
    if schema is Path:
        if not isinstance(raw, str):
            raise _expected("a path", raw, where)
        return Path(raw)
    if origin in (list, Sequence) or schema is list:
        if not isinstance(raw, list):
            raise _expected("list", raw, where)
        item = args[0] if args else object
        if item is float and all(type(x) is float for x in raw):  # the common case, quickly
            return raw
        return [read(x, item, f"{where}[{i}]", depth + 1) for i, x in enumerate(raw)]
    if origin is tuple or schema is tuple:
        if not isinstance(raw, list):
            raise _expected("tuple", raw, where)
        if not args or (len(args) == 2 and args[1] is Ellipsis):
            item = args[0] if args else object
            return tuple(read(x, item, f"{where}[{i}]", depth + 1) for i, x in enumerate(raw))
        if len(raw) != len(args):
            raise SchemaError(f"{where}: {len(raw)} items, expected {len(args)}")
        return tuple(read(x, t, f"{where}[{i}]", depth + 1)
                     for i, (x, t) in enumerate(zip(raw, args, strict=True)))
    if origin is dict or schema is dict:
        if not isinstance(raw, dict):
            raise _expected("dict", raw, where)
        key, value = args if args else (str, object)
        if key not in (str, typing.Any, object):
            raise SchemaError(f"{where}: a schema's dict keys are str")
        return {k: read(v, value, f"{where}[{k!r}]", depth + 1) for k, v in raw.items()}
    numpy = _numpy()
    if numpy is not None and schema is numpy.ndarray:
        return _array(raw, where, numpy)
    if dataclasses.is_dataclass(schema) and isinstance(schema, type):
        return _dataclass(raw, schema, where, depth)
    raise SchemaError(f"{where}: the schema {schema!r} is not one this module reads")


def _dataclass(raw: object, cls: type, where: str, depth: int) -> object:
    if not isinstance(raw, dict):
        raise _expected(cls.__name__, raw, where)
    if raw.get("$", cls.__name__) != cls.__name__:
        raise SchemaError(f"{where}: a {_shown(raw.get('$'))}, expected {cls.__name__}")
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(raw) - set(fields) - {"$"})
    if unknown:
        raise SchemaError(f"{where}: {cls.__name__} has no field {unknown[0]!r}")
    values = {}
    for name, f in fields.items():
        if name in raw:
            values[name] = read(raw[name], hints.get(name, object), f"{where}.{name}", depth + 1)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise SchemaError(f"{where}: {cls.__name__}'s field {name!r} is missing")
    try:
        return cls(**values)
    except Exception as exc:  # noqa: BLE001 - a class's own checks refusing the values
        raise SchemaError(f"{where}: {cls.__name__}: {exc}") from None


_HINTS: dict[type, dict] = {}


def _hints(cls: type) -> dict:
    hints = _HINTS.get(cls)
    if hints is None:
        hints = _HINTS[cls] = typing.get_type_hints(cls)
    return hints


def _bytes(raw: object, where: str) -> bytes:
    if not (isinstance(raw, dict) and set(raw) == {"$b"} and isinstance(raw["$b"], str)):
        raise _expected("bytes", raw, where)
    try:
        return base64.b64decode(raw["$b"], validate=True)
    except ValueError:
        raise SchemaError(f"{where}: bytes that are not base64") from None


def _array(raw: object, where: str, numpy):
    if isinstance(raw, list):  # a list of numbers is an array too
        try:
            array = numpy.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            raise _expected("an array of numbers", raw, where) from None
        return array
    if not (isinstance(raw, dict) and set(raw) == {"$a"} and isinstance(raw["$a"], list)
            and len(raw["$a"]) == 3):
        raise _expected("an array", raw, where)
    dtype, shape, data = raw["$a"]
    if dtype not in _DTYPES or not isinstance(shape, list) or len(shape) > 8 \
            or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise SchemaError(f"{where}: an array of dtype {_shown(dtype)}, shape {_shown(shape)}")
    buffer = _bytes({"$b": data}, where)
    size = math.prod(shape) * numpy.dtype(dtype).itemsize
    if size != len(buffer):
        raise SchemaError(f"{where}: an array of shape {shape} with {len(buffer)} bytes")
    return numpy.frombuffer(buffer, dtype=dtype).reshape(shape).copy()


def _check_plain(raw: object, where: str, depth: int) -> object:
    if depth > MAX_DEPTH:
        raise SchemaError(f"{where}: nested too deeply")
    if isinstance(raw, list):
        for i, x in enumerate(raw):
            _check_plain(x, f"{where}[{i}]", depth + 1)
    elif isinstance(raw, dict):
        for k, v in raw.items():
            _check_plain(v, f"{where}[{k!r}]", depth + 1)
    return raw


def _numpy():
    import sys

    return sys.modules.get("numpy")


def _expected(what: str, raw: object, where: str) -> SchemaError:
    return SchemaError(f"{where}: expected {what}, got {_shown(raw)}")


def _shown(raw: object) -> str:
    if isinstance(raw, dict):
        return "an object"
    if isinstance(raw, list):
        return "a list"
    text = repr(raw)
    return f"{type(raw).__name__} {text[:40]}"


def _names(options: tuple) -> str:
    return ", ".join(getattr(o, "__name__", repr(o)) for o in options)
