"""The page's tools, checked on the server (handlers run in the simulation thread, as the page's
clicks and drags run them): a push aimed by dragging a handle against falling, a joint's axis
arrow clicked against the URDF, the Move tool against the pose it was dragged to, the
Screenshot against an independent PNG reader and the files already there, plots of any topic's
fields against the signal they carry, subscriber names, see-through links, and Load."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from helpers import free_port, wait_until
from mexone.gui.app import GuiApp
from mexone.gui.inspector import ARROW_METRES_PER_NS, DRAG, JOINT_ARROW
from mexone.gui.load import save_upload
from mexone.gui.screenshot import page_picture
from mexone.lab import Lab
from mexone.physics import CompileOptions
from mexone.physics.monitor import has_fallen

from .test_gui_bench import call


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    folder = tmp_path_factory.mktemp("start")
    gui = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 record_folder=folder, model_folder=folder)
    thread = threading.Thread(target=gui.serve_forever, daemon=True)
    thread.start()
    yield gui
    gui.stop()
    thread.join(timeout=5)


def fresh(app, paused: bool = False) -> None:
    def reset():
        app.reset_world()
        if app.lab.sim.paused != paused:
            app.toggle_pause()
    call(app, reset)


# ----- push, direction by dragging ----------------------------------------------------------------
@pytest.mark.parametrize(("impulse", "falls"), [(40.0, True), (2.0, False)])
def test_a_push_aimed_by_dragging_the_handle(app, impulse, falls):
    """Drag the handle behind the torso, as long as the impulse wanted: forward it falls."""
    fresh(app, paused=True)
    sim, tools = app.lab.sim, app.panels["tools"]
    height = sim.base_height
    point = sim.data.xipos[sim.compiled.bodies["torso"]].copy()
    tools.mode.value, tools.direction.value = "push", DRAG
    tools.from_length.value = True
    origin = point - np.array([2.0, 0.0, 0.0])  # clicked from behind
    assert call(app, lambda: tools.click(origin, point - origin)) == "torso"
    assert tools.handle.visible and tools.preview.visible  # aimed away from the camera
    assert sim.time == 0.0  # a click with the handle only aims
    head = tools.aim[2]  # where the ray met the torso's back
    tail = head - np.array([impulse * ARROW_METRES_PER_NS, 0.0, 0.0])  # dragged behind it
    call(app, lambda: tools._aimed(tail))
    assert tools.impulse == pytest.approx(impulse, rel=0.01)  # magnitude from the length
    assert app.fields.held(tools.impulse_field) == [tools.impulse]  # the field shows it
    np.testing.assert_allclose(tools.preview.points[0], [tail, head], atol=1e-5)
    assert not tools.fire.disabled

    def fire():
        tools.push_aimed()
        app.toggle_pause()
    call(app, fire)
    assert tools.arrow.visible and not tools.handle.visible  # drawn while it acts
    assert wait_until(lambda: sim.time > 2.5, timeout=15)
    assert call(app, lambda: has_fallen(sim, height)) is falls
    if falls:
        assert call(app, lambda: sim.data.xpos[sim.compiled.root_body][0]) > 0.1  # forward
    assert not tools.arrow.visible
    with pytest.raises(ValueError, match="nothing aimed"):
        call(app, tools.push_aimed)
    tools.mode.value, tools.from_length.value = "inspect", False
    tools.impulse = 20.0
    fresh(app)


# ----- click a joint's axis arrow ---------------------------------------------------------------
def test_clicking_a_joint_axis_arrow_shows_the_joint(app):
    fresh(app, paused=True)
    sim = app.lab.sim
    elbow = sim.robot.joints["l_elbow"]
    body = sim.compiled.bodies[elbow.child]
    axis_world = sim.data.xmat[body].reshape(3, 3) @ np.array(elbow.axis)
    target = sim.data.xpos[body] + 0.6 * JOINT_ARROW * axis_world  # on the arrow
    origin = target + np.array([2.0, 0.0, 0.0])  # from in front
    app.panels["view"].overlay_boxes["Joints"].value = True
    call(app, lambda: app.panels["view"].show_overlay("Joints", True))
    assert call(app, lambda: app.panels["tools"].click(origin, target - origin)) == "l_elbow"
    report = app.panels["tools"].report.content
    q = sim.joint_positions()[sim.joint_names.index("l_elbow")]
    assert "**joint** `l_elbow` (revolute, rad)" in report
    assert "parent `l_upper_arm` → child `l_forearm`" in report
    assert f"position {q:.4g}" in report and "velocity" in report and "effort" in report
    assert f"limits [{elbow.limit.lower:g}, {elbow.limit.upper:g}]" in report
    # a ray 5 cm off the arrow is a link click, and without View > Joints the arrow is not there
    off = target + np.array([0.0, 0.0, 0.05])
    assert call(app, lambda: app.panels["tools"].click(origin + (off - target), -np.array([1, 0, 0.0]))) \
        != "l_elbow"
    app.panels["view"].overlay_boxes["Joints"].value = False
    call(app, lambda: app.panels["view"].show_overlay("Joints", False))
    assert call(app, lambda: app.panels["tools"].click(origin, target - origin)) != "l_elbow"
    fresh(app)


# ----- move the floating base ---------------------------------------------------------------------
def test_move_tool_places_the_base_paused_and_holds_it_while_running(app):
    fresh(app, paused=True)
    sim, move = app.lab.sim, app.panels["tools"].move
    root = sim.compiled.root_body
    move.enabled.value = True
    call(app, lambda: move.enable(True))
    assert move.gizmo.visible
    np.testing.assert_allclose(move.gizmo.position, sim.data.xpos[root], atol=1e-6)
    yaw = np.array([np.cos(0.4), 0.0, 0.0, np.sin(0.4)])  # 0.8 rad about z
    call(app, lambda: move.place((0.5, -0.3, 1.4), yaw, hold=True))  # a drag, paused
    np.testing.assert_allclose(sim.data.xpos[root], (0.5, -0.3, 1.4), atol=1e-9)
    np.testing.assert_allclose(sim.data.xquat[root], yaw, atol=1e-9)
    call(app, app.toggle_pause)  # running, still held by the drag
    start = sim.time
    assert wait_until(lambda: sim.time > start + 0.5, timeout=10)
    assert abs(call(app, lambda: sim.data.xpos[root][2]) - 1.4) < 0.01
    call(app, lambda: move.place((0.5, -0.3, 1.4), yaw, hold=False))  # let go: it falls
    released = sim.time
    assert wait_until(lambda: sim.time > released + 0.3, timeout=10)
    z = call(app, lambda: sim.data.xpos[root][2])
    assert z < 1.4 - 0.5 * 9.81 * 0.3**2 * 0.8  # free fall, at least 80 % of g t²/2
    call(app, app.toggle_pause)  # the gizmo follows, a frame later: compared at rest
    assert wait_until(lambda: np.allclose(move.gizmo.position, sim.data.xpos[root], atol=0.01),
                      timeout=10), (move.gizmo.position, sim.data.xpos[root])
    move.enabled.value = False
    call(app, lambda: move.enable(False))
    fresh(app)


# ----- screenshot -------------------------------------------------------------------------------------
def test_screenshot_saves_numbered_pngs_and_never_overwrites(app):
    fresh(app, paused=True)
    folder: Path = app.panels["simulation"].screenshots.folder
    mine = folder / "mexone_screenshot_001.png"
    mine.write_bytes(b"the user's own file")
    base = app.lab.sim.data.xpos[app.lab.sim.compiled.root_body].copy()
    eye = base + np.array([1.6, -1.6, 0.4])
    first = call(app, lambda: app.panels["simulation"].screenshot(eye, base, np.radians(45.0)))
    away = call(app, lambda: app.panels["simulation"].screenshot(eye, eye + np.array([1.0, -1.0, 0.0]), np.radians(45.0)))
    assert (first.name, away.name) == ("mexone_screenshot_002.png", "mexone_screenshot_003.png")
    assert mine.read_bytes() == b"the user's own file"
    robot = np.asarray(Image.open(first).convert("RGB"), dtype=float)
    empty = np.asarray(Image.open(away).convert("RGB"), dtype=float)
    assert robot.shape == (720, 1280, 3)
    centre = (slice(260, 460), slice(540, 740))  # the robot stands in the middle of the view
    assert np.abs(robot[centre] - empty[centre]).sum(axis=2).mean() > 30


def test_a_page_that_sends_no_picture_gets_mujocos_render(app):
    """The Screenshot button asks the page for its own picture; a page that times out (or sends
    a blank one: no WebGL) still gets a PNG, MuJoCo's render of its view."""
    class SilentCamera:
        def get_render(self, *args, **kwargs):
            raise TimeoutError("no frame")

    class BlankCamera:
        def get_render(self, height, width, **kwargs):
            return np.zeros((height, width, 4), dtype=np.uint8)  # transparent everywhere

    fresh(app, paused=True)
    base = app.lab.sim.data.xpos[app.lab.sim.compiled.root_body].copy()
    view = (base + np.array([1.6, -1.6, 0.4]), base, np.radians(45.0))
    for camera in (SilentCamera(), BlankCamera()):
        before = app.panels["simulation"].last_screenshot
        client = type("Client", (), {"camera": camera})()
        app.panels["simulation"].page_screenshot(client, (400, 600), view)
        assert wait_until(lambda b=before: app.panels["simulation"].last_screenshot not in (None, b), timeout=20)
        assert Image.open(app.panels["simulation"].last_screenshot).size == (1280, 720)  # MuJoCo's, not the page's


