"""The page's tools in a real headless Chromium: clicks land on the link or joint under the
mouse (the page's own ray), the push handle is dragged with the mouse, the Screenshot button
saves a PNG on the server, Follow keeps the robot in view, the centre-of-mass markers show
through the links, and a robot uploaded through the page replaces the running one.

With MEXONE_SCREENSHOT_DIR set, the tests also save the pictures of the new panels that the
README shows (docs/images/gui_*.png)."""

from __future__ import annotations

import io
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import (
    changed_near,
    chromium,
    free_port,
    on_screen,
    pixels,
    robot_drawn,
    wait_for_picture,
    wait_frames,
    wait_until,
)
from mexone.gui.app import GuiApp
from mexone.gui.inspector import DRAG, JOINT_ARROW
from mexone.lab import Lab
from mexone.physics import CompileOptions

from .test_gui_tools import PENDULUM

WIDTH, HEIGHT = 1280, 800
SHOTS = os.environ.get("MEXONE_SCREENSHOT_DIR")


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    folder = tmp_path_factory.mktemp("start")
    (folder / "pendulum.urdf").write_text(PENDULUM)  # what Load lists
    gui = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 record_folder=folder, model_folder=folder, paused=True)
    thread = threading.Thread(target=gui.serve_forever, daemon=True)
    thread.start()
    yield gui
    gui.stop()
    thread.join(timeout=5)


@pytest.fixture(scope="module")
def page(app):
    with chromium() as browser:
        tab = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
        tab.goto(f"http://127.0.0.1:{app.server.get_port()}")
        tab.wait_for_selector("canvas", timeout=30_000)
        tab.get_by_text("Simulation").first.wait_for(timeout=30_000)
        assert wait_until(lambda: len(app.server.get_clients()) == 1, timeout=30)
        assert wait_until(lambda: robot_drawn(tab), timeout=120)
        close = tab.locator(".mantine-Notification-closeButton")  # "software WebGL" notice
        if close.count():
            close.first.click()
        yield tab


def client(app):
    return next(iter(app.server.get_clients().values()))


def shoot(tab, name: str, reveal=None) -> None:
    """A README picture, when asked for (MEXONE_SCREENSHOT_DIR)."""
    if not SHOTS:
        return
    if reveal is not None:
        reveal.scroll_into_view_if_needed()
    time.sleep(0.5)
    from PIL import Image

    Path(SHOTS).mkdir(parents=True, exist_ok=True)
    image = Image.open(io.BytesIO(tab.screenshot())).convert("RGB")
    image.quantize(256).save(Path(SHOTS) / name, optimize=True)  # a quarter of the bytes


def _blue(im: np.ndarray) -> int:
    """Pixels of a picture that are clearly blue (the centres of mass' markers)."""
    return int(((im[..., 2] - np.maximum(im[..., 0], im[..., 1])) > 80).sum())


def paused_fresh(app) -> None:
    def reset():
        app.reset_model()
        if not app.lab.sim.paused:
            app.toggle_pause()
    app.work.call(reset)


def test_a_click_in_the_page_inspects_the_link_under_the_mouse(app, page):
    paused_fresh(app)
    sim = app.lab.sim
    torso = sim.data.xipos[sim.compiled.bodies["torso"]]
    page.mouse.click(*on_screen(page, app.server, torso))
    mass = sim.robot.links["torso"].inertial.mass
    assert wait_until(lambda: f"mass {mass:.6g} kg (URDF)" in app.panels["tools"].report.content,
                      timeout=15), app.panels["tools"].report.content
    assert "**link** `torso`" in app.panels["tools"].report.content
    page.get_by_text(f"mass {mass:.6g} kg (URDF)").first.wait_for(timeout=15_000)  # on the page


