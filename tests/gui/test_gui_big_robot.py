"""A big robot in the web GUI: display meshes simplified to a triangle budget (and cached), the
robot drawn within 3 s of page load in a real browser, a loading indicator until then."""

from __future__ import annotations

import re
import shutil
import threading
import time

import numpy as np
import pytest

from mexone.description.loader import load_model
from mexone.gui.app import GuiApp
from mexone.gui.display import TRIANGLE_BUDGET, display_budgets
from mexone.lab import Lab

CHROMIUM = shutil.which("chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
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


@pytest.mark.slow
def test_a_big_robot_is_drawn_within_3_s_of_page_load(big_robot):
    playwright = pytest.importorskip("playwright.sync_api")
    if CHROMIUM is None:
        pytest.skip("Debian chromium is not installed")
    app = GuiApp(lambda options: Lab.create(big_robot, False, options=options),
                 __import__("mexone.physics", fromlist=["CompileOptions"]).CompileOptions(), port=0)
    thread = threading.Thread(target=app.serve_forever, daemon=True)
    thread.start()
    try:
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
            tab = browser.new_page(viewport={"width": 1280, "height": 800})
            from PIL import Image
            import io

            def dark_fraction() -> float:  # the robot's dark parts on a light ground and sky
                shot = np.asarray(Image.open(io.BytesIO(tab.screenshot())).convert("RGB"))
                return float((shot.max(axis=2) < 90).mean())

            start = time.monotonic()
            tab.goto(f"http://127.0.0.1:{app.server.get_port()}")
            drawn = None
            while time.monotonic() - start < 20:
                if dark_fraction() > 0.002:
                    drawn = time.monotonic() - start
                    break
            assert drawn is not None, "the robot never appeared"
            assert drawn < 3.0, f"the robot took {drawn:.1f} s to appear"
            # the loading indicator is gone once the robot is there
            assert not tab.get_by_text("Loading the robot").is_visible()
            browser.close()
    finally:
        app.stop()
        thread.join(timeout=5)
