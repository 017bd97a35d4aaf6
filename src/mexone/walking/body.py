"""What the walking stack knows of the robot it walks, read from the simulated model: the feet
(sole frames, corners), the base, the standing posture. One home for Mex-One's names, so a
student's part and ours agree on them."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from mexone.dynamics import Dynamics

__all__ = ["Body", "FEET", "SOLE_OFFSET", "SOLE_SIZE", "STANCE_POSTURE", "yaw_of", "rot_z", "rot_y", "rot_x",
           "quat_to_matrix", "matrix_to_quat", "state_dynamics"]

FEET = ("l_foot", "r_foot")  # the foot links, left first (index 0 left, 1 right everywhere)
SOLE_OFFSET = np.array([0.02, 0.0, -0.06])  # the sole's centre in the foot link's frame (m)
SOLE_SIZE = (0.16, 0.08)  # m, the sole's length and width (Mex-One's foot box)
BASE = "pelvis"
TORSO = "torso"
# the bent-knee standing pose the stack walks in (rad); other joints 0
STANCE_POSTURE = {"l_hip_pitch": -0.35, "l_knee": 0.7, "l_ankle_pitch": -0.35,
                  "r_hip_pitch": -0.35, "r_knee": 0.7, "r_ankle_pitch": -0.35,
                  "l_shoulder_roll": 0.1, "r_shoulder_roll": -0.1, "l_elbow": -0.3, "r_elbow": -0.3}


def rot_z(yaw: float) -> np.ndarray:
    """The rotation (3, 3) by `yaw` rad about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(pitch: float) -> np.ndarray:
    """The rotation (3, 3) by `pitch` rad about y."""
    c, s = np.cos(pitch), np.sin(pitch)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_x(roll: float) -> np.ndarray:
    """The rotation (3, 3) by `roll` rad about x."""
    c, s = np.cos(roll), np.sin(roll)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def yaw_of(rotation: np.ndarray) -> float:
    """The heading (rad) of a rotation's x axis in the ground plane."""
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def quat_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) of a unit quaternion w x y z (MuJoCo's order)."""
    out = np.empty(9)
    mujoco.mju_quat2Mat(out, np.asarray(quat_wxyz, dtype=float))
    return out.reshape(3, 3)


def matrix_to_quat(rotation: np.ndarray) -> np.ndarray:
    """The unit quaternion w x y z of a rotation (3, 3)."""
    out = np.empty(4)
    mujoco.mju_mat2Quat(out, np.asarray(rotation, dtype=float).ravel())
    return out


@dataclass
class Body:
    """The model's indices the stack uses: `nv`, the free joint's dofs and each actuated joint's
    dof (in the controller's joint order), the feet's body ids."""

    model: mujoco.MjModel
    joints: list[str]
    dofs: np.ndarray  # each joint's index into nv-long vectors
    qpos: np.ndarray  # each joint's index into qpos

    @classmethod
    def of(cls, model: mujoco.MjModel, joints: list[str]) -> Body:
        dofs = np.array([model.jnt_dofadr[model.joint(j).id] for j in joints], dtype=int)
        qpos = np.array([model.jnt_qposadr[model.joint(j).id] for j in joints], dtype=int)
        return cls(model, list(joints), dofs, qpos)

    def posture(self, overrides: dict[str, float] | None = None) -> np.ndarray:
        """The standing pose in the joints' order (rad)."""
        table = {**STANCE_POSTURE, **(overrides or {})}
        return np.array([table.get(j, 0.0) for j in self.joints])

    def effort_limits(self) -> np.ndarray:
        m = self.model
        out = []
        for j in self.joints:
            jid = m.joint(j).id
            out.append(float(m.jnt_actfrcrange[jid][1]) if m.jnt_actfrclimited[jid] else np.inf)
        return np.array(out)


def state_dynamics(model: mujoco.MjModel, scratch: mujoco.MjData) -> Dynamics:
    """A Dynamics computed on `scratch` (whose qpos, qvel the caller fills: the estimated base,
    the encoders), not on the simulator's truth."""
    return Dynamics(model, scratch, copy=False)
