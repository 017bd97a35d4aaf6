"""The editor page in a real headless Chromium, driven only through the page: three STL parts in
millimetres uploaded, units guessed, masses and inertias, collision cylinders, two revolute
joints snapped to hole axes (the elbow's by dragging its gizmo with the mouse and letting it go
by the hole), motors, saved; the saved files judged by check_urdf and `mexone
check`; a refused overwrite; undo; the history after a reload. With MEXONE_SCREENSHOT_DIR set it
also writes the README's screenshot there (editor.png)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

import helpers
from mexone.cli import main
from mexone.description.urdf import read_urdf
from mexone.editor.app import EditorApp
from mexone.editor.session import EditSession
from mexone.lab import Lab
from mexone.robots import mex_one

DATA = Path(__file__).resolve().parents[1] / "data" / "editor"
MASSES = {"arm_base": "1", "arm_upper": "0.5", "arm_fore": "0.3"}


def wait_until(predicate, timeout=15.0) -> bool:
    return helpers.wait_until(predicate, timeout)


@pytest.fixture(scope="module")
def editor(tmp_path_factory):
    folder = tmp_path_factory.mktemp("editor")
    (folder / "out").mkdir()
    app = EditorApp(EditSession.open(folder / "work", name="arm"), folder / "out", port=0)
    thread = threading.Thread(target=app.serve_forever, daemon=True)
    thread.start()
    yield app
    app.stop()
    thread.join(timeout=5)


@pytest.fixture(scope="module")
def browser():
    with helpers.chromium() as chromium:
        yield chromium


def open_page(browser, app):
    # software WebGL redraws every pixel after each change: a small page keeps the test fast
    large = bool(os.environ.get("MEXONE_SCREENSHOT_DIR"))
    tab = browser.new_page(viewport={"width": 1400, "height": 1000} if large else
                           {"width": 900, "height": 700})
    tab.goto(f"http://127.0.0.1:{app.server.get_port()}")
    tab.get_by_text("Accept import").wait_for(timeout=30_000)
    return tab


@pytest.fixture(scope="module")
def page(editor, browser):
    tab = open_page(browser, editor)
    yield tab
    tab.close()


def choose(tab, label: str, option: str) -> None:
    """Pick `option` (a prefix of its text) in the dropdown labelled `label`."""
    tab.get_by_label(label, exact=True).click()
    tab.get_by_role("option").filter(has_text=option).first.click()


def selected(app, kind: str, name: str) -> bool:
    """The page's selection of a link or joint reached the server and its fields are filled
    (the selection fills them under the edit lock: typing before that is overwritten)."""
    if not wait_until(lambda: getattr(app, f"selected_{kind}") == name):
        return False
    with app.lock:
        return getattr(app, f"selected_{kind}") == name


def text_field(tab, label: str):
    """viser's text inputs are not tied to their labels (ids differ): the input beside it."""
    row = tab.locator("div.mantine-Flex-root").filter(has=tab.get_by_text(label, exact=True))
    return row.last.locator("input").first


def press(tab, editor, button: str, done) -> None:
    tab.get_by_role("button", name=button, exact=True).click()
    assert wait_until(done), f"'{button}' did nothing: {editor.messages}"


def type_number(tab, label: str, value: str, arrived) -> None:
    enter(tab.get_by_label(label, exact=True), value, arrived)


def enter(field, value: str, arrived) -> None:
    """Type into a field until the server has it: a selection made just before may still be
    filling the field from the server, over what was typed."""
    for _ in range(4):
        field.fill(value)
        field.press("Enter")
        if wait_until(arrived, timeout=4.0):
            return
    raise AssertionError(f"{field} never reached the server as {value}")


