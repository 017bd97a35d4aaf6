"""Walking, planned: footsteps, the centre of mass by ZMP preview control (Kajita et al. 2003),
swing-foot arcs, and whole-body IK turning them into joint positions, one control period apart.

The COM follows the linear inverted pendulum at a constant height z (the "cart-table"): the
zero moment point is p = x - (z/g) x''. Preview control picks the COM's jerk each period from
the state and the ZMP reference of the next `preview` seconds (the footsteps), so the COM
starts moving before the ZMP jumps to the next foot. The feet stay flat; the swing foot rises
`height` on a half sine while it moves on a cosine ease. WholeBodyIK (feet frames + COM +
upright pelvis) gives the joint positions; the routine sends them to the position
controllers. Open loop but for the heading: the IMU's yaw turns each step's foot against the
slip of the feet (see the README's limits).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields
from pathlib import Path

import mink
import numpy as np
import scipy.linalg

from mexone import yamlio
from mexone.errors import InputError
from mexone.motion.ik import WholeBodyIK

__all__ = ["Gait", "preview_gains", "zmp_reference", "bent_knees", "walk_ticks", "GAIT_YAML"]

G = 9.81
MAX_TURN = 0.05  # rad: the most a step turns to correct the heading
GAIT_YAML = Path(__file__).resolve().parent.parent / "routines" / "shipped" / "walk.yaml"


@dataclass(frozen=True)
class Gait:
    """The walking parameters a student edits (routines/shipped/walk.yaml)."""

    step_length: float = 0.06   # m, forward per step
    step_height: float = 0.03   # m, swing foot's highest lift
    period: float = 0.4         # s per step
    double_support: float = 0.2  # share of the period both feet are down
    knee_bend: float = 0.4      # rad: the legs walk bent (straight knees are singular for height)
    dt: float = 0.01            # s, control period
    preview: float = 1.6        # s of ZMP reference the COM looks ahead
    stand: float = 1.0          # s standing before the first step and after the last

    @classmethod
    def load(cls, path: Path | str = GAIT_YAML) -> Gait:
        raw = yamlio.load(Path(path).read_text()) or {}
        known = {f.name for f in fields(cls)}
        if not isinstance(raw, dict) or set(raw) - known:
            extra = sorted(set(raw) - known) if isinstance(raw, dict) else raw
            raise InputError(f"{path}: unknown gait parameter(s) {extra}",
                             hint="parameters: " + ", ".join(sorted(known)))
        gait = cls(**{k: float(v) for k, v in raw.items()})
        if not (gait.period > 0 and 0 <= gait.double_support < 1 and gait.dt > 0):
            raise InputError(f"{path}: period and dt must be > 0, double_support in [0, 1)")
        return gait


def preview_gains(z: float, dt: float, horizon: int):
    """The cart-table model (state: position, velocity, acceleration; input: jerk) and its
    preview controller: integral gain, state gain, and the gains on the next `horizon` ZMP
    references (Katayama et al. 1985, as Kajita 2003 uses)."""
    a = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    b = np.array([[dt ** 3 / 6], [dt * dt / 2], [dt]])
    c = np.array([[1.0, 0.0, -z / G]])
    # augmented with the summed ZMP error, so the ZMP settles on its reference
    aa = np.block([[np.eye(1), c @ a], [np.zeros((3, 1)), a]])
    bb = np.vstack([c @ b, b])
    q, r = np.diag([1.0, 0.0, 0.0, 0.0]), np.array([[1e-6]])
    p = scipy.linalg.solve_discrete_are(aa, bb, q, r)
    inv = np.linalg.inv(r + bb.T @ p @ bb)
    k = inv @ bb.T @ p @ aa
    closed = aa - bb @ k
    x = -closed.T @ p @ np.array([[1.0], [0.0], [0.0], [0.0]])
    preview = np.empty(horizon)
    for j in range(horizon):
        preview[j] = (inv @ bb.T @ x).item()
        x = closed.T @ x
    return a, b, c, k[0, 0], k[0, 1:], preview


def zmp_reference(gait: Gait, feet: list[np.ndarray], steps: int):
    """ZMP reference (ticks, 2) and the swings (start tick, end tick, foot, from, to): stand
    between the feet, then `steps` steps, left first, the first and last half as long."""
    dt, ref, swings = gait.dt, [], []
    feet = [f.copy() for f in feet]
    ref += [(feet[0] + feet[1]) / 2] * round(gait.stand / dt)
    n_double = round(gait.double_support * gait.period / dt)
    n_single = round((1 - gait.double_support) * gait.period / dt)
    for k in range(steps):
        swing, stance = k % 2, 1 - k % 2
        target = feet[swing].copy()
        reach = gait.step_length / 2 if k in (0, steps - 1) else gait.step_length
        target[0] = feet[stance][0] + (reach if k < steps - 1 else 0.0)
        start = ref[-1]
        ref += [start + (feet[stance] - start) * (i + 1) / n_double for i in range(n_double)]
        swings.append((len(ref), len(ref) + n_single, swing, feet[swing].copy(), target))
        ref += [feet[stance].copy()] * n_single
        feet[swing] = target
    start, middle = ref[-1], (feet[0] + feet[1]) / 2
    ref += [start + (middle - start) * (i + 1) / n_double for i in range(n_double)]
    ref += [middle] * round(gait.stand / dt)
    return np.array(ref), swings


def _heading(ik: WholeBodyIK) -> float:
    """The IK's base yaw (rad); body 1 is the floating base, the world's first child."""
    rotation = ik.configuration.data.xmat[1].reshape(3, 3)
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def _yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def bent_knees(ik: WholeBodyIK, qpos: np.ndarray, bend: float) -> np.ndarray:
    """The standing configuration with hips, knees and ankles bent (feet under the hips, the
    pelvis lowered so the soles stay on the ground): where walking starts and ends."""
    q = np.array(qpos, dtype=float)
    for side in "lr":
        for joint, angle in (("hip_pitch", -bend), ("knee", 2 * bend), ("ankle_pitch", -bend)):
            q[ik.model.jnt_qposadr[ik.model.joint(f"{side}_{joint}").id]] = angle
    thigh_and_shank = 0.46  # m, Mex-One's 0.23 + 0.23
    q[2] -= thigh_and_shank * (1 - np.cos(bend))
    return q


def walk_ticks(ik: WholeBodyIK, qpos: np.ndarray, gait: Gait, distance: float,
               heading: Callable[[], float] | None = None) -> Iterator[dict[str, float]]:
    """Walk `distance` m straight ahead from the standing configuration `qpos`: the joint
    positions of each control period, planned as they are needed (the first is the bent-knee
    stance the robot should already be in). `heading`, if given, measures the robot's yaw (rad,
    from the IMU): each step's foot is turned against it, so slipping feet do not steer."""
    if not (gait.step_length > 0 and distance > 0):
        raise InputError(f"walk: step_length {gait.step_length} and distance {distance} "
                         "must be > 0 m")
    ik.reset(bent_knees(ik, qpos, gait.knee_bend))
    feet = [ik.pose(f)[0] for f in ("l_foot", "r_foot")]
    ground = feet[0][2]
    steps = max(2, int(np.ceil(distance / gait.step_length)) + 1)
    ref, swings = zmp_reference(gait, [f[:2] for f in feet], steps)
    horizon = round(gait.preview / gait.dt)
    a, b, c, k_sum, k_state, k_preview = preview_gains(ik.com()[2] - ground, gait.dt, horizon)
    padded = np.vstack([ref, np.repeat(ref[-1:], horizon + 1, axis=0)])
    x = np.zeros((3, 2))  # the COM's position, velocity, acceleration in x and y
    x[0] = ik.com()[:2]
    summed = np.zeros(2)
    active = iter(swings)
    swing = next(active, None)
    turn = 0.0  # rad: the IK's heading that is the world's straight ahead (feet slip; it drifts)
    for i in range(len(ref)):
        summed += (c @ x)[0] - ref[i]
        jerk = -k_sum * summed - k_state @ x - k_preview @ padded[i + 1:i + 1 + horizon]
        x = a @ x + b @ jerk[None, :]
        ik.set_com(x[0])
        if swing is not None and i >= swing[0]:
            start, end, foot, origin, target = swing
            if i == start and heading is not None:
                # the world's heading less the IK's is the feet's slip: turn the IK's feet back
                slip = heading() - _heading(ik)
                turn = float(np.clip(-slip, turn - MAX_TURN, turn + MAX_TURN))
                if ik.base is not None:
                    ik.base.set_target(mink.SE3.from_rotation(mink.SO3.from_rpy_radians(0.0, 0.0, turn)))
            s = min(1.0, (i - start + 1) / (end - start))
            xy = origin + (target - origin) * (1 - np.cos(np.pi * s)) / 2
            ik.set_target(("l_foot", "r_foot")[foot],
                          [xy[0], xy[1], ground + gait.step_height * np.sin(np.pi * s)],
                          _yaw(turn))
            if s >= 1.0:
                swing = next(active, None)
        for _ in range(3):  # a few IK iterations per period: the targets are met, not chased
            ik.step(gait.dt)
        yield ik.joint_positions()
