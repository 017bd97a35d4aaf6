"""The ros_controllers types, each vectorised over its joints.

A controller claims joints, takes commands from its topic, and writes the hardware interface;
`update` runs every control period only if `needs_update` (integral terms, finite-difference
derivatives, trajectories, ideal servos). Semantics follow ros_controllers (Kinetic):
position controllers start by holding the current position, commands are clamped to the joint
limits, the PID is control_toolbox's, efforts are saturated at the URDF effort limit.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from mexone.bus.msgs import Float64, Float64MultiArray, JointTrajectory
from mexone.control.config import CONTROLLER_TYPES, ControllerSpec, PidGains
from mexone.control.hardware import SimHardware
from mexone.control.pid import PidArray
from mexone.control.servo import ServoBank
from mexone.errors import InputError

__all__ = ["Controller", "PositionController", "VelocityController", "EffortController",
           "TrajectoryController", "make_controller"]

log = logging.getLogger("mexone.control")


class Controller:
    msg_type: type = Float64

    def __init__(self, spec: ControllerSpec, hw: SimHardware):
        self.spec = spec
        self.name = spec.name
        self.hw = hw
        self.joints = list(spec.joints)
        self.rows = hw.rows(self.joints)
        self.running = False
        self._warned: set[str] = set()
        if self.msg_type is Float64 and not CONTROLLER_TYPES[spec.type][2]:
            self.msg_type = Float64MultiArray  # the JointGroup*Controller variants

    @property
    def needs_update(self) -> bool:
        return False

    def start(self, t: float) -> None:
        self.running = True

    def stop(self) -> None:
        self.running = False
        self.hw.release(self.rows)

    def update(self, t: float, dt: float) -> None:
        pass

    def command(self, msg) -> None:
        values = self._values(msg)
        if values is not None:
            self.set_command(values)

    def set_command(self, values: np.ndarray) -> None:
        raise NotImplementedError

    # ----- message checks -------------------------------------------------------------------
    def warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log.warning("%s: %s", self.name, text)

    def _values(self, msg) -> np.ndarray | None:
        if isinstance(msg, Float64):
            values = np.array([msg.data], dtype=float)
        elif isinstance(msg, Float64MultiArray):
            values = np.asarray(msg.data, dtype=float)
        else:
            raise InputError(f"{self.name} takes {self.msg_type.__name__}, not {type(msg).__name__}")
        if values.shape != (len(self.rows),):
            self.warn_once("size", f"command has {values.size} values for {len(self.rows)} joints; "
                                   "ignored")
            return None
        if not np.isfinite(values).all():
            self.warn_once("nan", f"command {values.tolist()} is not finite; ignored (the "
                                  "simulation never sees a NaN)")
            return None
        return values

    def _clamp_to_limits(self, values: np.ndarray) -> np.ndarray:
        lower, upper = self.hw.lower[self.rows], self.hw.upper[self.rows]
        clamped = np.clip(values, lower, upper)
        if not np.array_equal(clamped, values):
            bad = np.flatnonzero(clamped != values)
            parts = [f"{self.joints[i]} {values[i]:g} -> {clamped[i]:g}" for i in bad]
            self.warn_once("limit", f"command beyond the joint limits, clamped: {', '.join(parts)}")
        return clamped


def _gains(spec: ControllerSpec, pid_gains: dict[str, PidGains], joints: list[str],
           per_joint: dict[str, PidGains] | None = None) -> list[PidGains] | None:
    """Gains per joint: the controller's pid:, else gazebo_ros_control/pid_gains/<joint>."""
    out = []
    for joint in joints:
        gains = (per_joint or {}).get(joint) or spec.pid or pid_gains.get(joint)
        if gains is None:
            return None
        out.append(gains)
    return out


