"""The page as a student's bench, checked on the server (the page's handlers called directly, in
the simulation thread as the page's clicks run them): plots that keep their history, the status
that tells the truth, the inspector against the URDF, pushes against falling, recording against
an independent mcap reader, the step helper against `mexone run`'s metrics."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from helpers import free_port, wait_frames, wait_until
from mexone.control.metrics import TrackingRecorder
from mexone.errors import OutputExistsError
from mexone.gui.app import GuiApp
from mexone.gui.plots import CAPACITY, axis_scale
from mexone.gui.topics import TopicsPanel
from mexone.lab import Lab
from mexone.physics import CompileOptions
from mexone.physics.monitor import has_fallen


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    gui = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 record_folder=tmp_path_factory.mktemp("records"))
    thread = threading.Thread(target=gui.serve_forever, daemon=True)
    thread.start()
    yield gui
    gui.stop()
    thread.join(timeout=5)


def call(app, fn):
    """Run `fn` in the simulation thread, as a page's click does, and return its result."""
    return app.work.call(fn)


def fresh(app, paused: bool = False) -> None:
    def reset():
        app.reset_world()
        if app.lab.sim.paused != paused:
            app.toggle_pause()
    call(app, reset)


def typed(app, handle, text: str) -> None:
    """What a page's keystrokes leave behind, read once the typing settles."""
    entry = next(f for f in app.fields.fields if f.handle is handle)
    entry.typed, entry.since = text, 0.0


def test_pause_keeps_the_plot_history_and_step_n_adds_n_samples(app):
    fresh(app)
    assert wait_until(lambda: app.lab.sim.time > 2.0)
    call(app, app.toggle_pause)
    before = app.log.count
    t_before, _ = app.log.window(10.0, ["l_elbow/position"])
    assert wait_frames(app, 20)  # paused: nothing is added, nothing is lost
    assert app.log.count == before
    t_after, _ = app.log.window(10.0, ["l_elbow/position"])
    np.testing.assert_array_equal(t_before, t_after)
    assert t_after[-1] - t_after[0] > 1.9  # the whole run so far, at 100 Hz of sim time
    assert 0.009 < np.median(np.diff(t_after)) < 0.011
    call(app, lambda: app.step_n(37))
    assert wait_until(lambda: app.steps_left == 0 and app.log.count == before + 37)
    t, _ = app.log.window(10.0, ["l_elbow/position"])
    np.testing.assert_allclose(np.diff(t[-37:]), app.lab.sim.timestep, rtol=1e-6)
    assert "paused" in app.status_text() and "real-time factor 0" in app.status_text()


def test_plot_panes_show_sim_seconds_and_readable_small_ranges(app):
    panel = app.panels["plots"]
    call(app, lambda: panel.show_joint("l_elbow"))  # a joint that sags under gravity
    plot = panel.plots[0]
    assert plot.scales["x"]["time"] is False  # seconds, not a date
    t = np.asarray(plot.data[0])
    assert t[-1] == pytest.approx(app.lab.sim.time, abs=0.02)
    # uPlot prints 3 decimals: a span under 0.05 is drawn scaled, and says so
    assert axis_scale(np.array([0.0041, 0.0042])) == 1e3  # 4.1 to 4.2 (×10⁻³)
    assert axis_scale(np.array([0.00411, 0.00412])) == 1e6
    assert axis_scale(np.array([-0.025, 0.01])) == 1e3
    assert axis_scale(np.array([-2.0, 1.0])) == 1.0
    assert axis_scale(np.array([0.004, 0.004])) == 1e3  # flat: a tenth of its size
    values = np.concatenate([np.asarray(d) for d in plot.data[1:]])
    factor = axis_scale(values / 1.0)
    assert factor == 1.0  # the data already sent is scaled: its span reads with 3 decimals
    assert plot.axes[1]["size"] >= 70  # room for "-0.025"


