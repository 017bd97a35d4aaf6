"""A StateFeedback's design_file is a file a student hands in (issue 36): every malformed one is
one line naming that file -- from `mexone check --controllers` at the YAML's line and from the
lab `mexone sim` builds -- never a traceback nor mexone's own deploy.py, and nothing is allocated
beyond what the .npy headers declare once those are checked (a 120 kB .npz declaring a 120 MB K
is refused before its data is read). The design API's bad arguments are one InputError line
too, their bounds in ranges.py."""

from __future__ import annotations

import io
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.lib import format as npy

from helpers import fuzz, run_cli
from mexone.design.design_file import read_design
from mexone.errors import InputError
from mexone.lab import Lab

GOOD = {"K": np.array([[20.0, 0.5]]), "u0": np.array([0.0]), "joints": np.array(["l_elbow"]),
        "interface": np.array("effort"), "states": np.array(["l_elbow:q", "l_elbow:dq"]),
        "qpos": np.array([0.0]), "qvel": np.array([0.0]), "qpos_index": np.array([20]),
        "qvel_index": np.array([19]), "dt": np.array(0.002)}


def npz(path: Path, **changes) -> Path:
    arrays = {k: v for k, v in {**GOOD, **changes}.items() if v is not None}
    np.savez(path, **arrays)
    return path


