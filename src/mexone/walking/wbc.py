"""The whole-body controller's QP: joint torques and contact forces from the robot's dynamics.

Decision variables x = (q̈, f): the generalised accelerations (nv) and a 3-D force at each of the
four corners of each foot's sole (world frame). Subject to

- the floating base's Newton-Euler equations (the rows no motor drives):
  M_u q̈ + h_u = Σ_c J_c,u^T f_c;
- friction pyramids: f_n >= f_min and abs(f_t) <= μ f_n along the sole's axes; a foot in the air
  carries no force;
- torque limits: abs(τ) <= τ_max with τ = M_a q̈ + h_a - Σ_c J_c,a^T f_c;

it minimises the weighted task errors ``Σ_i w_i ||J_i q̈ + J̇_i q̇ - a_i*||²`` (the COM, the swing
foot, the torso, the posture: `Task`; each foot on the ground held there, J_foot q̈ + J̇_foot q̇ =
a_foot, with a large weight: no slip, no roll, yet never infeasible) plus a small
regularisation of q̈ and f. τ follows from q̈ and f (the actuated rows of the equations of
motion): the motors get torques, no PID under them. Solved by `qpsolvers` (daqp by default)
at the loop's rate.
"""

from __future__ import annotations

import functools
import math
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from mexone.control.student import Param, PythonController, State
from mexone.dynamics import Dynamics
from mexone.walking import body as _body
from mexone.walking import qp
from mexone.walking.footsteps import Steps, swing_point

__all__ = ["Task", "Foot", "WholeBodyQP", "Solution", "corner_jacobians", "sole_corners",
           "WholeBodyController"]


@dataclass
class Task:
    """A weighted acceleration task: ``||J q̈ + drift - target||² * weight``."""

    jacobian: np.ndarray  # (k, nv)
    drift: np.ndarray     # (k,): J̇ q̇
    target: np.ndarray    # (k,): the acceleration wanted (feed-forward + PD)
    weight: float | np.ndarray = 1.0  # scalar or (k,)


@dataclass
class Foot:
    """A foot's sole: its 6-D Jacobian at the sole's centre (world frame, linear rows first), J̇q̇
    there, the sole's rotation (world from sole) and its four corners (sole frame, from its
    centre). `contact`: on the ground (held there, may push) or in the air (free, no force)."""

    jacobian: np.ndarray  # (6, nv)
    drift: np.ndarray     # (6,)
    rotation: np.ndarray  # (3, 3)
    corners: np.ndarray   # (4, 3)
    contact: bool
    target: np.ndarray | None = None  # (6,): the acceleration held on the ground (default 0)


@dataclass
class Solution:
    """The QP's answer: accelerations, each sole corner's force, the motors' torques."""

    qdd: np.ndarray     # (nv,)
    forces: np.ndarray  # (n_feet, 4, 3) world frame, on the robot
    tau: np.ndarray     # (n_actuated,) in `actuated`'s order


