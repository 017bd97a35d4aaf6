"""GuiApp: `mexone sim`'s web page (viser), what Gazebo's window was to the seed, and more.

The simulation runs in the thread that calls `serve_forever`, paced to the real-time factor;
viser serves the page from its own threads. Everything a page does to the simulation is queued
(`self.work`) and runs between frames in the simulation thread, so a slow, closed or tenth
browser tab never touches the physics. Every value a page sends is checked here, on the server:
a page is not trusted to respect its own widgets' limits (see also gui/security.py).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import viser

from mexone import signals
from mexone.control.controllers import Controller
from mexone.control.spec import joint_label
from mexone.errors import InputError, MexoneError
from mexone.gui.fields import NumberFields
from mexone.gui.handles import IkHandles
from mexone.gui.health import Health
from mexone.gui.inspector import Inspector
from mexone.gui.move import MoveTool
from mexone.gui.panels import Panel, panel_types
from mexone.gui.plots import PLOT_PERIOD, PlotPanel, SignalLog
from mexone.gui.scene import OVERLAYS, RobotScene
from mexone.gui.screenshot import Screenshots, page_picture
from mexone.gui.security import LabAccess, guard, lab_access, warn_if_exposed
from mexone.gui.sensors import BALANCE, SensorPanel
from mexone.gui.stepresponse import StepResponse
from mexone.gui.walkpad import WalkPad
from mexone.gui.walkplan import WALK_PLAN, WalkPlanView
from mexone.lab import AUTO, Lab
from mexone.physics.compile import CompileOptions, Spawn
from mexone.physics.simulation import WorkQueue
from mexone.physics.watchdog import DivergenceError
from mexone.ranges import GAINS, GRAVITY, RTF, STEPS, TIMESTEP, number_text
from mexone.routines.runner import RoutineRunner, routine_choices

__all__ = ["GuiApp", "FPS", "MAX_STEPS"]

log = logging.getLogger(__name__)

FPS = 30.0  # scene updates per second of wall time
TICK = 0.001  # s of sim time between tick hooks (the ROS bridge's /clock)
MAX_STEPS = int(STEPS.high)  # Step N at most (a page could send anything): ranges.STEPS
STEP_BUDGET = 0.025  # s of wall time per frame spent on Step N, so the page stays live
PAGE_RENDER_SECONDS = 10.0  # a page that sends no picture by then gets MuJoCo's render instead
MAX_PAGE_RENDER = 4096  # px a side at most asked of a page for a screenshot


class _GuiLog(logging.Handler):
    """mexone's warnings (a clamped command, what Gazebo 7 did differently) on the page too."""

    def __init__(self, app: GuiApp):
        super().__init__(logging.WARNING)
        self.app = app

    def emit(self, record: logging.LogRecord) -> None:
        error = record.levelno >= logging.ERROR  # e.g. a student's controller stopped by a fault
        self.app.console.append(f"[{'ERROR' if error else 'WARN'}] {record.getMessage()}")
        self.app.notify("Error" if error else "Warning", record.getMessage(),
                        color="red" if error else "yellow")


