"""The region of attraction of a state feedback, found by batched rollouts (issue 38 item 4).

A grid over two of the plant's states (joint angles, or the base's velocities: a push) gives the
starting deviations; each start is simulated on a copy of the robot under the same law u = u0 -
K dx, clamped to the effort limits, with MuJoCo's batched `mujoco.rollout` (its C threads, one
control period at a time, the law applied to the whole batch between periods) or, for large
grids, the batch split over a Ray cluster's workers as `mexone sweep` does. A start is in the
region when the robot comes back: no fall (the base 0.3 m lower), and at rest at the end (every
velocity below 0.05 rad/s or m/s: the base may have slid or turned, which no input undoes).
The result is drawn against the Lyapunov level sets: the largest one whose slice holds only
starts that came back, and the one inside which no input saturates.
"""

from __future__ import annotations

import copy
import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import control
import mujoco
import numpy as np

from mexone.cluster import ray_session
from mexone.control.hardware import set_actuator_state
from mexone.design.check import _on_sim
from mexone.design.deploy import StateFeedback
from mexone.errors import InputError
from mexone.ranges import number_text

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure, SubFigure

    from mexone.control.controllers.python import PythonRunner
    from mexone.lab import Lab

__all__ = ["Region", "region_of_attraction", "plot_region", "BACKENDS"]

BACKENDS = ("threads", "ray")
_FALL_DROP = 0.3  # m the base may sink before the start counts as fallen
_AT_REST = 0.05  # rad/s, m/s: every velocity below this at the end (standing still): back


@dataclass(frozen=True)
class Region:
    """`axes` (two state labels) and their grid `values`; `back` (len0 x len1 bools): the start
    came back; `final`: the fastest velocity at the end (inf: fell); `lyapunov` P on the plant's state
    and its slice on the axes; `level`: the largest c with {x'Px <= c} on the slice holding only
    starts that came back (inf: none failed); `saturation_level`: the largest c inside which the
    law never asks more than the effort limits; `seconds` of wall time; `backend`."""

    axes: tuple[str, str]
    values: tuple[np.ndarray, np.ndarray]
    back: np.ndarray
    final: np.ndarray
    lyapunov: np.ndarray
    slice: np.ndarray
    level: float
    saturation_level: float
    duration: float
    seconds: float
    backend: str
    notes: tuple[str, ...] = field(default=())

    @property
    def fraction(self) -> float:
        """The share of the grid's starting points the controller brought back."""
        return float(self.back.mean())

    def as_dict(self) -> dict[str, Any]:
        """The region of attraction as plain JSON values."""
        return {"axes": list(self.axes), "points": int(self.back.size),
                "fraction_back": self.fraction, "level": _finite(self.level),
                "saturation_level": _finite(self.saturation_level), "duration": self.duration,
                "seconds": self.seconds, "backend": self.backend, "notes": list(self.notes)}


def _finite(x: float) -> float | str:
    return x if math.isfinite(x) else "inf"


