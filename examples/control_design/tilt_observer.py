"""A Kalman filter estimating the torso's tilt and tilt rate of Mex-One balancing on one foot,
from the torso IMU (gyro, accelerometer) and the joint encoders, compared with the true state
(issue 32, worked example 6d).

The model is the one-foot LQR's (one_foot_lqr.py): `linearize` with the IMU's sensor outputs
(MuJoCo's sensor derivatives) and the stance foot's pose (the leg-odometry assumption: a foot
flat on the ground does not move, which makes the base's position observable from the
encoders); the encoders are the joint-angle states. `control.dlqe` gives the gain of
x^[k+1] = A x^ + B u + L (y - C x^ - D u). The robot balances under the LQR with the noisy
controls of the acceptance test; the sensors read with noise added here.

    PYTHONPATH=src python examples/control_design/tilt_observer.py [--figure tilt.png]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import control
import mujoco
import numpy as np
from one_foot_lqr import Design, design, lqr, noise_std, one_foot_pose, run, setup, smoothed_noise

from mexone.design import linearize
from mexone.lab import Lab

__all__ = ["Estimate", "measurement_model", "estimate", "main", "SENSOR_STD"]

SENSOR_STD = {"gyro": 0.01, "acc": 0.1, "encoder": 1e-4, "foot": 1e-4}  # rad/s, m/s^2, rad, m


def measurement_model(lab: Lab, d: Design):
    """(C, D, y0, C_tilt): y = gyro (3), accelerometer (3), stance-foot pose (6), encoders (21
    joint angles); C_tilt: the torso's rotation about world x and y from the state."""
    point = d.point
    sensed = linearize(lab, point=point, outputs=["imu/gyro", "imu/acc", "pose:l_foot",
                                                  "pose:torso"])
    nv = lab.sim.model.nv
    c_imu, d_imu = sensed.C[:12], sensed.D[:12]
    c_tilt = sensed.C[[sensed.output_labels.index("torso:rx"),
                       sensed.output_labels.index("torso:ry")]]
    encoders = np.zeros((nv - 6, sensed.nstates))
    encoders[:, 6:nv] = np.eye(nv - 6)
    c = np.vstack([c_imu, encoders])
    dd = np.vstack([d_imu, np.zeros((nv - 6, sensed.ninputs))])
    model = lab.sim.model
    data = mujoco.MjData(model)
    data.qpos[:] = point.qpos
    mujoco.mj_kinematics(model, data)
    site = int(model.sensor_objid[model.sensor("imu/acc").id])
    rest_acc = data.site_xmat[site].reshape(3, 3).T @ -model.opt.gravity  # at rest: -g, sensed
    y0 = np.concatenate([np.zeros(3), rest_acc, np.zeros(6), np.zeros(nv - 6)])
    return c, dd, y0, c_tilt


@dataclass
class Estimate:
    """Time (s), true and estimated tilt (rad) and tilt rate (rad/s), (n, 2) each (world x, y),
    and the RMS errors after the first `settle` s."""

    t: np.ndarray
    tilt: np.ndarray
    tilt_hat: np.ndarray
    rate: np.ndarray
    rate_hat: np.ndarray
    rms_tilt: float
    rms_rate: float


def estimate(d: Design, c, dd, y0, c_tilt, log: dict, dt: float, seed: int = 1,
             settle: float = 0.5) -> Estimate:
    """Run the Kalman filter over a logged run (u, gyro, acc, true dx): the sensors get white
    noise of SENSOR_STD, the encoders are the true joint angles plus noise."""
    rng = np.random.default_rng(seed)
    a, b = d.sys.A, d.sys.B
    nv = (a.shape[0]) // 2
    u = np.array(log["u"])
    x_true = np.array(log["dx"])
    n = len(u)
    std = np.concatenate([[SENSOR_STD["gyro"]] * 3, [SENSOR_STD["acc"]] * 3,
                          [SENSOR_STD["foot"]] * 6, [SENSOR_STD["encoder"]] * (nv - 6)])
    y = np.column_stack([np.array(log["gyro"]), np.array(log["acc"]), np.zeros((n, 6)),
                         x_true[:, 6:nv]]) - y0 + std * rng.standard_normal((n, len(std)))
    u_dev = u - d.sys.linearization.u0
    process = b @ np.diag(noise_std(d) ** 2) @ b.T + 1e-4 * np.eye(a.shape[0])
    gain, _, _ = control.dlqe(a, np.eye(a.shape[0]), c, process, np.diag(std ** 2), method="scipy")
    x_hat = np.zeros(a.shape[0])
    est = np.zeros((n, a.shape[0]))
    for k in range(n):
        est[k] = x_hat
        x_hat = a @ x_hat + b @ u_dev[k] + gain @ (y[k] - c @ x_hat - dd @ u_dev[k])
    tilt, tilt_hat = x_true @ c_tilt.T, est @ c_tilt.T
    rate, rate_hat = x_true[:, nv:2 * nv] @ c_tilt[:, :nv].T, est[:, nv:2 * nv] @ c_tilt[:, :nv].T
    t = dt * np.arange(n)
    keep = t >= settle
    rms = lambda e: float(np.sqrt(np.mean(e[keep] ** 2)))  # noqa: E731
    return Estimate(t, tilt, tilt_hat, rate, rate_hat, rms(tilt_hat - tilt), rms(rate_hat - rate))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", default="tilt_observer.png")
    parser.add_argument("--duration", type=float, default=4.0)
    args = parser.parse_args()
    lab = Lab.create()
    setup(lab)
    point = one_foot_pose(lab)
    d = design(lab, point)
    c, dd, y0, c_tilt = measurement_model(lab, d)
    steps = int(round(args.duration / lab.sim.model.opt.timestep)) + 1
    noise = smoothed_noise(steps, d.sys.ninputs, noise_std(d))
    result = run(point, lqr(d, noise=noise, log=True), duration=args.duration)
    e = estimate(d, c, dd, y0, c_tilt, result.log, lab.sim.model.opt.timestep)
    print(f"balanced {result.sim_time:.1f} s under noisy controls (fell: {result.fell}); "
          f"true tilt RMS {1e3 * np.sqrt(np.mean(e.tilt ** 2)):.2f} mrad, rate RMS "
          f"{1e3 * np.sqrt(np.mean(e.rate ** 2)):.2f} mrad/s")
    print(f"Kalman estimate RMS error: tilt {1e3 * e.rms_tilt:.3f} mrad, tilt rate "
          f"{1e3 * e.rms_rate:.2f} mrad/s (gyro noise {1e3 * SENSOR_STD['gyro']:.0f} mrad/s)")
    figure(e, args.figure)


def figure(e: Estimate, path: str) -> None:
    """True vs estimated torso tilt about world x and its rate."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 1, figsize=(7, 4.2), sharex=True)
    for i, axis in enumerate("xy"):
        axes[0].plot(e.t, 1e3 * e.tilt[:, i], label=f"true, about {axis}")
        axes[0].plot(e.t, 1e3 * e.tilt_hat[:, i], "--", label=f"Kalman, about {axis}")
        axes[1].plot(e.t, 1e3 * e.rate[:, i], label=f"true, about {axis}")
        axes[1].plot(e.t, 1e3 * e.rate_hat[:, i], "--", label=f"Kalman, about {axis}")
    axes[0].set_ylabel("torso tilt (mrad)")
    axes[1].set_ylabel("tilt rate (mrad/s)")
    axes[1].set_xlabel("time (s)")
    axes[0].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