def lying_header(path: Path, shape: tuple[int, ...], data: bytes = b"\0" * 48) -> Path:
    """A .npz whose K.npy header declares `shape` and holds only `data`."""
    np.savez(path, **{k: v for k, v in GOOD.items() if k != "K"})
    member = io.BytesIO()
    npy.write_array_header_1_0(member, {"descr": "<f8", "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "a") as archive:
        archive.writestr("K.npy", member.getvalue() + data)
    return path


def deflated(path: Path, shape: tuple[int, int]) -> Path:
    """A .npz with a K of zeros that deflates to ~1/1000 of its size (streamed, never held)."""
    np.savez(path, **{k: v for k, v in GOOD.items() if k != "K"})
    header = io.BytesIO()
    npy.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": shape})
    chunk = bytes(8 << 20)
    with zipfile.ZipFile(path, "a", zipfile.ZIP_DEFLATED) as archive, \
            archive.open("K.npy", "w", force_zip64=True) as member:
        member.write(header.getvalue())
        left = shape[0] * shape[1] * 8
        while left:
            member.write(chunk[:min(left, len(chunk))])
            left -= min(left, len(chunk))
    return path


def written(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def truncated(path: Path) -> Path:
    data = npz(path).read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


CASES = {  # name: (make the file in a folder, what the one line says)
    "empty": (lambda d: written(d / "d.npz", b""), "cannot be read"),
    "truncated": (lambda d: truncated(d / "d.npz"), "cannot be read"),
    "header 3 x 1e12": (lambda d: lying_header(d / "d.npz", (3, 10**12)),
                        "K declares 3000000000000 values"),
    "deflated 3 x 5e6": (lambda d: deflated(d / "d.npz", (3, 5_000_000)),
                         "K declares 15000000 values"),
    "dt 0": (lambda d: npz(d / "d.npz", dt=np.array(0.0)), "dt 0 must be"),
    "dt NaN": (lambda d: npz(d / "d.npz", dt=np.array(np.nan)), "dt NaN must be"),
    "states short": (lambda d: npz(d / "d.npz", states=np.array(["l_elbow:q"])),
                     "states has 1 labels; qpos, qvel and act make 2 states"),
    "qvel_index -1": (lambda d: npz(d / "d.npz", qvel_index=np.array([-1])),
                      "qvel_index has -1: indices are whole numbers >= 0"),
    "qvel_index 99": (lambda d: npz(d / "d.npz", qvel_index=np.array([99])),
                      "qvel_index has 99; the robot has"),
    "unknown actuator": (lambda d: npz(d / "d.npz", act=np.array([0.0]),
                                       act_actuators=np.array(["nope/i"]),
                                       act_offsets=np.array([0]), K=np.array([[20.0, 0.5, 1.0]]),
                                       states=np.array(["l_elbow:q", "l_elbow:dq", "nope/i"])),
                         "act_actuators names 'nope/i', which is no actuator"),
    "object array": (lambda d: npz(d / "d.npz", joints=np.array(["l_elbow"], dtype=object)),
                     "joints holds object values, not text"),
}


def controllers_yaml(folder: Path, design: Path) -> Path:
    path = folder / "controllers.yaml"
    path.write_text("mex_rb:\n"
                    "  elbow_lqr:\n"
                    "    type: mexone/StateFeedback\n"
                    "    joints: [l_elbow]\n"
                    "    update_rate: 500\n"
                    f"    design_file: {design.name}\n")
    return path


@pytest.mark.parametrize("case", CASES)
def test_a_malformed_design_file_is_one_line_naming_it(tmp_path, case):
    make, says = CASES[case]
    design = make(tmp_path)
    path = controllers_yaml(tmp_path, design)
    code, out, err = run_cli(["check", "--controllers", path])
    found = [row.strip() for row in out.splitlines() if "[controller-configure]" in row]
    assert code == 1 and len(found) == 1 and "Traceback" not in out + err, out + err
    assert found[0].startswith(f"{path}:6: error: controller \"elbow_lqr\": design file "
                               f"{design}"), found
    assert says in found[0], found
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as sim:  # what `mexone sim --controllers` builds
            Lab.create(controllers=path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    line = str(sim.value)
    assert "\n" not in line and f"design file {design}" in line and "deploy.py" not in line, line
    assert says in line, line
    assert peak < 60e6, f"{peak / 1e6:.0f} MB allocated"  # a compiled Mex-One lab: ~20 MB


def test_a_good_design_file_runs_and_saves_without_a_nan_period(tmp_path):
    design = npz(tmp_path / "d.npz")
    lab = Lab.create(controllers=controllers_yaml(tmp_path, design))
    assert lab.manager.controllers["elbow_lqr"].running
    assert read_design(design).dt == 0.002
    assert read_design(npz(tmp_path / "any_rate.npz", dt=None)).dt is None  # no dt: any rate


@fuzz(120)
@given(st.binary(max_size=400), st.sampled_from([".npz", ".yaml"]))
def test_any_bytes_are_a_design_or_one_line(tmp_path, data, suffix):
    path = written(tmp_path / f"d{suffix}", data)
    try:
        read_design(path)
    except InputError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)


# ----- the design API ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def elbow():
    from mexone.design import linearize
    from mexone.physics.compile import CompileOptions

    lab = Lab.create(options=CompileOptions(fixed_base=True))
    return lab, linearize(lab, joints=["l_elbow"], period=0.002)


def test_the_design_api_refuses_bad_arguments_in_one_line(elbow):
    import time

    from mexone.design import compare, deploy, linearize, lqr

    lab, plant = elbow
    controller = deploy(lab, np.zeros((1, plant.nstates)), plant, name="elbow_zero")
    started = time.monotonic()
    cases = {
        "Q string": (lambda: lqr(plant, "diag", np.eye(1)), "lqr: Q is not a matrix of numbers"),
        "Q ragged": (lambda: lqr(plant, [[1.0, 0.0], [0.0]], np.eye(1)), "lqr: Q is not a matrix"),
        "plant None": (lambda: lqr(None, np.eye(2), np.eye(1)), "lqr: the plant is NoneType"),
        "rate NaN": (lambda: deploy(lab, np.zeros((1, plant.nstates)), plant, rate=float("nan")),
                     "deploy: rate NaN must be"),
        "name path": (lambda: deploy(lab, np.zeros((1, plant.nstates)), plant, name="../../x y"),
                      "deploy: name '../../x y' is not a controller name"),
        "joints string": (lambda: linearize(lab, joints="l_elbow"),
                          "joints is the string 'l_elbow': give a list"),
        "period 1e6": (lambda: linearize(lab, joints=["l_elbow"], period=1e6),
                       "period 1e+06 must be a finite number"),
        "duration 1e12": (lambda: compare(lab, controller, plant, {"l_elbow:q": 0.01},
                                          duration=1e12), "duration 1e+12 must be"),
    }
    for name, (call, says) in cases.items():
        with pytest.raises(InputError) as info:
            call()
        assert says in str(info.value) and "\n" not in str(info.value), (name, str(info.value))
    assert time.monotonic() - started < 20  # refused, not run (linearize(period=1e6): > 9 min)
    assert "x y" not in " ".join(lab.manager.controllers)