def region_of_attraction(lab: Lab, controller: object, plant: control.StateSpace,
                         axes: Mapping[str, tuple[float, float]],
                         shape: tuple[int, int] = (32, 32), duration: float = 1.5,
                         lyapunov: np.ndarray | None = None, threads: int | None = None,
                         backend: str = "threads",
                         address: str | None = None) -> Region:
    """The region of attraction of a deployed StateFeedback (from deploy, on `plant`) on a grid
    over two state labels (`axes`: label -> (low, high), deviations from the design's point),
    each start simulated for `duration` s. lyapunov: P (the S lqr returns), else the closed
    loop's discrete Lyapunov solution with Q = I (its modes on the unit circle, the base
    sliding on friction, pulled just inside). threads: MuJoCo's (default: the CPUs);
    backend "ray" splits the grid over a Ray cluster (address, or a local one)."""
    if not isinstance(controller, StateFeedback):
        raise InputError("region_of_attraction runs a StateFeedback's law on the whole batch; "
                         f"give the one deploy returned, not {type(controller).__name__}",
                         hint="for another controller, certify's margins and saturation apply")
    if backend not in BACKENDS:
        raise InputError(f"backend {backend!r} is not one of {', '.join(BACKENDS)}")
    labels = list(plant.state_labels)
    if len(axes) != 2:
        raise InputError(f"axes: give two state labels with their ranges, not {len(axes)}")
    first, second = axes
    names = (first, second)
    for name in names:
        if name not in labels:
            raise InputError(f"axis {name!r} is not a state of the plant",
                             hint=", ".join(labels[:8]) + ", ...")
        low, high = (float(v) for v in axes[name])
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise InputError(f"axis {name!r}: the range ({axes[name]}) is not low < high")
    if not (len(shape) == 2 and all(int(n) >= 2 for n in shape)):
        raise InputError(f"shape {shape}: two sizes of at least 2")
    if not math.isfinite(duration) or duration <= 0:
        raise InputError(f"duration {duration} is not a positive number of seconds")
    grid = (np.linspace(float(axes[first][0]), float(axes[first][1]), int(shape[0])),
            np.linspace(float(axes[second][0]), float(axes[second][1]), int(shape[1])))
    design = controller.design
    K = design.K
    a, b = np.asarray(plant.A), np.asarray(plant.B)
    closed = a - b @ K
    if lyapunov is None:
        radius = float(np.abs(np.linalg.eigvals(closed)).max())
        shrink = 1.0 if radius < 1 - 1e-6 else (1 - 1e-4) / radius  # the base's neutral modes
        try:
            P = np.asarray(control.dlyap((shrink * closed).T, np.eye(a.shape[0])))
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise InputError(f"no Lyapunov matrix for this loop ({str(exc).splitlines()[0]})",
                             hint="pass lyapunov=S, the S lqr(plant, Q, R) returns") from None
    else:
        P = np.asarray(lyapunov, dtype=float)
        if P.shape != closed.shape:
            raise InputError(f"lyapunov has shape {P.shape}; the plant needs {closed.shape}")
    job = _job(lab, controller, plant, names, grid, duration, P)
    starts = job.pop("starts")
    begin = time.perf_counter()
    if backend == "ray":
        ratio = _on_ray(job, starts, address, threads)
    else:
        ratio = _rollouts(job, starts, threads or os.cpu_count() or 1)
    seconds = time.perf_counter() - begin
    back = (ratio < _AT_REST).reshape(len(grid[0]), len(grid[1]))
    idx = [labels.index(n) for n in names]
    sub = P[np.ix_(idx, idx)]
    g0, g1 = np.meshgrid(grid[0], grid[1], indexing="ij")
    pts = np.stack([g0.ravel(), g1.ravel()], axis=1)
    v = np.einsum("ij,jk,ik->i", pts, sub, pts).reshape(back.shape)
    level = float(v[~back].min()) if (~back).any() else math.inf
    limits = job["limits"]
    headroom = np.minimum(limits - design.u0, limits + design.u0)
    Pinv = np.linalg.pinv(P)
    spread = np.einsum("ij,jk,ik->i", K, Pinv, K)
    with np.errstate(divide="ignore"):
        sat = float(np.min(np.where(spread > 0, headroom**2 / spread, np.inf)))
    notes = []
    if back.all():
        notes.append("every start came back: widen the axes to find the region's edge")
    return Region(names, grid, back, ratio.reshape(back.shape), P, sub, level, sat, duration,
                  seconds, backend, tuple(notes))


