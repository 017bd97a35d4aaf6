"""The centre-of-mass planner: linear MPC of the linear inverted pendulum (Wieber 2006), with the
next footstep's landing as a decision variable (Herdt et al. 2010) so a push moves the step.

Each axis of the COM is a triple integrator, state x = (c, ċ, c̈), input the jerk j held over a
sample T: x+ = A x + B j. The zero-moment point of the cart-table is z = c - (h/g) c̈. Over N
samples ahead, stacked: Z = P_zs x0 + P_zu J. The QP (per solve, both axes and the landing
shift d = (dx, dy))::

    min  w_z ||Z - Z_ref - E d||² + w_j ||J||² + w_d ||d||² + w_ξ ||ξ_N - Z_ref,N - E_N d||²
    s.t. |R(θ_k)^T (Z_k - centre_k - E_k d)| <= half_size_k    (the ZMP inside the support)
         |d| <= max_shift

where E_k is 1 where the support at sample k is the shifted landing's (or later) and the
support is the standing foot's sole (single support) or the corridor between both soles'
centres (double support), shrunk by a margin; ξ_N = c_N + ċ_N / ω, the divergent component of
motion (the capture point) at the horizon's end, is brought onto the last ZMP reference, so the
plan stays balanced beyond its horizon (without it a ZMP-tracking MPC lets the COM run away
where it no longer looks). The first jerk is applied; the plan is solved again
from the measured COM (position, velocity) at the controller's rate.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from mexone.control.student import Param, PythonController, State
from mexone.dynamics import Dynamics
from mexone.walking import body as _body
from mexone.walking import qp
from mexone.walking.footsteps import Steps

__all__ = ["LipmMpc", "Support", "Reach", "supports", "lipm_matrices", "ComPlanner"]

G = 9.81
HEIGHT_TIME = 0.2  # s: the COM height's time constant following the ground under the feet


def lipm_matrices(T: float, n: int, h: float) -> tuple[np.ndarray, ...]:
    """(A, B, P_ps, P_pu, P_vs, P_vu, P_as, P_au, P_zs, P_zu): the sample-to-sample model and
    the stacked predictions of position, velocity, acceleration and ZMP over n samples."""
    A = np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
    B = np.array([T**3 / 6, T * T / 2, T])
    rows = {}
    Ak = np.eye(3)
    s = np.zeros((n, 3, 3))
    u = np.zeros((n, 3, n))
    for k in range(n):
        Ak = A @ Ak
        s[k] = Ak
        for i in range(k + 1):
            u[k, :, i] = np.linalg.matrix_power(A, k - i) @ B
    rows["p"], rows["v"], rows["a"] = 0, 1, 2
    ps, vs, as_ = s[:, 0], s[:, 1], s[:, 2]
    pu, vu, au = u[:, 0], u[:, 1], u[:, 2]
    zs, zu = ps - (h / G) * as_, pu - (h / G) * au
    return A, B, ps, pu, vs, vu, as_, au, zs, zu


@dataclass
class Support:
    """Where the ZMP may be at each sample: rectangles (centre (n, 2), yaw (n,), half sizes (n, 2)),
    the ZMP reference (n, 2), and E (n, m): how much each of the m planned landings' shifts moves
    the support at each sample (1 where the foot it put down stands alone, 1/2 in double
    support; the landings up to the last one the horizon sees). `landings` (m, 4): each step's
    foot, x, y, yaw as planned; `feet` (2, 3): each foot's x, y, yaw on the ground now."""

    centre: np.ndarray
    yaw: np.ndarray
    half: np.ndarray
    ref: np.ndarray
    shifted: np.ndarray
    landings: np.ndarray
    feet: np.ndarray


@dataclass(frozen=True)
class Reach:
    """Where a landing may be moved, relative to the foot standing when it lands (in that
    landing's heading frame): across, between `min_apart` and `max_apart` out to its side;
    along, from `back` behind to `forward` ahead (m)."""

    min_apart: float = 0.09
    max_apart: float = 0.45
    forward: float = 0.25
    back: float = 0.15