def test_a_click_on_a_joint_axis_arrow_inspects_the_joint(app, page):
    paused_fresh(app)
    page.get_by_text("Joints", exact=True).first.click()  # View > Joints
    assert wait_until(lambda: app.panels["view"].overlay_boxes["Joints"].value, timeout=10)
    sim = app.lab.sim
    joint = sim.robot.joints["r_knee"]
    body = sim.compiled.bodies[joint.child]
    tip = sim.data.xpos[body] + sim.data.xmat[body].reshape(3, 3) @ (
        0.7 * JOINT_ARROW * np.asarray(joint.axis) / np.linalg.norm(joint.axis))
    page.mouse.click(*on_screen(page, app.server, tip))
    assert wait_until(lambda: "**joint** `r_knee`" in app.panels["tools"].report.content, timeout=15), \
        app.panels["tools"].report.content
    report = app.panels["tools"].report.content
    assert f"limits [{joint.limit.lower:g}, {joint.limit.upper:g}]" in report
    assert "parent `r_thigh`" in report or f"parent `{joint.parent}`" in report
    page.get_by_text("(revolute, rad)").first.wait_for(timeout=10_000)  # on the page
    shoot(page, "gui_joint.png", page.get_by_text("(revolute, rad)").first)
    page.get_by_text("Joints", exact=True).first.click()
    assert wait_until(lambda: not app.panels["view"].overlay_boxes["Joints"].value, timeout=10)


def test_the_push_handle_is_dragged_with_the_mouse(app, page):
    paused_fresh(app)
    tools = app.panels["tools"]
    tools.mode.value, tools.direction.value = "push", DRAG
    sim = app.lab.sim
    torso = sim.data.xipos[sim.compiled.bodies["torso"]]
    bare = pixels(page)
    page.mouse.click(*on_screen(page, app.server, torso))
    assert wait_until(lambda: tools.aim is not None and tools.dragged is not None, timeout=15)
    start = tools.dragged.copy()
    # grab the gizmo's z arrow (its handle sits along +z from the centre) and pull it up, once
    # the page draws it there
    grab = on_screen(page, app.server, start + np.array([0.0, 0.0, 0.6 * 0.25]))
    assert wait_for_picture(page, changed_near(bare, grab)), "the push gizmo is not drawn"
    page.mouse.move(*grab)
    page.mouse.down()
    for k in range(1, 6):
        page.mouse.move(grab[0], grab[1] - 16 * k)
    page.mouse.up()
    assert wait_until(lambda: tools.dragged[2] > start[2] + 0.05, timeout=15), tools.dragged
    head = tools.aim[2]
    direction = (head - tools.dragged) / np.linalg.norm(head - tools.dragged)
    assert direction[2] < -0.1  # pulled up behind: the push now points down into the robot
    # then its x arrow, along +x on the screen: the tail moves that way in the world
    lifted = tools.dragged.copy()
    grab = np.array(on_screen(page, app.server, lifted + np.array([0.6 * 0.25, 0.0, 0.0])))
    along = np.array(on_screen(page, app.server, lifted + np.array([0.5, 0.0, 0.0]))) - \
        np.array(on_screen(page, app.server, lifted))
    along /= np.linalg.norm(along)
    page.mouse.move(*grab)
    page.mouse.down()
    for k in range(1, 6):
        page.mouse.move(*(grab + along * 20 * k))
    page.mouse.up()
    assert wait_until(lambda: tools.dragged[0] > lifted[0] + 0.05, timeout=15), tools.dragged
    np.testing.assert_allclose(tools.preview.points[0][0], tools.dragged, atol=1e-4)
    shoot(page, "gui_push.png", page.get_by_text("Magnitude from length").first)
    page.get_by_role("button", name="Push", exact=True).click()
    assert wait_until(lambda: tools.arrow.visible and tools.aim is None, timeout=15)
    assert "pushed `torso`" in tools.report.content
    tools.mode.value, tools.direction.value = "inspect", "away from the camera"


