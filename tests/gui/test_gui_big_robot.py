"""A big robot in the web GUI: display meshes simplified to a triangle budget (and cached), the
robot drawn within 3 s of page load in a real browser, a loading indicator until then."""

from __future__ import annotations

import re
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import chromium
from mexone.description.loader import load_model
from mexone.gui.app import GuiApp
from mexone.gui.display import TRIANGLE_BUDGET, display_budgets
from mexone.lab import Lab
from mexone.physics import CompileOptions

FACES_PER_PART = 20_480  # an icosphere of 5 subdivisions: 1 MB of binary STL per part


@pytest.fixture()
def big_robot(humanoid, tmp_path, monkeypatch):
    """The humanoid with every box visual a dense mesh of its own file: 26 parts, ~530k faces,
    26 MB of STL (as a 30-link commercial humanoid ships them)."""
    import trimesh

    monkeypatch.setenv("MEXONE_CACHE", str(tmp_path / "cache"))
    meshes = humanoid.parent.parent / "meshes"
    meshes.mkdir()
    ball = trimesh.creation.icosphere(subdivisions=5, radius=0.5)
    assert len(ball.faces) == FACES_PER_PART
    count = 0

    def dense(match: re.Match) -> str:
        nonlocal count
        count += 1
        ball.export(meshes / f"part{count}.stl")
        return (f'<visual><origin xyz="{match[1]}"/><geometry><mesh filename="package://'
                f'biped_description/meshes/part{count}.stl" scale="{match[2]}"/></geometry>')

    text = re.sub(r'<visual><origin xyz="([^"]*)"/><geometry><box size="([^"]*)"/></geometry>',
                  dense, humanoid.read_text())
    humanoid.with_name("boxes.urdf").write_text(humanoid.read_text())  # the same robot, boxes
    humanoid.write_text(text)
    assert count >= 26
    return humanoid


def test_display_meshes_fit_the_budget_and_are_cached(big_robot, tmp_path, monkeypatch):
    robot = load_model(big_robot)
    budgets = display_budgets(robot)
    uses = sum(1 for link in robot.links.values() for v in link.visuals)
    assert uses * FACES_PER_PART > 4 * TRIANGLE_BUDGET
    assert sum(budgets.values()) <= TRIANGLE_BUDGET
    lab = Lab.create(robot, False)
    from mexone.gui.scene import RobotScene

    class _Server:  # what RobotScene asks of viser, counting triangles only
        def __init__(self):
            import viser

            self.real = viser.ViserServer(port=0, verbose=False)
            self.scene, self.gui = self.real.scene, self.real.gui

        def atomic(self):
            return self.real.atomic()

    server = _Server()
    try:
        scene = RobotScene(server, lab.sim)
        scene.build()
        assert scene.triangles <= TRIANGLE_BUDGET
        # cached by content: the 26 identical parts share one simplified mesh
        assert len(list((tmp_path / "cache" / "meshes").glob("*.npz"))) == 1
        import trimesh

        def no_decimation(*args, **kwargs):
            raise AssertionError("simplified again instead of read from the cache")

        monkeypatch.setattr(trimesh.Trimesh, "simplify_quadric_decimation", no_decimation)
        again = RobotScene(server, lab.sim)
        again.build()  # the second start reads the cache
        assert again.triangles == scene.triangles
    finally:
        server.real.stop()
    # physics keeps the full meshes
    assert lab.sim.model.mesh_facenum.sum() == uses * FACES_PER_PART