def test_any_signal_in_any_pane_and_csv_export(app):
    panel = app.panels["plots"]
    panel.pane.value, panel.signal.value = "pane 3", "imu/linear_acceleration/z"
    call(app, lambda: panel._edit("Add"))
    panel.signal.value = "r_knee/effort"
    call(app, lambda: panel._edit("Add"))
    assert panel.chosen[2] == ["imu/linear_acceleration/z", "r_knee/effort"]
    assert panel.plots[2].visible and len(panel.plots[2].data) == 3
    acc = np.asarray(panel.plots[2].data[1]) / axis_scale(np.asarray(panel.plots[2].data[1]))
    assert 9.0 < np.median(acc) < 10.6  # standing still: the IMU feels gravity
    t, values = app.log.window(panel.seconds, ["imu/linear_acceleration/z"])
    from mexone.gui.plots import to_csv
    rows = to_csv(t, values, ["imu/linear_acceleration/z"]).splitlines()
    assert rows[0] == "time,imu/linear_acceleration/z" and len(rows) == t.size + 1
    assert panel.png()[:8] == b"\x89PNG\r\n\x1a\n"
    call(app, lambda: panel._edit("Clear pane"))
    assert not panel.plots[2].visible
    assert CAPACITY >= 60 / 0.01


def test_refused_numbers_get_a_message_and_the_field_shows_the_server_value(app):
    knee_p = next(f.handle for f in app.fields.fields if f.handle.label == "p (l_knee)")
    held = app.fields.held(knee_p)
    for text, message in (("-1", "p (l_knee): -1 must be a finite number >= 0 and <= 100000"),
                          ("abc", "p (l_knee): 'abc' is not a number"),
                          ("NaN", "p (l_knee): 'NaN' is not a finite number"),
                          ("Infinity", "p (l_knee): 'Infinity' is not a finite number")):
        typed(app, knee_p, text)
        assert wait_until(lambda m=message: any(r.startswith(m) for r in app.refusals)), text
        assert knee_p.value == f"{held[0]:.10g}"
    typed(app, app.panels["simulation"].steps, "1e3")  # scientific notation is a number
    # the server takes the value, then shows it in the field (a moment later on a loaded machine)
    assert wait_until(lambda: app.fields.held(app.panels["simulation"].steps) == [1000.0] and app.panels["simulation"].steps.value == "1000")


def test_a_huge_gain_shows_on_the_status_line_within_a_second(app):
    fresh(app)
    p = next(f.handle for f in app.fields.fields if f.handle.label == "p (l_elbow)")
    original = app.fields.held(p)[0]
    seen: dict[str, float] = {}  # sim time when the gain took hold, when it was named

    def watch(sim) -> None:  # simulation thread, every tick
        if "held" not in seen and app.fields.held(p) == [1e5]:
            seen["held"] = sim.time
        if "held" in seen and "named" not in seen and "unstable control" in app.status_text():
            seen["named"] = sim.time

    call(app, lambda: app.tick_hooks.append(watch))
    try:
        start = time.time()
        typed(app, p, "1e5")  # the most ranges.GAIN_P allows: 1e20 is refused
        assert wait_until(lambda: "named" in seen, timeout=30)
        print(f"named after {seen['named'] - seen['held']:.3f} s of sim time "
              f"({time.time() - start:.2f} s of wall time since typed)")
        assert "l_elbow" in app.status_text()
        # within a second of the lab running at real time, counted on the simulation's own
        # clock (the chatter's window is sim time): a stalled or slower host stretches the wall
        # time alike for every part of the lab, not what the page tells the student
        assert seen["named"] - seen["held"] < 1.0
    finally:
        call(app, lambda: app.tick_hooks.remove(watch))
        typed(app, p, f"{original}")  # the next tests' gain, whatever happened here
    assert wait_until(lambda: app.fields.held(p) == [original])
    fresh(app)
    assert wait_until(lambda: "unstable" not in app.status_text())