def test_the_move_gizmo_lifts_the_robot_with_the_mouse(app, page):
    paused_fresh(app)
    sim, move = app.lab.sim, app.panels["tools"].move
    root = sim.compiled.root_body
    before = sim.data.xpos[root].copy()
    bare = pixels(page)
    page.get_by_text("Move the robot").click()
    assert wait_until(lambda: move.enabled.value and move.gizmo.visible, timeout=10)
    grab = on_screen(page, app.server, before + np.array([0.0, 0.0, 0.6 * 0.35]))  # its z arrow
    assert wait_for_picture(page, changed_near(bare, grab)), "the move gizmo is not drawn"
    page.mouse.move(*grab)
    page.mouse.down()
    for k in range(1, 6):
        page.mouse.move(grab[0], grab[1] - 16 * k)
    page.mouse.up()
    assert wait_until(lambda: sim.data.xpos[root][2] > before[2] + 0.05, timeout=15)
    np.testing.assert_allclose(sim.data.xpos[root][:2], before[:2], atol=0.02)  # straight up
    assert wait_until(lambda: move.holding is None, timeout=10)  # let go
    assert sim.paused  # paused, it stays where it was put
    lifted = sim.data.xpos[root][2]
    assert wait_frames(app, 15)  # loop iterations that ran, paused
    assert sim.data.xpos[root][2] == lifted
    shoot(page, "gui_move.png", page.get_by_text("Move the robot"))
    page.get_by_text("Move the robot").click()
    assert wait_until(lambda: not move.gizmo.visible, timeout=10)