def test_a_page_picture_is_put_on_white_and_a_blank_one_refused():
    rgba = np.zeros((2, 3, 4), dtype=np.uint8)
    assert page_picture(rgba) is None and page_picture(None) is None
    rgba[0, 0] = (0, 0, 200, 255)  # opaque blue
    rgba[1, 2] = (100, 0, 0, 128)  # half-transparent red
    picture = page_picture(rgba)
    assert picture.shape == (2, 3, 3) and picture.dtype == np.uint8
    assert picture[0, 0].tolist() == [0, 0, 200]
    assert picture[0, 1].tolist() == [255, 255, 255]
    assert picture[1, 2].tolist() == [177, 127, 127]  # 100 a + 255 (1 - a), a = 128 / 255


# ----- plots of any topic, subscriber names, one plot implementation ---------------------------------
def test_any_topic_field_is_plotted_and_its_subscribers_are_named(app):
    fresh(app)
    panel = app.panels["plots"]
    imu_topic = "/mex_rb/imu"
    panel.topic.value = imu_topic
    call(app, panel._browse)
    assert wait_until(lambda: "linear_acceleration/z" in panel.field.options, timeout=10)
    assert "orientation/w" in panel.field.options and "header/stamp/secs" in panel.field.options
    panel.field.value = "linear_acceleration/z"
    panel.pane.value = "pane 3"
    call(app, panel._add_field)
    name = f"{imu_topic}/linear_acceleration/z"
    assert panel.chosen[2] == [name] and name in panel.signal.options
    t0 = app.lab.sim.time
    assert wait_until(lambda: app.lab.sim.time > t0 + 1.0, timeout=10)
    t, values = app.log.window(0.8, [name, "imu/linear_acceleration/z"])
    # the topic's field carries what the sensor signal carries (held between the IMU's messages)
    assert 9.0 < np.median(values[0]) < 10.6
    assert np.median(values[0]) == pytest.approx(np.median(values[1]), abs=0.3)
    call(app, lambda: panel.update(force=True))
    assert panel.plots[2].visible and len(panel.plots[2].data) == 2
    with pytest.raises(ValueError, match="not a numeric field"):
        call(app, lambda: app.log.add_topic_field(imu_topic, "no/such/field"))
    # browsing a camera subscribes to it; browsing on lets it go (it stops rendering)
    image = "/mex_rb/kinect/rgb/image_raw"
    panel.topic.value = image
    call(app, panel._browse)
    assert wait_until(lambda: "height" in panel.field.options, timeout=10)
    assert "data[0]" not in panel.field.options  # bytes are not numbers to plot
    panel.topic.value = "/mex_rb/zmp"
    call(app, panel._browse)
    assert not app.lab.bus.topics[image].subscriptions
    assert imu_topic in app.log.watched  # plotted: kept
    # who listens: the plot, and on a command topic its controller
    call(app, app.panels["topics"].update)
    table = app.panels["topics"].table.content
    row = next(r for r in table.splitlines() if r.startswith(f"- `{imu_topic}`"))
    assert "subscribers: mexone GUI (plots)" in row
    row = next(r for r in table.splitlines()
               if r.startswith("- `/mex_rb/l_elbow_position_controller/command`"))
    assert "subscribers: l_elbow_position_controller" in row
    call(app, lambda: panel._edit("Clear pane"))


