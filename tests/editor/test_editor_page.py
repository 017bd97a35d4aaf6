"""The editor page's server side: the GUI's Origin guard, values a page sends refused by the
server, clicks that pick links, findings that select, Simulate handing the model to `mexone
sim`'s page, and the `mexone edit` verb's errors."""

from __future__ import annotations

import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import viser
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from mexone.cli import main
from mexone.description.model import Box
from mexone.editor.app import EditorApp
from mexone.editor.session import EditSession
from mexone.robots import mex_one

ARM = Path(__file__).resolve().parents[1] / "data" / "editor"


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    folder = tmp_path_factory.mktemp("page")
    (folder / "out").mkdir()
    session = EditSession.open(folder / "work", name="arm")
    for link in ("arm_base", "arm_upper"):
        session.import_part(f"{link}.stl", (ARM / f"{link}.stl").read_bytes())
    session.fix_to_world("arm_base")
    editor = EditorApp(session, folder / "out", port=0)
    yield editor
    editor.stop()


def test_a_page_from_another_origin_is_refused(app):
    import socket

    port = app.server.get_port()
    sock = socket.create_connection(("127.0.0.1", port))
    with pytest.raises(InvalidStatus) as refused:  # HTTP 403 at the handshake: nothing served
        connect(f"ws://127.0.0.1:{port}", sock=sock, origin="http://evil.example:8000",
                subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10)
    assert refused.value.response.status_code == 403


def test_values_a_page_sends_are_checked_by_the_server(app):
    session = app.session
    step = session.index
    app._link.value = "arm_upper"
    app._select_link("arm_upper")
    app._mass.value = float("nan")  # a page can send anything its widgets would not
    assert not app.act("inertia", lambda: session.compute_inertia(app._need_link(), app._mass.value))
    app._base.value = "../../etc/evil"
    assert not app.act("save", lambda: app.save("urdf"))
    assert "refused" in app._status_msg.content
    assert session.index == step
    assert not any(app.out_dir.iterdir())


def test_clicks_pick_parent_and_child_and_a_finding_selects_its_element(app):
    app.click_sets = "parent"
    app._clicked("arm_base")
    assert app._parent.value == "arm_base" and app.selected_link == "arm_base"
    app.click_sets = "child"
    app._clicked("arm_upper")
    assert app._child.value == "arm_upper"
    assert any("hole axis" in option for option in app._snap.options)
    app.click_sets = "select"
    findings = app.session.findings()  # two roots, for now: the loose upper arm
    assert any(f.code == "multiple-roots" for f in findings)
    assert app._finding_buttons


def test_simulate_hands_the_page_to_mexone_sim_and_back(app):
    session = app.session
    assert not app.act("simulate", app.simulate)  # two roots: sim refuses, the editor stays
    assert app.sim_app is None and "root" in app._status_msg.content
    _snap, point, axis = next(s for s in session.snaps("arm_upper") if s[0].kind == "hole axis"
                              and abs(s[1][0]) < 1e-6)
    app.act("joint", lambda: session.add_joint("shoulder", "arm_base", "arm_upper", "revolute", point, axis))
    app.act("motor", lambda: session.set_motor("shoulder"))
    step, joint = session.index, app.selected_joint
    assert app.act("simulate", app.simulate)
    sim_app = app.sim_app
    assert sim_app.server is app.server and sim_app.lab.manager is not None  # the same page
    start = sim_app.lab.sim.time
    end = time.time() + 20
    while sim_app.lab.sim.time - start < 0.5 and time.time() < end:
        time.sleep(0.05)
    assert sim_app.lab.sim.time - start >= 0.5  # it runs, in its own thread
    assert abs(sim_app.lab.sim.joint_positions()[0]) < 0.05  # held by the editor's controller
    assert app.act("back", app._stop_sim)
    assert app.sim_app is None and sim_app.stopping.is_set()
    assert session.index == step and app._joint.value == joint  # the editor, as it was
    assert "back to editing" in app._status_msg.content


def test_the_swing_preview_moves_the_drawn_child_only(app):
    app._select_joint("shoulder")
    before = np.array(app._nodes["arm_upper"].position)
    app._swing(0.5)  # q at the top of the range
    assert np.linalg.norm(np.array(app._nodes["arm_upper"].wxyz) - [1, 0, 0, 0]) > 0.1
    assert np.allclose(app._nodes["arm_base"].position, app.session.world_frames()["arm_base"][:3, 3])
    assert app.session.model.joints["shoulder"].origin.xyz == pytest.approx(tuple(before))
    app.act("view", app._draw)


def test_the_gizmo_let_go_away_from_every_snap_stays_and_by_a_hole_snaps(app):
    import asyncio
    from types import SimpleNamespace

    session = app.session
    app._select_joint("shoulder")
    step, origin = session.index, session.joint("shoulder").origin

    def let_go(at) -> None:  # what viser calls at a drag's end, with the pose it was let go at
        app._gizmo.position = at
        event = SimpleNamespace(phase="end", client=object(), target=app._gizmo)
        messages = list(app.messages)
        asyncio.run(app._gizmo_moved(event))
        end = time.time() + 10
        while app.messages == messages and time.time() < end:
            time.sleep(0.02)

    free = np.array([0.3, -0.2, 0.3])  # far from the upper arm
    let_go(free)
    assert "no snap within 15 mm" in app._status_msg.content
    assert session.index == step and session.joint("shoulder").origin == origin
    assert np.allclose(app._gizmo.position, free)  # it stays where it was dropped
    let_go((np.nan, 0.0, 0.0))
    assert "refused" in app._status_msg.content and session.index == step
    hole = np.array([0.0, 0.03, 0.1])  # the upper arm's bore, back end
    let_go(hole + [0.004, 0.002, -0.003])
    assert "shoulder snapped to hole axis (0.0, 30.0, 100.0)" in app._status_msg.content
    assert session.index == step + 1
    frame = session.world_frames()["arm_upper"]
    assert np.allclose(frame[:3, 3], hole, atol=1e-9) and np.allclose(app._gizmo.position, hole)
    assert np.allclose(frame[:3, :3] @ session.joint("shoulder").axis, (0.0, 1.0, 0.0), atol=1e-9)
    assert app.act("undo", session.undo) and session.joint("shoulder").origin == origin