def _job(lab: Lab, controller: StateFeedback, plant: control.StateSpace, names: tuple[str, str],
         grid: tuple[np.ndarray, np.ndarray], duration: float, P: np.ndarray) -> dict[str, Any]:
    """Everything a worker needs, picklable: the model as set now (gains, clamps), the base
    controls, the starts (full physics states), the law and how to read dx."""
    design = controller.design
    point = design.point
    labels = list(plant.state_labels)

    def take() -> dict[str, Any]:
        sim = lab.sim
        m = copy.copy(sim.model)
        data = mujoco.MjData(m)
        mujoco.mj_copyData(data, m, sim.data)
        manager = lab.manager
        assert manager is not None  # the StateFeedback runs in it
        runner = cast("PythonRunner", manager.controllers[controller.name])
        hw = manager.hw
        motors = hw.layout.motor[runner.rows]
        ff = m.actuator_ctrladr[motors] + 2
        gear = m.actuator_gear[motors, 0]
        limits = hw.effort_limit[runner.rows].copy()
        base = data.ctrl.copy()
        spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        size = mujoco.mj_stateSize(m, spec)
        starts = np.zeros((grid[0].size * grid[1].size, size))
        nv = point.qvel.size
        probe = mujoco.MjData(m)
        k = 0
        for x0 in grid[0]:
            for x1 in grid[1]:
                dx = np.zeros(len(labels))
                dx[labels.index(names[0])] = x0
                dx[labels.index(names[1])] = x1
                qpos = data.qpos.copy()
                qpos[point.qpos_index] = point.qpos
                v = np.zeros(m.nv)
                v[point.qvel_index] = dx[:nv]
                mujoco.mj_integratePos(m, qpos, v, 1.0)
                mujoco.mj_copyData(probe, m, data)
                probe.qpos[:] = qpos
                probe.qvel[:] = 0.0
                probe.qvel[point.qvel_index] = point.qvel + dx[nv:2 * nv]
                set_actuator_state(probe, ctrl=base)
                mujoco.mj_getState(m, probe, starts[k], spec)
                k += 1
        return {"model": m, "base": base, "ff": ff, "gear": gear, "limits": limits,
                "K": design.K, "u0": design.u0, "qpos0": point.qpos, "qvel0": point.qvel,
                "qpos_index": point.qpos_index, "qvel_index": point.qvel_index,
                "act_index": np.asarray(point.act_index, int) if point.act_index.size else
                np.zeros(0, int), "act0": point.act, "P": P, "period": 1.0 / controller.rate,
                "duration": duration, "base_z": _base_z(m), "starts": starts}
    return _on_sim(lab, take)


def _base_z(model: mujoco.MjModel) -> int:
    """qpos address of the floating base's height, -1 on a fixed base."""
    free = int(mujoco.mjtJoint.mjJNT_FREE)
    joints = [j for j in range(model.njnt) if int(model.jnt_type[j]) == free]
    return int(model.jnt_qposadr[joints[0]]) + 2 if joints else -1


def _offsets(model: mujoco.MjModel) -> tuple[int, int, int]:
    s = mujoco.mjtState
    t = mujoco.mj_stateSize(model, int(s.mjSTATE_TIME))
    q = mujoco.mj_stateSize(model, int(s.mjSTATE_TIME | s.mjSTATE_QPOS))
    v = mujoco.mj_stateSize(model, int(s.mjSTATE_TIME | s.mjSTATE_QPOS | s.mjSTATE_QVEL))
    return t, q, v


def _rollouts(job: dict[str, Any], starts: np.ndarray, threads: int) -> np.ndarray:
    """Each start's fastest velocity at the end (inf: fell or diverged). The fallen leave the
    batch at once."""
    from mujoco import rollout

    model = job["model"]
    n = starts.shape[0]
    t_off, q_off, v_off = _offsets(model)
    steps = max(1, round(job["period"] / model.opt.timestep))
    periods = max(1, round(job["duration"] / job["period"]))
    datas = [mujoco.MjData(model) for _ in range(max(1, threads))]
    K, u0 = job["K"], job["u0"]
    limits, ff, gear = job["limits"], job["ff"], job["gear"]
    z = job["base_z"]
    state = starts.copy()
    live = np.arange(n)
    height0 = state[:, t_off + z] if z >= 0 else None
    controls = np.empty((n, steps, model.nu))
    controls[:] = job["base"]
    try:
        for _ in range(periods):
            if live.size == 0:
                break
            batch = state[live]
            dx = _deviations(job, model, batch, (t_off, q_off, v_off))
            u = np.clip(u0 - dx @ K.T, -limits, limits)
            ctrl = controls[:live.size]
            ctrl[:, :, ff] = (u / gear)[:, None, :]
            out, _ = rollout.rollout(model, datas, batch, ctrl, nstep=steps,
                                     persistent_pool=True)
            batch = out[:, -1, :]
            bad = ~np.isfinite(batch).all(axis=1)
            if height0 is not None:
                bad |= batch[:, t_off + z] < height0[live] - _FALL_DROP
            state[live] = np.where(bad[:, None], state[live], batch)
            live = live[~bad]
    finally:
        rollout.shutdown_persistent_pool()
    speed = np.abs(state[:, q_off:v_off]).max(axis=1)
    fallen = np.ones(n, dtype=bool)
    fallen[live] = False
    speed[fallen] = np.inf
    return speed