def drag_gizmo_onto(tab, editor, hole: np.ndarray) -> None:
    """Grab the joint gizmo's x arrow with the mouse, pull it along x to 8 mm short of the hole
    and let go; then the joint frame must sit exactly on the hole's axis, the axis along the hole
    (panning the view first if the part is under the control panel)."""
    session, joint = editor.session, editor.selected_joint
    start = session.world_frames()[session.joint(joint).child][:3, 3]
    assert wait_until(lambda: editor._gizmo.visible and np.allclose(editor._gizmo.position, start))
    camera = next(iter(editor.server.get_clients().values())).camera
    if helpers.on_screen(tab, editor.server, start)[0] > 0.4 * tab.viewport_size["width"]:
        # the part is under the control panel: pan the view (right-drag) as a user would
        look_at = np.array(camera.look_at)
        tab.mouse.move(300, 600)
        tab.mouse.down(button="right")
        for k in range(1, 9):
            tab.mouse.move(300 - 30 * k, 600)
        tab.mouse.up(button="right")
        assert wait_until(lambda: np.linalg.norm(np.array(camera.look_at) - look_at) > 0.1)
    time.sleep(1.0)  # the gizmo (and the panned camera) arrive on the page and the server
    # the page's camera reaches the server in messages: project only once it holds still
    held = {"at": None, "since": time.monotonic()}

    def camera_still() -> bool:
        now = (tuple(np.round(camera.position, 6)), tuple(np.round(camera.look_at, 6)))
        if now != held["at"]:
            held.update(at=now, since=time.monotonic())
        return time.monotonic() - held["since"] > 0.5
    assert wait_until(camera_still, timeout=10)
    handle = np.array([0.6 * editor._gizmo.scale, 0.0, 0.0])  # its x arrow, along +x from the centre
    aim = hole + [0.008, 0.0, 0.0]  # 8 mm short of the hole's centre, 3 mm off its rim: the magnet's job
    grab, to = np.array(helpers.on_screen(tab, editor.server, start + handle)), np.array(helpers.on_screen(tab, editor.server, aim + handle))
    assert 0 < grab[0] < 0.5 * tab.viewport_size["width"] and 0 < to[0] < grab[0], (grab, to)
    step = session.index
    tab.mouse.move(*grab)
    tab.mouse.down()
    for k in range(1, 9):
        tab.mouse.move(*(grab + (to - grab) * k / 8))
    tab.mouse.up()
    assert wait_until(lambda: f"{joint} snapped to hole axis" in editor._status_msg.content), \
        (editor.messages, editor._gizmo.position)
    assert session.index == step + 1  # one step: one undo takes it back
    let_go = float(editor.messages[0].split("let go ")[1].split(" mm")[0])
    assert 4.0 < let_go < 12.0, editor.messages[0]  # dropped near, not on, the hole
    frame = session.world_frames()[session.joint(joint).child]
    np.testing.assert_allclose(frame[:3, 3], hole, atol=1e-6)  # exactly on it, not near it
    np.testing.assert_allclose(frame[:3, :3] @ session.joint(joint).axis, (0.0, -1.0, 0.0), atol=1e-6)
    assert wait_until(lambda: np.allclose(editor._gizmo.position, hole, atol=1e-6))  # the gizmo jumped


