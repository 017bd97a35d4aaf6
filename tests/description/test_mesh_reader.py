"""The lab reads STL meshes with numpy (description/meshes.py `read_triangles`) so that it never
imports trimesh (~65 MB a process, with scipy and networkx): the same triangles as trimesh, and a
lab that really does not import it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from mexone.description.meshes import Triangles, load_mesh, read_triangles
from mexone.errors import ModelError

REPO = Path(__file__).resolve().parents[2]
SHIPPED = sorted((REPO / "src" / "mexone" / "robots").rglob("*.[sS][tT][lL]"))
TEST_DATA = sorted((REPO / "tests" / "data").rglob("*.[sS][tT][lL]"))
OTHERS = sorted(p for suffix in ("obj", "dae") for p in (REPO / "tests" / "data").rglob(f"*.{suffix}"))


def _same(ours: Triangles, theirs: trimesh.Trimesh) -> None:
    np.testing.assert_array_equal(ours.vertices, theirs.vertices)
    np.testing.assert_array_equal(ours.faces, theirs.faces)
    np.testing.assert_array_equal(ours.bounds, theirs.bounds)


def test_every_shipped_and_test_stl_reads_as_trimesh_reads_it():
    assert len(SHIPPED) >= 38 and TEST_DATA
    for path in SHIPPED + TEST_DATA:
        ours = read_triangles(path)
        _same(ours, trimesh.load(path, force="mesh", process=False))
        assert ours.vertices.dtype == np.float64 and ours.faces.dtype == np.int64, path


def test_ascii_stl_and_other_formats_read_as_trimesh_reads_them(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.3)
    ascii_stl = tmp_path / "ball.stl"
    ascii_stl.write_bytes(trimesh.exchange.stl.export_stl_ascii(mesh).encode())
    # an ASCII STL in capitals, and a binary one whose 80-byte header starts with "solid"
    shouting = tmp_path / "BALL.STL"
    shouting.write_text(ascii_stl.read_text().upper())
    solid_header = tmp_path / "solid.stl"
    binary = trimesh.exchange.stl.export_stl(mesh)
    solid_header.write_bytes(b"solid made by a CAD tool".ljust(80, b" ") + binary[80:])
    for path in (ascii_stl, shouting, solid_header):
        _same(read_triangles(path), trimesh.load(path, force="mesh", process=False))
    for path in OTHERS:  # through trimesh itself
        _same(read_triangles(path), load_mesh(path))


def test_a_mirroring_scale_keeps_the_outside_out_as_trimesh_does():
    path = SHIPPED[0]
    for scale in ((0.001, 0.001, 0.001), (-1.0, 1.0, 1.0), (2.0, -0.5, -1.0)):
        theirs = load_mesh(path).copy()
        theirs.apply_scale(scale)
        ours = read_triangles(path).scaled(scale)
        np.testing.assert_allclose(ours.vertices, theirs.vertices, rtol=1e-12)
        np.testing.assert_array_equal(ours.faces, theirs.faces)


@pytest.mark.parametrize("content", [b"", b"solid x\nfacet normal 0 0 1\nendsolid x\n",
                                     b"solid x\n vertex 1 2 nope\n", b"\x00" * 84 + b"\x01",
                                     b"not a mesh at all"])
def test_a_broken_stl_is_a_model_error_naming_the_file(tmp_path, content):
    path = tmp_path / "broken.stl"
    path.write_bytes(content)
    with pytest.raises(ModelError, match="broken.stl"):
        read_triangles(path)


PROBE = """
import json, sys
from mexone.cli import main
status = main(["sim", "--port", "0", "--duration", "0.05"])
print(json.dumps([status, sorted({name.split(".")[0] for name in sys.modules})]))
"""


def test_a_lab_with_its_page_built_imports_no_trimesh_scipy_or_mink():
    """Each costs a student's lab megabytes it does not use (benchmarks/RESULTS.md, a class on
    one machine); a plain `mexone sim` builds its page's scene at start, so this covers it."""
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                          timeout=180)
    assert done.returncode == 0, done.stderr
    status, imported = json.loads(done.stdout.strip().splitlines()[-1])
    assert status == 0
    assert "viser" in imported and "mujoco" in imported  # the page was really served
    heavy = {"trimesh", "scipy", "networkx", "mink", "qpsolvers", "matplotlib", "control"}
    assert not heavy & set(imported), done.stderr
