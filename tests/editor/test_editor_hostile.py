"""Hostile values for every edit a page (any websocket client) can drive: impossible inertias,
absurd numbers, snaps that do not exist, flat or huge parts. Each is refused in one line that
names the value without numpy reprs, and a refused edit leaves the model, the undo history and
every file in the work folder byte-identical; what is accepted is a model the reader reads."""

from __future__ import annotations

import hashlib
import io
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from helpers import fuzz
from mexone.control.spec import PidGains
from mexone.description.check import check_model, inertial_problem
from mexone.description.model import Box, Cylinder, Dynamics, Inertial, Limit, Pose, Sphere
from mexone.description.urdf import write_urdf
from mexone.editor.parts import read_part, read_parts
from mexone.editor.save import save_urdf
from mexone.editor.session import EditSession
from mexone.errors import InputError, MexoneError

ARM = Path(__file__).resolve().parents[1] / "data" / "editor"


def PROPERTY(test):  # noqa: N802 - reads as the decorator it is
    """CI: derandomized, 40 examples each (helpers.fuzz)."""
    return pytest.mark.fuzz(fuzz(40)(test))


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> Path:
    """arm_base fixed to the world, arm_upper on a motored revolute joint, arm_fore loose."""
    folder = tmp_path_factory.mktemp("hostile") / "work"
    session = EditSession.open(folder, name="arm")
    for link in ("arm_base", "arm_upper", "arm_fore"):
        session.import_part(f"{link}.stl", (ARM / f"{link}.stl").read_bytes())
        session.fit_collision(link, "cylinder")
    session.fix_to_world("arm_base")
    snap = session.snap_of("arm_upper", session.snap_choices("arm_upper")[0])
    _snap, point, axis = session.snaps("arm_upper")[snap]
    session.add_joint("shoulder", "arm_base", "arm_upper", "revolute", point, axis)
    session.set_motor("shoulder")
    return folder


@pytest.fixture
def session(template, tmp_path) -> EditSession:
    shutil.copytree(template, tmp_path / "work")
    return EditSession.open(tmp_path / "work")


def snapshot(session: EditSession) -> tuple:
    """Everything a refused edit must leave as it was: each file's bytes, the model, the history."""
    files = {str(p.relative_to(session.folder)): hashlib.sha256(p.read_bytes()).hexdigest()
             for p in sorted(session.folder.rglob("*")) if p.is_file()}
    return files, write_urdf(session.model), session.extras.to_json(), session.index, session.can_redo


def refused_or_sound(session: EditSession, edit) -> None:
    """A refusal changes nothing and says one line without numpy reprs; an acceptance leaves a
    model the reader reads back and `mexone check` can judge."""
    before = snapshot(session)
    try:
        edit()
    except MexoneError as exc:
        line = exc.one_line()
        assert "\n" not in line and "np.float" not in line and len(line) < 400, line
        assert snapshot(session) == before, line
        return
    assert session.index == before[3] + 1
    reopened = EditSession.open(session.folder)
    assert write_urdf(reopened.model) == write_urdf(session.model)
    check_model(session.model)


# ----- values a websocket client can send -----------------------------------------------------
HUGE = st.sampled_from([1e300, -1e300, 1e308, 1e37, 1e-300, -1e-300, 5e-324, 1e5, 1e6, 1e7])
NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True), HUGE,
                   st.floats(-10, 10), st.just(0.0))
ODD = st.one_of(st.text(max_size=5), st.none(), st.booleans(), st.lists(st.integers(), max_size=2))


def vectors(n: int):
    """n numbers mostly, sometimes the wrong count or not numbers at all."""
    return st.one_of(st.lists(NUMBER, min_size=n, max_size=n), st.lists(NUMBER, max_size=n + 2), ODD)


NAMES = st.sampled_from(["arm_base", "arm_upper", "arm_fore", "world", "shoulder", "nope", "", "a b"])


@PROPERTY
@given(mass=st.one_of(NUMBER, ODD), com=vectors(3), inertia=vectors(6), link=NAMES)
def test_typed_inertials(session, mass, com, inertia, link):
    refused_or_sound(session, lambda: session.set_inertial(link, mass, com, inertia))


@PROPERTY
@given(mass=st.one_of(NUMBER, ODD), link=NAMES)
def test_inertia_from_the_mesh(session, mass, link):
    refused_or_sound(session, lambda: session.compute_inertia(link, mass))


