"""What many test files share: a free port, waiting on a condition (never a fixed sleep), and
Debian's Chromium driven by Playwright for the page tests."""

from __future__ import annotations

import os
import shutil
import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium")
# headless with software WebGL (SwiftShader): the CI machine has no GPU
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--use-gl=angle", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate: Callable[[], object], timeout: float = 10.0, poll: float = 0.02) -> bool:
    end = time.time() + timeout
    while time.time() < end:
        if predicate():
            return True
        time.sleep(poll)
    return False


@contextmanager
def chromium() -> Iterator:
    """A Playwright browser on Debian's Chromium (the test skips where either is missing; in CI,
    MEXONE_CI turns that skip into a failure)."""
    playwright = pytest.importorskip("playwright.sync_api")
    if CHROMIUM is None:
        pytest.skip("Debian chromium is not installed")
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            yield browser
        finally:
            browser.close()


def pixels(tab) -> np.ndarray:
    """The page as the user sees it now (a screenshot), RGB as int16 (differences stay signed)."""
    import io

    from PIL import Image

    # software WebGL on a loaded machine can keep a frame from the compositor for long
    shot = tab.screenshot(timeout=120_000)
    return np.asarray(Image.open(io.BytesIO(shot)).convert("RGB"), dtype=np.int16)


def robot_drawn(tab) -> bool:
    """The robot's first frame is on a 1280 x 800 page's canvas (dark pixels mid-view)."""
    centre = pixels(tab)[200:600, 500:760]
    return bool((centre.sum(axis=2) < 200).mean() > 0.002)


def wait_for_picture(tab, shows: Callable[[np.ndarray], object], timeout: float = 30.0) -> bool:
    """Until the page's picture `shows` what a test waits for (a gizmo drawn, markers gone): a
    condition, never a guessed sleep, polled at a screenshot's pace (each costs tens of ms of
    software WebGL, more under load)."""
    return wait_until(lambda: shows(pixels(tab)), timeout=timeout, poll=0.2)


def changed_near(before: np.ndarray, point: tuple[float, float], radius: int = 24,
                 threshold: int = 60) -> Callable[[np.ndarray], bool]:
    """A `wait_for_picture` condition: something new is drawn within `radius` CSS pixels of
    `point` (a gizmo's handle arriving where the mouse will grab it)."""
    x, y = int(round(point[0])), int(round(point[1]))
    box = (slice(max(0, y - radius), y + radius), slice(max(0, x - radius), x + radius))
    return lambda now: bool((np.abs(now[box] - before[box]).sum(axis=2) > threshold).any())


def on_screen(tab, server, point) -> tuple[float, float]:
    """Where the first page's camera draws a world point on `tab`, in CSS pixels (three.js: a
    vertical field of view, +z up in viser's world): for mouse clicks and drags in the canvas."""
    cam = next(iter(server.get_clients().values())).camera
    width, height = tab.viewport_size["width"], tab.viewport_size["height"]
    eye, target = np.asarray(cam.position), np.asarray(cam.look_at)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(point) - eye
    depth = d @ forward
    half = np.tan(cam.fov / 2)
    x = (d @ right) / (depth * half * width / height)
    y = (d @ up) / (depth * half)
    return (x + 1) / 2 * width, (1 - y) / 2 * height


def run_cli(argv: list, cwd=None, env: dict[str, str] | None = None) -> tuple[int, str, str]:
    """`mexone ARGV` in this process (the CLI's `main`), in folder `cwd`, without the machine's
    ROS_PACKAGE_PATH (plus `env`): exit code, stdout, stderr. A corpus of cases then costs one
    import of the verbs, not a Python start-up per case."""
    import io
    import logging
    from contextlib import redirect_stderr, redirect_stdout

    from mexone import signals
    from mexone.cli import main

    with pytest.MonkeyPatch.context() as patch, redirect_stdout(io.StringIO()) as out, \
            redirect_stderr(io.StringIO()) as err:
        patch.setattr(signals, "stop_on_signals", lambda: None)  # pytest keeps its handlers
        if cwd is not None:
            patch.chdir(cwd)
        patch.delenv("ROS_PACKAGE_PATH", raising=False)
        for key, value in (env or {}).items():
            patch.setenv(key, value)
        logging.getLogger("mexone").handlers.clear()  # log to `err`
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code
        logging.getLogger("mexone").handlers.clear()
    return code, out.getvalue(), err.getvalue()


def wait_frames(app, frames: int, timeout: float = 20.0) -> bool:
    """Until a GuiApp's simulation thread has finished `frames` more frames: "nothing changes
    while paused" is then shown over loop iterations that ran, not over a guessed wall time."""
    start = app._frames
    return wait_until(lambda: app._frames >= start + frames, timeout=timeout)


FUZZ_EXAMPLES = int(__import__("os").environ.get("MEXONE_FUZZ_EXAMPLES", "0"))


def fuzz(examples: int):
    """hypothesis settings for a property test of hostile input: in CI derandomized, `examples`
    of them; a longer run with fresh ones: MEXONE_FUZZ_EXAMPLES=2000 pytest -m fuzz
    --hypothesis-seed=N."""
    from hypothesis import HealthCheck, settings

    return settings(max_examples=FUZZ_EXAMPLES or examples, derandomize=not FUZZ_EXAMPLES,
                    deadline=None, database=None, suppress_health_check=list(HealthCheck))


def built_panel(cls, server, lab):
    """A GUI panel (gui/panels.py) on its own, outside a page: built for `lab` on `server`, its
    work (`do`) run at once, in the caller's thread."""
    from types import SimpleNamespace

    from mexone.gui.fields import NumberFields
    from mexone.gui.panels import PageSettings
    from mexone.gui.plots import SignalLog

    host = SimpleNamespace(lab=lab, server=server, settings=PageSettings(), do=lambda fn: fn(),
                           refuse=lambda text: None, notify=lambda *a, **k: None,
                           panel=lambda name: None)
    host.fields, host.log = NumberFields(server.gui, host.refuse), SignalLog(lab)
    panel = cls(host)
    panel.build()
    return panel


def sleeping(duration: str) -> list[int]:
    """The pids of live `sleep DURATION` processes: an attack's left-behind programs, found by
    the duration only they sleep."""
    found = []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                words = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
                state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except OSError:
                continue
            if words[:2] == [b"sleep", duration.encode()] and state not in "ZX":
                found.append(int(pid))
    return found
