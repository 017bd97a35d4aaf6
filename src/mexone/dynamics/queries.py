"""The robot's rigid-body dynamics at one state, computed by the simulated MuJoCo model itself.

No second model (URDF re-read into KDL or pinocchio) can drift from what is simulated: M(q) is
MuJoCo's own inertia matrix (joint armature included), h(q, q̇) its `qfrc_bias`, the Jacobians
its `mj_jac*`. Everything runs on a scratch `MjData`: the caller's data is only read.

Coordinates (columns of M and of every Jacobian, entries of h, g and tau) are MuJoCo's
generalised velocities `qvel`, nv of them, in the model's joint order; `dofs(joints)` gives a
joint's columns. A floating-base robot (Mex-One) has a free joint first:

- `q[0:3]`: the root link's origin in the world frame (m); `q[3:7]`: its orientation as a unit
  quaternion (w, x, y, z), world from body. So nq = nv + 1.
- `dq[0:3]` (columns 0-2): the root origin's linear velocity in the **world** frame (m/s);
  `dq[3:6]` (columns 3-5): the root's angular velocity in the **root link's own** frame (rad/s),
  as MuJoCo defines a free joint's qvel. The joints follow (one column each).
- A fixed-base robot (welded to the world, or compiled with fixed_base) has no such columns.

Frames: every URDF link is a MuJoCo body of the same name (links joined by fixed joints stay
separate bodies: the compiler does not fuse them), so a link's frame is its URDF frame; MuJoCo
site names (e.g. "sensor/imu") and body names of other models are frames too. Jacobians are in
the world frame, rows linear (3) then angular (3), of the frame's origin or of a world point
moving with it: v = J[:3] dq, w = J[3:] dq.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mexone.errors import ArgumentTypeError, InputError
from mexone.ranges import number_text

if TYPE_CHECKING:
    from mexone.physics.simulation import Simulation

__all__ = ["Dynamics"]

_BODY, _SITE = 0, 1


class Dynamics:
    """Dynamics queries at one state of a MuJoCo model (section 2 of the controller contract).

    `Dynamics(model, data)` reads `data`'s state (qpos, qvel, mocap) now and after each
    `refresh()`; queries are computed lazily, once per refresh, on a private `MjData`.
    `links` maps extra frame names to body ids (a compiled robot's URDF links); `robot_bodies`
    are the bodies whose centre of mass `com()` is (default: every body but the world).
    copy=False: `data` is handed over (nobody else uses it) and the queries compute in it."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData,
                 links: Mapping[str, int] | None = None,
                 robot_bodies: Iterable[int] | None = None, *, copy: bool = True) -> None:
        if not isinstance(model, mujoco.MjModel) or not isinstance(data, mujoco.MjData):
            raise ArgumentTypeError("Dynamics(model, data) takes a mujoco.MjModel and a mujoco.MjData")
        self.model = model
        self._source = data
        self._data = mujoco.MjData(model) if copy else data
        self._frames = _frames(model, links or {})
        bodies = sorted(set(robot_bodies) if robot_bodies is not None
                        else set(range(1, model.nbody)) or {0})
        inside = set(bodies)
        self._roots = [b for b in bodies if int(model.body_parentid[b]) not in inside or b == 0]
        self._joint_dofs: dict[str, np.ndarray] = {}
        for j in range(model.njnt):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
            if name:
                width = {0: 6, 1: 3}.get(int(model.jnt_type[j]), 1)
                self._joint_dofs[name] = model.jnt_dofadr[j] + np.arange(width)
        self._stage = 0  # 0 stale, 1 positions, 2 velocities
        self._cache: dict[str, Any] = {}
        self.refresh()

    # ----- state ---------------------------------------------------------------------------------
    @classmethod
    def snapshot(cls, lab: Any, timeout: float = 10.0) -> Dynamics:
        """A `Dynamics` of a Lab's (or a Simulation's) robot at its current state, for routines
        and notebooks: the state is copied in the simulation thread (through `sim.work`) when a
        loop runs in another thread, so it is consistent. Its `refresh()` changes nothing."""
        sim: Simulation = getattr(lab, "sim", lab)
        if not hasattr(sim, "work") or not hasattr(sim, "compiled"):
            raise ArgumentTypeError("Dynamics.snapshot(lab) takes a mexone Lab or Simulation")

        def take() -> Dynamics:
            state = mujoco.MjData(sim.model)
            state.qpos[:], state.qvel[:] = sim.data.qpos, sim.data.qvel
            state.mocap_pos[:], state.mocap_quat[:] = sim.data.mocap_pos, sim.data.mocap_quat
            state.time = sim.data.time
            links = sim.compiled.bodies
            return cls(sim.model, state, links, links.values(), copy=False)

        if not sim.loop_elsewhere():
            return take()
        return sim.work.call(take, timeout=timeout)

    @classmethod
    def live(cls, sim: Simulation) -> Dynamics:
        """A `Dynamics` bound to a Simulation's live data, with its robot's link names and COM:
        for code in the simulation thread (a controller), which calls `refresh()` before each
        use. A model change (a model spawned or removed) needs a new one."""
        links = sim.compiled.bodies
        return cls(sim.model, sim.data, links, links.values())

    def refresh(self) -> None:
        """Take the source data's state again (cheap: the copy and the computations happen at
        the first query after it). A controller's dynamics is refreshed before every update."""
        self._stage = 0
        self._cache.clear()

    def _positions(self) -> mujoco.MjData:
        d = self._data
        if self._stage == 0:
            src = self._source
            d.qpos[:] = src.qpos
            d.qvel[:] = src.qvel
            if self.model.nmocap:
                d.mocap_pos[:], d.mocap_quat[:] = src.mocap_pos, src.mocap_quat
            d.time = src.time
            mujoco.mj_kinematics(self.model, d)
            mujoco.mj_comPos(self.model, d)
            self._stage = 1
        return d

    def _velocities(self) -> mujoco.MjData:
        d = self._positions()
        if self._stage < 2:
            mujoco.mj_comVel(self.model, d)
            self._stage = 2
        return d

    @property
    def q(self) -> np.ndarray:
        """qpos as used (nq,): a copy."""
        return self._positions().qpos.copy()

    @property
    def dq(self) -> np.ndarray:
        """qvel as used (nv,): a copy."""
        return self._positions().qvel.copy()

    @property
    def frames(self) -> list[str]:
        """Every frame name the queries accept (links, bodies, sites)."""
        return sorted(self._frames)

    def dofs(self, joints: str | Iterable[str]) -> np.ndarray:
        """The joints' indices into nv-long vectors (a free joint has 6, a ball joint 3)."""
        names = [joints] if isinstance(joints, str) else list(joints)
        out = []
        for name in names:
            found = self._joint_dofs.get(name)
            if found is None:
                raise InputError(f"no joint named {_shown(name)} in the model",
                                 hint="joints: " + ", ".join(self._joint_dofs))
            out.append(found)
        return np.concatenate(out).astype(int) if out else np.zeros(0, dtype=int)

    # ----- joint space ---------------------------------------------------------------------------
    def mass_matrix(self) -> np.ndarray:
        """M(q), (nv, nv): the joint-space inertia matrix, joint armature included."""
        m = self._cache.get("M")
        if m is None:
            d = self._positions()
            mujoco.mj_makeM(self.model, d)
            m = np.zeros((self.model.nv, self.model.nv))
            mujoco.mj_fullM(self.model, d, m)
            self._cache["M"] = m
        return m.copy()

    def bias(self) -> np.ndarray:
        """h(q, dq) = C(q, dq) dq + g(q), (nv,): MuJoCo's qfrc_bias (Coriolis, centrifugal and
        gravity; joint damping and springs are passive forces, not in it)."""
        h = self._cache.get("h")
        if h is None:
            d = self._velocities()
            h = np.zeros(self.model.nv)
            mujoco.mj_rne(self.model, d, 0, h)
            self._cache["h"] = h
        return h.copy()

    def gravity(self) -> np.ndarray:
        """g(q), (nv,): the generalised force that holds the robot still against gravity (the
        bias at zero velocity). Gravity compensation applies +g."""
        g = self._cache.get("g")
        if g is None:
            d = self._positions()
            velocities = d.qvel.copy()
            d.qvel[:] = 0.0
            mujoco.mj_comVel(self.model, d)
            g = np.zeros(self.model.nv)
            mujoco.mj_rne(self.model, d, 0, g)
            d.qvel[:] = velocities
            self._stage = 1  # cvel now belongs to zero velocity
            self._cache["g"] = g
        return g.copy()

    def inverse_dynamics(self, qacc: np.ndarray, contacts: bool = False) -> np.ndarray:
        """tau (nv,) giving acceleration `qacc` (nv,). Without contacts: M qacc + h. With
        contacts=True: MuJoCo's mj_inverse at this state, the generalised force the actuators
        (and applied forces) must supply given the contacts, equality constraints, joint limits
        and passive forces (damping, springs) as simulated."""
        qacc = self._vector(qacc, "qacc")
        if not contacts:
            return self.mass_matrix() @ qacc + self.bias()
        d = self._positions()
        d.qacc[:] = qacc
        mujoco.mj_inverse(self.model, d)
        self._stage = 1  # mj_inverse recomputed the same kinematics; the velocity stage to redo
        return d.qfrc_inverse.copy()

    def _vector(self, value: ArrayLike, what: str) -> np.ndarray:
        out = _floats(value, what)
        if out.shape != (self.model.nv,):
            raise InputError(f"{what} has {out.size} values; the model has nv = {self.model.nv}")
        if not np.isfinite(out).all():
            raise InputError(f"{what} is not finite")
        return out

    # ----- frames --------------------------------------------------------------------------------
    def _frame(self, frame: str) -> tuple[int, int]:
        found = self._frames.get(frame) if isinstance(frame, str) else None
        if found is None:
            raise InputError(f"no frame named {_shown(frame)}",
                             hint="frames: " + ", ".join(sorted(self._frames)))
        return found

    def _body_and_point(self, frame: str, point: ArrayLike | None) -> tuple[int, np.ndarray]:
        kind, index = self._frame(frame)
        d = self._positions()
        if kind == _SITE:
            body, origin = int(self.model.site_bodyid[index]), d.site_xpos[index]
        else:
            body, origin = index, d.xpos[index]
        if point is None:
            return body, origin.copy()
        p = _floats(point, "point")
        if p.shape != (3,) or not np.isfinite(p).all():
            shown = ", ".join(number_text(v) for v in p[:4]) + (", ..." if p.size > 4 else "")
            raise InputError(f"point ({shown}) is not 3 finite numbers (a world point, m)")
        return body, p

    def pose(self, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), rotation (3, 3)) of the frame in the world frame."""
        kind, index = self._frame(frame)
        d = self._positions()
        if kind == _SITE:
            return d.site_xpos[index].copy(), d.site_xmat[index].reshape(3, 3).copy()
        return d.xpos[index].copy(), d.xmat[index].reshape(3, 3).copy()

    def jacobian(self, frame: str, point: ArrayLike | None = None) -> np.ndarray:
        """(6, nv): rows linear velocity (3) then angular velocity (3), world frame, of the
        frame's origin or of `point` (a world point moving with the frame)."""
        body, p = self._body_and_point(frame, point)
        jac = np.zeros((6, self.model.nv))
        mujoco.mj_jac(self.model, self._data, jac[:3], jac[3:], p, body)
        return jac

    def jacobian_dot_qdot(self, frame: str, point: ArrayLike | None = None) -> np.ndarray:
        """(6,): J̇ dq, the acceleration of the frame's origin (or point) and of its angular
        velocity at zero qacc: a = J qacc + J̇ dq."""
        body, p = self._body_and_point(frame, point)
        d = self._velocities()
        jdot = np.zeros((6, self.model.nv))
        mujoco.mj_jacDot(self.model, d, jdot[:3], jdot[3:], p, body)
        return jdot @ d.qvel

    # ----- whole body ----------------------------------------------------------------------------
    def mass(self) -> float:
        """The robot's total mass (kg)."""
        return float(sum(self.model.body_subtreemass[r] for r in self._roots))

    def com(self) -> np.ndarray:
        """(3,): the robot's centre of mass in the world frame."""
        d = self._positions()
        if len(self._roots) == 1:
            return d.subtree_com[self._roots[0]].copy()
        masses = self.model.body_subtreemass[self._roots]
        return masses @ d.subtree_com[self._roots] / masses.sum()

    def com_jacobian(self) -> np.ndarray:
        """(3, nv): d com / dt = J_com dq."""
        d = self._positions()
        out = np.zeros((3, self.model.nv))
        part = np.zeros((3, self.model.nv))
        for root in self._roots:
            mujoco.mj_jacSubtreeCom(self.model, d, part, root)
            out += self.model.body_subtreemass[root] * part
        return out / self.mass()

    def centroidal_momentum(self) -> np.ndarray:
        """(6,): the robot's linear momentum (kg m/s) then its angular momentum about the centre
        of mass (kg m^2/s), world frame."""
        d = self._velocities()
        mujoco.mj_subtreeVel(self.model, d)
        out = np.zeros(6)
        if len(self._roots) == 1:
            root = self._roots[0]
            out[:3] = self.model.body_subtreemass[root] * d.subtree_linvel[root]
            out[3:] = d.subtree_angmom[root]
            return out
        masses = self.model.body_subtreemass[self._roots]
        momenta = masses[:, None] * d.subtree_linvel[self._roots]
        offsets = d.subtree_com[self._roots] - self.com()  # each subtree's momentum about the COM
        out[:3] = momenta.sum(axis=0)
        out[3:] = d.subtree_angmom[self._roots].sum(axis=0) + np.cross(offsets, momenta).sum(axis=0)
        return out

def _shown(name: object) -> str:
    """A name for a one-line message: quoted, control characters escaped."""
    if isinstance(name, str):
        text = name
    else:
        text = number_text(name) if isinstance(name, (int, float)) else repr(name)
    return "'" + text.encode("unicode_escape").decode("ascii")[:80] + "'"


def _floats(value: ArrayLike, what: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"{what} is not a list of numbers") from None


def _frames(model: mujoco.MjModel, links: Mapping[str, int]) -> dict[str, tuple[int, int]]:
    out: dict[str, tuple[int, int]] = {}
    for i in range(model.nsite):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, i)
        if name:
            out[name] = (_SITE, i)
    for i in range(model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i)
        if name:
            out[name] = (_BODY, i)
    for name, body in links.items():
        out[name] = (_BODY, int(body))
    return out
