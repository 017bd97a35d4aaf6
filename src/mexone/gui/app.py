"""GuiApp: `mexone sim`'s web page (viser), what Gazebo's window was to the seed, and more.

The simulation runs in the main thread, paced to the real-time factor; viser serves the page
from its own thread. Everything a page does to the simulation goes through `self.actions` and
runs between frames in the simulation thread, so a slow, closed or tenth browser tab never
touches the physics.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import viser
import viser.uplot as uplot

from mexone.bus.msgs import Float64, Float64MultiArray
from mexone.control.controllers import (
    PositionController,
    TrajectoryController,
    VelocityController,
)
from mexone.errors import MexoneError
from mexone.gui.scene import OVERLAYS, RobotScene
from mexone.lab import Lab
from mexone.physics.compile import CompileOptions
from mexone.physics.watchdog import DivergenceError
from mexone.routines.runner import RoutineRunner, shipped_routines

__all__ = ["GuiApp", "FPS"]

FPS = 30.0  # scene updates per second of wall time
PLOT_SECONDS = 10.0
TICK = 0.001  # s of sim time between tick hooks (the ROS bridge's /clock)


class _GuiLog(logging.Handler):
    """mexone's warnings (a clamped command, what Gazebo 7 did differently) on the page too."""

    def __init__(self, app: GuiApp):
        super().__init__(logging.WARNING)
        self.app = app

    def emit(self, record: logging.LogRecord) -> None:
        self.app.console.append(f"[WARN] {record.getMessage()}")
        self.app.notify("Warning", record.getMessage(), color="yellow")


