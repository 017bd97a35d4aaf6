"""A design file (a StateFeedback's `design_file:`, written by save_design) read as what it is: a
file a student hands in. Every way it can be wrong is one InputError line naming the file: not
a zip or a YAML, truncated, an array of the wrong kind, shape or length, a NaN, a period that is
no period, indices or actuators the robot does not have. Nothing is allocated beyond what the
.npy headers declare, and those are checked first (a 1.2 MB .npz can declare a 1.2 GB K): the
arrays' sizes are bounded by ranges.DESIGN_VALUES before a byte of their data is read.
"""

from __future__ import annotations

import io
import math
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.lib import format as npy
from numpy.typing import ArrayLike

from mexone import yamlio
from mexone.errors import InputError, printable
from mexone.inputs import read_input
from mexone.ranges import DESIGN_VALUES, SAMPLE_PERIOD, number_text

__all__ = ["RawDesign", "read_design", "check_on_robot", "FIELDS", "REQUIRED", "INTERFACES"]

# field -> (kind: "number", "integer" or "text"; most dimensions)
FIELDS = {"K": ("number", 2), "u0": ("number", 1), "joints": ("text", 1), "interface": ("text", 0),
          "qpos": ("number", 1), "qvel": ("number", 1), "qpos_index": ("integer", 1),
          "qvel_index": ("integer", 1), "states": ("text", 1), "act": ("number", 1),
          "act_actuators": ("text", 1), "act_offsets": ("integer", 1), "dt": ("number", 0)}
REQUIRED = ("K", "qpos", "qvel", "states", "joints")
INTERFACES = ("effort", "position", "velocity")
_HINT = "write it with mexone.design.save_design(path, K, plant)"
_BROKEN = (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, ValueError, TypeError,
           OverflowError, OSError, KeyError, IndexError, NotImplementedError, MemoryError)


@dataclass(frozen=True)
class RawDesign:
    """A design file's fields, checked against each other (not yet against a robot)."""

    K: np.ndarray
    u0: np.ndarray
    joints: tuple[str, ...]
    interface: str
    qpos: np.ndarray
    qvel: np.ndarray
    qpos_index: np.ndarray
    qvel_index: np.ndarray
    states: tuple[str, ...]
    act: np.ndarray
    act_actuators: tuple[str, ...]
    act_offsets: np.ndarray
    dt: float | None  # None: no period (a continuous design's gain, any rate)




def check_on_robot(path: Path, qpos_index: np.ndarray, qvel_index: np.ndarray,
                   act_actuators: Sequence[str], nq: int, nv: int, actuators: set[str] | None) -> None:
    """A design file's indices within a robot of nq positions and nv velocities (at most), its
    activation states' actuators among `actuators` (None: not known here)."""
    for name, index, size in (("qpos_index", qpos_index, nq), ("qvel_index", qvel_index, nv)):
        if np.size(index) and int(np.max(index)) >= size:
            raise _error(path, f"{name} has {int(np.max(index))}; the robot has {size} "
                               f"({name.removesuffix('_index')} 0 to {size - 1})",
                         hint="linearize and save_design again on this robot")
    unknown = [a for a in act_actuators if actuators is not None and a not in actuators]
    if unknown:
        raise _error(path, f"act_actuators names {printable(unknown[0], 80)!r}, which is no "
                           "actuator of the robot with a state",
                     hint="linearize and save_design again on this robot")


def _error(path: Path, what: str, hint: str | None = _HINT) -> InputError:
    return InputError(f"design file {path}: {what}", file=str(path), hint=hint)


def read_design(path: str | Path) -> RawDesign:
    """A design file (.npz or .yaml), every field checked: the one reader mexone uses."""
    path = Path(path)
    if path.suffix not in (".npz", ".yaml", ".yml"):
        raise InputError(f"design file {path} is not .npz or .yaml", file=str(path))
    try:
        data = read_input(path)
    except InputError as exc:
        raise InputError(f"design file {path} does not exist" if exc.what == "no such file" else
                         f"design file {path}: {exc.what}", file=str(path), hint=exc.hint) from None
    try:
        raw = _npz(data, path) if path.suffix == ".npz" else _yaml(data, path)
    except InputError:
        raise
    except _BROKEN as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise _error(path, f"cannot be read ({printable(why, 120)})") from None
    return _checked(raw, path)


def _npz(data: bytes, path: Path) -> dict[str, np.ndarray]:
    """The .npz's arrays of FIELDS, each header read and bounded before its data."""
    out: dict[str, np.ndarray] = {}
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        for info in archive.infolist():
            key = info.filename.removesuffix(".npy")
            if key not in FIELDS:
                continue
            with archive.open(info) as member:
                shape, dtype = _header(member, key, path)
            _bounded(key, shape, dtype, path)
            with archive.open(info) as member:
                out[key] = npy.read_array(member, allow_pickle=False)
    return out


def _header(member: IO[bytes], key: str, path: Path) -> tuple[tuple[int, ...], np.dtype]:
    version = npy.read_magic(member)
    if version == (1, 0):
        shape, _, dtype = npy.read_array_header_1_0(member)
    elif version == (2, 0):
        shape, _, dtype = npy.read_array_header_2_0(member)
    else:
        raise _error(path, f"{key}.npy is .npy version {version[0]}.{version[1]}, not 1.0 or 2.0")
    return shape, dtype