def test_a_mujoco_warning_shows_on_the_status_line(app):
    import mujoco

    fresh(app)
    seen: dict[str, int] = {}  # the page's frame count when MuJoCo warned, when it was named

    def warn():  # what MuJoCo's mj_warning does: count it (and print it once, to the terminal)
        app.lab.sim.data.warning[mujoco.mjtWarning.mjWARN_BADCTRL].number += 3
        seen["warned"] = app._frames

    def watch(sim) -> None:  # simulation thread, every tick
        if "named" not in seen and "NaN, Inf or huge value in CTRL" in app.status_text():
            seen["named"] = app._frames

    call(app, lambda: app.tick_hooks.append(watch))
    try:
        call(app, warn)
        assert wait_until(lambda: "named" in seen, timeout=30)
    finally:
        call(app, lambda: app.tick_hooks.remove(watch))
    # the very next frame reads MuJoCo's counters: counted in the page's frames (30 a second),
    # not in a wall time a stalled or slower host stretches
    assert seen["named"] - seen["warned"] <= 1, seen
    fresh(app)  # a reset zeroes MuJoCo's counters, and the line clears
    assert wait_until(lambda: "CTRL" not in app.status_text())


def test_divergence_names_the_setting_changed_last(app):
    fresh(app)
    typed(app, app.panels["physics"].gravity, "0, 0, -1000")
    assert wait_until(lambda: app.fields.last_change == "Gravity (m/s²) = 0, 0, -1000")
    from mexone.physics.divergence import DivergenceError
    call(app, lambda: app._diverged(DivergenceError("simulation diverged", hint="gains?")))
    assert "last setting changed on this page: Gravity (m/s²) = 0, 0, -1000" in app._status.content
    typed(app, app.panels["physics"].gravity, "0 0 -9.81")
    assert wait_until(lambda: app.lab.sim.model.opt.gravity[2] == -9.81)
    fresh(app)
    assert app.error is None


def test_clicking_a_link_shows_its_urdf_mass(app):
    fresh(app, paused=True)
    torso = app.lab.sim.robot.links["torso"].inertial.mass
    origin, target = np.array([2.0, 0.0, 0.75]), app.lab.sim.data.xipos[app.lab.sim.compiled.bodies["torso"]]
    link = call(app, lambda: app.panels["tools"].click(origin, target - origin))
    assert link == "torso"
    assert f"mass {torso:.6g} kg (URDF)" in app.panels["tools"].report.content
    assert "joint above" in app.panels["tools"].report.content
    assert call(app, lambda: app.panels["tools"].click(origin, -(target - origin))) is None  # sky


# Mex-One on its PD controllers stands 3 N s at the torso and falls from 4 N s (the issue's
# 5 N s is beyond it: see docs/DECISIONS.md)
@pytest.mark.parametrize(("impulse", "falls"), [(40.0, True), (2.0, False)])
def test_pushing_the_torso_forward(app, impulse, falls):
    fresh(app, paused=True)
    sim = app.lab.sim
    height = sim.base_height
    point = sim.data.xipos[sim.compiled.bodies["torso"]].copy()
    app.panels["tools"].impulse = impulse

    def push():
        app.panels["tools"].push("torso", point, (1.0, 0.0, 0.0))
        app.toggle_pause()
    call(app, push)
    assert app.panels["tools"].arrow.visible  # drawn while it acts
    assert wait_until(lambda: sim.time > 2.5, timeout=15)
    fell = call(app, lambda: has_fallen(sim, height))
    forward = call(app, lambda: sim.data.xpos[sim.compiled.root_body][0])
    assert fell is falls
    if falls:
        assert forward > 0.1
    assert not app.panels["tools"].arrow.visible
    fresh(app)


