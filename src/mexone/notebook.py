"""The lab in Jupyter: the live page beside a notebook, and an inline replay of what a cell
simulated that a saved notebook's HTML still plays (viser's self-contained scene export, drawn
by the browser: no GPU, no server).

`simulate(lab, seconds)` runs the simulation with a notebook progress bar and records the bodies'
poses; `Replay.show()` (or a Replay as a cell's last value) draws them with a time slider.
`serve(lab)` starts `mexone sim`'s web page for a Lab made in the notebook, in a thread of its
own: from then on that thread alone touches MuJoCo state, and the notebook hands it work with
`LivePage.call` until `LivePage.stop()`."""

from __future__ import annotations

import contextlib
import html
import io
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import mujoco
import numpy as np

from mexone.errors import InputError
from mexone.lab import Lab
from mexone.ranges import PORT, REPLAY_FPS, REPLAY_SECONDS, RTF

__all__ = ["Replay", "simulate", "record", "LivePage", "serve"]

_CHUNK = 0.05  # s of sim time between progress-bar updates


@dataclass(repr=False)
class Replay:
    """What a cell simulated: the generalised positions `qpos[i]` at sim times `times[i]` (s),
    for the lab's model. Shown inline by `show()`, or by being a cell's last value."""

    lab: Lab
    fps: float
    times: list[float] = field(default_factory=list)
    qpos: list[np.ndarray] = field(default_factory=list)

    def __repr__(self) -> str:  # a cell's text output, print(): not every frame's qpos
        return f"Replay({len(self.times)} frames over {self.duration:.3f} s at {self.fps:g} fps)"

    def sample(self, sim) -> None:
        """Record the state now (the simulation thread calls it, between steps)."""
        self.times.append(float(sim.time))
        self.qpos.append(np.array(sim.data.qpos, copy=True))

    @property
    def duration(self) -> float:
        """The replay's length in seconds of sim time."""
        return self.times[-1] - self.times[0] if self.times else 0.0

    def scene_html(self, dark_mode: bool = False) -> str:
        """A self-contained HTML page that plays the recording (viser's client and the scene,
        embedded): open it anywhere, or save it."""
        if not self.times:
            raise InputError("nothing recorded yet", hint="simulate(lab, seconds) first")
        import viser

        from mexone.gui.scene import RobotScene

        sim = self.lab.sim
        data = mujoco.MjData(sim.model)  # the replay's own state: the live one stays untouched
        ghost = SimpleNamespace(robot=sim.robot, compiled=sim.compiled, model=sim.model, data=data)
        with _quiet_viser():  # its banner names a port no page is served on
            server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
        try:
            self._pose(data, 0)
            scene = RobotScene(server, ghost)  # type: ignore[arg-type]  # a Simulation's fields
            scene.build()
            base = data.xpos[1] if sim.model.nbody > 1 else np.zeros(3)  # the first link's start
            server.initial_camera.fov = math.radians(45.0)  # as the live page: the robot fills half
            server.initial_camera.position = tuple(base + (1.3, -1.35, 0.45))
            server.initial_camera.look_at = tuple(base + (0.0, 0.0, 0.02))
            recorder = server.get_scene_serializer()
            scene.update(everything=True)  # frame 0 again, as messages at t = 0: where each loop starts over
            for i in range(1, len(self.times)):
                recorder.insert_sleep(self.times[i] - self.times[i - 1])
                self._pose(data, i)
                scene.update()
            return recorder.as_html(dark_mode=dark_mode)
        finally:
            with _quiet_viser():
                server.stop()

    def _pose(self, data: mujoco.MjData, i: int) -> None:
        data.qpos[:] = self.qpos[i]
        mujoco.mj_kinematics(self.lab.sim.model, data)

    def html(self, height: int = 420) -> str:
        """The replay as an iframe for a notebook's output (kept in a saved notebook's HTML)."""
        page = html.escape(self.scene_html(), quote=True)
        return (f'<div class="mexone-replay" style="border:1px solid #ddd">'
                f'<iframe srcdoc="{page}" width="100%" height="{int(height)}" '
                f'style="border:none;display:block"></iframe></div>')

    def _repr_html_(self) -> str:
        return self.html()

    def show(self, height: int = 420) -> None:
        """Draw the replay in the notebook's output (IPython's display)."""
        from IPython.display import HTML, display

        display(HTML(self.html(height)))


@contextlib.contextmanager
def _quiet_viser():
    """viser's banners (the server's address when it starts, "Server stopped") kept out of the
    cell's output, which a saved notebook keeps: viser prints them with rich, whose console in
    Jupyter writes through IPython's display, past any redirect of stdout. Muted for the block
    (rich's shared console: another thread's rich output meanwhile is muted too)."""
    import rich

    console = rich.get_console()
    was, console.quiet = console.quiet, True
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            yield
    finally:
        console.quiet = was


