"""Issue 38 on the one-foot LQR (examples/control_design/one_foot_lqr.py): its margins checked on
the robot (a loop around an unstable plant: a lower gain margin too), a Kalman filter on the IMU
and the encoders in the loop estimating the torso's tilt under pushes, and the region of
attraction by batched rollouts (threads and Ray give the same)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples" / "control_design"))

import one_foot_lqr as lq  # noqa: E402

from mexone.design import deploy, linearize  # noqa: E402
from mexone.design.loop import linearize_loop  # noqa: E402
from mexone.design.margins import loop_margins  # noqa: E402
from mexone.design.observers import compare_estimate, kalman, rows_of  # noqa: E402
from mexone.design.onset import simulate_onset  # noqa: E402
from mexone.design.region import plot_region, region_of_attraction  # noqa: E402

pytestmark = pytest.mark.slow

NOISE = {"imu/gyro": 0.01, "imu/acc": 0.1, "encoders": 1e-4}  # the worked example's
PUSHES = [(0.6, "pelvis", (0.0, 0.5, 0.0)), (1.8, "pelvis", (0.8, 0.0, 0.0))]  # N s


@pytest.fixture
def balancing(designed):
    """A fresh lab on one foot under the LQR, deployed as a StateFeedback."""
    _, point, d = designed
    lab = lq._fresh_lab(point, False)
    controller = deploy(lab, d.K, d.sys, name="balance")
    lab.sim.run(0.3)
    return lab, controller


def test_one_foot_lqr_margins_hold_on_the_robot(designed, balancing):
    """Delay within one control period (1 ms), gain increase and reduction within 10 %."""
    lab, _ = balancing
    loop = linearize_loop(lab)
    result = loop_margins(loop)
    assert result.all.gain_reduction > 0.1  # an unstable plant: too little gain falls
    onsets = {o.kind: o for o in simulate_onset(lab, loop, result.all)}
    assert set(onsets) == {"delay", "gain", "gain reduction"}
    for onset in onsets.values():
        assert onset.agrees, onset


def test_kalman_filter_on_imu_and_encoders_tracks_the_torso_tilt_under_pushes(designed, balancing):
    """The acceptance: RMS error of the torso's tilt under 0.5 mrad and of its rate under
    5 mrad/s, standing on one foot and pushed twice, the sensors noisier than the URDF's."""
    lab0, point, d = designed
    lab, _ = balancing
    sensed = linearize(lab0, point=point, outputs=["imu/gyro", "imu/acc", "pose:l_foot",
                                                    "pose:torso"])
    tilt = ["torso:rx", "torso:ry"]
    exports = {"tilt": rows_of(sensed, tilt), "tilt_rate": rows_of(sensed, tilt, rate=True)}
    b, n, nv = np.asarray(sensed.B), sensed.nstates, lab.sim.model.nv
    base = np.zeros(n)
    base[nv:nv + 6] = 3e-4 ** 2  # the pushes: the base's velocities
    process = b @ np.diag(lq.noise_std(d) ** 2 + 0.1 ** 2) @ b.T + np.diag(base)
    variance = np.r_[[NOISE["imu/gyro"] ** 2] * 3, [NOISE["imu/acc"] ** 2] * 3, [1e-8] * 6,
                     [NOISE["encoders"] ** 2] * 21]
    est = kalman(sensed, ["imu/gyro", "imu/acc", "pose:l_foot", "encoders"], process, variance,
                 exports=exports)
    observer = deploy(lab, est, name="tilt_kf")
    observer.extra_noise = dict(NOISE)
    run = compare_estimate(lab, observer, duration=3.0, pushes=PUSHES)
    true_tilt = np.sqrt(np.mean(run.outputs["tilt"][0] ** 2))
    assert true_tilt > 3e-3  # the pushes tilted it (measured: about 5 mrad RMS)
    assert run.error("tilt") < 0.5e-3, run.error("tilt")  # measured: 0.07 mrad
    assert run.error("tilt_rate") < 5e-3, run.error("tilt_rate")  # measured: 3.9 mrad/s


def test_region_of_attraction_by_batched_rollouts(designed, balancing):
    _, _, d = designed
    lab, controller = balancing
    axes = {"base:vx": (-0.25, 0.25), "base:vy": (-0.2, 0.2)}
    region = region_of_attraction(lab, controller, d.sys, axes, shape=(5, 5), duration=1.5,
                                  threads=2)
    assert region.back.shape == (5, 5)
    assert region.back[2].any() and not region.back.all()  # the middle comes back, not all
    g0, g1 = np.meshgrid(*region.values, indexing="ij")
    pts = np.stack([g0.ravel(), g1.ravel()], axis=1)
    v = np.einsum("ij,jk,ik->i", pts, region.slice, pts).reshape(region.back.shape)
    assert region.back[v < region.level].all()  # the level set holds only returns
    assert len(plot_region(region).axes[0].collections) == 2
    ray = region_of_attraction(lab, controller, d.sys, axes, shape=(5, 5), duration=1.5,
                               threads=2, backend="ray")
    np.testing.assert_array_equal(ray.back, region.back)