def test_recording_from_the_page_never_overwrites(app):
    from mcap.reader import make_reader

    fresh(app)
    call(app, lambda: app.panels["record"].start("run.mcap"))
    t0 = app.lab.sim.time
    assert wait_until(lambda: app.lab.sim.time > t0 + 3.0, timeout=20)
    call(app, app.panels["record"].stop)
    path = app.settings.record_folder / "run.mcap"
    with path.open("rb") as f:
        count = sum(1 for _s, channel, _m in make_reader(f).iter_messages()
                    if channel.topic == "/mex_rb/joint_states")
    assert 140 <= count <= 165  # 50 Hz for 3 s of sim time
    assert f"{path.stat().st_size / 1024:.0f} kB" in app.panels["record"].status.content
    size = path.stat().st_size
    with pytest.raises(OutputExistsError):
        call(app, lambda: app.panels["record"].start("run.mcap"))
    assert path.stat().st_size == size
    with pytest.raises(Exception, match="must be a file name"):
        call(app, lambda: app.panels["record"].start("../elsewhere.mcap"))


def test_topics_panel_rates_and_echo(app):
    fresh(app)
    panel = app.panels["topics"]
    panel.choice.value = "/mex_rb/joint_states"
    panel.echoing.value = True
    call(app, panel._resubscribe)
    own_refresh = panel.update  # the page's own refresh would start a new window mid-test
    panel.update = lambda: None

    def count():
        panel._last = -math.inf  # a new window from here
        TopicsPanel.update(panel)
        return app.lab.sim.time

    try:
        call(app, count)
        sim_start = call(app, count)
        # a second of sim time in the window (a condition: a slow or stalled host ran less
        # of it in a second of wall time, 0.099 s once under load)
        assert wait_until(lambda: app.lab.sim.time - sim_start >= 1.0, timeout=60)
        sim_span = call(app, count) - sim_start
    finally:
        panel.update = own_refresh
    # 50 Hz of simulation time, as rostopic hz counts under /use_sim_time: one message more or
    # less in the window, whatever the real-time factor of a loaded machine
    assert sim_span > 0.1
    assert panel.rates["/mex_rb/joint_states"] == pytest.approx(50, abs=1.01 / sim_span)
    assert "l_elbow" in panel.echo_view.content and "position" in panel.echo_view.content
    assert "sensor_msgs/JointState" in panel.table.content
    panel.echoing.value = False
    call(app, panel._resubscribe)


def test_step_response_matches_the_metrics_of_mexone_run(app):
    fresh(app)
    assert wait_until(lambda: app.lab.sim.time > 0.5)
    call(app, lambda: app.panels["step_response"].start("l_elbow", -0.8))
    assert wait_until(lambda: app.panels["step_response"].result is not None, timeout=15)
    page = app.panels["step_response"].result
    # the same step without the page: TrackingRecorder, as `mexone run` measures a routine
    lab = Lab.create()
    recorder = TrackingRecorder(lab.sim, lab.manager)
    lab.sim.run(page_start(app))
    lab.manager.command("l_elbow_position_controller", {"l_elbow": -0.8})
    lab.sim.run(2.0)
    ref = recorder.metrics()["l_elbow"]
    assert page["overshoot"] == pytest.approx(ref.overshoot, rel=0.05, abs=0.005)
    assert page["settling_time"] == pytest.approx(ref.settling_time, rel=0.05, abs=0.01)
    assert page["rise_time"] is not None and page["rise_time"] < page["settling_time"]
    assert page["steady_error"] < 0.01
    assert "overshoot" in app.panels["step_response"].view.content


def page_start(app) -> float:
    return round(app.panels["step_response"].started, 3)


def test_start_paused_holds_after_a_reset(app):
    app.panels["simulation"].paused_after_reset.value = True
    call(app, app.reset_model)
    assert app.lab.sim.paused
    assert wait_frames(app, 8)
    assert app.lab.sim.time == 0.0
    app.panels["simulation"].paused_after_reset.value = False
    fresh(app)