def sole_corners(length: float, width: float, offset: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """(4, 3) corners of a rectangular sole (m), about its centre shifted by `offset` (x, y)."""
    x, y = length / 2, width / 2
    ox, oy = offset
    return np.array([[ox + x, oy + y, 0], [ox + x, oy - y, 0], [ox - x, oy - y, 0], [ox - x, oy + y, 0]],
                    dtype=float)


def corner_jacobians(foot: Foot) -> np.ndarray:
    """(4, 3, nv): the linear Jacobian of each corner, from the centre's 6-D one
    (v_p = v + ω × r = J_v q̇ - [r]× J_ω q̇)."""
    lin, ang = foot.jacobian[:3], foot.jacobian[3:]
    out = np.empty((4, 3, lin.shape[1]))
    for i, corner in enumerate(foot.corners):
        r = foot.rotation @ corner
        # [r]x J_w, row by row
        out[i, 0] = lin[0] - (r[1] * ang[2] - r[2] * ang[1])
        out[i, 1] = lin[1] - (r[2] * ang[0] - r[0] * ang[2])
        out[i, 2] = lin[2] - (r[0] * ang[1] - r[1] * ang[0])
    return out


class WholeBodyQP:
    """The QP above for a robot with `nv` dofs of which `actuated` (indices) have motors with
    `effort_limit` (N m); `mu`: the friction coefficient the pyramids use (keep it under the
    real one); `min_force`: N each corner of a foot on the ground pushes at least (keeps the
    sole flat: every corner loaded).

    The corner forces are solved in their sole's frame (f = R f'), where the pyramids are
    constant rows (abs(f'_x), abs(f'_y) <= mu f'_z) and f'_z >= f_min a bound; a foot's four
    corner forces act on the robot as the wrench W0 f' at the sole's centre (W0 constant in the
    sole frame), so J_c^T f = (R^T J_foot)^T W0 f'. A foot in the air has no force variables."""

    def __init__(self, nv: int, actuated: Sequence[int] | np.ndarray,
                 effort_limit: Sequence[float] | np.ndarray,
                 n_feet: int = 2, mu: float = 0.6, min_force: float = 0.5,
                 accel_weight: float = 1e-6, force_weight: float = 1e-5, contact_weight: float = 1e3,
                 solver: str = "daqp"):
        self.nv, self.n_feet = nv, n_feet
        self.actuated = np.asarray(actuated, dtype=int)
        self.unactuated = np.setdiff1d(np.arange(nv), self.actuated)
        self.limit = np.asarray(effort_limit, dtype=float)
        self.mu, self.min_force = mu, min_force
        self.accel_weight, self.force_weight = accel_weight, force_weight
        self.contact_weight = contact_weight
        self.solver = qp.check_solver(solver)
        self.nf = 12 * n_feet
        self.nx = nv + self.nf
        # the pyramid's rows for one foot's 12 sole-frame corner forces: ±f'_t - mu f'_z <= 0
        self._pyramid = np.zeros((16, 12))
        for c in range(4):
            for r, (axis, sign) in enumerate(((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):
                self._pyramid[4 * c + r, 3 * c + axis] = sign
                self._pyramid[4 * c + r, 3 * c + 2] = -mu
        self._regularisation = np.concatenate([np.full(nv, accel_weight), np.full(self.nf, force_weight)])
        self._shapes: dict[int, _Shape] = {}  # per number of feet down: what does not change

    def _shape(self, n_down: int) -> _Shape:
        """The parts of the QP fixed by how many feet are down (built once each: an update only
        fills in the rows that change)."""
        shape = self._shapes.get(n_down)
        if shape is None:
            nv, na, nu = self.nv, len(self.actuated), len(self.unactuated)
            nx = nv + 12 * n_down
            G = np.zeros((nu + na + 16 * n_down, nx))
            for k in range(n_down):
                G[nu + na + 16 * k:nu + na + 16 * (k + 1), nv + 12 * k:nv + 12 * (k + 1)] = self._pyramid
            lb = np.full(nx, -np.inf)
            lb[nv + 2::3] = self.min_force
            lb.flags.writeable = False
            shape = self._shapes[n_down] = _Shape(G, lb, np.diag_indices(nx), np.zeros(16 * n_down),
                                                  np.full(16 * n_down, -np.inf))
        return shape

    def solve(self, M: np.ndarray, h: np.ndarray, tasks: Sequence[Task], feet: Sequence[Foot]
              ) -> Solution:
        """The torques, forces and accelerations now; qp.Infeasible when there are none."""
        nv = self.nv
        down = [foot for foot in feet if foot.contact]
        nf = 12 * len(down)
        nx = nv + nf
        # the cost: every task's rows stacked, weighted by the square root of their weights
        rows, rhs = [], []
        for task in tasks:
            w = np.sqrt(np.asarray(task.weight, dtype=float))
            rows.append(task.jacobian * (w[:, None] if w.ndim else w))
            rhs.append((task.target - task.drift) * w)
        held = math.sqrt(self.contact_weight)
        jct = np.empty((nv, nf))  # J_c^T for each corner's sole-frame force
        for k, foot in enumerate(down):
            # held on the ground: a stiff task rather than an equality, so torque limits never
            # make the QP infeasible (the foot would rather slip a little than the QP fail)
            target = np.zeros(6) if foot.target is None else foot.target
            rows.append(foot.jacobian * held)
            rhs.append((target - foot.drift) * held)
            rt = foot.rotation.T
            local = np.vstack([rt @ foot.jacobian[:3], rt @ foot.jacobian[3:]])  # (6, nv)
            corners = np.ascontiguousarray(foot.corners, dtype=float).tobytes()
            jct[:, 12 * k:12 * (k + 1)] = local.T @ _wrench_map(corners)
        shape = self._shape(len(down))
        J = np.vstack(rows)
        P = np.zeros((nx, nx))
        P[:nv, :nv] = J.T @ J
        q = np.zeros(nx)
        q[:nv] = -(J.T @ np.concatenate(rhs))
        P[shape.diagonal] += self._regularisation[:nx]
        # the unactuated rows of M q̈ + h = S^T τ + J_c^T f (equalities), then the torque limits
        # on τ = M_a q̈ + h_a - J_c,a^T f and the pyramids (two-sided where they can be)
        na, nu = len(self.actuated), len(self.unactuated)
        G = shape.G  # its pyramid rows filled once; the rows below are all written each time
        G[:nu, :nv] = M[self.unactuated]
        G[:nu, nv:] = -jct[self.unactuated]
        act = G[nu:nu + na]
        act[:, :nv] = M[self.actuated]
        act[:, nv:] = -jct[self.actuated]
        h_a = h[self.actuated]
        high = np.concatenate([self.limit - h_a, shape.high])
        low = np.concatenate([-self.limit - h_a, shape.low])
        lb = shape.lb if self.solver == "daqp" else shape.lb.copy()  # daqp reads it only
        x = qp.solve(P, q, G[nu:], high, G[:nu], -h[self.unactuated], lb=lb, G_low=low,
                     solver=self.solver, what="whole-body QP")
        qdd = x[:nv]
        forces = np.zeros((self.n_feet, 4, 3))
        k = 0
        for i, foot in enumerate(feet):
            if foot.contact:
                forces[i] = x[nv + 12 * k:nv + 12 * (k + 1)].reshape(4, 3) @ foot.rotation.T
                k += 1
        tau = act[:, :nv] @ qdd + act[:, nv:] @ x[nv:] + h_a
        return Solution(qdd, forces, tau)


@dataclass
class _Shape:
    """A WholeBodyQP's fixed parts for a number of feet down: the inequality rows' matrix (its
    pyramid rows set, the rest overwritten by each solve), the variables' lower bounds, the
    cost's diagonal, the pyramids' upper and lower sides."""

    G: np.ndarray
    lb: np.ndarray
    diagonal: tuple[np.ndarray, ...]
    high: np.ndarray
    low: np.ndarray


@functools.lru_cache(maxsize=16)
def _wrench_map(corners: bytes) -> np.ndarray:
    """(6, 12): the wrench at the sole's centre (force, moment) of its corners' forces (4, 3
    float64, as bytes: cached per sole), all in the sole's frame: [I ... I; [r_1]x ... [r_4]x]."""
    out = np.zeros((6, 12))
    for c, (x, y, z) in enumerate(np.frombuffer(corners).reshape(4, 3)):
        out[:3, 3 * c:3 * c + 3] = np.eye(3)
        out[3:, 3 * c:3 * c + 3] = [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]
    return out


# ----- the plug-in: the whole-body controller in the manager's loop ----------------------------

NAN = float("nan")


class WholeBodyController(PythonController):
    """Torque-level whole-body control: the QP above at the loop's rate, every joint through the
    effort interface.

    Reads (chained inputs; each optional): `steps` (the footstep planner's `Steps`: which foot
    is in the air and where it lands, when), `com` (9: the COM's position, velocity and
    acceleration wanted, world frame), `landing` (5: foot, x, y, z, yaw: the COM planner's
    adjusted landing of the foot in the air), `base` (13: the estimator's position, quaternion
    w x y z, linear velocity (world) and angular velocity (base frame): the base's state it
    computes the dynamics at; unbound, the simulator's). Without `com` it stands over its feet.
    Exports `status` (2: 1 while it controls, 0 after a safe stop; the QP's solve time, ms).

    The safe stop: a step out of reach or not finite is refused in one line and the robot
    stands (both feet down, the COM over them, the plan ignored until a restart); a QP with no
    solution (a NaN from upstream) is one line and the joints hold where they are, gravity
    compensated."""

    command_interface = "effort"
    inputs = {"steps": Steps.LENGTH, "com": 9, "landing": 5, "base": 13}
    exports = {"status": 2}
    optional_inputs = ("steps", "com", "landing", "base")

    kp_com = Param(60.0, low=0.0, high=1e4, doc="COM stiffness", unit="1/s^2")
    kd_com = Param(15.0, low=0.0, high=1e3, doc="COM damping", unit="1/s")
    kp_foot = Param(700.0, low=0.0, high=1e5, doc="swing foot stiffness", unit="1/s^2")
    kd_foot = Param(53.0, low=0.0, high=1e3, doc="swing foot damping", unit="1/s")
    kp_torso = Param(200.0, low=0.0, high=1e5, doc="torso attitude stiffness", unit="1/s^2")
    kd_torso = Param(30.0, low=0.0, high=1e3, doc="torso attitude damping", unit="1/s")
    kp_posture = Param(50.0, low=0.0, high=1e5, doc="posture stiffness", unit="1/s^2")
    kd_posture = Param(10.0, low=0.0, high=1e3, doc="posture damping", unit="1/s")
    w_com = Param(100.0, low=0.0, high=1e6, doc="COM task weight")
    w_foot = Param(10.0, low=0.0, high=1e6, doc="swing foot task weight")
    w_torso = Param(10.0, low=0.0, high=1e6, doc="torso task weight")
    w_posture = Param(0.05, low=0.0, high=1e6, doc="posture task weight")
    mu = Param(0.6, low=0.05, high=2.0, doc="friction coefficient the QP assumes")
    com_height = Param(0.0, low=0.0, high=2.0, doc="COM above the soles when standing (0: as it starts)",
                       unit="m")
    step_height = Param(0.04, low=0.0, high=0.2, doc="swing foot's lift", unit="m")
    max_reach = Param(0.6, low=0.05, high=2.0, doc="a landing further from the standing foot is "
                      "refused (the robot stands)", unit="m")
    solver = Param("daqp", choices=("daqp", "proxqp", "osqp", "quadprog"), doc="qpsolvers' solver")

    def configure(self) -> None:
        model = self.dynamics.model
        self.body = _body.Body.of(model, self.joints)
        self.qp = WholeBodyQP(model.nv, self.dofs, self.effort_limits, mu=self.mu, solver=self.solver)
        self.corners = sole_corners(*_body.SOLE_SIZE)
        self.damping = model.dof_damping[self.dofs].copy()
        self.scratch = mujoco.MjData(model)
        self.dyn = _body.state_dynamics(model, self.scratch)
        self.posture = self.body.posture()
        self.stopped: str | None = None  # the QP failed: the joints hold (the safe stop's end)
        self.standing: str | None = None  # bad input: it stands, the plan ignored
        self.finish: np.ndarray | None = None  # the step that lands before it stands
        self.solve_times: deque[float] = deque(maxlen=5000)  # the last 5000: bounded
        self.swing_from: dict[int, np.ndarray] = {}
        self._posture_rows: tuple[np.ndarray, np.ndarray] | None = None

    def activate(self, state: State) -> None:
        self.stopped = self.standing = self.finish = None
        dyn = self._dynamics(state)
        soles = [self._sole(dyn, f) for f in range(2)]
        self.home = [np.array([*p, _body.yaw_of(r)]) for p, r in soles]  # x y z yaw per foot
        middle = (soles[0][0] + soles[1][0]) / 2
        self.height = self.com_height or float(dyn.com()[2] - middle[2])
        self.start_com = dyn.com()
        self.start_t = state.time
        self.q0 = state.q.copy()

    # ----- reading the state ----------------------------------------------------------------
    def _input(self, state: State, name: str) -> np.ndarray | None:
        inputs = getattr(state, "inputs", None)
        if not inputs or name not in inputs:
            return None
        value = inputs[name]
        return None if not np.isfinite(value[0]) else value

    def _dynamics(self, state: State) -> Dynamics:
        d = self.scratch
        d.qpos[:] = state.all_q
        d.qvel[:] = state.all_dq
        base = self._input(state, "base")
        if base is not None:
            d.qpos[:3], d.qpos[3:7] = base[:3], base[3:7]
            d.qvel[:3], d.qvel[3:6] = base[7:10], base[10:13]
        self.dyn.refresh()
        return self.dyn

    def _sole(self, dyn: Dynamics, foot: int) -> tuple[np.ndarray, np.ndarray]:
        p, r = dyn.pose(_body.FEET[foot])
        return p + r @ _body.SOLE_OFFSET, r

    # ----- the update -------------------------------------------------------------------------
    def update(self, state: State, t: float, dt: float) -> np.ndarray | None:
        if self.stopped is not None:
            return self._hold(state)
        dyn = self._dynamics(state)
        steps = self._input(state, "steps") if self.standing is None else None
        swing = Steps.swing_now(steps, t) if steps is not None else None
        if swing is not None:
            swing = swing.copy()
            swing[1:5] = self._target(state, swing)
            if (problem := self._unreachable(dyn, swing)) is not None:
                self._stand(t, problem)
                swing = None
        ref = self._input(state, "com") if self.standing is None else None
        if ref is not None and not np.all(np.isfinite(ref)):
            self._stand(t, "the COM reference is not finite", finish=swing)
            ref = None
        if self.standing is not None and self.finish is not None:  # the step under way lands
            if t < self.finish[8]:
                swing = self.finish
            else:
                self.finish, self.start_com, self.start_t = None, dyn.com(), t
        feet, tasks = [], []
        dq = self.scratch.qvel
        for f in range(2):
            centre, rot = self._sole(dyn, f)
            jac = dyn.jacobian(_body.FEET[f], centre)
            drift = dyn.jacobian_dot_qdot(_body.FEET[f], centre)
            in_air = swing is not None and int(swing[0]) == f
            feet.append(Foot(jac, drift, rot, self.corners, not in_air,
                             target=-20.0 * (jac @ dq)))
            if in_air and swing is not None:
                tasks.append(self._swing_task(swing, f, centre, rot, jac, drift, dq, t))
            elif f in self.swing_from:
                del self.swing_from[f]
        tasks.append(self._com_task(ref, swing, dyn, dq, t))
        tasks.append(self._torso_task(dyn, dq, feet))
        tasks.append(self._posture_task(state))
        start = time.perf_counter()
        try:
            sol = self.qp.solve(dyn.mass_matrix(), dyn.bias(), tasks, feet)
        except Exception as exc:  # noqa: BLE001 - an infeasible QP stops safely
            return self._stop(state, f"{exc}")
        self.solve_times.append(time.perf_counter() - start)
        self.exports["status"][:] = (1.0, self.solve_times[-1] * 1e3)
        return sol.tau + self.damping * state.dq

    def _target(self, state: State, swing: np.ndarray) -> np.ndarray:
        """Where the step in the air lands (x, y, z, yaw): the COM planner's `landing` when it
        moved it, else the plan's."""
        landing = self._input(state, "landing")
        moved = landing is not None and int(landing[0]) == int(swing[0])
        return landing[1:5] if moved and landing is not None else swing[1:5]

    def _unreachable(self, dyn: Dynamics, swing: np.ndarray) -> str | None:
        """Why the step in the air cannot be taken (not finite, or further from the standing
        foot than the legs reach), or None."""
        target = swing[1:5]
        if not np.all(np.isfinite(target)) or not np.all(np.isfinite(swing[7:9])):
            return "a step to a position that is not finite"
        stance = self._sole(dyn, 1 - int(swing[0]))[0]
        reach = float(np.linalg.norm(target[:2] - stance[:2]))
        if reach > self.max_reach or abs(target[2] - stance[2]) > self.max_reach / 2:
            return (f"a step to ({target[0]:.3f}, {target[1]:.3f}, {target[2]:.3f}) m, "
                    f"{reach:.2f} m from the standing foot (the legs reach {self.max_reach:g} m)")
        return None

    def _stand(self, t: float, why: str, finish: np.ndarray | None = None) -> None:
        """The safe stop's first stage: the step under way (`finish`) lands where it was going,
        then both feet down, the COM over them, the plan ignored."""
        if self.standing is None:
            self.standing, self.finish = why, finish
            self.log.error("%s at t = %.3f s: refused, the robot stands (the plan is ignored until "
                           "the controller is restarted)", why, t)
            self.start_com = self.dyn.com()
            self.start_t = t

    def _com_task(self, ref: np.ndarray | None, swing: np.ndarray | None, dyn: Dynamics, dq: np.ndarray,
                  t: float) -> Task:
        c, jc = dyn.com(), dyn.com_jacobian()
        v = jc @ dq
        if ref is None:  # stand: over the feet's middle (the standing foot while one is up)
            soles = [self._sole(dyn, f)[0] for f in range(2)]
            middle = (soles[0] + soles[1]) / 2
            if swing is not None:
                middle = soles[1 - int(swing[0])]
            ramp = min(1.0, (t - self.start_t) / 1.0)
            goal = np.array([*middle[:2], middle[2] + self.height])
            goal = self.start_com + (goal - self.start_com) * (3 * ramp**2 - 2 * ramp**3)
            ref = np.concatenate([goal, np.zeros(6)])
        acc = ref[6:9] + self.kp_com * (ref[:3] - c) + self.kd_com * (ref[3:6] - v)
        # the COM's J̇q̇ by finite difference is not in Dynamics: the centroidal drift is small
        return Task(jc, np.zeros(3), acc, self.w_com)

    def _torso_task(self, dyn: Dynamics, dq: np.ndarray, feet: list[Any]) -> Task:
        p, r = dyn.pose(_body.TORSO)
        jac = dyn.jacobian(_body.TORSO)[3:]
        yaw = math.atan2(feet[0].rotation[1, 0] + feet[1].rotation[1, 0],
                         feet[0].rotation[0, 0] + feet[1].rotation[0, 0])
        want = _body.rot_z(yaw)
        err = _rotation_error(want, r)
        w = jac @ dq
        acc = self.kp_torso * err - self.kd_torso * w
        return Task(jac, dyn.jacobian_dot_qdot(_body.TORSO)[3:], acc, self.w_torso)

    def _posture_task(self, state: State) -> Task:
        if self._posture_rows is None:  # the joints' rows of the identity: built once
            jac = np.zeros((len(self.dofs), self.scratch.qvel.shape[0]))
            jac[np.arange(len(self.dofs)), self.dofs] = 1.0
            drift = np.zeros(len(self.dofs))
            jac.flags.writeable = drift.flags.writeable = False
            self._posture_rows = (jac, drift)
        acc = self.kp_posture * (self.posture - state.q) - self.kd_posture * state.dq
        jacobian, drift = self._posture_rows
        return Task(jacobian, drift, acc, self.w_posture)

    def _swing_task(self, swing: np.ndarray, f: int, centre: np.ndarray, rot: np.ndarray,
                    jac: np.ndarray, drift: np.ndarray, dq: np.ndarray, t: float) -> Task:
        if f not in self.swing_from:  # where it lifted from: x y z yaw, and its pitch and roll
            self.swing_from[f] = np.array([*centre, _body.yaw_of(rot), math.asin(-rot[2, 0]),
                                           math.atan2(rot[2, 1], rot[2, 2])])
        start = self.swing_from[f]
        target = swing[1:5]
        pos, vel, acc = swing_point(start, target, swing[7], swing[8], t, self.step_height)
        # the sole turns from its pitch and roll at lift-off to the ground's where it lands
        s = min(max((t - swing[7]) / max(swing[8] - swing[7], 1e-6), 0.0), 1.0)
        pitch, roll = start[4:6] + (swing[5:7] - start[4:6]) * s
        want = _body.rot_z(pos[3]) @ _body.rot_y(pitch) @ _body.rot_x(roll)
        err_r = _rotation_error(want, rot)
        v = jac @ dq
        a = np.empty(6)
        a[:3] = acc[:3] + self.kp_foot * (pos[:3] - centre) + self.kd_foot * (vel[:3] - v[:3])
        a[3:] = self.kp_foot * err_r + self.kd_foot * (np.array([0, 0, vel[3]]) - v[3:])
        return Task(jac, drift, a, self.w_foot)

    # ----- the safe stop ------------------------------------------------------------------------
    def _stop(self, state: State, why: str) -> np.ndarray:
        self.stopped = why
        self.log.error("%s: holding the robot where it stands (a safe stop)", why)
        self.q_hold = state.q.copy()
        self.exports["status"][:] = (0.0, NAN)
        return self._hold(state)

    def _hold(self, state: State) -> np.ndarray:
        """Stand, then hold: the joints' PD about where the stop found them, gravity compensated."""
        g = self.dynamics.gravity()[self.dofs]
        return g + 200.0 * (self.q_hold - state.q) - 5.0 * state.dq

    def report(self) -> dict[str, Any]:
        times = np.asarray(self.solve_times) * 1e3
        out: dict[str, Any] = {"stopped": self.stopped, "standing": self.standing}
        if len(times):
            out.update(qp_ms_median=round(float(np.median(times)), 3),
                       qp_ms_p99=round(float(np.percentile(times, 99)), 3))
        return out


def _rotation_error(want: np.ndarray, have: np.ndarray) -> np.ndarray:
    """The world-frame rotation vector taking `have` to `want` (small angles: log map)."""
    err = want @ have.T
    quat = _body.matrix_to_quat(err)
    if quat[0] < 0:
        quat = -quat
    angle = 2 * math.atan2(np.linalg.norm(quat[1:]), quat[0])
    n = np.linalg.norm(quat[1:])
    return quat[1:] / n * angle if n > 1e-12 else np.zeros(3)