class PositionController(Controller):
    """effort_controllers/JointPositionController (and the Group and position_controllers
    variants): torque = PID(setpoint - q, v_desired - qdot), or an ideal servo when asked.
    The servo itself lives in the shared ServoBank, so all joints update in one vector step."""

    def __init__(self, spec, hw, bank: ServoBank, gains: list[PidGains] | None, ideal: bool):
        super().__init__(spec, hw)
        self.bank = bank
        self.ideal = ideal
        self.gains = gains

    @property
    def setpoint(self) -> np.ndarray:
        return self.bank.setpoint[self.rows]

    @property
    def needs_update(self) -> bool:
        return self.ideal  # integral terms are the bank's job

    def start(self, t: float) -> None:
        super().start(t)
        if self.ideal:
            self.bank.release(self.rows)
            self.bank.setpoint[self.rows] = self.hw.position(self.rows)  # starting(): hold
            self.bank.velocity[self.rows] = 0.0
        else:
            self.bank.configure(self.rows, self.gains)

    def stop(self) -> None:
        self.running = False
        self.bank.release(self.rows)

    def set_command(self, values: np.ndarray) -> None:
        self.follow(self._clamp_to_limits(values), np.zeros(len(self.rows)))

    def follow(self, position: np.ndarray, velocity: np.ndarray) -> None:
        """Track a (possibly moving) reference; positions are clamped to the joint limits."""
        self.bank.setpoint[self.rows] = np.clip(position, self.hw.lower[self.rows],
                                                self.hw.upper[self.rows])
        self.bank.velocity[self.rows] = velocity
        if not self.ideal:
            self.bank.write(self.rows)

    def update(self, t: float, dt: float) -> None:
        if self.ideal:
            self.hw.teleport(self.rows, self.bank.setpoint[self.rows], self.bank.velocity[self.rows])


class VelocityController(Controller):
    """effort_controllers/JointVelocityController: torque = PID(v_cmd - qdot) with the D term on
    the error's finite difference; velocity_controllers without gains: ideal velocity servo."""

    def __init__(self, spec, hw, gains: list[PidGains] | None):
        super().__init__(spec, hw)
        self.pid = PidArray(gains) if gains else None
        self.target = np.zeros(len(self.rows))

    @property
    def needs_update(self) -> bool:
        return self.pid is None or self.pid.integrates or bool(np.any(self.pid.d != 0))

    def start(self, t: float) -> None:
        super().start(t)
        self.target[:] = 0.0
        if self.pid is None:
            self.hw.release(self.rows)
            return
        self.pid.reset()
        self.hw.set_feedback(self.rows, np.zeros(len(self.rows)), -self.pid.p)
        self.hw.set_u(self.rows, self.pid.p * self.target)

    def set_command(self, values: np.ndarray) -> None:
        limit = np.array([self.hw.sim.robot.joints[j].limit.velocity
                          if self.hw.sim.robot.joints[j].limit else np.inf for j in self.joints])
        limit = np.where(limit > 0, limit, np.inf)
        clamped = np.clip(values, -limit, limit)
        if not np.array_equal(clamped, values):
            self.warn_once("vlimit", f"velocity command {values.tolist()} beyond the URDF velocity "
                                     f"limit, clamped to {clamped.tolist()}")
        self.target = clamped
        if self.pid is not None and not self.needs_update:
            self.hw.set_u(self.rows, self.pid.p * self.target)

    def update(self, t: float, dt: float) -> None:
        if self.pid is None:
            self.hw.teleport(self.rows, None, self.target)
            return
        error = self.target - self.hw.velocity(self.rows)
        rate = self.pid.error_rate(error, dt)
        self.hw.set_u(self.rows, self.pid.p * self.target + self.pid.integral(error, dt)
                      + self.pid.d * rate)


class EffortController(Controller):
    """effort_controllers/JointEffortController and JointGroupEffortController."""

    def start(self, t: float) -> None:
        super().start(t)
        self.hw.release(self.rows)

    def set_command(self, values: np.ndarray) -> None:
        limit = self.hw.effort_limit[self.rows]
        clamped = np.clip(values, -limit, limit)
        if not np.array_equal(clamped, values):
            self.warn_once("effort", f"effort {values.tolist()} beyond the URDF effort limit, "
                                     f"saturated at {clamped.tolist()}")
        self.hw.set_u(self.rows, clamped)


@dataclass
class _Segment:
    t0: float
    t1: float
    p0: np.ndarray
    p1: np.ndarray
    v0: np.ndarray | None
    v1: np.ndarray | None


