"""Homogeneous transforms in the URDF convention (fixed-axis roll, pitch, yaw: R = Rz Ry Rx).

Written here rather than imported from trimesh.transformations because importing trimesh costs
half a second, and every CLI verb needs these few lines.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["rpy_to_matrix", "matrix_to_rpy", "make_transform", "split_transform", "invert"]


def rpy_to_matrix(rpy: Sequence[float] | np.ndarray) -> np.ndarray:
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(rot: np.ndarray) -> np.ndarray:
    """Inverse of rpy_to_matrix; at gimbal lock (pitch = ±pi/2) roll is set to 0."""
    sp = -rot[2, 0]
    if abs(sp) >= 1.0 - 1e-12:
        pitch = np.copysign(np.pi / 2, sp)
        yaw = np.arctan2(-rot[0, 1], rot[1, 1])
        return np.array([0.0, pitch, yaw])
    return np.array(
        [np.arctan2(rot[2, 1], rot[2, 2]), np.arcsin(sp), np.arctan2(rot[1, 0], rot[0, 0])]
    )


def make_transform(xyz: Sequence[float] | np.ndarray, rpy: Sequence[float] | np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rpy_to_matrix(rpy)
    out[:3, 3] = np.asarray(xyz, dtype=float)
    return out


def split_transform(mat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(xyz, rpy) of a homogeneous transform."""
    return mat[:3, 3].copy(), matrix_to_rpy(mat[:3, :3])


def invert(mat: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = mat[:3, :3].T
    out[:3, 3] = -mat[:3, :3].T @ mat[:3, 3]
    return out
