"""Importing a CAD part: its bytes read as a mesh, its unit chosen (or guessed from its size),
stored in the working folder under a name the server picks."""

from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass

import numpy as np

from mexone.editor.massprops import solid_of
from mexone.errors import InputError
from mexone.ranges import SIZE, number_text

__all__ = ["UNITS", "MESH_TYPES", "Part", "read_part", "read_parts", "guess_unit", "safe_name", "quoted",
           "MAX_PART_BYTES", "MAX_ZIP_PARTS"]

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254}
MESH_TYPES = ("stl", "obj", "dae")
MAX_PART_BYTES = 64 * 1024 * 1024  # a 64 MB STL is over a million triangles: simplify it first
MAX_ZIP_PARTS = 100  # parts in one zipped folder
# A robot part spans a few centimetres to a metre; the unit that puts it closest to this (in
# log scale) is the guess. Inches are offered but never guessed: 6 in and 15 cm look alike.
_TYPICAL_SIZE = 0.15  # m
_GUESSED = ("m", "cm", "mm")


@dataclass
class Part:
    name: str  # link name the part becomes
    mesh: object  # trimesh.Trimesh in the file's own units
    guess: str  # unit guessed from its size

    @property
    def extent(self) -> float:
        """Largest side of its bounding box, in the file's units."""
        return float(np.max(self.mesh.extents))


def quoted(filename: object) -> str:
    """An uploaded file's name for a one-line message: quoted, escapes shown, at most 64 chars."""
    return repr(filename[:64] if isinstance(filename, str) else filename)[:80]


def safe_name(text: str, taken=()) -> str:
    """A link/file name from an uploaded file's name: letters, digits and _ only (never a path),
    made unique against `taken`."""
    stem = re.sub(r"\.(stl|obj|dae)$", "", text.strip(), flags=re.IGNORECASE)
    stem = re.sub(r"[^A-Za-z0-9_]+", "_", stem.rsplit("/", 1)[-1].rsplit("\\", 1)[-1]).strip("_")
    stem = (stem or "part").lower()[:40]
    if stem[0].isdigit():
        stem = "part_" + stem
    name, n = stem, 2
    while name in taken:
        name, n = f"{stem}_{n}", n + 1
    return name


def guess_unit(extent: float) -> str:
    """The unit that makes a part of this extent (in file units) robot-sized."""
    if not (math.isfinite(extent) and extent > 0):
        return "m"
    return min(_GUESSED, key=lambda u: abs(math.log(extent * UNITS[u] / _TYPICAL_SIZE)))


def read_part(filename: str, data: bytes, taken=()) -> Part:
    """The mesh in an uploaded file; `filename` only picks the reader and the link's name."""
    import trimesh

    kind = filename.rsplit(".", 1)[-1].lower() if "." in filename else ""
    if kind not in MESH_TYPES:
        raise InputError(f"{quoted(filename)} is not an STL, OBJ or DAE file", hint="export the part as STL")
    if len(data) > MAX_PART_BYTES:
        raise InputError(f"{quoted(filename)} is {len(data) / 1e6:.0f} MB, over "
                         f"{MAX_PART_BYTES // 2**20} MB", hint="simplify the mesh in the CAD program")
    try:
        with np.errstate(all="ignore"):  # a 1e37-wide part overflows while merging: refused below
            mesh = trimesh.load(io.BytesIO(data), file_type=kind, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for bad files
        raise InputError(f"{quoted(filename)} is unreadable: {' '.join(str(exc).split())[:160]}",
                         hint="export it again as binary STL") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(f"{quoted(filename)} holds no triangles", hint="export it again as STL")
    if not np.isfinite(mesh.vertices).all():
        raise InputError(f"{quoted(filename)} has vertices that are not numbers", hint="export it again")
    extent = float(np.max(mesh.extents))
    if extent <= 0:
        raise InputError(f"{quoted(filename)} is flat in every direction (zero size)",
                         hint="export the solid, not a sketch")
    smallest = min(UNITS, key=UNITS.get)
    SIZE.check(extent * UNITS[smallest], f"{quoted(filename)} ({number_text(extent)} units wide), its "
               f"largest side even in {smallest},", hint="export the part at its real size")
    solid_of(mesh, quoted(filename))
    return Part(safe_name(filename, taken), mesh, guess_unit(extent))


def read_parts(filename: str, data: bytes, taken=()) -> list[Part]:
    """One part, or every STL/OBJ/DAE in a zipped folder of parts (a browser uploads files, not
    folders). The zip's sizes are checked before anything is unpacked, and it is unpacked in
    memory: its paths never name a file here."""
    if not filename.lower().endswith(".zip"):
        return [read_part(filename, data, taken)]
    import zipfile

    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        entries = [e for e in archive.infolist() if not e.is_dir()
                   and e.filename.rsplit(".", 1)[-1].lower() in MESH_TYPES]
    except (zipfile.BadZipFile, ValueError) as exc:
        raise InputError(f"{quoted(filename)} is not a readable zip: {' '.join(str(exc).split())[:160]}",
                         hint="zip the parts' folder again") from None
    if not entries:
        raise InputError(f"{quoted(filename)} holds no STL, OBJ or DAE file", hint="zip the folder of parts")
    if len(entries) > MAX_ZIP_PARTS or sum(e.file_size for e in entries) > MAX_PART_BYTES:
        raise InputError(f"{quoted(filename)} unpacks to {len(entries)} parts and "
                         f"{sum(e.file_size for e in entries) / 1e6:.0f} MB, over {MAX_ZIP_PARTS} parts "
                         f"or {MAX_PART_BYTES // 2**20} MB", hint="import the parts in smaller groups")
    parts: list[Part] = []
    budget = MAX_PART_BYTES  # a header can lie about sizes: count what really unpacks
    for entry in sorted(entries, key=lambda e: e.filename):
        names = set(taken) | {p.name for p in parts}
        with archive.open(entry) as member:
            content = member.read(budget + 1)
        budget -= len(content)
        if budget < 0:
            raise InputError(f"{quoted(filename)} unpacks to more than {MAX_PART_BYTES // 2**20} MB",
                             hint="import the parts in smaller groups")
        parts.append(read_part(entry.filename, content, names))
    return parts
