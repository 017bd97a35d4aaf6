"""The lab in Jupyter (mexone.notebook, examples/notebooks): a replay records what was simulated
and exports a page that plays it; the live page runs the lab in its own thread and hands the
notebook work; every shipped notebook runs from the installed wheel (with its `notebook` extra),
and its saved HTML, opened in Chromium, draws the robot moving in the inline replay."""

from __future__ import annotations

import io
import json
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from helpers import chromium, wait_until
from mexone.errors import InputError
from mexone.lab import Lab
from mexone.notebook import record, serve, simulate

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "examples" / "notebooks").glob("*.ipynb"))


@pytest.fixture(scope="module")
def lab():
    return Lab.create(controllers=False)


def test_simulate_records_the_poses_at_the_frame_rate(lab):
    start = lab.sim.time
    replay = simulate(lab, 0.2, fps=50, progress=False)
    assert lab.sim.time == pytest.approx(start + 0.2, abs=1e-9)
    assert len(replay.times) == 11  # the start and one frame per 20 ms
    assert np.allclose(np.diff(replay.times), 0.02)
    assert np.array_equal(replay.qpos[-1], lab.sim.data.qpos)  # the last frame is the state now
    assert replay.qpos[0][2] > replay.qpos[-1][2]  # falling: the pelvis lower at the end
    assert repr(replay) == "Replay(11 frames over 0.200 s at 50 fps)"  # not the lab, every qpos


def test_record_samples_whatever_runs_the_simulation(lab):
    with record(lab, fps=10) as replay:
        lab.sim.run(0.3)
    assert len(replay.times) == 4
    assert not lab.sim.periodic or all(t.callback != replay.sample for t in lab.sim.periodic)


def test_the_scene_page_embeds_the_recording(lab):
    page = simulate(lab, 0.1, fps=20, progress=False).scene_html()
    assert "window.__VISER_EMBED_DATA__=" in page and "</html>" in page
    assert len(page) > 500_000  # viser's client and the robot's meshes, in one file


@pytest.mark.parametrize("fps", [0, -1, float("nan"), 1e6])
def test_a_bad_frame_rate_is_one_line(lab, fps):
    with pytest.raises(InputError, match="fps .* must be a finite number"):
        simulate(lab, 0.1, fps=fps, progress=False)


@pytest.mark.parametrize("port", [70000, -1, 8.5])
def test_a_bad_port_is_one_line_and_serves_nothing(lab, port):
    # was: viser's thread died with an OverflowError traceback and serve() never returned
    with pytest.raises(InputError, match="serve: port .* must be a whole number >= 0 and <= 65535"):
        serve(lab, port=port)
    assert getattr(lab, "_live_page", None) is None


def test_nothing_recorded_is_one_line(lab):
    from mexone.notebook import Replay

    with pytest.raises(InputError, match="nothing recorded"):
        Replay(lab, 30.0).scene_html()


def test_the_live_page_runs_the_lab_in_its_own_thread(lab):
    page = serve(lab, rtf=0)
    try:
        thread = page.call(lambda: __import__("threading").get_ident())
        assert thread == page.thread.ident  # the work ran in the simulation thread
        t0 = page.call(lambda: lab.sim.time)
        assert page.call(lambda: lab.sim.time) >= t0  # it runs on between calls
        with pytest.raises(InputError, match="live page"):
            simulate(lab, 0.1, progress=False)  # the notebook's thread keeps its hands off
        with pytest.raises(ZeroDivisionError):  # the cell sees its own error; the page runs on
            page.call(lambda: 1 / 0)
        assert page.running
        assert page.url in page._repr_html_()
    finally:
        page.stop()
    assert not page.running
    simulate(lab, 0.01, progress=False)  # the lab is the notebook's again


def test_viser_says_nothing_into_the_cell(lab, monkeypatch):
    """viser's banners (a random port's address, "Server stopped") stay out of a cell's output,
    which a saved notebook keeps. In Jupyter viser's rich console writes through IPython's
    display, past a redirect of stdout: a console of rich's own, writing into a buffer, stands
    in for that one here."""
    import rich
    from rich.console import Console

    said = io.StringIO()
    monkeypatch.setattr(rich, "_console", Console(file=said, force_terminal=False))
    assert "__VISER_EMBED_DATA__" in simulate(lab, 0.05, progress=False).scene_html()
    page = serve(lab, rtf=0)
    page.stop()
    assert said.getvalue() == ""
    assert not rich.get_console().quiet  # the console is the user's again


def test_the_notebooks_are_committed_without_outputs():
    """What running a notebook writes (outputs, counts, widget state) is not kept in git."""
    import nbformat

    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        nbformat.validate(nb)
        for cell in nb.cells:
            if cell.cell_type == "code":
                assert not cell.outputs and cell.execution_count is None, path.name
        assert "widgets" not in nb.metadata, path.name


DRIVER = """
import os, sys, time, json, nbformat
from nbclient import NotebookClient
from nbconvert import HTMLExporter
times = {}
for path in sys.argv[1:]:
    nb = nbformat.read(path, as_version=4)
    start = time.monotonic()
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": os.path.dirname(path)}}).execute()
    times[path] = time.monotonic() - start
    html, _ = HTMLExporter().from_notebook_node(nb)
    open(path[:-6] + ".html", "w").write(html)
print(json.dumps(times))
"""


