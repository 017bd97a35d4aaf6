"""The page's signal log (gui/plots.py SignalLog) without a page: it samples on its own sim-time
timer every PLOT_PERIOD exactly while the simulation runs, each row is the state at that
instant, and a window of it is the rows of the last seconds even where the ring wrapped."""

from __future__ import annotations

import numpy as np
import pytest

from mexone.gui import plots
from mexone.gui.plots import PLOT_PERIOD, SignalLog
from mexone.lab import Lab


@pytest.fixture(scope="module")
def lab():
    return Lab.create()


def test_samples_fall_every_plot_period_and_hold_the_state_of_their_instant(lab):
    lab.sim.reset()
    log = SignalLog(lab)
    kept = []  # the joints' positions at each sample instant, read independently
    timer = lab.sim.add_periodic(PLOT_PERIOD, lambda sim: kept.append((sim.time,
                                                                      sim.joint_positions())))
    try:
        lab.sim.run(0.5)
    finally:
        lab.sim.remove_periodic(timer)
        log.close()
    t, values = log.window(10.0, [f"{j}/position" for j in lab.sim.joint_names])
    assert log.count == 50
    np.testing.assert_allclose(t, PLOT_PERIOD * np.arange(1, 51), atol=1e-12)
    assert [time for time, _ in kept] == pytest.approx(list(t), abs=1e-12)
    np.testing.assert_array_equal(values.T, np.array([q for _, q in kept], dtype=np.float32))
    lab.sim.run(0.1)  # closed: no more samples
    assert log.count == 50


def test_a_window_of_a_wrapped_ring_is_its_last_seconds(lab, monkeypatch):
    monkeypatch.setattr(plots, "CAPACITY", 40)
    lab.sim.reset()
    log = SignalLog(lab)
    try:
        lab.sim.run(1.23)  # 123 samples through a ring of 40
        names = ["base/height", "l_knee/position"]
        every_t = PLOT_PERIOD * np.arange(1, 124)
        for seconds, rows in ((0.2, 21), (0.05, 6), (0.0, 1), (10.0, 40)):
            t, values = log.window(seconds, names)
            np.testing.assert_allclose(t, every_t[-rows:], atol=1e-12)
            assert values.shape == (2, rows)
            order = np.arange(log.count - rows, log.count) % 40
            np.testing.assert_array_equal(values, log.values[order][:, [log.index[n] for n in names]].T)
        assert log.window(1.0, [])[1].shape == (0, 40)
        lab.sim.reset()  # time jumps back: the log starts afresh
        lab.sim.run(0.03)
        t, _ = log.window(10.0, names)
        np.testing.assert_allclose(t, [0.01, 0.02, 0.03], atol=1e-12)
    finally:
        log.close()
