"""Issue 32 item 6 (a), (d): the one-foot LQR from linearize + control.dlqr balances Mex-One,
u0 alone falls, it beats the shipped PD against pushes; the Kalman filter tracks the torso tilt.
The push sizes are coarse here (the benchmark bisects finely)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples" / "control_design"))

import one_foot_lqr as lq  # noqa: E402
import tilt_observer as to  # noqa: E402

pytestmark = pytest.mark.slow


def test_operating_point_balances_on_the_left_foot(designed):
    _, point, d = designed
    assert point.contacts == ("l_foot",)
    assert np.abs(point.residual).max() < 1e-3
    assert d.K.shape == (21, 54) and np.abs(d.poles).max() < 1.0


def test_stands_10_s_then_12_s_with_noise_and_u0_alone_falls(designed):
    _, point, d = designed
    noise = lq.smoothed_noise(22_000, d.sys.ninputs, lq.noise_std(d))
    both = lq.run(point, lq.lqr(d, noise=noise, noise_from=10.0), duration=22.0, sample=0.05)
    assert not both.fell and both.sim_time > 21.99
    alone = lq.run(point, lq.lqr(d, feedback=False), duration=10.0, sample=0.05)
    assert alone.fell


@pytest.mark.parametrize("direction,impulse", [("left", 2.75), ("right", 2.8),
                                               ("forward", 5.42), ("backward", 5.6)])
def test_survives_a_push_the_shipped_pd_does_not(designed, direction, impulse):
    _, point, d = designed
    assert not lq.survives(point, "pd", direction, impulse)
    assert lq.survives(point, lq.lqr(d), direction, impulse)


def test_kalman_tracks_the_torso_tilt(designed):
    lab, point, d = designed
    c, dd, y0, c_tilt = to.measurement_model(lab, d)
    noise = lq.smoothed_noise(2001, d.sys.ninputs, lq.noise_std(d))
    result = lq.run(point, lq.lqr(d, noise=noise, log=True), duration=2.0)
    e = to.estimate(d, c, dd, y0, c_tilt, result.log, lab.sim.model.opt.timestep)
    assert e.rms_tilt < 0.2 * np.sqrt(np.mean(e.tilt ** 2)) + 1e-4