@pytest.fixture(scope="module")
def executed(wheel, venv, tmp_path_factory):
    """Every shipped notebook run by the wheel's Python, with its saved HTML beside it."""
    assert NOTEBOOKS, "no notebooks in examples/notebooks"
    venv.run("python", "-m", "pip", "install", "-q", "--disable-pip-version-check",
             f"{wheel}[notebook]", timeout=900)  # what docs/notebooks.md tells users (the
    # session's venv has it already, tests/wheelenv.py's EXTRAS: then pip finds it satisfied)
    examples = tmp_path_factory.mktemp("examples")  # as in the checkout: ../control_design
    for name in ("notebooks", "control_design"):
        shutil.copytree(NOTEBOOKS[0].parents[1] / name, examples / name,
                        ignore=shutil.ignore_patterns("__pycache__", ".ipynb_checkpoints"))
    folder = examples / "notebooks"

    def execute(nb: Path) -> dict[str, float]:
        out = venv.run("python", "-c", DRIVER, str(folder / nb.name), cwd=folder, timeout=1800)
        return json.loads(out.stdout.strip().splitlines()[-1])

    # two at a time, each in a driver and kernel of its own: a notebook waits on its kernel's
    # start and on its subprocesses, and the serial phase leaves the other core idle (they
    # write no file in common and hold no time limit: the test asks for no error)
    with ThreadPoolExecutor(max_workers=2) as pool:
        times = {k: v for done in pool.map(execute, NOTEBOOKS) for k, v in done.items()}
    print("notebook execution (s):", {Path(k).name: round(v, 1) for k, v in times.items()})
    return folder


@pytest.mark.slow
def test_every_notebook_runs_from_the_wheel(executed):
    import nbformat

    for nb in NOTEBOOKS:
        ran = nbformat.read(executed / nb.name, as_version=4)
        outputs = [o for c in ran.cells for o in c.get("outputs", [])]
        errors = [o for o in outputs if o["output_type"] == "error"]
        assert not errors, f"{nb.name}: {errors[0]['ename']}: {errors[0]['evalue']}"
        # viser's banners (a server's random port, "Server stopped") are no part of a saved
        # notebook; the inline replay's own page embeds viser's client, so it is left out
        said = [json.dumps(o.get("text") or o.get("data", {}).get("text/plain", ""))
                for o in outputs]
        banners = [text for text in said if "viser" in text or "Server stopped" in text]
        assert not banners, f"{nb.name}: {banners[0][:200]}"
        assert (executed / nb.name).with_suffix(".html").stat().st_size > 0


def _shot(element) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(element.screenshot())).convert("RGB"), dtype=np.int16)


@pytest.mark.slow
def test_the_saved_html_plays_the_robot_in_the_inline_replay(executed):
    """The fall in lab_in_jupyter.ipynb, played by viser's client from the HTML alone (a
    file:// page, no server): paused and moved along its time slider, the view at the start
    (standing) and near the end (fallen) differ where the robot is drawn (the camera and the
    ground hold still, so nothing else in the view moves)."""
    page_file = executed / "lab_in_jupyter.html"
    with chromium() as browser:
        tab = browser.new_page(viewport={"width": 1100, "height": 900})
        tab.goto(page_file.as_uri())
        frame = tab.locator(".mexone-replay iframe").first
        frame.scroll_into_view_if_needed()
        inner = frame.element_handle().content_frame()
        slider = inner.wait_for_selector(".mantine-Slider-root", timeout=60_000)
        box = slider.bounding_box()
        middle = box["y"] + box["height"] / 2
        play = min((b for b in inner.query_selector_all("button")
                    if (bb := b.bounding_box()) and abs(bb["y"] + bb["height"] / 2 - middle) < 30
                    and bb["x"] < box["x"]), key=lambda b: b.bounding_box()["x"])
        clock = inner.locator("input").first  # the player's time, s
        play.click()  # pause: what is on screen is one frame
        seen: list[str] = []

        def still() -> bool:  # the clock reads the same twice in a row
            seen.append(clock.input_value())
            return len(seen) > 2 and seen[-1] == seen[-2] == seen[-3]

        assert wait_until(still, timeout=30, poll=0.2), f"the player did not pause: {seen}"

        def seek(fraction: float, reached) -> np.ndarray:
            tab.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)
            assert wait_until(lambda: reached(float(clock.input_value())), timeout=30)
            return _shot(frame)[:-60]  # above the player's bar

        start = seek(0.05, lambda t: t < 0.3)
        changed = 0.0
        deadline = time.monotonic() + 60
        while changed < 0.01 and time.monotonic() < deadline:  # a slow renderer catches up
            end = seek(0.9, lambda t: t > 1.2)
            changed = float((np.abs(start - end).sum(axis=2) > 40).mean())
        assert changed >= 0.01, f"the replay shows no falling robot ({changed:.4f} of the view changed)"