@PROPERTY
@given(size=vectors(3), xyz=vectors(3), rpy=vectors(3), kind=st.sampled_from([Box, Cylinder, Sphere]),
       link=NAMES, index=st.one_of(st.integers(-2, 2), ODD))
def test_typed_collisions(session, size, xyz, rpy, kind, link, index):
    def edit():
        values = ([*size, 0.0, 0.0, 0.0] if isinstance(size, list) else [size] * 3)[:3]  # as the page unpacks
        geometry = {Box: lambda: Box(tuple(values)), Cylinder: lambda: Cylinder(*values[:2]),
                    Sphere: lambda: Sphere(*values[:1])}[kind]()
        session.set_collision(link, index, geometry, Pose(xyz, rpy))

    refused_or_sound(session, edit)


@PROPERTY
@given(values=st.lists(st.one_of(NUMBER, st.none()), min_size=4, max_size=4), link=NAMES)
def test_surfaces(session, values, link):
    refused_or_sound(session, lambda: session.set_surface(link, *values))


@PROPERTY
@given(rgba=vectors(4), link=NAMES)
def test_colours(session, rgba, link):
    refused_or_sound(session, lambda: session.set_color(link, rgba))


@PROPERTY
@given(axis=st.one_of(st.none(), vectors(3)), limit=vectors(4), dynamics=vectors(2), joint=NAMES,
       type=st.one_of(st.none(), st.sampled_from(["revolute", "prismatic", "fixed", "planar", "x"])))
def test_joint_edits(session, axis, limit, dynamics, joint, type):
    def edit():
        lim = Limit(*limit) if isinstance(limit, list) and len(limit) == 4 else None
        dyn = Dynamics(*dynamics) if isinstance(dynamics, list) and len(dynamics) == 2 else None
        session.set_joint(joint, type=type, axis=axis, limit=lim, dynamics=dyn)

    refused_or_sound(session, edit)


@PROPERTY
@given(xyz=vectors(3), rpy=vectors(3), keep=st.booleans(), joint=NAMES)
def test_typed_joint_frames(session, xyz, rpy, keep, joint):
    refused_or_sound(session, lambda: session.move_joint_frame(joint, Pose(xyz, rpy), keep))


@PROPERTY
@given(at=vectors(3), joint=NAMES)
def test_dropped_gizmos(session, at, joint):
    refused_or_sound(session, lambda: session.snap_joint_near(joint, at))


SNAP_TEXT = st.one_of(st.from_regex(r"-?[0-9]{1,5}: [a-z ]{0,12}", fullmatch=True), st.text(max_size=12), ODD,
                      st.sampled_from(["9999: x", "-1: x", "0:", "(none)", "1e3: hole"]))


@PROPERTY
@given(choice=SNAP_TEXT, index=st.one_of(st.integers(-5, 10_000), ODD), joint=NAMES)
def test_snap_choices(session, choice, index, joint):
    def by_text():
        child = session.joint(joint).child
        session.snap_joint(joint, session.snap_of(child, choice))

    refused_or_sound(session, by_text)
    refused_or_sound(session, lambda: session.snap_joint(joint, index))


@PROPERTY
@given(choice=SNAP_TEXT, point=vectors(3), axis=vectors(3), name=st.sampled_from(["elbow", "x y", "shoulder"]),
       parent=NAMES, child=NAMES, type=st.sampled_from(["revolute", "fixed", "ball"]))
def test_new_joints(session, choice, point, axis, name, parent, child, type):
    def by_snap():
        index = session.snap_of(child, choice)
        _snap, at, along = session.snaps(child)[index]
        session.add_joint(name, parent, child, type, at, along)

    refused_or_sound(session, by_snap)
    refused_or_sound(session, lambda: session.add_joint(name, parent, child, type, point, axis))


@PROPERTY
@given(gains=vectors(3), on=st.booleans(), joint=NAMES)
def test_motors(session, gains, on, joint):
    def edit():
        pid = PidGains(*gains, -1.0, 1.0) if isinstance(gains, list) and len(gains) == 3 else None
        session.set_motor(joint, on, pid)

    refused_or_sound(session, edit)