class GuiApp:
    def __init__(self, make_lab: Callable[[CompileOptions], Lab], options: CompileOptions,
                 host: str = "127.0.0.1", port: int = 8080, target_rtf: float = 1.0,
                 routine_dirs: list[Path] | None = None, paused: bool = False,
                 record_folder: Path | None = None, model_folder: Path | None = None,
                 server: viser.ViserServer | None = None, exercise=None,
                 access: LabAccess | None = None):
        """`server`: draw into that page (guarded by its owner, who stops it) instead of
        serving one (the model editor's Simulate). `exercise`: an ExerciseTarget
        (gui/exercises.py) for the Exercises panel. `access`: who may open the page (default:
        as the environment says, a secret inside a JupyterHub; gui/security.py)."""
        self.options = options
        self.lab = make_lab(options)
        self.target_rtf = target_rtf
        self.lab.sim.target_rtf = target_rtf or None
        self.routine_dirs = routine_dirs
        self.start_paused = paused
        self.record_folder = record_folder
        self.model_folder = Path.cwd() if model_folder is None else model_folder  # Load's files
        self.model_label = self.lab.sim.robot.name
        self.owns_server = server is None
        self.server = server or viser.ViserServer(host=host, port=port, label="mexone", verbose=False)
        self.access = access or lab_access()
        if self.owns_server:
            guard(self.server, self.access)
            warn_if_exposed(host, self.server.get_port())
        self.work = WorkQueue()
        self.stopping = threading.Event()
        self.sensor_panel: SensorPanel | None = None
        self.routine: RoutineRunner | None = None
        self.console: deque[str] = deque(maxlen=14)
        self.follow_offset: dict[int, np.ndarray] = {}  # client -> camera position - robot
        self.error: str | None = None
        self.refusals: deque[str] = deque(maxlen=20)  # what the page asked for and was refused
        self.steps_left = 0  # Step N in progress, a budget per frame
        self._frames = 0
        self.tick_hooks: list[Callable] = []  # run every TICK of sim time (the ROS bridge)
        self.screenshots = Screenshots(self.record_folder or Path.cwd())
        self.last_screenshot: Path | None = None
        self.exercise = exercise
        self.extra_routines: dict[str, Path] = {}  # routines a panel offers (an exercise's)
        # the plug-in panels (gui/panels.py): one instance each for the page's life
        self.panels: dict[str, Panel] = {}
        self._failed_panels: set[str] = set()
        for cls in panel_types():
            self._panel_call(cls.name, lambda c=cls: c.wanted(self) and self.panels.update(
                {c.name: c(self)}))
        self._build_all()
        # one click handler for the page's life: it reaches whichever robot is loaded now
        self._on_click = self.server.scene.on_click()(lambda e: self.do(
            lambda: self.inspector.click(e.ray_origin, e.ray_direction)))
        logging.getLogger("mexone").addHandler(_GuiLog(self))
        self.server.initial_camera.fov = math.radians(45.0)  # a 1 m robot fills half the view
        self.server.initial_camera.position = (1.3, -1.35, 0.95)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.52)
        if paused:
            self._toggle_pause()

    def _build_all(self) -> None:
        """The scene and every panel, for the robot in self.lab (at start and after Load)."""
        self.scene = RobotScene(self.server, self.lab.sim)
        self.scene.build()
        self.log = SignalLog(self.lab)
        self.health = Health(self.lab.sim, self.log)
        self.fields = NumberFields(self.server.gui, self.refuse)
        self._build_gui()

    # ----- threads ----------------------------------------------------------------------------
    def do(self, action: Callable[[], None]) -> None:
        """Run `action` in the simulation thread, between frames."""
        self.work.put(action)

    def serve_forever(self, duration: float | None = None) -> None:
        sim_start = self.lab.sim.time
        while not self.stopping.is_set() and not signals.requested():
            self.work.drain(on_error=self._refused)
            sim = self.lab.sim
            sim.work.drain(on_error=self._refused)  # other front ends' work (ROS services)
            if duration is not None and sim.time - sim_start >= duration:
                break
            frame = (self.target_rtf or 4.0) / FPS
            if self.steps_left and not self.error:
                self._step_some()
            elif sim.paused or self.error:
                time.sleep(1.0 / FPS)
            else:
                gate = self.routine.scheduler if self.routine and self.routine.running else None
                tick = min(frame, TICK if self.tick_hooks else PLOT_PERIOD)
                try:
                    sim.run(frame, tick=tick, gate=gate, on_tick=self._tick,
                            until=signals.requested)
                except DivergenceError as exc:
                    self._diverged(exc)
            self._after_frame()

    def _step_some(self) -> None:
        """Advance Step N for at most STEP_BUDGET of wall time: Pause or Reset interrupts it."""
        sim, end = self.lab.sim, time.perf_counter() + STEP_BUDGET
        try:
            while self.steps_left and time.perf_counter() < end:
                sim.step(1)  # a sample after each step: Step N adds N to the plots
                self.steps_left -= 1
                self.log.sample()
        except DivergenceError as exc:
            self._diverged(exc)

    def _diverged(self, exc: DivergenceError) -> None:
        self.error = exc.one_line()
        if self.fields.last_change:  # the page knows what the user changed last
            self.error += f" (the last setting changed on this page: {self.fields.last_change})"
        self.steps_left = 0
        self._status.content = f"**diverged** — {self.error}. Press *Reset world*."
        self.notify("Diverged", self.error)

    def _tick(self, sim) -> None:
        for hook in self.tick_hooks:
            hook(sim)
        if self.log.due(sim.time):
            self.log.sample()

    def stop(self) -> None:
        self.stopping.set()
        logger = logging.getLogger("mexone")
        for handler in [h for h in logger.handlers if isinstance(h, _GuiLog) and h.app is self]:
            logger.removeHandler(handler)
        if self.routine:
            self.routine.stop(join=0.5)
        for panel in self.panels.values():
            panel.stop()
        self.screenshots.close()
        self.ik_handles.close()
        if self.owns_server:
            self.server.stop()
        else:  # the page goes back to its owner (the editor) without our click handler
            self.server.scene.remove_click_callback(self._on_click)

    def _refused(self, exc: Exception) -> None:
        if not isinstance(exc, MexoneError | ValueError):
            raise exc
        self.refuse(exc.one_line() if isinstance(exc, MexoneError) else str(exc))

    def refuse(self, text: str) -> None:
        self.refusals.append(text)
        self.notify("Refused", text)

    def notify(self, title: str, body: str, color: str = "red") -> None:
        for client in self.server.get_clients().values():
            client.add_notification(title, body, auto_close_seconds=6.0, color=color)

    # ----- per frame --------------------------------------------------------------------------
    def _after_frame(self) -> None:
        self._frames += 1
        sim = self.lab.sim
        self.fields.commit()
        self.scene.update()
        if self.log.due(sim.time):
            self.log.sample()  # the first sample, and one after a reset or a single Step
        for problem in self.health.check():
            self.notify("Simulation problem", problem, color="orange")
        if self.follow.value:
            self._follow()
        self.sensor_panel.update(time.monotonic())
        self.inspector.update()
        self.move.update()
        self.walk_plan.update()
        if self.step_response.running:
            self.step_response.update()
        if self._frames % 5 == 0:
            if not self.error:
                self._status.content = self.status_text()
            self.plot_panel.update()
            self.sensor_panel.update_plots()
            self._sync_sliders()
        for name, panel in self.panels.items():
            if self._frames % panel.period == 0 and name not in self._failed_panels:
                self._panel_call(name, panel.update)
        if self.routine and not self.routine.running:
            self._routine_done()

    def status_text(self) -> str:
        """The status line: what the simulation is doing, and whatever is wrong with it."""
        sim = self.lab.sim
        if sim.paused:
            state = "**paused** (real-time factor 0)"
        else:
            state = f"running at real-time factor {sim.rtf.value:4.2f}"
        text = f"**sim time** {sim.time:8.3f} s &nbsp; {state}"
        problems = self.health.problems
        if problems:
            text += "<br>⚠ " + "<br>⚠ ".join(problems)
        if self.sensor_panel.com_marker.visible and self.sensor_panel.stability:
            text += f"<br>{self.sensor_panel.stability}"
        return text

    def _follow(self) -> None:
        """Keep each page's view on the robot: the camera keeps the offset it had when Follow
        was ticked (the page's own camera reports lag behind a fast robot)."""
        base = np.array(self.lab.sim.data.xpos[self.lab.sim.compiled.root_body])
        for client_id, client in self.server.get_clients().items():
            offset = self.follow_offset.get(client_id)
            if offset is None:
                offset = np.asarray(client.camera.position) - np.asarray(client.camera.look_at)
                self.follow_offset[client_id] = offset
            with client.atomic():
                client.camera.look_at = tuple(base)
                client.camera.position = tuple(base + offset)

    # ----- panels -----------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(dark_mode=False)
        self._status = gui.add_markdown("**sim time** 0.000 s")
        with gui.add_folder("Simulation"):
            self.play = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
            self.play.on_click(lambda _: self.do(self._toggle_pause))
            step = gui.add_button("Step", hint="one physics step")
            step.on_click(lambda _: self.do(lambda: self.step_n(1)))
            self.steps = self.fields.add("Steps", 100, STEPS, lambda v: None)
            step_n = gui.add_button("Step N")
            step_n.on_click(lambda _: self.do(lambda: self.step_n(self.fields.held(self.steps)[0])))
            gui.add_button("Reset model").on_click(lambda _: self.do(self.reset_model))
            gui.add_button("Reset world").on_click(lambda _: self.do(self.reset_world))
            self.rtf = self.fields.add("Real-time factor", self.target_rtf, RTF, self._set_rtf,
                                       hint="0 = as fast as possible")
            self.follow = gui.add_checkbox("Follow robot", False)
            self.follow.on_update(lambda _: self.follow_offset.clear())
            self.paused_after_reset = gui.add_checkbox("Start paused", self.start_paused,
                                                       hint="after a reset, wait for Play "
                                                            "(mexone sim --paused)")
            shot = gui.add_button("Screenshot", icon=viser.Icon.CAMERA,
                                  hint="a PNG of this view as the page draws it (MuJoCo's render "
                                       "if the page sends none), saved as "
                                       "mexone_screenshot_NNN.png in the folder mexone started in")
            shot.on_click(lambda e: self._screenshot_clicked(e.client))
        with gui.add_folder("View"):
            self.overlay_boxes = {}
            for overlay in OVERLAYS:
                box = self.overlay_boxes[overlay] = gui.add_checkbox(overlay, False)
                box.on_update(lambda e, name=overlay: self.do(
                    lambda: self._show_overlay(name, bool(e.target.value))))
            self.transparent = gui.add_checkbox("Transparent", False,
                                                hint="on by itself while Center of Mass or "
                                                     "Inertia shows (they sit inside the links)")
            self.transparent.on_update(lambda e: self.do(self._update_transparency))
            wireframe = gui.add_checkbox("Wireframe", False)
            wireframe.on_update(lambda e: self.do(
                lambda: self.scene.set_wireframe(bool(e.target.value))))
            balance = gui.add_checkbox(BALANCE, False, hint="COM projection (green), ZMP (red), "
                                                            "support polygon (blue), foot forces")
            balance.on_update(lambda e: self.do(
                lambda: self.sensor_panel.show_balance(bool(e.target.value))))
            self.walk_plan_box = gui.add_checkbox(
                WALK_PLAN, False, hint="a walk's footsteps (blue), planned ZMP (orange) and COM "
                                       "(green), measured ZMP (red)")
            self.walk_plan_box.on_update(lambda e: self.do(
                lambda: self.walk_plan.show(bool(e.target.value))))
        self._build_joints()
        self._build_plots()
        self.step_response = StepResponse(self.server, self.lab, self.do, self.fields.add,
                                          on_start=self._plot_step)
        self.inspector = Inspector(self.server, self.lab, self.do, self.fields,
                                   joints_shown=lambda: bool(self.overlay_boxes["Joints"].value))
        with self.inspector.folder:
            self.move = MoveTool(self.server, self.lab, self.do)
        self.sensor_panel = SensorPanel(self.server, self.lab, self.log)
        self._build_routines()
        self._build_physics()
        for name, panel in self.panels.items():
            self._panel_call(name, panel.build)
        self.walk_pad = WalkPad(self.server, self.lab, self.do)
        self.walk_plan = WalkPlanView(self.server, self.lab)
        self.ik_handles = IkHandles(self.server, self.lab, self.do)

    def _panel_call(self, name: str, method: Callable[[], None]) -> None:
        """A plug-in panel's build or update: one that raises is said once and left out (a
        panel's bug never ends the simulation)."""
        try:
            method()
        except Exception as exc:  # noqa: BLE001 - any panel's bug; the lab goes on
            self._failed_panels.add(name)
            text = exc.one_line() if isinstance(exc, MexoneError) else f"{type(exc).__name__}: {exc}"
            log.error("the %s panel stopped: %s", name, text)

    @property
    def controllers_panel(self):
        """The Controllers panel (gui/controllers.py)."""
        return self.panels["controllers"]

    @property
    def topics_panel(self):
        """The Topics panel (gui/topics.py)."""
        return self.panels["topics"]

    @property
    def record_panel(self):
        """The Record panel (gui/topics.py)."""
        return self.panels["record"]

    @property
    def load_panel(self):
        """The Load robot panel (gui/load.py)."""
        return self.panels["load"]

    def _screenshot_clicked(self, client) -> None:
        if client is None:
            return
        camera = client.camera
        view = (np.asarray(camera.position), np.asarray(camera.look_at), float(camera.fov))
        # the page reports its canvas size: a page could claim any, so at most MAX_PAGE_RENDER
        size = tuple(min(int(v), MAX_PAGE_RENDER) for v in (camera.image_height, camera.image_width))
        # asking the page blocks until it answers: never in viser's or the simulation's thread
        threading.Thread(target=self._page_screenshot, args=(client, size, view), daemon=True,
                         name="screenshot").start()

    def _page_screenshot(self, client, size: tuple[int, int], view) -> None:
        """The page's own picture if it sends one, else MuJoCo's render of the same view."""
        picture = None
        if min(size) > 0:
            try:
                picture = page_picture(client.camera.get_render(
                    *size, transport_format="png", timeout=PAGE_RENDER_SECONDS))
            except Exception as exc:  # noqa: BLE001 - a closed or silent page: use the fallback
                log.info("screenshot: the page sent no picture (%s); rendering it here", exc)
        if picture is None:
            self.do(lambda: self.screenshot(*view))
        else:
            self.do(lambda: self._saved(self.screenshots.write(picture)))

    def screenshot(self, position, look_at, fov: float) -> Path:
        """Simulation thread: render this view offscreen and save a new numbered PNG."""
        return self._saved(self.screenshots.save(self.lab.sim, position, look_at, fov))

    def _saved(self, path: Path) -> Path:
        self.last_screenshot = path
        self.notify("Screenshot", f"saved {path.name} in {path.parent}", color="green")
        return path

    # ----- Load: another robot, same server ----------------------------------------------------
    def load(self, path: Path | None, controllers: Path | str = AUTO,
             spawn: Spawn | None = None) -> None:
        """Simulation thread: open the robot in `path` (None: the robot loaded now, again) with
        controllers from its physics (or the `controllers` YAML) and rebuild the scene and every
        panel. A file that fails to load changes nothing."""
        if self.tick_hooks:
            raise MexoneError("Load: not while joined to ROS (--ros): the ROS graph knows this "
                              "robot", hint="restart mexone sim with the other robot")
        if self.lab.bus.taps and self.record_panel.recorder is None:
            raise MexoneError("Load: not while --record records this robot",
                              hint="stop mexone sim (the bag closes), then open the other robot")
        lab = Lab.create(model=self.lab.sim.robot if path is None else path,
                         controllers=controllers, world=self.lab.sim.compiled.world,
                         spawn=spawn or Spawn(), options=self.options,
                         target_rtf=self.target_rtf or None)
        self.stop_routine()
        for panel in self.panels.values():
            panel.unload()  # Record ends its recording, Topics its echo
        self.log.close()
        self.walk_plan.close()
        self.ik_handles.close(join=0)  # this is the simulation thread, which its worker may await
        self.screenshots.close()
        for camera in self.sensor_panel.cameras.values():
            if camera.renderer is not None:
                camera.renderer.close()
                camera.renderer = None
        self.lab = lab
        self.model_label = self.model_label if path is None else path.name
        self.steps_left, self.error = 0, None
        self.follow_offset.clear()
        self.server.scene.reset()
        self.server.gui.reset()
        self._build_all()
        self.notify("Loaded", f"{lab.sim.robot.name} from {self.model_label} ("
                    + ("controllers from its physics)" if controllers == AUTO else
                       f"controllers of {Path(controllers).name})"), color="green")
        if (self.start_paused or self.paused_after_reset.value) and not self.lab.sim.paused:
            self._toggle_pause()

    def _show_overlay(self, name: str, on: bool) -> None:
        self.scene.show(name, on)
        self._update_transparency()

    def _update_transparency(self) -> None:
        inside = any(self.overlay_boxes[k].value for k in ("Center of Mass", "Inertia"))
        self.scene.set_transparent(bool(self.transparent.value) or inside)

    def step_n(self, n: float) -> None:
        """Gazebo's step button: n physics steps, spread over frames."""
        n = STEPS.check(n, "Steps:")
        if not self.lab.sim.paused:
            self._toggle_pause()
        self.steps_left = n

    def _toggle_pause(self) -> None:
        sim = self.lab.sim
        self.steps_left = 0  # pausing (or playing) interrupts Step N
        sim.rtf.clear()  # no stale real-time factor from before
        if sim.paused:
            sim.resume()
            self.play.label, self.play.icon = "Pause", viser.Icon.PLAYER_PAUSE
        else:
            sim.pause()
            self.play.label, self.play.icon = "Play", viser.Icon.PLAYER_PLAY

    def _set_rtf(self, value: float) -> None:
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
                gui.add_markdown(self.lab.no_controllers or "No controllers loaded.")
                return
            self.units = gui.add_dropdown("Units", ("rad", "deg"), initial_value="rad")
            self.units.on_update(lambda _: self.do(self._rescale_sliders))
            gui.add_button("Home", hint="every position controller to 0").on_click(
                lambda _: self.do(self.home))
            for ctrl in manager.controllers.values():
                if ctrl.kind == "trajectory":
                    gui.add_markdown(f"`{ctrl.name}`: send JointTrajectory messages from a routine")
                if ctrl.sliders:
                    for index, joint in enumerate(ctrl.joints):
                        self._add_slider(ctrl, index, joint)
        with gui.add_folder("Gains", expand_by_default=False):
            for ctrl in manager.controllers.values():
                if ctrl.gains is not None and ctrl.kind == "position":
                    self._add_gains(ctrl)

    def _scale(self, ctrl: Controller) -> float:
        """Slider units per command unit (degrees for angles when asked)."""
        return 180.0 / math.pi if ctrl.unit == "rad" and self.units.value == "deg" else 1.0

    def _add_slider(self, ctrl: Controller, index: int, joint: str) -> None:
        lo, hi = ctrl.command_range(index)
        slider = self.server.gui.add_slider(f"{joint}", min=round(lo, 4), max=round(hi, 4),
                                            step=0.001, initial_value=0.0,
                                            hint=f"{ctrl.name} ({ctrl.unit})")
        self.sliders[(ctrl.name, joint)] = slider

        def moved(event) -> None:
            if event.client is None:  # our own syncs are not commands
                return
            value = event.target.value  # now: a sync may change the slider before we run
            self._touched[(ctrl.name, joint)] = time.monotonic()

            def send() -> None:
                number = float(value) / self._scale(ctrl)
                lo, hi = ctrl.command_range(index)
                if not (math.isfinite(number) and lo - 1e-9 <= number <= hi + 1e-9):
                    raise InputError(f"{joint}: {number_text(value)} is outside {number_text(lo)} to "
                                     f"{number_text(hi)} {ctrl.unit}")
                self.lab.controllers.command(ctrl.name, {joint: number})

            self.do(send)

        slider.on_update(moved)

    def _rescale_sliders(self) -> None:
        manager = self.lab.controllers
        for (name, joint), slider in self.sliders.items():
            ctrl = manager.controllers[name]
            index = ctrl.joints.index(joint)
            lo, hi = ctrl.command_range(index)
            f = self._scale(ctrl)
            slider.min, slider.max, slider.step = round(lo * f, 4), round(hi * f, 4), 0.001 * f
            slider.value = float(ctrl.setpoint[index]) * f

    def _sync_sliders(self) -> None:
        """Show what the controllers are commanded, whoever commanded it."""
        if not self.sliders:
            return
        manager = self.lab.controllers
        now = time.monotonic()
        for (name, joint), slider in self.sliders.items():
            if now - self._touched.get((name, joint), -1e9) < 1.0:
                continue  # do not fight a hand on the slider
            ctrl = manager.controllers[name]
            value = round(float(ctrl.setpoint[ctrl.joints.index(joint)]) * self._scale(ctrl), 3)
            if abs(slider.value - value) > 1e-3:
                slider.value = value

    def home(self) -> None:
        """Every position controller's joints to 0."""
        manager = self.lab.controllers
        for ctrl in manager.controllers.values():
            if ctrl.running and ctrl.kind == "position":
                manager.command(ctrl.name, [0.0] * len(ctrl.joints))

    def _add_gains(self, ctrl: Controller) -> None:
        gui = self.server.gui
        gains = ctrl.gains[0]
        label = joint_label(ctrl.name)
        with gui.add_folder(label, expand_by_default=False):
            for key in ("p", "i", "d"):
                self.fields.add(f"{key} ({label})", float(getattr(gains, key)), GAINS[key],
                                lambda v, c=ctrl, k=key: self._set_gain(c, k, v))

    def _set_gain(self, ctrl: Controller, key: str, value: float) -> None:
        gains = [replace(g, **{key: value}) for g in ctrl.gains]
        self.lab.controllers.set_gains(ctrl.name, gains)

    # ----- plots --------------------------------------------------------------------------------
    def _build_plots(self) -> None:
        joint = "l_elbow" if "l_elbow/command" in self.log.index else \
            self.log.signals[0].name.split("/")[0]
        defaults = [[f"{joint}/command", f"{joint}/position"], [f"{joint}/effort"]]
        defaults = [[n for n in pane if n in self.log.index] for pane in defaults]
        self.plot_panel = PlotPanel(self.server, self.log, self.do, self.refuse, self.fields.add,
                                    defaults)

    def _plot_step(self, joint: str) -> None:
        """The step-response helper shows its joint in pane 1."""
        names = [n for n in (f"{joint}/command", f"{joint}/position") if n in self.log.index]
        self.plot_panel.show(0, names)

    # ----- routines -----------------------------------------------------------------------------
    def _build_routines(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Routines"):
            self.routine_files = routine_choices(self.routine_dirs) | self.extra_routines
            names = tuple(self.routine_files)
            self.routine_choice = gui.add_dropdown("Routine", names, initial_value=names[0],
                                                   hint="shipped routines and the .py files of "
                                                        "the folders mexone sim --routines named")
            gui.add_button("Refresh list").on_click(lambda _: self.do(self.refresh_routines))
            start = gui.add_button("Start", icon=viser.Icon.PLAYER_PLAY)
            start.on_click(lambda _: self.do(self.start_routine))
            stop = gui.add_button("Stop", icon=viser.Icon.PLAYER_STOP)
            stop.on_click(lambda _: self.do(self.stop_routine))
            self.console_view = gui.add_markdown("*console: no routine yet*")

    def refresh_routines(self) -> None:
        self.routine_files = routine_choices(self.routine_dirs) | self.extra_routines
        self.routine_choice.options = tuple(self.routine_files)

    def _log(self, level: str, text: str) -> None:
        self.console.append(f"[{level}] [{self.lab.sim.time:.3f}] {text}")
        self.console_view.content = "```\n" + "\n".join(self.console) + "\n```"

    def start_routine(self) -> None:
        if self.lab.controllers is None:
            raise MexoneError("no controllers loaded: a routine has nothing to command")
        choice = self.routine_choice.value
        path = self.routine_files.get(choice)  # never a path the page made up
        if path is None:
            raise InputError(f"'{choice}' is not one of the routines this server offers",
                             hint="pick one from the list (mexone sim --routines DIR adds a folder)")
        self.stop_routine()
        self.console.clear()
        self.routine = RoutineRunner(self.lab, path, log=self._log, poll=1.0 / FPS)
        self.routine.start()
        self._log("INFO", f"started {self.routine.path.name}")

    def stop_routine(self) -> None:
        if self.routine is not None:
            self.routine.stop(join=0.5)
            self._routine_done()

    def _routine_done(self) -> None:
        runner, self.routine = self.routine, None
        runner.stop(join=0.5)
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
            self.gravity = self.fields.add("Gravity (m/s²)", [float(g) for g in model.opt.gravity],
                                           GRAVITY, self._apply_gravity, hint="x, y, z")
            self.timestep = self.fields.add("Time step (s)", float(model.opt.timestep), TIMESTEP,
                                            self.lab.sim.set_timestep)
            self.self_collide = gui.add_checkbox("Self-collision", self.options.self_collision
                                                 is not False, hint="applies at Reset world")

    def _apply_gravity(self, gravity: list[float]) -> None:
        self.lab.sim.model.opt.gravity[:] = gravity

    def reset_model(self) -> None:
        """Robot back to its spawn pose at home, sim time 0; controllers restart, holding home."""
        self.stop_routine()
        self.steps_left = 0
        self.lab.sim.reset()
        for slider in self.sliders.values():
            slider.value = 0.0
        self.log.clear()
        self.error = None
        if self.paused_after_reset.value and not self.lab.sim.paused:
            self._toggle_pause()

    def reset_world(self) -> None:
        """Reset, with the Physics panel's settings (self-collision included) applied."""
        self.lab.sim.set_self_collision(None if self.self_collide.value else False)
        self.options = replace(self.options, self_collision=None if self.self_collide.value else False)
        self.reset_model()