def _feet_at(steps: np.ndarray, rows: np.ndarray,
             taus: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each foot's (x, y, yaw) at the times `taus` (2, n, 3), whether it is in the air (2, n)
    and which planned step (its row's index) put it where it stands (2, n; -1: none yet)."""
    n = len(taus)
    feet = Steps.feet(steps)
    pose = np.repeat(feet[:, None, [0, 1, 3]], n, axis=1)
    air = np.zeros((2, n), dtype=bool)
    by = np.full((2, n), -1)
    for i in np.argsort(rows[:, 8], kind="stable") if len(rows) else ():
        row = rows[i]
        f = int(row[0])
        air[f] |= (row[7] <= taus) & (taus < row[8])
        landed = taus >= row[8]
        pose[f, landed] = row[[1, 2, 4]]
        by[f, landed] = i
    return pose, air, by


def supports(steps: np.ndarray, t: float, T: float, n: int, sole: tuple[float, float],
             margin: float) -> Support:
    """The support rectangles and ZMP reference at the n samples after t."""
    rows = Steps.rows(steps)
    m = len(rows)
    a, b = sole[0] / 2 - margin, sole[1] / 2 - margin
    taus = t + T * np.arange(1, n + 1)
    pose, air, by = _feet_at(steps, rows, taus)
    onehot = [np.zeros((n, m)), np.zeros((n, m))]  # foot f stands where step i put it
    for f in range(2):
        put = np.flatnonzero(by[f] >= 0)
        onehot[f][put, by[f, put]] = 1.0
    # double support: the corridor between the soles' centres
    p0, p1 = pose[0, :, :2], pose[1, :, :2]
    delta = p1 - p0
    dist = np.hypot(delta[:, 0], delta[:, 1])
    th = np.arctan2(delta[:, 1], delta[:, 0])
    heading = np.arctan2(np.sin(pose[0, :, 2]) + np.sin(pose[1, :, 2]),
                         np.cos(pose[0, :, 2]) + np.cos(pose[1, :, 2]))
    across = np.abs(np.cos(th - heading))  # 1: the corridor runs along the feet's length
    centre = (p0 + p1) / 2
    yaw = th.copy()
    half = np.stack([dist / 2 + a * across + 0.5 * b * (1 - across), a * (1 - across) + b * across], axis=1)
    shifted = 0.5 * (onehot[0] + onehot[1])
    # the ZMP moves from the last stance foot to the next one across a double support
    lifts = rows[np.argsort(rows[:, 7])] if len(rows) else rows
    ref = centre.copy()
    both = np.flatnonzero(~(air[0] | air[1]))
    if len(lifts) and len(both):
        tk = taus[both]
        nxt = np.searchsorted(lifts[:, 7], tk - 1e-9)  # the first step lifting at or after tau
        before = np.maximum(nxt - 1, 0)
        prev = (nxt > 0) & (lifts[before, 8] <= tk + 1e-9)  # a step landed before tau
        standing_prev = 1 - lifts[before, 0].astype(int)
        start = np.where(prev[:, None], pose[standing_prev, both, :2], centre[both])
        t0 = np.where(prev, lifts[before, 8], t)
        ahead = nxt < len(lifts)
        after = np.minimum(nxt, len(lifts) - 1)
        goal = np.where(ahead[:, None], pose[1 - lifts[after, 0].astype(int), both, :2], centre[both])
        t1 = np.where(ahead, lifts[after, 7], t0 + 0.2)
        sfrac = np.clip((tk - t0) / np.maximum(t1 - t0, 1e-6), 0.0, 1.0)
        ref[both] = start + (goal - start) * (3 * sfrac**2 - 2 * sfrac**3)[:, None]
    # single support: the standing foot's sole
    for f in range(2):
        single = air[1 - f]
        centre[single] = pose[f, single, :2]
        ref[single] = pose[f, single, :2]
        yaw[single] = pose[f, single, 2]
        half[single] = (a, b)
        shifted[single] = onehot[f][single]
    # landings beyond the horizon move nothing in it: left out of the QP (the first kept)
    used = np.flatnonzero(shifted.any(axis=0))
    m = max(int(used[-1]) + 1 if len(used) else 0, min(1, m))
    return Support(centre, yaw, half, ref, shifted[:, :m], rows[:m, [0, 1, 2, 4]].copy(),
                   Steps.feet(steps)[:, [0, 1, 3]].copy())


class LipmMpc:
    """The QP above for a COM at height `h` (m), `n` samples of `T` s."""

    def __init__(self, h: float, T: float = 0.1, n: int = 16, w_zmp: float = 1.0,
                 w_jerk: float = 1e-6, w_shift: float = 1.0, max_shift: float = 0.06,
                 w_dcm: float = 10.0, solver: str = "daqp"):
        self.h, self.T, self.n = h, T, n
        self.w_dcm = w_dcm
        self.w_zmp, self.w_jerk, self.w_shift, self.max_shift = w_zmp, w_jerk, w_shift, max_shift
        self.solver = qp.check_solver(solver)
        (self.A, self.B, self.ps, self.pu, self.vs, self.vu, self.as_, self.au,
         self.zs, self.zu) = lipm_matrices(T, n, h)
        omega = np.sqrt(G / h)
        # the capture point at the last sample: xi = xs x0 + xu J
        self.xi_s = self.ps[-1] + self.vs[-1] / omega
        self.xi_u = self.pu[-1] + self.vu[-1] / omega
        self.qz = self.zu.T @ self.zu + w_dcm / w_zmp * np.outer(self.xi_u, self.xi_u)
        self._hj = w_zmp * self.qz + w_jerk * np.eye(n)  # the jerks' block, never changing
        self._zuT = np.ascontiguousarray(self.zu.T)

    def solve(self, x0: np.ndarray, y0: np.ndarray, support: Support, adjustable: bool = True,
              fixed_shift: np.ndarray | None = None,
              reach: Reach | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(jerk x (n,), jerk y (n,), each planned landing's shift (m, 2)) from the COM's states
        x0, y0 (c, ċ, c̈). Not `adjustable`: the first landing's shift is `fixed_shift`
        (default 0: as planned; it is about to land). `reach`: each landing stays within reach
        of the foot standing when it lands (the first one's: where it stands now)."""
        n, m, wz, wd = self.n, support.shifted.shape[1], self.w_zmp, self.w_dcm
        nx = 2 * n + 2 * m
        E = support.shifted
        eN = E[-1]
        zu, zuT = self.zu, self._zuT
        zsx, zsy = self.zs @ x0, self.zs @ y0
        # the Hessian: the jerks' blocks, their coupling with the shifts, the shifts' own
        P = np.zeros((nx, nx))
        P[:n, :n] = P[n:2 * n, n:2 * n] = self._hj
        if m:
            ze = -(wz * (zuT @ E) + wd * np.outer(self.xi_u, eN))  # (n, m)
            ee = wz * (E.T @ E) + wd * np.outer(eN, eN) + self.w_shift * np.eye(m)
            sx, sy = slice(2 * n, 2 * n + m), slice(2 * n + m, nx)
            P[:n, sx] = P[n:2 * n, sy] = ze
            P[sx, :n] = P[sy, n:2 * n] = ze.T
            P[sx, sx] = P[sy, sy] = ee
        ref = support.ref
        ex, ey = zsx - ref[:, 0], zsy - ref[:, 1]
        xix = self.xi_s @ x0 - ref[-1, 0]
        xiy = self.xi_s @ y0 - ref[-1, 1]
        q = np.empty(nx)
        q[:n] = wz * (zuT @ ex) + (wd * xix) * self.xi_u
        q[n:2 * n] = wz * (zuT @ ey) + (wd * xiy) * self.xi_u
        q[2 * n:2 * n + m] = -wz * (E.T @ ex) - (wd * xix) * eN
        q[2 * n + m:] = -wz * (E.T @ ey) - (wd * xiy) * eN
        # the ZMP inside each sample's rectangle: -half <= R(θ)^T (z - centre) <= half, rows
        # along (u) and across (w) the rectangle, each two-sided
        c, s = np.cos(support.yaw), np.sin(support.yaw)
        gx, gy = zsx - support.centre[:, 0], zsy - support.centre[:, 1]
        du, dw = c * gx + s * gy, -s * gx + c * gy
        rows = np.empty((2 * n, nx))
        cz, sz = c[:, None] * zu, s[:, None] * zu
        cE, sE = c[:, None] * E, s[:, None] * E
        rows[:n, :n], rows[:n, n:2 * n], rows[:n, 2 * n:2 * n + m], rows[:n, 2 * n + m:] = cz, sz, -cE, -sE
        rows[n:, :n], rows[n:, n:2 * n], rows[n:, 2 * n:2 * n + m], rows[n:, 2 * n + m:] = -sz, cz, sE, -cE
        half = support.half
        high = np.concatenate([half[:, 0] - du, half[:, 1] - dw])
        low = np.concatenate([-half[:, 0] - du, -half[:, 1] - dw])
        lb = np.full(nx, -np.inf)
        ub = np.full(nx, np.inf)
        lb[2 * n:], ub[2 * n:] = -self.max_shift, self.max_shift
        if m and not adjustable:
            fixed = np.zeros(2) if fixed_shift is None else np.asarray(fixed_shift, dtype=float)
            lb[2 * n], lb[2 * n + m] = fixed
            ub[2 * n], ub[2 * n + m] = fixed
        if m and reach is not None:
            extra, extra_low, extra_high = _reach_rows(support, reach, n, m, adjustable)
            rows = np.vstack([rows, extra])
            low, high = np.concatenate([low, extra_low]), np.concatenate([high, extra_high])
        v = qp.solve(P, q, rows, high, lb=lb, ub=ub, G_low=low, solver=self.solver, what="COM MPC")
        return v[:n], v[n:2 * n], np.stack([v[2 * n:2 * n + m], v[2 * n + m:]], axis=1)

    @staticmethod
    def advance(x: np.ndarray, jerk: float, dt: float) -> np.ndarray:
        """The axis state after dt of constant jerk."""
        return np.array([x[0] + x[1] * dt + x[2] * dt * dt / 2 + jerk * dt**3 / 6,
                         x[1] + x[2] * dt + jerk * dt * dt / 2, x[2] + jerk * dt])


def _reach_rows(support: Support, reach: Reach, n: int, m: int, first: bool = True
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two-sided rows (across, along) keeping each landing within reach of the foot standing
    when it lands: the other foot's landing before it (its shift a variable too) or where that
    foot stands now. A landing planned out of reach may stay where planned (the rows never make
    the plan as given infeasible: a moved landing only comes closer); `first` False: the first
    landing (fixed, about to land) has no rows."""
    nx = 2 * n + 2 * m
    landings, feet = support.landings.tolist(), support.feet.tolist()
    rows = np.zeros((2 * m, nx))
    low, high = np.empty(2 * m), np.empty(2 * m)
    last = {0: -1, 1: -1}  # each foot's latest landing so far (-1: where it stands now)
    for i in range(m):
        f = int(landings[i][0])
        j = last[1 - f]
        sx, sy = (feet[1 - f][0], feet[1 - f][1]) if j < 0 else (landings[j][1], landings[j][2])
        c, s = math.cos(landings[i][3]), math.sin(landings[i][3])
        side = 1.0 if f == 0 else -1.0
        gx, gy = landings[i][1] - sx, landings[i][2] - sy
        for r, (ax, ay, lo, hi) in enumerate(((-side * s, side * c, reach.min_apart, reach.max_apart),
                                              (c, s, -reach.back, reach.forward))):
            k = 2 * i + r
            if i == 0 and not first:
                low[k], high[k] = -np.inf, np.inf
                continue
            rows[k, 2 * n + i], rows[k, 2 * n + m + i] = ax, ay
            if j >= 0:
                rows[k, 2 * n + j], rows[k, 2 * n + m + j] = -ax, -ay
            now = ax * gx + ay * gy
            low[k], high[k] = min(lo - now, 0.0), max(hi - now, 0.0)
        last[f] = i
    return rows, low, high


class ComPlanner(PythonController):
    """The COM planner in the loop: `LipmMpc` solved every update from the COM's measured
    position and velocity (computed at the estimator's base state when `base` is bound) and the
    footstep plan. Claims no joints.

    Reads `steps` (the footstep planner's `Steps`) and `base` (13, optional: the estimator's).
    Exports `com` (9: position, velocity, acceleration wanted one update ahead, world frame) and
    `landing` (5: foot, x, y, z, yaw: where the next landing goes after the push adjustment;
    NaN when no step is planned)."""

    command_interface = "effort"
    inputs = {"steps": Steps.LENGTH, "base": 13}
    optional_inputs = ("base",)
    exports = {"com": 9, "landing": 5}

    sample = Param(0.05, low=0.01, high=0.5, doc="MPC sample time", unit="s")
    horizon = Param(24, low=2, high=100, doc="MPC samples ahead")
    w_jerk = Param(1e-6, low=0.0, high=1e3, doc="weight on the jerk")
    w_shift = Param(0.3, low=0.0, high=1e6, doc="weight on moving a planned landing")
    max_shift = Param(0.4, low=0.0, high=0.6, doc="how far a push may move a planned landing", unit="m")
    min_apart = Param(0.09, low=0.0, high=0.5, doc="a moved landing stays this far from the other foot, "
                      "across", unit="m")
    max_apart = Param(0.45, low=0.0, high=1.0, doc="a moved landing stays within this of the other "
                      "foot, across", unit="m")
    reach_forward = Param(0.32, low=0.0, high=1.0, doc="a moved landing is at most this far ahead of "
                          "the other foot", unit="m")
    reach_back = Param(0.15, low=0.0, high=1.0, doc="a moved landing is at most this far behind the "
                       "other foot", unit="m")
    margin = Param(0.015, low=0.0, high=0.04, doc="the ZMP keeps this far inside the soles", unit="m")
    feedback = Param(1.0, low=0.0, high=1.0, doc="share of the measured COM state the plan starts from")
    com_height = Param(0.0, low=0.0, high=2.0, doc="COM above the soles (0: as it stands at start)", unit="m")
    solver = Param("daqp", choices=("daqp", "proxqp", "osqp", "quadprog"), doc="qpsolvers' solver")

    def configure(self) -> None:
        model = self.dynamics.model
        self.scratch = mujoco.MjData(model)
        self.dyn = _body.state_dynamics(model, self.scratch)
        self.solve_times: deque[float] = deque(maxlen=20000)  # the last 20000: bounded
        self.mpc: LipmMpc | None = None
        self.stopped: str | None = None

    def activate(self, state: State) -> None:
        dyn = self._dynamics(state)
        soles = [dyn.pose(f)[0] + dyn.pose(f)[1] @ _body.SOLE_OFFSET for f in _body.FEET]
        ground = (soles[0][2] + soles[1][2]) / 2
        self.height = self.com_height or _standing_height(dyn, self.joints_posture())
        self.ground = ground
        self.mpc = LipmMpc(self.height, self.sample, self.horizon, w_jerk=self.w_jerk,
                           w_shift=self.w_shift, max_shift=self.max_shift, solver=self.solver)
        self.reach = Reach(self.min_apart, self.max_apart, self.reach_forward, self.reach_back)
        c = dyn.com()
        self.shift_for, self.shift = np.nan, np.zeros(2)
        self.x = np.array([c[0], 0.0, 0.0])
        self.y = np.array([c[1], 0.0, 0.0])
        self.stopped = None

    def joints_posture(self) -> dict[str, float]:
        return _body.STANCE_POSTURE

    def _dynamics(self, state: State) -> Dynamics:
        d = self.scratch
        d.qpos[:], d.qvel[:] = state.all_q, state.all_dq
        inputs = getattr(state, "inputs", None) or {}
        base = inputs.get("base") if "base" in inputs else None
        if base is not None and np.isfinite(base[0]):
            d.qpos[:3], d.qpos[3:7] = base[:3], base[3:7]
            d.qvel[:3], d.qvel[3:6] = base[7:10], base[10:13]
        self.dyn.refresh()
        return self.dyn

    def update(self, state: State, t: float, dt: float) -> np.ndarray | None:
        out = self.exports
        steps = state.inputs["steps"]
        if self.stopped is not None or not np.isfinite(steps[0]):
            return None
        dyn = self._dynamics(state)
        c, v = dyn.com(), dyn.com_jacobian() @ self.scratch.qvel
        k = self.feedback
        self.x[:2] = k * np.array([c[0], v[0]]) + (1 - k) * self.x[:2]
        self.y[:2] = k * np.array([c[1], v[1]]) + (1 - k) * self.y[:2]
        steps = self._measured(dyn, steps, t)
        rows = Steps.rows(steps)
        adjustable = len(rows) > 0 and t < rows[0][8] - 0.05
        if len(rows) and rows[0][7] != self.shift_for:  # a new step: nothing moved yet
            self.shift_for, self.shift = rows[0][7], np.zeros(2)
        support = supports(steps, t, self.sample, self.horizon, _body.SOLE_SIZE, self.margin)
        start = time.perf_counter()
        assert self.mpc is not None  # activate() made it
        try:
            jx, jy, shifts = self.mpc.solve(self.x, self.y, support, adjustable, self.shift, self.reach)
        except qp.Infeasible as exc:
            self.stopped = str(exc)
            self.log.error("%s at t = %.3f s: the COM reference holds still (a safe stop)", exc, t)
            out["com"][3:] = 0.0
            return None
        self.solve_times.append(time.perf_counter() - start)
        period = dt if dt > 0 else 0.002
        self.x = LipmMpc.advance(self.x, jx[0], period)
        self.y = LipmMpc.advance(self.y, jy[0], period)
        feet = Steps.feet(steps)
        # the height follows the ground under the feet, smoothly (a step's 2 cm over 0.2 s)
        ground = (feet[0, 2] + feet[1, 2]) / 2
        rate = (ground - self.ground) / HEIGHT_TIME
        self.ground += rate * period
        out["com"][:] = [self.x[0], self.y[0], self.ground + self.height, self.x[1], self.y[1], rate,
                         self.x[2], self.y[2], 0.0]
        if len(rows):
            row, shift = rows[0], shifts[0]
            self.shift = shift  # kept once the step can no longer move (its last 0.05 s)
            out["landing"][:] = [row[0], row[1] + shift[0], row[2] + shift[1], row[3], row[4]]
        else:
            out["landing"][:] = np.nan
        return None

    def _measured(self, dyn: Dynamics, steps: np.ndarray, t: float) -> np.ndarray:
        """The plan with the feet on the ground where they really are (the encoders and the base):
        the support is where the soles stand, whatever the planner believes (a landing moved by a
        push, a foot that slipped)."""
        steps = steps.copy()
        swing = Steps.swing_now(steps, t)
        for f, name in enumerate(_body.FEET):
            if swing is not None and int(swing[0]) == f:
                continue
            p, r = dyn.pose(name)
            sole = p + r @ _body.SOLE_OFFSET
            steps[4 * f:4 * f + 4] = (sole[0], sole[1], sole[2], _body.yaw_of(r))
        return steps

    def report(self) -> dict[str, Any]:
        times = np.asarray(self.solve_times) * 1e3
        out: dict[str, Any] = {"stopped": self.stopped}
        if len(times):
            out.update(mpc_ms_median=round(float(np.median(times)), 3),
                       mpc_ms_p99=round(float(np.percentile(times, 99)), 3))
        return out


def _standing_height(dyn: Dynamics, posture: dict[str, float]) -> float:
    """The COM's height above the soles in the standing posture (the feet flat, the pelvis level)."""
    model = dyn.model
    data = mujoco.MjData(model)
    data.qpos[2] = 1.0
    data.qpos[3] = 1.0
    for name, value in posture.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    foot = model.body(_body.FEET[0]).id
    sole = data.xpos[foot] + data.xmat[foot].reshape(3, 3) @ _body.SOLE_OFFSET
    return float(data.subtree_com[1][2] - sole[2])