@PROPERTY
@given(matrix=st.one_of(vectors(16), st.lists(NUMBER, min_size=16, max_size=16).map(
    lambda v: np.r_[np.eye(4)[:3].ravel(), 0, 0, 0, 1] + np.r_[[0, 0, 0, 1] * 3, [0] * 4] * v[0])),
    link=NAMES)
def test_placements(session, matrix, link):
    refused_or_sound(session, lambda: session.place(link, matrix))


@PROPERTY
@given(name=st.one_of(NAMES, st.text(max_size=70), ODD), fixed=st.booleans())
def test_names_a_page_sends(session, name, fixed):
    refused_or_sound(session, lambda: session.rename(name))
    refused_or_sound(session, lambda: session.fix_to_world(name, fixed))
    refused_or_sound(session, lambda: session.remove_joint(name))
    refused_or_sound(session, lambda: session.remove_link(name))


def stl(vertices, faces) -> bytes:
    buffer = io.BytesIO()
    trimesh.Trimesh(np.asarray(vertices, dtype=float), faces, process=False).export(buffer, file_type="stl")
    return buffer.getvalue()


@PROPERTY
@given(points=st.lists(st.lists(NUMBER.filter(np.isfinite), min_size=3, max_size=3), min_size=3, max_size=6),
       unit=st.sampled_from([None, "m", "mm", "inch", "parsec"]))
def test_imported_parts(session, points, unit):
    faces = [[0, 1, 2], *([[0, 2, 3], [0, 3, 1], [1, 3, 2]] if len(points) >= 4 else [])]
    refused_or_sound(session, lambda: session.import_part("part.stl", stl(points, faces), unit))


FORE = (ARM / "arm_fore.stl").read_bytes()


@PROPERTY
@given(name=st.one_of(st.text(max_size=20).map(lambda t: t + ".stl"),
                      st.sampled_from(["a.zip", "b.OBJ", "c.dae", "x", "../../e.stl", "a\nb.stl"])),
       data=st.one_of(st.binary(max_size=300),
                      st.tuples(st.integers(0, len(FORE) - 1), st.binary(min_size=1, max_size=8)).map(
                          lambda cut: FORE[:cut[0]] + cut[1] + FORE[cut[0] + len(cut[1]):])))
def test_uploads(name, data):
    """What the page's upload button hands the server: any name, any bytes (a mutated real STL)."""
    try:
        parts = read_parts(name, data)
    except MexoneError as exc:
        line = exc.one_line()
        assert "\n" not in line and "np.float" not in line and len(line) < 400, line
        return
    for part in parts:
        assert len(part.mesh.faces) > 0 and np.isfinite(part.mesh.vertices).all()


# ----- the found cases, each failing before ---------------------------------------------------
IMPOSSIBLE = {  # (ixx, ixy, ixz, iyy, iyz, izz): check's code
    "negative moment 1 1 -1": ((1, 0, 0, 1, 0, -1), "inertia-not-positive"),
    "triangle 1 1 5": ((1, 0, 0, 1, 0, 5), "inertia-triangle"),
    "all zero": ((0, 0, 0, 0, 0, 0), "inertia-not-positive"),
    "1 1 1 with Ixy 5": ((1, 5, 0, 1, 0, 1), "inertia-not-positive"),
}


@pytest.mark.parametrize("case", IMPOSSIBLE)
def test_impossible_inertias_are_refused_as_check_reports_them(session, case):
    inertia, code = IMPOSSIBLE[case]
    before = snapshot(session)
    with pytest.raises(InputError) as refused:
        session.set_inertial("arm_fore", 1.0, (0, 0, 0), inertia)
    assert snapshot(session) == before
    found = inertial_problem(Inertial(1.0, tuple(float(v) for v in inertia)))
    assert found is not None and found[0] == code
    assert found[1] in refused.value.one_line()  # the one rule, said the same way