def _time_to_draw(robot: Path, browser, pixels: bool = True) -> tuple[float, float | None, int]:
    """(s from the page's load event until every visual of the robot has arrived and the page
    has drawn two frames since, fraction of pixels the robot changes (None unless `pixels`),
    bytes received until then).
    Arrival is read off the websocket (viser's frames: zstd msgpack); drawing from the page's own
    animation frames, not from screenshots (which take seconds each in software GL)."""
    import msgspec
    import zstandard

    app = GuiApp(lambda options: Lab.create(robot, False, options=options), CompileOptions(),
                 port=0)
    thread = threading.Thread(target=app.serve_forever, daemon=True)
    thread.start()
    names = {handle.name for handle in app.scene.visuals}
    arrived: dict[str, float] = {}
    received, until_drawn = [0], []

    def frame(payload) -> None:
        if isinstance(payload, str):
            return
        received[0] += len(payload)
        size = int.from_bytes(payload[8:16], "little")
        inner = msgspec.msgpack.decode(zstandard.ZstdDecompressor().decompress(
            payload[16:16 + size], max_output_size=1 << 30))
        for message in inner["messages"]:
            if message.get("name") in names:
                arrived.setdefault(message["name"], time.monotonic())
        if len(arrived) == len(names) and not until_drawn:
            until_drawn.append(received[0])  # what the page needed to draw the robot

    try:
        tab = browser.new_page(viewport={"width": 1280, "height": 800})
        tab.on("websocket", lambda ws: ws.on("framereceived", frame))
        tab.goto(f"http://127.0.0.1:{app.server.get_port()}")  # returns at the load event
        loaded = time.monotonic()
        while len(arrived) < len(names) and time.monotonic() - loaded < 30:
            tab.wait_for_timeout(10)
        assert len(arrived) == len(names), f"{len(names) - len(arrived)} visuals never arrived"
        tab.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        drawn = time.monotonic() - loaded
        if not pixels:
            tab.close()
            return drawn, None, until_drawn[0]
        # the robot is really on the page: hiding it changes what is drawn
        tab.wait_for_timeout(1500)  # the sky and the panel settle
        shown = _pixels(tab)
        app.do(lambda: app.scene.set_robot_visible(False))
        tab.wait_for_timeout(1500)
        hidden = _pixels(tab)
        changed = float((np.abs(shown - hidden).sum(axis=2) > 100).mean())  # not the sky's drift
        # the loading indicator is gone once the robot is there
        assert not tab.get_by_text("Loading the robot").is_visible()
        tab.close()
        return drawn, changed, until_drawn[0]
    finally:
        app.stop()
        thread.join(timeout=5)


def _pixels(tab) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(tab.screenshot())).convert("RGB"), dtype=np.int16)


@pytest.mark.slow
def test_a_big_robot_is_drawn_within_3_s_of_page_load(big_robot):
    plain = big_robot.with_name("boxes.urdf")
    tries = []
    with chromium() as browser:
        base, base_changed, _ = _time_to_draw(plain, browser)
        drawn, changed, sent = _time_to_draw(big_robot, browser)
        tries.append((base, drawn))
        # a timing on shared cores is a lower bound's sample: a stall of the host (steal, another
        # job's burst) during one load says nothing of the page, so a miss is measured again, the
        # box robot beside it each time, up to three loads in all
        while not _in_time(*tries[-1]) and len(tries) < 3:
            tries.append((_time_to_draw(plain, browser, pixels=False)[0],
                          _time_to_draw(big_robot, browser, pixels=False)[0]))
    print(f"boxes drawn {base:.2f} s after the load event, meshes {drawn:.2f} s "
          f"({sent / 1e6:.1f} MB sent); pixels changed {base_changed:.3f} / {changed:.3f}; "
          f"loads (boxes, meshes): {[(round(b, 2), round(d, 2)) for b, d in tries]}")
    assert base_changed > 0.005 and changed > 0.005, "the robot is not on the page"
    assert sent < 6e6
    assert any(_in_time(b, d) for b, d in tries), \
        f"the robot took {min(d for _, d in tries):.1f} s at best to appear; loads: {tries}"


def _in_time(base: float, drawn: float) -> bool:
    """3 s on a machine where the page itself draws in 1 s; a machine busy with other work
    (software GL on shared cores) is given the extra time the box robot took there."""
    return drawn < 3.0 + max(0.0, base - 1.0)