@pytest.mark.slow
def test_build_the_arm_from_the_page_and_save_it(editor, page, tmp_path):
    session = editor.session
    for link in MASSES:  # import: upload, see the guess, accept
        page.locator("input[type=file]").set_input_files(str(DATA / f"{link}.stl"))
        assert wait_until(lambda link=link: link in editor._pending.content)
        assert "Guess: **mm**" in editor._pending.content
        assert wait_until(lambda: page.get_by_label("Unit", exact=True).input_value() == "mm")
        press(page, editor, "Accept import", lambda link=link: link in session.model.links)
    assert session.model.links["arm_upper"].visuals[0].geometry.scale == (0.001,) * 3

    choose(page, "Link", "arm_base")
    press(page, editor, "Fix to world / free", lambda: session.model.fixed_to_world)
    for link, mass in MASSES.items():  # the link inspector
        choose(page, "Link", link)
        assert selected(editor, "link", link)
        type_number(page, "Mass (kg)", mass, lambda mass=mass: editor._mass.value == float(mass))
        press(page, editor, "Compute COM + inertia from mesh",
              lambda link=link, mass=mass: session.model.links[link].inertial.mass == float(mass))
        choose(page, "Collision", "cylinder")
        press(page, editor, "Fit collision",
              lambda link=link: session.extras.collision_shapes.get(link) == "cylinder")

    # the shoulder from the snap list; the elbow put on a face, then its gizmo dragged with the
    # mouse to the hole and let go: the magnet puts the frame on the hole's axis
    for name, parent, child, snap in (("shoulder", "arm_base", "arm_upper", "hole axis (0.0, 10.0, 100.0)"),
                                      ("elbow", "arm_upper", "arm_fore", "face centre (211.1, -10.0, 100.0)")):
        choose(page, "Parent", parent)
        choose(page, "Child", child)
        assert wait_until(lambda child=child: editor._child.value == child)
        choose(page, "Snap on child", snap)
        enter(text_field(page, "New joint name"), name, lambda name=name: editor._jname.value == name)
        press(page, editor, "Add joint", lambda name=name: name in session.model.joints)
        if name == "elbow":
            drag_gizmo_onto(page, editor, np.array([0.15, -0.01, 0.1]))  # the hole's front end
        press(page, editor, "Auto gains", lambda name=name: name in session.extras.motors)

    frames = session.world_frames()  # the frames sit on the holes' axes
    assert frames["arm_upper"][[0, 2], 3] == pytest.approx([0.0, 0.1], abs=1e-9)
    assert frames["arm_fore"][[0, 2], 3] == pytest.approx([0.15, 0.1], abs=1e-9)
    assert not session.findings()  # the live checks panel is clean
    assert "no problems found" in editor._checks.content

    out = editor.out_dir
    enter(text_field(page, "Base name"), "arm", lambda: editor._base.value == "arm")
    press(page, editor, "Save URDF", lambda: (out / "arm.urdf").is_file())
    press(page, editor, "Save controllers YAML", lambda: (out / "arm_controllers.yaml").is_file())
    if shutil.which("check_urdf"):
        result = subprocess.run(["check_urdf", str(out / "arm.urdf")], capture_output=True, text=True)
        assert result.returncode == 0, result.stdout + result.stderr
    assert main(["check", str(out / "arm.urdf"), "--controllers", str(out / "arm_controllers.yaml")]) == 0
    saved = read_urdf(out / "arm.urdf")
    assert [t.joint for t in saved.transmissions] == ["shoulder", "elbow"]
    assert saved.links["arm_fore"].inertial.mass == pytest.approx(0.3)
    assert np.allclose(saved.joints["elbow"].origin.xyz, (0.15, -0.02, 0.0))  # front end of the bore

    for link, mass in MASSES.items():  # trimesh's inertia for that mesh and mass
        mesh = trimesh.load(DATA / f"{link}.stl")
        mesh.apply_scale(0.001)
        mesh.density = float(mass) / mesh.volume
        rot = saved.link_frames[link][:3, :3]
        np.testing.assert_allclose(rot @ saved.links[link].inertial.tensor @ rot.T, mesh.moment_inertia,
                                   rtol=1e-6, atol=1e-12)
    lab = Lab.create(out / "arm.urdf", out / "arm_controllers.yaml")  # mexone sim, headless
    lab.sim.run(2.0)
    assert np.all(np.abs(lab.sim.joint_positions()) < 0.03)

    before = (out / "arm.urdf").read_text()  # no overwrite without the box ticked
    page.get_by_role("button", name="Save URDF", exact=True).click()
    assert wait_until(lambda: "refused" in editor._status_msg.content and "already exists" in
                      editor._status_msg.content)
    assert (out / "arm.urdf").read_text() == before

    if os.environ.get("MEXONE_SCREENSHOT_DIR"):
        editor.act("show", lambda: editor._select_joint("elbow"))
        editor._show_collisions.value = True
        editor.act("show", editor._draw)
        for close in page.locator("button.mantine-Notification-closeButton").all():
            close.click()
        time.sleep(2.0)
        page.screenshot(path=str(Path(os.environ["MEXONE_SCREENSHOT_DIR"]) / "editor.png"))

    step = session.index  # undo from the page, then a reload finds the same history
    labels = [json.loads((session.history / f"{i:04d}.json").read_text())["label"] for i in range(step + 1)]
    press(page, editor, "Undo", lambda: session.index == step - 1)
    assert "elbow" not in session.extras.motors, labels[-5:]
    page.reload()
    page.get_by_text("Accept import").wait_for(timeout=30_000)
    assert wait_until(lambda: page.get_by_text(f"history step {step - 1}").count() > 0)
    press(page, editor, "Redo", lambda: session.index == step)
    assert "elbow" in session.extras.motors
    # Simulate: the same page becomes mexone sim's, then the editor again
    press(page, editor, "Simulate", lambda: editor.sim_app is not None)
    page.get_by_role("button", name="Pause").wait_for(timeout=30_000)
    sim_start = editor.sim_app.lab.sim.time
    assert wait_until(lambda: editor.sim_app.lab.sim.time > sim_start + 0.2)
    page.get_by_role("button", name="Back to editing").click()
    page.get_by_text("Accept import").wait_for(timeout=30_000)
    assert editor.sim_app is None and session.index == step


@pytest.mark.slow
def test_a_mex_one_joint_frame_moved_3cm_is_flagged_on_the_page_and_undo_clears_it(browser, tmp_path):
    app = EditorApp(EditSession.open(tmp_path / "work", mex_one.urdf_path()), tmp_path, port=0)
    try:
        tab = open_page(browser, app)
        assert wait_until(lambda: "no problems found" in app._checks.content)
        choose(tab, "Joint", "l_shoulder_pitch")
        assert selected(app, "joint", "l_shoulder_pitch")
        x, y, z = app.session.model.joints["l_shoulder_pitch"].origin.xyz
        row = tab.locator("div.mantine-Flex-root").filter(has=tab.get_by_text("Frame xyz (parent)"))
        fields = [row.last.locator("input").nth(i) for i in range(3)]
        # the page shows this joint's frame (typing before would send the last joint's x and z)
        assert wait_until(lambda: [float(f.input_value() or "nan") for f in fields] == [x, y, z])
        enter(fields[1], f"{y + 0.03:.6f}",
              lambda: np.allclose(app._origin.value, (x, y + 0.03, z), atol=1e-6))
        step = app.session.index
        press(tab, app, "Place frame (typed)", lambda: app.session.index == step + 1)
        flagged = tab.get_by_role("button").filter(has_text="joint-off-junction")
        assert wait_until(lambda: flagged.count() == 1), app._checks.content
        choose(tab, "Joint", "l_elbow")
        assert selected(app, "joint", "l_elbow")
        flagged.first.click()  # a finding selects what it is about
        assert wait_until(lambda: app.selected_joint == "l_shoulder_pitch")
        press(tab, app, "Undo", lambda: app.session.index == step)
        assert wait_until(lambda: tab.get_by_text("no problems found").count() > 0)
        assert flagged.count() == 0
        tab.close()
    finally:
        app.stop()