def _bounded(key: str, shape: tuple[int, ...], dtype: np.dtype, path: Path) -> None:
    kind, most = FIELDS[key]
    if dtype.hasobject or dtype.kind not in ("U" if kind == "text" else "fiub"):
        wanted = "text" if kind == "text" else "numbers"
        raise _error(path, f"{key} holds {dtype} values, not {wanted}")
    if len(shape) > max(most, 1) or (most == 0 and math.prod(shape) != 1):
        raise _error(path, f"{key} has shape {shape}: {_dims(most)}")
    count = math.prod(shape)
    if not DESIGN_VALUES.contains(count) or count * dtype.itemsize > DESIGN_VALUES.high * 8:
        raise _error(path, f"{key} declares {count} values of {dtype.itemsize} bytes: "
                           f"{DESIGN_VALUES.describe()}", hint="is it the right file?")


def _dims(most: int) -> str:
    return ("one value", "a list", "a matrix (joints x states)")[most]


def _yaml(data: bytes, path: Path) -> dict[str, Any]:
    raw = yamlio.load(data.decode("utf-8-sig"), path)
    if not isinstance(raw, dict):
        raise _error(path, "is not a mapping of K, u0, joints, states, qpos, qvel, ...")
    out = {}
    for key, value in raw.items():
        if key not in FIELDS:
            raise _error(path, f"unknown field {printable(key, 40)!r}",
                         hint="fields: " + ", ".join(FIELDS))
        kind, most = FIELDS[key]
        array = np.asarray(value, dtype=str if kind == "text" else float)
        _bounded(key, array.shape, array.dtype, path)
        out[key] = array
    return out


def _numbers(raw: dict[str, Any], key: str, path: Path, default: ArrayLike | None = None
             ) -> np.ndarray:
    if key not in raw:
        if default is None:
            raise _error(path, f"has no {key!r}")
        return np.asarray(default, dtype=float)
    values = np.asarray(raw[key])
    if FIELDS[key][1] == 1:
        values = values.reshape(-1)
    values = values.astype(float)
    if not np.all(np.isfinite(values)):
        raise _error(path, f"{key} has a NaN or inf")
    return values


def _indices(raw: dict[str, Any], key: str, size: int, path: Path) -> np.ndarray:
    values = _numbers(raw, key, path, default=np.arange(size))
    if values.size != size:
        raise _error(path, f"{key} has {values.size} entries for {size} values of "
                           f"{key.removesuffix('_index')}")
    if values.size and (values.min() < 0 or np.any(values != np.round(values))):
        raise _error(path, f"{key} has {number_text(values.min())}: indices are whole numbers >= 0")
    if len(set(values.tolist())) != values.size:
        raise _error(path, f"{key} names an entry twice")
    return values.astype(int)


def _texts(raw: dict[str, Any], key: str, path: Path, default: Sequence[str] = ()
           ) -> tuple[str, ...]:
    values = np.asarray(raw.get(key, default)).reshape(-1)
    return tuple(str(v) for v in values)


def _checked(raw: dict[str, Any], path: Path) -> RawDesign:
    for key in REQUIRED:
        if key not in raw:
            raise _error(path, f"has no {key!r}")
    K = np.atleast_2d(_numbers(raw, "K", path))
    qpos, qvel = _numbers(raw, "qpos", path), _numbers(raw, "qvel", path)
    act = _numbers(raw, "act", path, default=[])
    joints = _texts(raw, "joints", path)
    states = _texts(raw, "states", path)
    if not joints or len(set(joints)) != len(joints):
        raise _error(path, "joints must name each joint the design drives once")
    nx = 2 * qvel.size + act.size
    if len(states) != nx:
        raise _error(path, f"states has {len(states)} labels; qpos, qvel and act make {nx} "
                           f"states (2 x {qvel.size} + {act.size})")
    if K.shape != (len(joints), nx):
        raise _error(path, f"K has shape ({', '.join(map(str, K.shape))}); its point needs "
                           f"({len(joints)}, {nx}) ({len(joints)} joints x {nx} states)")
    u0 = _numbers(raw, "u0", path, default=np.zeros(len(joints)))
    if u0.size != len(joints):
        raise _error(path, f"u0 has {u0.size} values for {len(joints)} joints")
    interface = str(np.asarray(raw.get("interface", "effort")).reshape(-1)[0])
    if interface not in INTERFACES:
        raise _error(path, f"interface {printable(interface, 40)!r} is not one of "
                           f"{', '.join(INTERFACES)}")
    actuators = _texts(raw, "act_actuators", path)
    offsets = _numbers(raw, "act_offsets", path, default=[])
    if len(actuators) != act.size or offsets.size != act.size:
        raise _error(path, f"act has {act.size} values but act_actuators {len(actuators)} and "
                           f"act_offsets {offsets.size}")
    if offsets.size and (offsets.min() < 0 or np.any(offsets != np.round(offsets))):
        raise _error(path, "act_offsets must be whole numbers >= 0")
    dt = None
    if "dt" in raw:
        value = float(np.asarray(raw["dt"]).reshape(-1)[0])
        if not SAMPLE_PERIOD.contains(value):
            raise _error(path, f"dt {number_text(value)} must be {SAMPLE_PERIOD.describe()} (the "
                               "period the design was made for; leave dt out for a continuous "
                               "design's gain)")
        dt = value
    return RawDesign(K, u0, joints, interface, qpos, qvel,
                     _indices(raw, "qpos_index", qpos.size, path),
                     _indices(raw, "qvel_index", qvel.size, path), states, act, actuators,
                     offsets.astype(int), dt)