def test_screenshot_button_saves_the_pages_own_picture_with_its_overlays(app, page, monkeypatch):
    from PIL import Image

    import mexone.gui.simulation

    # the page's picture, however loaded the machine (software WebGL on 2 shared cores can take
    # longer than the product's 10 s before it falls back to MuJoCo's render)
    monkeypatch.setattr(mexone.gui.simulation, "PAGE_RENDER_SECONDS", 120.0)
    paused_fresh(app)
    folder = app.panels["simulation"].screenshots.folder
    camera = client(app).camera
    page.get_by_role("button", name="Screenshot").click()
    first = folder / "mexone_screenshot_001.png"
    assert wait_until(first.exists, timeout=150)
    assert wait_until(lambda: app.panels["simulation"].last_screenshot == first, timeout=10)
    plain = np.asarray(Image.open(first).convert("RGB"), dtype=np.int16)
    # the page's picture (its canvas' size, not MuJoCo's 1280 x 720): the robot in the middle,
    # dark against the light floor
    height, width = plain.shape[:2]
    assert (height, width) == (camera.image_height, camera.image_width)
    middle = plain[height // 4: 3 * height // 4, width // 3: 2 * width // 3]
    assert (middle.sum(axis=2) < 250).mean() > 0.01
    # an overlay only the page draws: the links' centres of mass, blue spheres
    page.get_by_text("Center of Mass", exact=True).click()
    assert wait_until(lambda: all(h.visible for h in app.scene.overlays["Center of Mass"]))
    assert wait_for_picture(page, lambda now: _blue(now) > _blue(plain) + 50)  # the page draws them
    page.get_by_role("button", name="Screenshot").click()
    second = folder / "mexone_screenshot_002.png"
    assert wait_until(second.exists, timeout=150)
    assert wait_until(lambda: app.panels["simulation"].last_screenshot == second, timeout=10)
    marked = np.asarray(Image.open(second).convert("RGB"), dtype=np.int16)
    page.get_by_text("Center of Mass", exact=True).click()
    assert _blue(marked) > _blue(plain) + 50, (_blue(marked), _blue(plain))


def test_follow_robot_keeps_it_in_view_after_a_jump_and_a_reset(app, page):
    paused_fresh(app)
    page.get_by_text("Follow robot").click()
    assert wait_until(lambda: app.panels["simulation"].follow.value, timeout=10)
    sim = app.lab.sim
    base = sim.robot.base_link

    def jump():
        pos, quat = sim.link_pose(base)
        sim.set_free_body(base, pos + np.array([3.0, 2.0, 0.0]), quat)
    app.work.call(jump)
    target = sim.data.xpos[sim.compiled.root_body].copy()
    assert wait_until(lambda: np.linalg.norm(np.asarray(client(app).camera.look_at)[:2]
                                             - target[:2]) < 0.05, timeout=15)
    _assert_robot_in_the_middle(app, page)
    app.work.call(app.reset_model)  # back at the origin: the view comes along
    assert wait_until(lambda: np.linalg.norm(np.asarray(client(app).camera.look_at)[:2]) < 0.2,
                      timeout=15)
    _assert_robot_in_the_middle(app, page)
    page.get_by_text("Follow robot").click()
    assert wait_until(lambda: not app.panels["simulation"].follow.value, timeout=10)


def _assert_robot_in_the_middle(app, page) -> None:
    """Hiding the robot changes the middle of the view (the camera has come to it: the caller
    waited on the page's camera)."""
    shown = pixels(page)
    app.work.call(lambda: app.scene.set_robot_visible(False))
    middle = (slice(150, 650), slice(440, 840))
    gone = wait_for_picture(page, lambda hidden: (np.abs(shown[middle] - hidden[middle])
                                                  .sum(axis=2) > 30).mean() > 0.02)
    app.work.call(lambda: app.scene.set_robot_visible(True))
    assert gone, "the robot is not in the middle of the view"
    assert wait_until(lambda: robot_drawn(page), timeout=30, poll=0.2)  # back, for the next look


def test_centre_of_mass_markers_show_through_the_links(app, page):
    paused_fresh(app)
    opaque = pixels(page)
    page.get_by_text("Center of Mass", exact=True).click()
    assert wait_until(lambda: app.panels["view"].overlay_boxes["Center of Mass"].value, timeout=10)
    assert wait_until(lambda: all(h.opacity for h in app.scene.visuals), timeout=10)
    assert wait_for_picture(page, lambda now: _blue(now) > _blue(opaque) + 50)  # drawn through
    with_markers = pixels(page)
    app.work.call(lambda: [setattr(h, "visible", False)
                           for h in app.scene.overlays["Center of Mass"]])
    # the blue markers sit inside the links: seen only because the links turned see-through
    assert wait_for_picture(page, lambda without: (np.abs(with_markers - without).sum(axis=2) > 40)
                            .mean() > 0.0005)
    page.get_by_text("Center of Mass", exact=True).click()
    assert wait_until(lambda: not app.panels["view"].overlay_boxes["Center of Mass"].value, timeout=10)
    assert wait_until(lambda: all(h.opacity is None for h in app.scene.visuals), timeout=10)


def test_topic_fields_plot_and_the_topics_table_in_the_page(app, page):
    panel = app.panels["plots"]
    app.work.call(app.toggle_pause)  # running
    panel.topic.value = "/mex_rb/imu"
    app.work.call(panel._browse)
    assert wait_until(lambda: "angular_velocity/x" in panel.field.options, timeout=15)
    panel.field.value, panel.pane.value = "linear_acceleration/z", "pane 2"
    app.work.call(panel._add_field)
    assert wait_until(lambda: "/mex_rb/imu/linear_acceleration/z" in page.evaluate(
        "() => Object.values(window.__viserTestpoints?.uplots ?? {})"
        ".flatMap(p => p.chart.series.map(s => s.label ?? '')).join(' ')"), timeout=20)
    if SHOTS:
        page.get_by_text("Any topic", exact=True).click()
    shoot(page, "gui_topic_plot.png",
          page.locator(".u-legend", has_text="/mex_rb/imu/linear_acceleration/z").first)
    page.get_by_text("Topics", exact=True).click()
    page.get_by_text("mexone GUI (plots)").first.wait_for(timeout=15_000)
    shoot(page, "gui_topics.png", page.get_by_text("subscribers: mexone GUI (plots)").first)
    page.get_by_text("Topics", exact=True).click()
    app.work.call(lambda: panel._edit("Clear pane"))


def test_a_robot_uploaded_through_the_page_replaces_the_running_one(app, page, tmp_path):
    """Last: the page's robot changes."""
    source = tmp_path / "pendulum.urdf"
    source.write_text(PENDULUM)
    page.get_by_text("Load robot", exact=True).click()
    page.locator("input[type=file]").first.set_input_files(str(source))
    assert wait_until(lambda: app.lab.sim.robot.name == "pendulum", timeout=60)
    # the page is rebuilt for it: its panels, its one joint's slider
    page.get_by_text("now: pendulum.urdf").wait_for(state="attached", timeout=30_000)
    assert app.lab.manager is not None and "swing" in app.lab.sim.joint_names
    page.get_by_role("slider").first.wait_for(timeout=15_000)
    assert page.get_by_role("slider").count() == 1
    assert page.get_by_text("mex_rb").count() == 0
    page.get_by_text("Load robot", exact=True).click()
    shoot(page, "gui_load.png", page.get_by_text("now: pendulum.urdf"))