def _deviations(job: dict[str, Any], model: mujoco.MjModel, state: np.ndarray,
                offsets: tuple[int, int, int]) -> np.ndarray:
    """dx of each state in the batch: the design's coordinates (mj_differentiatePos)."""
    t_off, q_off, v_off = offsets
    qpos_index, qvel_index = job["qpos_index"], job["qvel_index"]
    act_index, act0 = job["act_index"], job["act0"]
    m = len(qvel_index)
    out = np.zeros((state.shape[0], job["K"].shape[1]))
    dq = np.zeros(model.nv)
    ref = np.zeros(model.nq)
    for i in range(state.shape[0]):
        qpos = state[i, t_off:q_off]
        ref[:] = qpos
        ref[qpos_index] = job["qpos0"]
        mujoco.mj_differentiatePos(model, dq, 1.0, ref, qpos)
        out[i, :m] = dq[qvel_index]
    out[:, m:2 * m] = state[:, q_off:v_off][:, qvel_index] - job["qvel0"]
    if act_index.size:
        out[:, 2 * m:] = state[:, v_off:v_off + model.na][:, act_index] - act0
    return out


def _on_ray(job: dict[str, Any], starts: np.ndarray, address: str | None, threads: int | None) -> np.ndarray:
    with ray_session(threads or os.cpu_count() or 1, address) as ray:
        workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        remote = ray.remote(_rollouts)
        shared = ray.put(job)
        chunks = np.array_split(starts, workers)
        return np.concatenate(ray.get([remote.remote(shared, c, 1) for c in chunks if len(c)]))


def plot_region(region: Region, ax: Axes | None = None) -> Figure | SubFigure:
    """The starts that came back (filled) and did not (crosses) on the two axes, with the
    Lyapunov level sets: the largest holding only returns, and the saturation-free one."""
    import matplotlib.pyplot as plt

    fig: Figure | SubFigure
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
    else:
        fig = ax.figure
    g0, g1 = np.meshgrid(*region.values, indexing="ij")
    ax.scatter(g0[region.back], g1[region.back], s=8, color="tab:green", label="came back")
    ax.scatter(g0[~region.back], g1[~region.back], s=10, marker="x", color="tab:red",
               label="did not")
    theta = np.linspace(0, 2 * np.pi, 300)
    circle = np.stack([np.cos(theta), np.sin(theta)])
    for level, style, what in ((region.level, "-", "largest level set inside"),
                               (region.saturation_level, "--", "no input saturates inside")):
        if not math.isfinite(level) or level <= 0:
            continue
        w, vec = np.linalg.eigh(region.slice)
        if np.any(w <= 0):
            continue
        ellipse = vec @ (np.sqrt(level / w)[:, None] * circle)
        ax.plot(ellipse[0], ellipse[1], style, color="black", label=f"x'Px = {level:.3g}: {what}")
    ax.set_xlabel(region.axes[0])
    ax.set_ylabel(region.axes[1])
    ax.set_xlim(region.values[0][0], region.values[0][-1])
    ax.set_ylim(region.values[1][0], region.values[1][-1])
    ax.set_title(f"region of attraction: {100 * region.fraction:.0f} % of {region.back.size} "
                 f"starts came back ({number_text(region.seconds)} s)")
    ax.legend(fontsize="x-small", loc="lower right")
    return fig
