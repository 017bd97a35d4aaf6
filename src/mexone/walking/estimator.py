"""The floating-base state estimator: a Kalman filter on the base's position and velocity from
the IMU, the joint encoders and the feet's contacts (leg odometry), compared with the truth.

The base's attitude and angular velocity come from the IMU (its orientation relative to the
world and its gyro, turned into the base's frame). The filter's state is x = (p, v), the base's
position and velocity in the world frame:

- predict, every update, with the IMU's proper acceleration f turned into the world and gravity
  added back (a = R f + g): p+ = p + v dt + a dt²/2, v+ = v + a dt; process noise from
  `accel_noise`;
- correct with each foot on the ground (contact sensor's normal force above `contact_force`):
  a foot on the ground does not move, so the base's velocity is v = -J_foot q̇ with the base's
  linear velocity left out of q̇ (its angular velocity the gyro's, the joints' the encoders'), and
  the base's position is the foot's latched position less the leg's kinematics,
  p = p_foot - (p_foot(q) - p_base(q)); a foot's position is latched when it touches down.

Linear in x with a known attitude, so the filter is the textbook one (Joseph form); its gain
settles to the discrete Riccati equation's (tests/walking check that). The position drifts
along the ground as every leg-odometry estimate does (nothing sees the world): what matters for
walking is the velocity and the attitude.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from mexone.control.student import Param, PythonController, State
from mexone.walking import body as _body

__all__ = ["BaseKalman", "StateEstimator"]

GRAVITY = np.array([0.0, 0.0, -9.81])


class BaseKalman:
    """x = (p, v) (6,), world frame; `predict(a, dt)` with the base's acceleration, `correct(z,
    H, r)` with a measurement z = H x + noise of variance r."""

    def __init__(self, p0: np.ndarray, accel_noise: float = 1.0):
        self.x = np.concatenate([np.asarray(p0, dtype=float), np.zeros(3)])
        self.P = np.diag([1e-4] * 3 + [1e-2] * 3)
        self.accel_noise = accel_noise

    @staticmethod
    def model(dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(F, B): x+ = F x + B a."""
        F = np.eye(6)
        F[:3, 3:] = dt * np.eye(3)
        B = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
        return F, B

    def predict(self, a: np.ndarray, dt: float) -> None:
        F, B = self.model(dt)
        self.x = F @ self.x + B @ a
        self.P = F @ self.P @ F.T + (self.accel_noise**2) * (B @ B.T)

    def correct(self, z: np.ndarray, H: np.ndarray, r: float | np.ndarray) -> None:
        R = np.diag(np.broadcast_to(np.asarray(r, dtype=float), z.shape))
        PHt = self.P @ H.T
        K = np.linalg.solve(H @ PHt + R, PHt.T).T
        self.x = self.x + K @ (z - H @ self.x)
        I_KH = np.eye(6) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ R @ K.T


H_POSITION = np.hstack([np.eye(3), np.zeros((3, 3))])
H_VELOCITY = np.hstack([np.zeros((3, 3)), np.eye(3)])


class StateEstimator(PythonController):
    """The estimator in the loop: claims no joints, reads the IMU (`imu`), the feet's contact
    sensors (`l_foot_contact`, `r_foot_contact`) and the encoders (`state.all_q`'s joints: the
    base's entries are not read). Exports `base` (13: position, quaternion w x y z, linear
    velocity (world), angular velocity (base frame): qpos/qvel's free-joint layout) and
    `contact` (2: 1 where a foot is on the ground); `report()` gives its error against the
    simulator's truth."""

    command_interface = "effort"
    exports = {"base": 13, "contact": 2}

    imu = Param("imu", doc="the IMU sensor's name")
    accel_noise = Param(2.0, low=1e-6, high=1e3, doc="process noise: the acceleration's", unit="m/s^2")
    velocity_noise = Param(0.05, low=1e-6, high=10.0, doc="leg odometry's velocity noise", unit="m/s")
    position_noise = Param(0.005, low=1e-6, high=1.0, doc="leg kinematics' position noise", unit="m")
    contact_force = Param(20.0, low=0.0, high=1e4, doc="a foot's normal force that counts as contact",
                          unit="N")

    def configure(self) -> None:
        model = self.dynamics.model
        self.scratch = mujoco.MjData(model)
        self.dyn = _body.state_dynamics(model, self.scratch)
        site = model.site("sensor/imu") if self.imu == "imu" else model.site(f"sensor/{self.imu}")
        self.imu_in_base = _body.quat_to_matrix(model.site_quat[site.id])  # the pelvis carries it
        # against the truth, as running figures (a list per update grew without end, each
        # entry an object the collector walked): updates, largest position error, sum of the
        # squared velocity errors
        self.errors: list[float] = [0, 0.0, 0.0]
        self.latched: list[np.ndarray | None] = [None, None]

    def activate(self, state: State) -> None:
        self.scratch.qpos[:] = state.all_q  # starts from the spawn pose: where it was put
        self.scratch.qvel[:] = 0.0
        self.kf = BaseKalman(state.all_q[:3], self.accel_noise)
        self.latched = [None, None]
        self.t_last = state.time

    def _attitude(self, state: State) -> tuple[np.ndarray, np.ndarray]:
        imu = state.sensors[self.imu]
        x, y, z, w = imu.orientation
        r_imu = _body.quat_to_matrix(np.array([w, x, y, z]))
        rotation = r_imu @ self.imu_in_base.T
        return rotation, self.imu_in_base @ np.asarray(imu.angular_velocity)

    def update(self, state: State, t: float, dt: float) -> np.ndarray | None:
        rotation, omega = self._attitude(state)
        imu = state.sensors[self.imu]
        accel = rotation @ self.imu_in_base @ np.asarray(imu.linear_acceleration) + GRAVITY
        step = t - self.t_last if t > self.t_last else dt
        self.t_last = t
        kf = self.kf
        kf.predict(accel, step)
        # the kinematics at the estimate: the attitude from the IMU, the joints from the encoders
        d = self.scratch
        d.qpos[:] = state.all_q
        d.qpos[:3] = kf.x[:3]
        d.qpos[3:7] = _body.matrix_to_quat(rotation)
        d.qvel[:] = state.all_dq
        d.qvel[:3] = 0.0
        d.qvel[3:6] = omega
        self.dyn.refresh()
        contact = np.zeros(2)
        zs, hs, rs = [], [], []  # every foot's measurements, corrected at once
        for f, name in enumerate(_body.FEET):
            sensor = state.sensors[f"{name}_contact"]
            if float(np.dot(sensor.force, [0, 0, 1])) < self.contact_force:
                self.latched[f] = None
                continue
            contact[f] = 1.0
            p_foot = self.dyn.pose(name)[0]
            offset = p_foot - kf.x[:3]
            if self.latched[f] is None:
                self.latched[f] = p_foot.copy()
            jac = self.dyn.jacobian(name)
            zs += [-(jac[:3] @ d.qvel), self.latched[f] - offset]
            hs += [H_VELOCITY, H_POSITION]
            rs += [self.velocity_noise**2] * 3 + [self.position_noise**2] * 3
        if zs:
            kf.correct(np.concatenate(zs), np.vstack(hs), np.array(rs))
        out = self.exports
        out["base"][:3] = kf.x[:3]
        out["base"][3:7] = d.qpos[3:7]
        out["base"][7:10] = kf.x[3:]
        out["base"][10:13] = omega
        out["contact"][:] = contact
        truth = state.base
        if truth is not None:
            errors = self.errors
            errors[0] += 1
            errors[1] = max(errors[1], float(np.linalg.norm(kf.x[:3] - truth.position)))
            errors[2] += float(np.linalg.norm(kf.x[3:] - truth.linear_velocity)) ** 2
        return None

    def report(self) -> dict[str, Any]:
        """Its error against the simulator's truth: position (m, largest), velocity (m/s, RMS)."""
        n, worst, squares = self.errors
        if not n:
            return {}
        return {"position_error_max_m": round(worst, 4),
                "velocity_error_rms_mps": round(math.sqrt(squares / n), 4)}