class record:  # noqa: N801 - used as a context manager, like open()
    """`with record(lab) as replay: ...`: record the robot at `fps` while the block simulates
    (whatever runs the simulation: `lab.sim.run`, a routine, a design check)."""

    def __init__(self, lab: Lab, fps: float = 30.0):
        self.replay = Replay(lab, REPLAY_FPS.check(fps, "record: fps"))
        self._timer = None

    def __enter__(self) -> Replay:
        sim = self.replay.lab.sim
        self.replay.sample(sim)
        self._timer = sim.add_periodic(1.0 / self.replay.fps, self.replay.sample)
        return self.replay

    def __exit__(self, *exc) -> None:
        self.replay.lab.sim.remove_periodic(self._timer)


def simulate(lab: Lab, seconds: float, fps: float = 30.0, progress: bool = True) -> Replay:
    """Simulate `seconds` of sim time (as fast as the machine allows unless the lab has a target
    real-time factor), with a progress bar that suits where it runs (tqdm.auto: a widget in
    Jupyter, text in a terminal), and return the replay."""
    from tqdm.auto import tqdm

    seconds = REPLAY_SECONDS.check(seconds, "simulate: seconds")
    if getattr(lab, "_live_page", None) is not None:
        raise InputError("this lab is served by a live page: its thread runs the simulation",
                         hint="use page.call(...) or page.stop() first")
    with record(lab, fps) as replay, tqdm(total=round(seconds, 3), unit="s", disable=not progress,
                                          desc="simulating", leave=False) as bar:
        start = lab.sim.time
        while lab.sim.time - start < seconds - 1e-9:
            lab.sim.run(min(_CHUNK, seconds - (lab.sim.time - start)))
            bar.update(round(lab.sim.time - start - bar.n, 3))
    return replay


@dataclass
class LivePage:
    """`mexone sim`'s web page for a notebook's Lab, its simulation in a thread of its own."""

    app: Any  # mexone.gui.app.GuiApp
    thread: threading.Thread
    url: str

    def call(self, action: Callable[[], Any], timeout: float = 60.0) -> Any:
        """Run `action()` in the simulation thread between frames and return what it returns
        (or raise what it raised): how a notebook reads or changes the live robot."""
        if not self.thread.is_alive():
            raise InputError("the live page has stopped", hint="serve(lab) again")
        done: Future = Future()

        def run() -> None:
            try:
                done.set_result(action())
            except BaseException as exc:  # noqa: BLE001 - handed back to the notebook's cell
                done.set_exception(exc)

        self.app.do(run)
        return done.result(timeout)

    def __enter__(self) -> LivePage:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def stop(self) -> None:
        """Stop the page and its simulation thread; the lab is the notebook's again."""
        self.app.stopping.set()  # the loop ends its frame, then the page closes
        self.thread.join(timeout=10.0)
        with _quiet_viser():
            self.app.stop()
        self.app.lab._live_page = None

    @property
    def running(self) -> bool:
        """Whether the page's simulation loop runs."""
        return self.thread.is_alive()

    def _repr_html_(self) -> str:
        state = "running" if self.running else "stopped"
        url = html.escape(self.url, quote=True)
        return f'<p>mexone live page ({state}): <a href="{url}" target="_blank">{url}</a></p>'


def serve(lab: Lab, port: int = 0, host: str = "127.0.0.1", rtf: float = 1.0,
          paused: bool = False) -> LivePage:
    """Serve the web GUI for `lab` (port 0: a free one) and return at once: the simulation runs
    in the page's thread, paced to `rtf` (0: as fast as possible), until `page.stop()`.
    viser runs its own event loop in its own thread, so Jupyter's stays free."""
    from mexone.cli.common import check_can_serve
    from mexone.gui.app import GuiApp
    from mexone.physics.compile import CompileOptions

    rtf = RTF.check(rtf, "serve: rtf")
    port = int(PORT.check(port, "serve: port"))  # else viser's thread dies and serve waits on it
    check_can_serve(host)
    if getattr(lab, "_live_page", None) is not None:
        raise InputError("this lab already has a live page", hint="page.stop() first")
    with _quiet_viser():  # the page's repr says where it is
        app = GuiApp(lambda _options: lab, CompileOptions(), host=host, port=port,
                     target_rtf=rtf, paused=paused)
    thread = threading.Thread(target=app.serve_forever, name="mexone-live-page", daemon=True)
    # inside a JupyterHub: the hub's proxied path with this page's key (gui/security.py)
    page = LivePage(app, thread, app.access.page_url(host, app.server.get_port()))
    lab._live_page = page
    thread.start()
    return page

