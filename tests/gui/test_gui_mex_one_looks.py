"""Mex-One's visual shells (issue 28) reach the page as fast as the boxes they replaced."""

from __future__ import annotations

import pytest

from gui.test_gui_big_robot import _time_to_draw
from helpers import chromium
from mexone.description.loader import load_model
from mexone.description.model import Visual
from mexone.description.urdf import write_urdf
from mexone.robots import mex_one


def _boxes(folder):
    """Mex-One drawn as it was before the shells: its collision primitives, one grey each."""
    robot = load_model(mex_one.urdf_path())
    for link in robot.links.values():
        link.visuals = [Visual(c.geometry, c.origin, f"{link.name}_visual_{i}", "grey",
                               (0.75, 0.75, 0.78, 1.0)) for i, c in enumerate(link.collisions)]
    path = folder / "boxes.urdf"
    path.write_text(write_urdf(robot))
    return path


@pytest.mark.slow
def test_the_shells_are_drawn_as_fast_as_the_boxes(tmp_path, monkeypatch):
    monkeypatch.setenv("MEXONE_CACHE", str(tmp_path / "cache"))
    boxes = _boxes(tmp_path)
    with chromium() as browser:
        # boxes then shells, a pair per round; a timing on shared cores is a sample: a stall of
        # the host (steal, another job's burst) during one load says nothing of the page, so a
        # missed round is measured again, up to three rounds in all (as test_gui_big_robot)
        rounds = []
        while not any(_as_fast(b, d) for (b, _, _), (d, _, _) in rounds) and len(rounds) < 3:
            rounds.append((_time_to_draw(boxes, browser, pixels=False),
                           _time_to_draw(mex_one.urdf_path(), browser, pixels=False)))
    times = [(round(b, 2), round(d, 2)) for (b, _, _), (d, _, _) in rounds]
    sent = min(s for _, (_, _, s) in rounds)
    print(f"(boxes, shells) drawn s after the load event: {times}; shells {sent / 1e6:.2f} MB sent")
    assert sent < 2e6
    assert any(_as_fast(b, d) for (b, _, _), (d, _, _) in rounds), f"(boxes, shells) s: {times}"


def _as_fast(base: float, drawn: float) -> bool:
    """The shells drawn about as fast as the boxes they replaced, loaded just before them."""
    return drawn <= max(1.5 * base, base + 1.0)