class TrajectoryController(PositionController):
    """joint_trajectory_controller: time-parameterised waypoints, linear between positions,
    cubic (Hermite) where the points carry velocities; holds the last point when done."""

    msg_type = JointTrajectory

    def __init__(self, spec, hw, bank, gains, ideal):
        super().__init__(spec, hw, bank, gains, ideal)
        self.segments: list[_Segment] = []

    @property
    def needs_update(self) -> bool:
        return True

    def start(self, t: float) -> None:
        super().start(t)
        self.segments = []

    def command(self, msg) -> None:
        if not isinstance(msg, JointTrajectory):
            raise InputError(f"{self.name} takes JointTrajectory, not {type(msg).__name__}")
        order = {name: i for i, name in enumerate(msg.joint_names)}
        missing = [j for j in self.joints if j not in order]
        if missing or not msg.points:
            self.warn_once("traj", f"trajectory without points or joints {missing}; ignored")
            return
        now = self.hw.sim.time
        start = msg.header.stamp.to_sec() or now
        idx = [order[j] for j in self.joints]
        segments, t_prev = [], now
        p_prev, v_prev = self.setpoint.copy(), self.bank.velocity[self.rows].copy()
        for point in msg.points:
            p = np.array([point.positions[i] for i in idx], dtype=float)
            v = np.array([point.velocities[i] for i in idx], dtype=float) if point.velocities else None
            if not np.isfinite(p).all() or (v is not None and not np.isfinite(v).all()):
                self.warn_once("nan", "trajectory point is not finite; trajectory ignored")
                return
            t = start + point.time_from_start.to_sec()
            if t > t_prev:
                segments.append(_Segment(t_prev, t, p_prev, self._clamp_to_limits(p),
                                         v_prev if v is not None else None, v))
            t_prev, p_prev, v_prev = max(t, t_prev), self._clamp_to_limits(p), \
                v if v is not None else np.zeros(len(p))
        if not segments:
            segments.append(_Segment(now, now, p_prev, p_prev, None, None))
        self.segments = segments

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        for seg in self.segments:
            if t < seg.t1:
                h = seg.t1 - seg.t0
                s = min(max((t - seg.t0) / h, 0.0), 1.0)
                if seg.v0 is None or seg.v1 is None:
                    return seg.p0 + s * (seg.p1 - seg.p0), (seg.p1 - seg.p0) / h
                h00, h10, h01, h11 = 2*s**3 - 3*s**2 + 1, s**3 - 2*s**2 + s, -2*s**3 + 3*s**2, s**3 - s**2
                pos = h00 * seg.p0 + h10 * h * seg.v0 + h01 * seg.p1 + h11 * h * seg.v1
                d00, d10, d01, d11 = 6*s**2 - 6*s, 3*s**2 - 4*s + 1, -6*s**2 + 6*s, 3*s**2 - 2*s
                vel = (d00 * seg.p0 + d01 * seg.p1) / h + d10 * seg.v0 + d11 * seg.v1
                return pos, vel
        last = self.segments[-1]
        return last.p1, np.zeros(len(last.p1))

    def update(self, t: float, dt: float) -> None:
        if self.segments:
            self.follow(*self.sample(t))
        super().update(t, dt)


def make_controller(spec: ControllerSpec, hw: SimHardware, bank: ServoBank,
                    pid_gains: dict[str, PidGains]) -> Controller:
    kind = spec.kind
    joints = list(spec.joints)
    if kind == "effort":
        return EffortController(spec, hw)
    gains = _gains(spec, pid_gains, joints, spec.gains)
    if kind == "velocity":
        if gains is None and spec.interface == "EffortJointInterface":
            raise InputError(f"controller '{spec.name}' has no PID gains",
                             file=spec.source, line=spec.line, hint="add pid: {p: ..., d: ...}")
        return VelocityController(spec, hw, gains)
    if gains is None and not spec.ideal_servo:
        raise InputError(f"controller '{spec.name}' has no PID gains", file=spec.source,
                         line=spec.line, hint="add pid: {p: ..., d: ...}, or ideal_servo: true "
                                              "to teleport the joint as Gazebo 7 did")
    cls = TrajectoryController if kind == "trajectory" else PositionController
    return cls(spec, hw, bank, gains, spec.ideal_servo)

