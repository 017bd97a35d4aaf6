"""Standing balance of Mex-One by LQR state feedback on the linear inverted pendulum, with the
ankle pitch torques. Exercise 8's reference (the teacher's pack only: the worked example
examples/controllers/04_lqr_sway teaches LQR on the sideways sway, not this answer).

The model: the robot on stiff knee and hip PDs pivots on its ankles, c = h theta the centre of
mass ahead of them, m h^2 ddtheta = m g h theta + u, so d/dt (c, dc) = [[0, 1], [g/h, 0]] x +
[0, 1/(m h)] u; u = -m g c0 - K (x - x0) with K from control.lqr, kept within the soles' centre
of pressure (N toe, N heel from the feet's force-torque load), -u / 2 on each ankle pitch. With
m = 15 kg, h = 0.5 m and the weights below, K = (325 N m/m, 122 N m s/m), poles -1.6 and
-14.6 /s. Measured: survives 5.5 N s forward (PD alone 3.5), backward 3.5 (3.0)."""

from __future__ import annotations

import control
import numpy as np

from mexone.control import Param, PythonController

__all__ = ["Balance", "pendulum"]

G = 9.81
IMU, IMU_FRAME = "imu", "sensor/imu"  # Mex-One's torso IMU: its name and its frame (a site)
BASE, WAIST, WAIST_CHILD = "pelvis", "waist_yaw", "torso"  # the IMU rides above the waist joint
FEET = ("l_ankle_ft", "r_ankle_ft")  # the six-axis sensors between ankle and foot


def pendulum(mass: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """The robot as a rigid body on its ankles, linearised upright: state x = (c, dc), c the
    COM's horizontal offset ahead of the ankles; input u = the ankles' torque on the body.
    m h^2 dd(theta) = m g h theta + u with c = h theta:  ddc = (g/h) c + u / (m h)."""
    a = np.array([[0.0, 1.0], [G / height, 0.0]])
    b = np.array([[0.0], [1.0 / (mass * height)]])
    return a, b


class Balance(PythonController):
    """u = -m g c0 - K (x - x0): K from the LQR of the pendulum above (python-control's `lqr`),
    x from the whole-body COM (the joint encoders, the base's motion with the IMU's gyro), u kept
    within what the feet's measured load can carry (the foot force-torque sensors), split over
    both ankles."""

    command_interface = "effort"
    q_position = Param(1.0, low=0.0, high=1e6, doc="LQR weight on c, 1/m^2 (Bryson: 1/max^2)")
    q_velocity = Param(1.0, low=0.0, high=1e6, doc="LQR weight on dc, s^2/m^2")
    r_torque = Param(1e-4, low=1e-9, high=1e3, doc="LQR weight on u, 1/(N m)^2")
    toe = Param(0.10, low=0.0, high=0.5, doc="m, sole ahead of the ankle: the COP's limit forward")
    heel = Param(0.06, low=0.0, high=0.5, doc="m, sole behind the ankle: the COP's limit backward")
    imu_gyro = Param(True, doc="the base's angular velocity from the IMU (else the simulator's)")

    def configure(self) -> None:
        self.gain = np.zeros(2)
        self.x0 = np.zeros(2)
        self.mass = 0.0
        self.worst = 0.0  # m: the largest COM offset from where it stood
        self.height = 0.5
        self.waist = int(self.dynamics.dofs(WAIST)[0])

    def com_state(self, state) -> np.ndarray:
        """(c, dc): the COM's x ahead of the ankles' midpoint and its x velocity, world frame,
        from the joint encoders and the base's motion, the base's angular velocity being the
        torso IMU's gyro (as a real robot knows it) unless `imu_gyro` is off."""
        dyn = self.dynamics
        ankles = 0.5 * (dyn.pose("l_ankle")[0] + dyn.pose("r_ankle")[0])
        dq = state.all_dq
        if self.imu_gyro:
            dq = dq.copy()
            dq[3:6] = self.base_rate(state)
        return np.array([dyn.com()[0] - ankles[0], dyn.com_jacobian()[0] @ dq])

    def base_rate(self, state) -> np.ndarray:
        """The pelvis's angular velocity in its own frame (a free joint's qvel[3:6]) from the
        IMU on the torso: the gyro turned into the pelvis's axes, less the waist's yaw rate."""
        pelvis = self.dynamics.pose(BASE)[1]
        imu = self.dynamics.pose(IMU_FRAME)[1]
        gyro = pelvis.T @ imu @ np.asarray(state.sensors[IMU].angular_velocity)
        waist_axis = pelvis.T @ self.dynamics.jacobian(WAIST_CHILD)[3:, self.waist]
        return gyro - waist_axis * state.all_dq[self.waist]

    def activate(self, state) -> None:
        self.mass = self.dynamics.mass()
        ankles = 0.5 * (self.dynamics.pose("l_ankle")[0] + self.dynamics.pose("r_ankle")[0])
        self.height = float(self.dynamics.com()[2] - ankles[2])
        a, b = pendulum(self.mass, self.height)
        q = np.diag([self.q_position, self.q_velocity])
        gain, _, poles = control.lqr(a, b, q, np.array([[self.r_torque]]))
        self.gain = np.asarray(gain).ravel()
        self.x0 = self.com_state(state)
        self.x0[1] = 0.0
        self.log.info("LQR gain K = (%.0f N m/m, %.1f N m s/m), closed-loop poles %s",
                      self.gain[0], self.gain[1], np.round(poles, 2))

    def update(self, state, t: float, dt: float):
        x = self.com_state(state)
        self.worst = max(self.worst, abs(float(x[0] - self.x0[0])))
        hold = -self.mass * G * self.x0[0]  # the torque that holds the COM where it stood
        u = hold - self.gain @ (x - self.x0)  # N m on the body, about +y (leans it forward)
        load = sum(max(0.0, state.sensors[ft].force[2]) for ft in FEET)  # N the soles carry
        u = min(max(u, -load * self.toe), load * self.heel)  # centre of pressure within the soles
        return np.full(len(self.joints), -u / len(self.joints))  # the body's reaction: -u

    def report(self) -> dict:
        """What `mexone sim --json` prints: the gain and how far the COM strayed (mm)."""
        return {"gain": [round(float(k), 2) for k in self.gain],
                "max_com_offset_mm": round(1e3 * self.worst, 2)}