class GuiApp:
    def __init__(self, make_lab: Callable[[CompileOptions], Lab], options: CompileOptions,
                 host: str = "127.0.0.1", port: int = 8080, target_rtf: float = 1.0):
        self.make_lab = make_lab
        self.options = options
        self.lab = make_lab(options)
        self.target_rtf = target_rtf
        self.lab.sim.target_rtf = target_rtf or None
        self.server = viser.ViserServer(host=host, port=port, label="mexone", verbose=False)
        self.actions: queue.Queue[Callable[[], None]] = queue.Queue()
        self.stopping = threading.Event()
        self.scene = RobotScene(self.server, self.lab.sim)
        self.scene.build()
        self.routine: RoutineRunner | None = None
        self.console: deque[str] = deque(maxlen=14)
        self.history: deque[tuple[float, np.ndarray, np.ndarray, np.ndarray]] = deque(
            maxlen=int(PLOT_SECONDS * FPS))
        self.error: str | None = None
        self._frames = 0
        self.tick_hooks: list[Callable] = []  # run every TICK of sim time (the ROS bridge)
        self._build_gui()
        logging.getLogger("mexone").addHandler(_GuiLog(self))
        self.server.initial_camera.fov = math.radians(45.0)  # a 1 m robot fills half the view
        self.server.initial_camera.position = (1.6, -1.6, 1.0)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.5)

    # ----- threads ----------------------------------------------------------------------------
    def do(self, action: Callable[[], None]) -> None:
        """Run `action` in the simulation thread, between frames."""
        self.actions.put(action)

    def serve_forever(self, duration: float | None = None) -> None:
        sim_start = self.lab.sim.time
        while not self.stopping.is_set():
            self._drain()
            sim = self.lab.sim
            if duration is not None and sim.time - sim_start >= duration:
                break
            frame = (self.target_rtf or 4.0) / FPS
            if sim.paused or self.error:
                time.sleep(1.0 / FPS)
                self._after_frame()
                continue
            gate = self.routine.scheduler if self.routine and self.routine.running else None
            try:
                sim.run(frame, tick=min(frame, TICK) if self.tick_hooks else frame, gate=gate,
                        on_tick=self._tick if self.tick_hooks else None)
            except DivergenceError as exc:
                self.error = exc.one_line()
                self._status.content = f"**diverged** — {self.error}. Press *Reset world*."
            self._after_frame()

    def _tick(self, sim) -> None:
        for hook in self.tick_hooks:
            hook(sim)

    def stop(self) -> None:
        self.stopping.set()
        logger = logging.getLogger("mexone")
        for handler in [h for h in logger.handlers if isinstance(h, _GuiLog) and h.app is self]:
            logger.removeHandler(handler)
        if self.routine:
            self.routine.stop()
        self.server.stop()

    def _drain(self) -> None:
        while True:
            try:
                action = self.actions.get_nowait()
            except queue.Empty:
                return
            try:
                action()
            except MexoneError as exc:
                self.notify("Refused", exc.one_line())

    def notify(self, title: str, body: str, color: str = "red") -> None:
        for client in self.server.get_clients().values():
            client.add_notification(title, body, auto_close_seconds=6.0, color=color)

    # ----- per frame --------------------------------------------------------------------------
    def _after_frame(self) -> None:
        self._frames += 1
        sim = self.lab.sim
        self.scene.update()
        hw = self.lab.controllers.hw if self.lab.controllers else None
        if hw is not None:
            bank = self.lab.controllers.bank
            rows = np.arange(len(hw.joints))
            self.history.append((sim.time, bank.setpoint.copy(), hw.position(rows).copy(),
                                 hw.effort(rows).copy()))
        if self.follow.value:
            base = sim.data.xpos[sim.compiled.root_body]
            for client in self.server.get_clients().values():
                offset = np.asarray(client.camera.position) - np.asarray(client.camera.look_at)
                client.camera.look_at = tuple(base)
                client.camera.position = tuple(base + offset)
        if self._frames % 5 == 0:
            if not self.error:
                state = "paused" if sim.paused else "running"
                self._status.content = (f"**sim time** {sim.time:8.3f} s &nbsp; **real-time factor** "
                                        f"{sim.rtf.value:4.2f} &nbsp; ({state})")
            self._update_plots()
            self._sync_sliders()
        if self.routine and not self.routine.running and self.routine.thread is not None:
            self._routine_done()

    # ----- panels -----------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(dark_mode=False)
        self._status = gui.add_markdown("**sim time** 0.000 s")
        with gui.add_folder("Simulation"):
            self.play = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
            self.play.on_click(lambda _: self.do(self._toggle_pause))
            step = gui.add_button("Step", hint="one physics step")
            step.on_click(lambda _: self.do(lambda: self.lab.sim.step(1)))
            self.step_n = gui.add_number("Steps", initial_value=100, min=1, max=100000, step=1)
            step_n = gui.add_button("Step N")
            step_n.on_click(lambda _: self.do(lambda: self.lab.sim.step(int(self.step_n.value))))
            gui.add_button("Reset model").on_click(lambda _: self.do(self.reset_model))
            gui.add_button("Reset world").on_click(lambda _: self.do(self.reset_world))
            self.rtf = gui.add_number("Real-time factor", initial_value=self.target_rtf, min=0.0,
                                      max=100.0, step=0.1, hint="0 = as fast as possible")
            self._validated(self.rtf, self._set_rtf)
            self.follow = gui.add_checkbox("Follow robot", False)
        with gui.add_folder("View"):
            for overlay in OVERLAYS:
                box = gui.add_checkbox(overlay, False)
                box.on_update(lambda e, name=overlay: self.do(
                    lambda: self.scene.show(name, e.target.value)))
            transparent = gui.add_checkbox("Transparent", False)
            transparent.on_update(lambda e: self.do(lambda: self.scene.set_transparent(e.target.value)))
            wireframe = gui.add_checkbox("Wireframe", False)
            wireframe.on_update(lambda e: self.do(lambda: self.scene.set_wireframe(e.target.value)))
        self._build_joints()
        self._build_plots()
        self._build_routines()
        self._build_physics()

    def _validated(self, handle, apply: Callable[[float], None]) -> None:
        """Refuse a bad number with a message and put the last good value back."""
        last = [handle.value]

        def changed(_event) -> None:
            value = handle.value
            if value is None or not math.isfinite(float(value)):
                handle.value = last[0]
                self.notify("Refused", f"{handle.label}: '{value}' is not a number")
                return

            def act() -> None:
                try:
                    apply(float(value))
                    last[0] = value
                except (MexoneError, ValueError) as exc:
                    handle.value = last[0]
                    self.notify("Refused", f"{handle.label}: {exc}")

            self.do(act)

        handle.on_update(changed)

    def _toggle_pause(self) -> None:
        sim = self.lab.sim
        if sim.paused:
            sim.resume()
            self.play.label, self.play.icon = "Pause", viser.Icon.PLAYER_PAUSE
        else:
            sim.pause()
            self.play.label, self.play.icon = "Play", viser.Icon.PLAYER_PLAY

    def _set_rtf(self, value: float) -> None:
        if value < 0:
            raise ValueError("must be >= 0 (0 = unlimited)")
        self.target_rtf = value
        self.lab.sim.target_rtf = value or None
        if not self.lab.sim.paused:
            self.lab.sim.resume()  # restarts the pacing from now at the new rate

    # ----- joints -------------------------------------------------------------------------------
    def _build_joints(self) -> None:
        gui = self.server.gui
        self.sliders: dict[tuple[str, str], viser.GuiSliderHandle] = {}
        self._touched: dict[tuple[str, str], float] = {}  # when a person last moved a slider
        manager = self.lab.controllers
        with gui.add_folder("Joints"):
            if manager is None:
                gui.add_markdown("No controllers loaded (`--no-controllers`).")
                return
            self.units = gui.add_dropdown("Units", ("rad", "deg"), initial_value="rad")
            self.units.on_update(lambda _: self.do(self._rescale_sliders))
            gui.add_button("Home", hint="every position controller to 0").on_click(
                lambda _: self.do(self.home))
            for ctrl in manager.controllers.values():
                if isinstance(ctrl, TrajectoryController):
                    gui.add_markdown(f"`{ctrl.name}`: send JointTrajectory messages from a routine")
                    continue
                for joint in ctrl.joints:
                    self._add_slider(ctrl, joint)
        with gui.add_folder("Gains", expand_by_default=False):
            for ctrl in manager.controllers.values():
                if isinstance(ctrl, PositionController) and not ctrl.ideal:
                    self._add_gains(ctrl)

    def _slider_range(self, ctrl, joint: str) -> tuple[float, float, str]:
        limit = self.lab.sim.robot.joints[joint].limit
        if isinstance(ctrl, PositionController):
            if limit and limit.upper > limit.lower:
                return limit.lower, limit.upper, "rad"
            return -math.pi, math.pi, "rad"
        if isinstance(ctrl, VelocityController):
            v = limit.velocity if limit and limit.velocity > 0 else 5.0
            return -v, v, "rad/s"
        e = limit.effort if limit and limit.effort > 0 else 10.0
        return -e, e, "N m"

    def _add_slider(self, ctrl, joint: str) -> None:
        lo, hi, unit = self._slider_range(ctrl, joint)
        slider = self.server.gui.add_slider(f"{joint}", min=round(lo, 4), max=round(hi, 4),
                                            step=0.001, initial_value=0.0,
                                            hint=f"{ctrl.name} ({unit})")
        self.sliders[(ctrl.name, joint)] = slider

        def moved(event) -> None:
            if event.client is not None:  # a person moved it; our own syncs are not commands
                value = event.target.value  # now: a sync may change the slider before we run
                self._touched[(ctrl.name, joint)] = time.monotonic()
                self.do(lambda: self._send(ctrl.name, {joint: value}))

        slider.on_update(moved)

    def _to_si(self, ctrl, value: float) -> float:
        degrees = isinstance(ctrl, PositionController) and self.units.value == "deg"
        return math.radians(value) if degrees else value

    def _send(self, name: str, moved: dict[str, float] | None = None) -> None:
        """Command controller `name`: `moved` joints from the person, the rest from sliders."""
        manager = self.lab.controllers
        ctrl = manager.controllers[name]
        moved = moved or {}
        values = [self._to_si(ctrl, moved.get(j, self.sliders[(name, j)].value))
                  for j in ctrl.joints]
        msg = Float64(values[0]) if ctrl.msg_type is Float64 else Float64MultiArray(values)
        self.lab.bus.publish(manager.topic(name), msg)

    def _rescale_sliders(self) -> None:
        for (name, joint), slider in self.sliders.items():
            ctrl = self.lab.controllers.controllers[name]
            if not isinstance(ctrl, PositionController):
                continue
            lo, hi, _ = self._slider_range(ctrl, joint)
            f = 180.0 / math.pi if self.units.value == "deg" else 1.0
            value = float(ctrl.setpoint[ctrl.joints.index(joint)])
            slider.min, slider.max, slider.step = round(lo * f, 4), round(hi * f, 4), 0.001 * f
            slider.value = value * f

    def _sync_sliders(self) -> None:
        """Show what the position controllers are commanded, whoever commanded it."""
        if not getattr(self, "sliders", None):
            return
        f = 180.0 / math.pi if self.units.value == "deg" else 1.0
        now = time.monotonic()
        for (name, joint), slider in self.sliders.items():
            ctrl = self.lab.controllers.controllers[name]
            if now - self._touched.get((name, joint), -1e9) < 1.0:
                continue  # do not fight a hand on the slider
            if isinstance(ctrl, PositionController):
                value = round(float(ctrl.setpoint[ctrl.joints.index(joint)]) * f, 3)
                if abs(slider.value - value) > 1e-3:
                    slider.value = value

    def home(self) -> None:
        for (name, _joint), slider in self.sliders.items():
            if isinstance(self.lab.controllers.controllers[name], PositionController):
                slider.value = 0.0
        for name, ctrl in self.lab.controllers.controllers.items():
            if isinstance(ctrl, PositionController) and not isinstance(ctrl, TrajectoryController):
                self._send(name)

    def _add_gains(self, ctrl: PositionController) -> None:
        gui = self.server.gui
        gains = ctrl.gains[0]
        with gui.add_folder(ctrl.name.replace("_position_controller", ""), expand_by_default=False):
            for key in ("p", "i", "d"):
                number = gui.add_number(key, initial_value=float(getattr(gains, key)), min=0.0,
                                        step=0.01)
                self._validated(number, lambda v, c=ctrl, k=key: self._set_gain(c, k, v))

    def _set_gain(self, ctrl: PositionController, key: str, value: float) -> None:
        if value < 0:
            raise ValueError("gains must be >= 0")
        ctrl.gains = [replace(g, **{key: value}) for g in ctrl.gains]
        self.lab.controllers.bank.set_gains(ctrl.rows, ctrl.gains)
        self.lab.controllers.reschedule()

    # ----- plots --------------------------------------------------------------------------------
    def _build_plots(self) -> None:
        gui = self.server.gui
        manager = self.lab.controllers
        with gui.add_folder("Plots"):
            if manager is None:
                gui.add_markdown("No controllers: nothing to plot.")
                self.plot_joint = None
                return
            joints = manager.hw.joints
            self.plot_joint = gui.add_dropdown("Joint", tuple(joints), initial_value=joints[0])
            empty = (np.zeros(1), np.zeros(1), np.zeros(1))
            self.tracking = gui.add_uplot(
                empty, (uplot.Series(label="t (s)"),
                        uplot.Series(label="command (rad)", stroke="#1f77b4", width=2),
                        uplot.Series(label="actual (rad)", stroke="#d62728", width=2)),
                title="command vs actual", aspect=1.6)
            self.effort_plot = gui.add_uplot(
                empty, (uplot.Series(label="t (s)"),
                        uplot.Series(label="error (rad)", stroke="#2ca02c", width=2),
                        uplot.Series(label="effort (N m)", stroke="#9467bd", width=2, scale="effort")),
                title="tracking error and effort", aspect=1.6,
                scales={"x": uplot.Scale(time=False), "effort": uplot.Scale()},
                axes=(uplot.Axis(), uplot.Axis(label="rad"),
                      uplot.Axis(label="N m", side=1, scale="effort")))

    def _update_plots(self) -> None:
        if self.plot_joint is None or len(self.history) < 2:
            return
        row = self.lab.controllers.hw.index[self.plot_joint.value]
        t = np.array([h[0] for h in self.history])
        cmd = np.array([h[1][row] for h in self.history])
        actual = np.array([h[2][row] for h in self.history])
        effort = np.array([h[3][row] for h in self.history])
        self.tracking.data = (t, cmd, actual)
        self.effort_plot.data = (t, cmd - actual, effort)

    # ----- routines -----------------------------------------------------------------------------
    def _build_routines(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Routines"):
            self.routine_choice = gui.add_dropdown("Routine", (*shipped_routines(), "file"),
                                                   initial_value="arms")
            self.routine_file = gui.add_text("File", initial_value="",
                                             hint="path of your routine when Routine is 'file'")
            start = gui.add_button("Start", icon=viser.Icon.PLAYER_PLAY)
            start.on_click(lambda _: self.do(self.start_routine))
            stop = gui.add_button("Stop", icon=viser.Icon.PLAYER_STOP)
            stop.on_click(lambda _: self.do(self.stop_routine))
            self.console_view = gui.add_markdown("*console: no routine yet*")

    def _log(self, level: str, text: str) -> None:
        self.console.append(f"[{level}] [{self.lab.sim.time:.3f}] {text}")
        self.console_view.content = "```\n" + "\n".join(self.console) + "\n```"

    def start_routine(self) -> None:
        if self.lab.controllers is None:
            raise MexoneError("no controllers loaded: a routine has nothing to command")
        self.stop_routine()
        choice = self.routine_choice.value
        target = self.routine_file.value.strip() if choice == "file" else choice
        self.console.clear()
        self.routine = RoutineRunner(self.lab, target, log=self._log)
        self.routine.start()
        self._log("INFO", f"started {self.routine.path.name}")

    def stop_routine(self) -> None:
        if self.routine is not None:
            self.routine.stop()
            self._routine_done()

    def _routine_done(self) -> None:
        runner, self.routine = self.routine, None
        runner.stop()
        if runner.error:
            self._log("ERROR", runner.error.splitlines()[-1])
            self.console_view.content += "\n```\n" + runner.error + "\n```"
        else:
            self._log("INFO", f"{runner.path.name} ended")

    # ----- physics and resets -------------------------------------------------------------------
    def _build_physics(self) -> None:
        gui = self.server.gui
        model = self.lab.sim.model
        with gui.add_folder("Physics", expand_by_default=False):
            self.gravity = gui.add_vector3("Gravity", initial_value=tuple(model.opt.gravity),
                                           step=0.01)
            self.gravity.on_update(lambda _: self.do(self._apply_physics))
            self.timestep = gui.add_number("Time step (s)", initial_value=float(model.opt.timestep),
                                           min=1e-5, max=0.01, step=0.0001)
            self._validated(self.timestep, self._set_timestep)
            self.self_collide = gui.add_checkbox("Self-collision", self.options.self_collision
                                                 is not False, hint="applies at Reset world")

    def _apply_physics(self) -> None:
        gravity = np.asarray(self.gravity.value, dtype=float)
        if not np.isfinite(gravity).all():
            raise MexoneError("gravity must be three finite numbers")
        self.lab.sim.model.opt.gravity[:] = gravity

    def _set_timestep(self, value: float) -> None:
        if not 1e-5 <= value <= 0.01:
            raise ValueError("the time step must be between 1e-5 and 0.01 s")
        self.lab.sim.model.opt.timestep = value

    def reset_model(self) -> None:
        """Robot back to its spawn pose at home, sim time 0; controllers restart, holding home."""
        self.stop_routine()
        self.lab.sim.reset()
        if self.lab.controllers:
            self.lab.controllers.restart()
        for slider in getattr(self, "sliders", {}).values():
            slider.value = 0.0
        self.history.clear()
        self.error = None

    def reset_world(self) -> None:
        """Rebuild the world with the Physics panel's settings (self-collision included)."""
        self.stop_routine()
        self.options = replace(self.options, self_collision=None if self.self_collide.value else False)
        paused = self.lab.sim.paused
        self.lab = self.make_lab(self.options)
        self.lab.sim.target_rtf = self.target_rtf or None
        self.scene.sim = self.lab.sim
        self._apply_physics()
        self._set_timestep(float(self.timestep.value))
        if paused:
            self.lab.sim.pause()
        for slider in getattr(self, "sliders", {}).values():
            slider.value = 0.0
        self.history.clear()
        self.error = None