def test_the_edit_verb_says_what_is_wrong_in_one_line(tmp_path, capsys):
    assert main(["edit", "--out", str(tmp_path / "missing"), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "missing" in err and "Traceback" not in err
    assert main(["edit", str(tmp_path / "nope.urdf"), "--port", "0"]) == 2


def test_the_edit_verb_opens_mex_one_and_stops(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = {}
    thread = threading.Thread(target=lambda: code.setdefault("rc", main(
        ["edit", str(mex_one.urdf_path()), "--port", "0", "--duration", "1"])))
    thread.start()
    thread.join(timeout=60)
    assert code.get("rc") == 0
    assert "editing mex_rb at http://127.0.0.1:" in capsys.readouterr().err
    assert (tmp_path / ".mexone_edit" / "mex_rb" / "model.urdf").is_file()
    shutil.rmtree(tmp_path / ".mexone_edit")


def test_a_zipped_folder_of_parts_waits_to_be_accepted_one_by_one(app):
    import io
    import zipfile
    from types import SimpleNamespace

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("parts/Fore Arm.STL", (ARM / "arm_fore.stl").read_bytes())
        archive.writestr("parts/../../evil.stl", (ARM / "arm_base.stl").read_bytes())
        archive.writestr("parts/readme.txt", "not a part")
    app._upload._impl.value = SimpleNamespace(name="parts.zip", content=buffer.getvalue())
    assert app.act("upload", app._received)
    assert [p.name for p in app.pending] == ["evil", "fore_arm"]
    assert app.act("discard", app._discard)
    app._unit.value = "cm"  # the page's choice wins over the guess (mm)
    assert app.act("import", app._accept)
    assert app.session.model.links["fore_arm"].visuals[0].geometry.scale == (0.01, 0.01, 0.01)
    assert not app.pending and not (app.session.folder.parent / "evil.stl").exists()
    app.act("undo", app.session.undo)
    bomb = io.BytesIO()
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("big.stl", b"\0" * (65 * 2**20))
    app._upload._impl.value = SimpleNamespace(name="bomb.zip", content=bomb.getvalue())
    assert not app.act("upload", app._received)
    assert "over" in app._status_msg.content


def test_the_gizmo_places_a_joint_frame(app):
    session = app.session
    app._select_joint("shoulder")
    frame = session.world_frames()["arm_upper"]
    app._gizmo.position = frame[:3, 3] + np.array([0.0, 0.0, 0.01])
    app._gizmo.wxyz = (1.0, 0.0, 0.0, 0.0)
    assert app.act("frame", app._gizmo_frame)
    assert session.world_frames()["arm_upper"][:3, 3] == pytest.approx(frame[:3, 3] + [0, 0, 0.01])
    mesh, origin = session.part_mesh("arm_upper")  # the part did not move with its frame
    placed = session.world_frames()["arm_upper"] @ origin
    assert (placed[:3, :3] @ mesh.vertices.T + placed[:3, 3:]).T.min(axis=0) == pytest.approx(
        [-0.02, 0.01, 0.08], abs=1e-9)
    app.act("undo", session.undo)


def test_a_fitted_collision_is_edited_by_typing(app):
    session = app.session
    app._select_link("arm_base")
    app.act("fit", lambda: session.fit_collision("arm_base", "box"))
    size = session.model.links["arm_base"].collisions[0].geometry.size
    app._col_size.value = (0.05, 0.03, 0.15)
    app._col_xyz.value = (0.0, 0.0, 0.05)
    assert app.act("collision", app._edit_collision)
    col = session.model.links["arm_base"].collisions[0]
    assert col.geometry.size == (0.05, 0.03, 0.15) and col.origin.xyz == (0.0, 0.0, 0.05)
    app._col_size.value = (0.05, -1.0, 0.15)  # the server refuses a negative size
    assert not app.act("collision", app._edit_collision)
    session.undo()
    session.undo()
    assert session.model.links["arm_base"].collisions[0].geometry != Box(size)


def test_a_snap_or_a_part_the_page_should_not_send_is_one_line_on_the_page(app):
    """'9999: x' raised IndexError in viser's thread pool and '-1: x' picked the last snap; a
    flat STL printed a server traceback and left its mesh in the work folder."""
    import io
    from types import SimpleNamespace

    import trimesh

    step, meshes = app.session.index, sorted(app.session.meshes.iterdir())
    app._parent._impl.value, app._child._impl.value = "arm_base", "arm_upper"
    app._update_snaps()
    for choice in ("9999: x", "-1: x"):
        app._snap._impl.value = choice  # any websocket client can send any string
        assert not app.act("joint", app._add_joint)
        assert f"snap '{choice}' is not one of the" in app._status_msg.content
    buffer = io.BytesIO()
    trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], [[0, 1, 2]]).export(buffer, file_type="stl")
    app._upload._impl.value = SimpleNamespace(name="sheet.stl", content=buffer.getvalue())
    assert not app.act("upload", app._received)
    assert "'sheet.stl' is flat" in app._status_msg.content and not app.pending
    assert app.session.index == step and sorted(app.session.meshes.iterdir()) == meshes