@pytest.mark.parametrize("edit, words", [
    (lambda s: s.set_inertial("arm_fore", 1e300, (0, 0, 0), (1e-3, 0, 0, 1e-3, 0, 1e-3)), "mass 1e+300"),
    (lambda s: s.set_inertial("arm_fore", 1e-300, (0, 0, 0), (1e-3, 0, 0, 1e-3, 0, 1e-3)), "mass 1e-300"),
    (lambda s: s.compute_inertia("arm_fore", 1e300), "mass 1e+300"),
    (lambda s: s.set_inertial("arm_fore", 1, (0, 0, 1e300), (1e-3, 0, 0, 1e-3, 0, 1e-3)), "centre of mass 1e+300"),
    (lambda s: s.set_collision("arm_fore", 0, Cylinder(1e300, 0.1), Pose()), "collision size 1e+300"),
    (lambda s: s.set_surface("arm_fore", mu1=1e300), "mu1 1e+300"),
    (lambda s: s.set_joint("shoulder", limit=Limit(-1e300, 1e300, 10, 3)), "limit -1e+300"),
    (lambda s: s.set_joint("shoulder", limit=Limit(-1, 1, 1e300, 3)), "effort limit 1e+300"),
    (lambda s: s.set_joint("shoulder", dynamics=Dynamics(1e300, 0)), "damping 1e+300"),
    (lambda s: s.move_joint_frame("shoulder", Pose((1e300, 0, 0))), "joint position 1e+300"),
    (lambda s: s.set_motor("shoulder", True, PidGains(1e300)), "p 1e+300"),
    (lambda s: s.import_part("wide.stl", stl([[0, 0, 0], [1e37, 0, 0], [0, 1e37, 0], [0, 0, 1e37]],
                                             [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]), "m"), "1e+37 units"),
    (lambda s: s.import_part("big.stl", stl([[0, 0, 0], [1e3, 0, 0], [0, 1e3, 0], [0, 0, 1e3]],
                                            [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]), "m"), "its mass"),
])
def test_absurd_finite_values_are_refused_by_their_range(session, edit, words):
    before = snapshot(session)
    with pytest.raises(InputError) as refused:
        edit(session)
    assert words in refused.value.one_line() and "must be" in refused.value.one_line()
    assert snapshot(session) == before


def test_an_axis_of_1e308_is_a_direction_and_save_keeps_working(session, tmp_path):
    session.set_joint("shoulder", axis=(1e308, 1e308, 1e308))
    np.testing.assert_allclose(session.joint("shoulder").axis, [3**-0.5] * 3)
    assert save_urdf(session, tmp_path / "arm.urdf").is_file()


def test_an_edit_the_reader_refuses_changes_no_file(session, tmp_path, monkeypatch):
    """What the axis overflow did: a step the reader then refused had already rewritten
    model.urdf, and every Save failed after it."""
    from mexone.editor import session as module

    before = snapshot(session)
    zero_axis = write_urdf  # the URDF as written, with the shoulder's axis zeroed

    def writer(model, comment=None):
        return zero_axis(model, comment).replace('<axis xyz="', '<axis xyz="0 0 0" old="')

    monkeypatch.setattr(module, "write_urdf", writer)
    with pytest.raises(MexoneError, match="zero axis"):
        session.set_joint("shoulder", limit=Limit(-1, 1, 10, 3))
    monkeypatch.undo()
    assert snapshot(session) == before
    assert save_urdf(session, tmp_path / "arm.urdf").is_file()


@pytest.mark.parametrize("name, vertices, faces", [
    ("flat", [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]], [[0, 1, 2], [1, 3, 2]]),
    ("one_triangle", [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], [[0, 1, 2]]),
    ("collinear", [[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], [[0, 1, 2]]),
])
@pytest.mark.parametrize("networkx", [True, False])
def test_flat_parts_are_refused_in_one_line_and_leave_nothing(session, monkeypatch, name, vertices, faces,
                                                              networkx):
    if not networkx:  # the hull's repair needs networkx; a part is refused the same without it
        monkeypatch.setitem(sys.modules, "networkx", None)
    data = stl(vertices, faces)
    with pytest.raises(InputError, match="is flat"):
        read_part(f"{name}.stl", data)
    before = snapshot(session)
    with pytest.raises(InputError, match="is flat"):
        session.import_part(f"{name}.stl", data, "m")
    assert snapshot(session) == before


@pytest.mark.parametrize("choice", ["9999: x", "-1: x", "0", "", "(none)"])
def test_a_snap_that_was_not_offered_is_refused(session, choice):
    with pytest.raises(InputError, match="is not one of the .* offered"):
        session.snap_of("arm_fore", choice)
    last = session.snap_choices("arm_fore")[-1]
    assert session.snap_of("arm_fore", last) == len(session.snap_choices("arm_fore")) - 1
