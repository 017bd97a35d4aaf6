"""GuiApp: `mexone sim`'s web page (viser), what Gazebo's window was to the seed, and more: the
frame loop, the message plumbing and Load; everything on the page is a panel (gui/panels.py: one
registry, the shipped panels and a package's alike), and GuiApp the `PanelHost` they talk to.
The simulation runs in the thread that calls `serve_forever`, paced to the real-time factor;
viser serves the page from its own threads. Everything a page does to the simulation is queued
(`self.work`) and runs between frames in the simulation thread, so a slow, closed or tenth tab
never touches the physics. Every value a page sends is checked on the server: a page is not
trusted to respect its own widgets' limits (see also gui/security.py).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

import viser

from mexone import signals
from mexone.errors import MexoneError
from mexone.gui.fields import NumberFields
from mexone.gui.health import Health
from mexone.gui.panels import FPS, PageSettings, Panel, panel_types
from mexone.gui.plots import SignalLog
from mexone.gui.scene import RobotScene
from mexone.gui.security import LabAccess, guard, lab_access, warn_if_exposed
from mexone.lab import AUTO, Lab
from mexone.physics.compile import CompileOptions, Spawn
from mexone.physics.divergence import DivergenceError
from mexone.physics.simulation import Simulation, WorkQueue
from mexone.ranges import STEPS
from mexone.routines.runner import RoutineRunner

__all__ = ["GuiApp", "FPS", "MAX_STEPS"]

log = logging.getLogger(__name__)

TICK = 0.001  # s of sim time between tick hooks (the ROS bridge's /clock)
MAX_STEPS = int(STEPS.high)  # Step N at most (a page could send anything): ranges.STEPS
STEP_BUDGET = 0.025  # s of wall time per frame spent on Step N, so the page stays live


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
        """`server`: draw into that page (guarded by its owner, who stops it) instead of serving
        one (the editor's Simulate). `exercise`: an ExerciseTarget (gui/exercises.py). `access`:
        who may open the page (default: as the environment says; gui/security.py)."""
        self.options = options
        self.lab = make_lab(options)
        self.target_rtf, self.lab.sim.target_rtf = target_rtf, target_rtf or None
        self.settings = PageSettings(Path.cwd() if model_folder is None else model_folder,
                                     record_folder, routine_dirs, paused, exercise)
        self.pause_after_reset, self.model_label = paused, self.lab.sim.robot.name
        self.owns_server = server is None
        self.server = server or viser.ViserServer(host=host, port=port, label="mexone", verbose=False)
        self.access = access or lab_access()
        if self.owns_server:
            guard(self.server, self.access)
            warn_if_exposed(host, self.server.get_port())
        self.work, self.stopping = WorkQueue(), threading.Event()
        self.routine: RoutineRunner | None = None  # the Routines panel's, run in lockstep
        self.console: deque[str] = deque(maxlen=14)
        self.error: str | None = None
        self.refusals: deque[str] = deque(maxlen=20)  # what the page asked for and was refused
        self.steps_left, self._frames = 0, 0  # Step N in progress (a budget per frame); frames
        self.tick_hooks: list[Callable] = []  # run every TICK of sim time (the ROS bridge)
        self.extra_routines: dict[str, Path] = {}  # routines a panel offers (an exercise's)
        self.panels: dict[str, Panel] = {}  # one instance each for the page's life, built in order
        self._failed_panels: set[str] = set()
        for cls in panel_types():
            self._panel_call(cls.name, lambda c=cls: c.wanted(self) and self.panels.update(
                {c.name: c(self)}))
        self._build_all()
        logging.getLogger("mexone").addHandler(_GuiLog(self))
        camera = self.server.initial_camera  # a 1 m robot fills half the view
        camera.fov, camera.position, camera.look_at = math.radians(45.0), (1.3, -1.35, 0.95), (0, 0, 0.52)
        if paused:
            self.toggle_pause()

    def _build_all(self) -> None:
        """The scene and every panel, for the robot in self.lab (at start and after Load)."""
        self.scene = RobotScene(self.server, self.lab.sim)
        self.scene.build()
        self.log = SignalLog(self.lab)
        self.health = Health(self.lab.sim, self.log)
        self.fields = NumberFields(self.server.gui, self.refuse)
        self.server.gui.configure_theme(dark_mode=False)
        self._status = self.server.gui.add_markdown("**sim time** 0.000 s")
        for name, panel in self.panels.items():
            self._panel_call(name, panel.build)

    def panel(self, name: str) -> Panel | None:
        """The panel called `name` on this page, if it is here and working."""
        return None if name in self._failed_panels else self.panels.get(name)

    def _panel_call(self, name: str, method: Callable[[], object], always: bool = False) -> None:
        """A panel's build, update or hook: one that raises is said once and left out (a
        panel's bug never ends the simulation); `always`: a hook that ends what it started
        (unload, reset, stop), called on a panel left out too."""
        if name in self._failed_panels and not always:
            return
        try:
            method()
        except Exception as exc:  # noqa: BLE001 - any panel's bug; the lab goes on
            if name not in self._failed_panels:
                self._failed_panels.add(name)
                text = exc.one_line() if isinstance(exc, MexoneError) else \
                    f"{type(exc).__name__}: {exc}"
                log.error("the %s panel stopped: %s", name, text)

    def _each_panel(self, hook: str, *args) -> None:  # a hook that ends what a panel started
        for name, panel in self.panels.items():
            self._panel_call(name, lambda p=panel: getattr(p, hook)(*args), always=True)

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
                tick = min(frame, TICK) if self.tick_hooks else frame  # log: its own timer
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

    def _tick(self, sim: Simulation) -> None:
        for hook in self.tick_hooks:
            hook(sim)

    def stop(self) -> None:
        self.stopping.set()
        logger = logging.getLogger("mexone")
        for handler in [h for h in logger.handlers if isinstance(h, _GuiLog) and h.app is self]:
            logger.removeHandler(handler)
        self._each_panel("stop")  # the page goes back to an owner (the editor) without them
        if self.owns_server:
            self.server.stop()

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
        # no viser batch around a frame: its end would wake viser's loop even when nothing
        # changed (most frames of a standing robot), twice the cost of the messages it saves
        self._frames += 1
        self.fields.commit()
        self.scene.update()
        if self.log.due(self.lab.sim.time):  # the first sample (paused), one after a reset
            self.log.sample()
        for problem in self.health.check():
            self.notify("Simulation problem", problem, color="orange")
        if self._frames % 5 == 0 and not self.error:
            self._status.content = self.status_text()
        for name, panel in self.panels.items():
            if self._frames % panel.period == 0:
                self._panel_call(name, panel.update)

    def status_text(self) -> str:
        """The status line: what the simulation is doing, whatever is wrong with it, and what
        the panels add (the Sensors panel: whether the robot is statically stable)."""
        sim = self.lab.sim
        state = "**paused** (real-time factor 0)" if sim.paused else \
            f"running at real-time factor {sim.rtf.value:4.2f}"
        lines = [f"**sim time** {sim.time:8.3f} s &nbsp; {state}"]
        lines += ["⚠ " + problem for problem in self.health.problems]
        for name, panel in self.panels.items():
            self._panel_call(name, lambda p=panel: lines.append(p.status_line() or ""))
        return "<br>".join(line for line in lines if line)

    # ----- what the panels ask of the page (simulation thread) ---------------------------------
    def step_n(self, n: float) -> None:
        """Gazebo's step button: n physics steps, spread over frames."""
        n = STEPS.check(n, "Steps:")
        if not self.lab.sim.paused:
            self.toggle_pause()
        self.steps_left = n

    def toggle_pause(self) -> None:
        sim = self.lab.sim
        self.steps_left = 0  # pausing (or playing) interrupts Step N
        sim.rtf.clear()  # no stale real-time factor from before
        sim.resume() if sim.paused else sim.pause()

    def reset_model(self, world: bool = False) -> None:
        """Robot back to its spawn pose at home, sim time 0; controllers restart, holding home."""
        self._each_panel("reset", world)  # a routine stops; Reset world applies the Physics panel
        self.steps_left = 0
        self.lab.sim.reset()
        self.log.clear()
        self.error = None
        if self.pause_after_reset and not self.lab.sim.paused:
            self.toggle_pause()

    def reset_world(self) -> None:
        """Reset, with the Physics panel's settings (self-collision included) applied."""
        self.reset_model(world=True)

    # ----- Load: another robot, same server ----------------------------------------------------
    def load(self, path: Path | None, controllers: Path | str = AUTO,
             spawn: Spawn | None = None) -> None:
        """Simulation thread: open the robot in `path` (None: the robot loaded now, again) with
        controllers from its physics (or the `controllers` YAML) and rebuild the scene and every
        panel. A file that fails to load changes nothing."""
        if self.tick_hooks:
            raise MexoneError("Load: not while joined to ROS (--ros): the ROS graph knows this "
                              "robot", hint="restart mexone sim with the other robot")
        record = self.panel("record")
        if self.lab.bus.taps and getattr(record, "recorder", None) is None:
            raise MexoneError("Load: not while --record records this robot",
                              hint="stop mexone sim (the bag closes), then open the other robot")
        lab = Lab.create(model=self.lab.sim.robot if path is None else path,
                         controllers=controllers, world=self.lab.sim.compiled.world,
                         spawn=spawn or Spawn(), options=self.options,
                         target_rtf=self.target_rtf or None)
        self._each_panel("unload")  # a routine stops, Record ends its recording, Topics its echo
        self.log.close()
        self.lab.sensors.close()  # the cameras' renderers belong to the old model
        self.lab = lab
        self.model_label = self.model_label if path is None else path.name
        self.steps_left, self.error = 0, None
        self.server.scene.reset()
        self.server.gui.reset()
        self._build_all()
        self.notify("Loaded", f"{lab.sim.robot.name} from {self.model_label} ("
                    + ("controllers from its physics)" if controllers == AUTO else
                       f"controllers of {Path(controllers).name})"), color="green")
        if (self.settings.start_paused or self.pause_after_reset) and not self.lab.sim.paused:
            self.toggle_pause()