def test_sensor_panel_plots_are_panes_of_the_signal_log(app):
    fresh(app)
    t0 = app.lab.sim.time
    assert wait_until(lambda: app.lab.sim.time > t0 + 0.5, timeout=10)
    call(app, app.toggle_pause)  # the log and the panes hold still while compared
    call(app, app.panels["sensors"].update_plots)
    imu, forces = app.panels["sensors"].panes
    assert imu.names == [f"imu/linear_acceleration/{a}" for a in "xyz"]
    z = np.asarray(imu.plot.data[3])
    from mexone.gui.plots import axis_scale
    assert 9.0 < np.median(z / axis_scale(np.asarray(imu.plot.data[3]))) < 10.6  # gravity
    assert forces.names == ["l_ankle_ft/force/z", "r_ankle_ft/force/z"]
    t, values = app.log.window(0.3, forces.names)
    drawn = np.asarray(forces.plot.data[1])[-t.size:]
    factor = round(drawn[-1] / values[0, -1])  # drawn in ×10⁻³ units when its span is small
    assert factor in (1, 1000, 1000_000)
    np.testing.assert_allclose(drawn / factor, values[0], rtol=1e-5)  # what the log holds
    weight = float(app.lab.sim.model.body_mass.sum()) * 9.81
    assert 0.6 * weight < abs(values[:, -1].sum()) < 1.05 * weight  # the feet carry the robot
    fresh(app)


# ----- view: see-through links for COM and inertia, follow robot --------------------------------------
def test_center_of_mass_and_inertia_make_the_links_see_through(app):
    for overlay in ("Center of Mass", "Inertia"):
        app.panels["view"].overlay_boxes[overlay].value = True
        call(app, lambda o=overlay: app.panels["view"].show_overlay(o, True))
        assert all(h.visible for h in app.scene.overlays[overlay])
        assert all(h.opacity is not None and h.opacity < 1 for h in app.scene.visuals)
        app.panels["view"].overlay_boxes[overlay].value = False
        call(app, lambda o=overlay: app.panels["view"].show_overlay(o, False))
        assert all(h.opacity is None for h in app.scene.visuals)


# ----- load another robot ---------------------------------------------------------------------------
PENDULUM = """<?xml version="1.0"?>
<robot name="pendulum">
  <link name="base"><inertial><mass value="5"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><box size="0.2 0.2 0.2"/></geometry></visual>
    <collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision></link>
  <link name="arm"><inertial><origin xyz="0 0 -0.25"/><mass value="0.7"/><inertia ixx="0.01" iyy="0.01" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 -0.25"/><geometry><cylinder radius="0.02" length="0.5"/></geometry></visual></link>
  <joint name="swing" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 1.0"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="20" velocity="10"/></joint>
  <joint name="fixed" type="fixed"><parent link="world"/><child link="base"/></joint>
  <link name="world"/>
</robot>
"""


def test_load_opens_another_robot_and_a_bad_file_changes_nothing(app):
    folder = app.settings.model_folder
    (folder / "robots").mkdir()
    (folder / "robots" / "pendulum.urdf").write_text(PENDULUM)
    (folder / "broken.urdf").write_text("<robot name='x'><link name='a'></robot>")
    call(app, app.panels["load"].refresh)
    assert set(app.panels["load"].choices) == {"broken.urdf", "robots/pendulum.urdf"}
    before = app.lab
    with pytest.raises(Exception, match="broken.urdf"):
        call(app, lambda: app.panels["load"].open("broken.urdf"))
    assert app.lab is before and app.lab.sim.robot.name == "mex_rb"  # still the old robot
    with pytest.raises(Exception, match="not one of the files"):
        call(app, lambda: app.panels["load"].open("../../etc/passwd.urdf"))
    with pytest.raises(Exception, match="not a robot file"):
        save_upload("notes.txt", b"hello")
    call(app, lambda: app.panels["load"].open("robots/pendulum.urdf"))
    lab = app.lab
    assert lab is not before and lab.sim.robot.name == "pendulum"
    assert set(app.scene.links) == set(lab.sim.compiled.bodies)  # the scene is rebuilt
    assert "swing/position" in app.log.index and "l_elbow/position" not in app.log.index
    assert "swing_position_controller" in lab.manager.controllers  # gains from its physics
    assert [j for (_, j) in app.panels["joints"].sliders] == ["swing"]
    # it runs, and the panels work on it: the step helper on its one joint
    t0 = lab.sim.time
    assert wait_until(lambda: lab.sim.time > t0 + 0.3, timeout=10)
    call(app, lambda: app.panels["step_response"].start("swing", 0.3))
    assert wait_until(lambda: app.panels["step_response"].result is not None, timeout=20)
    q = lab.sim.joint_positions()[lab.sim.joint_names.index("swing")]
    assert abs(q - 0.3) < 0.05
    with pytest.raises(Exception, match="fixed to the world"):  # said, not silently ignored
        call(app, lambda: app.panels["tools"].move.enable(True))
    assert not app.panels["tools"].move.gizmo.visible
    # an upload: saved in a temporary folder, never the start folder
    path = save_upload("up.urdf", PENDULUM.replace("pendulum", "uploaded").encode())
    assert path.parent != folder and path.read_text().startswith("<?xml")
    call(app, lambda: app.load(path))
    assert app.lab.sim.robot.name == "uploaded"


def test_the_walk_plan_overlay_belongs_to_the_robot_loaded(app):
    """View > Walk plan: built with the page's panels (Load builds it anew on the new lab);
    shown, it asks for the measured ZMP; hidden, it stops asking."""
    view = app.panels["walk_plan"]
    assert view.lab is app.lab
    zmp = f"{app.lab.namespace}/zmp"
    app.panels["view"].walk_plan_box.value = True  # the View menu's box, as a click sets it
    call(app, lambda: None)  # its handler has run in the simulation thread
    assert view.visible and app.lab.bus.wanted(zmp)
    # no walk: nothing planned, so no node shows (an empty one would be a zero-length line)
    assert not any(view.nodes[k].visible for k in ("footsteps", "zmp_plan", "com_plan"))
    app.panels["view"].walk_plan_box.value = False
    call(app, lambda: None)
    assert not view.visible and not any(node.visible for node in view.nodes.values())
    assert not app.lab.bus.wanted(zmp) or app.lab.bus.taps
