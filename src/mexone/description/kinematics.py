"""Forward kinematics of a RobotModel in any joint configuration (the model's own
`link_frames` is the home pose), for spawning in a pose and for tuning gains in it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from mexone.description.model import RobotModel

__all__ = ["link_frames_at", "joint_motion", "with_mimics"]


def joint_motion(axis: Sequence[float] | np.ndarray, joint_type: str, q: float) -> np.ndarray:
    """The 4x4 transform a joint at position q adds after its origin."""
    out = np.eye(4)
    if not q:
        return out
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    if joint_type == "prismatic":
        out[:3, 3] = a * q
    elif joint_type in ("revolute", "continuous"):
        k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        out[:3, :3] = np.eye(3) + np.sin(q) * k + (1 - np.cos(q)) * (k @ k)
    return out


def with_mimics(robot: RobotModel, positions: Mapping[str, float]) -> dict[str, float]:
    """The positions plus every <mimic> follower's, q = offset + multiplier * q_leader."""
    out = dict(positions)
    for _ in range(len(robot.joints)):  # followers of followers
        changed = False
        for joint in robot.joints.values():
            mimic = joint.mimic
            if mimic is not None and mimic.joint in out and joint.name not in positions:
                value = mimic.offset + mimic.multiplier * out[mimic.joint]
                if out.get(joint.name) != value:
                    out[joint.name], changed = value, True
        if not changed:
            break
    return out


def link_frames_at(robot: RobotModel, positions: Mapping[str, float] | None = None
                   ) -> dict[str, np.ndarray]:
    """World transform of every link frame with the given joint positions (others at 0),
    the root at the identity."""
    if not positions:
        return robot.link_frames
    q = with_mimics(robot, positions)
    frames = {robot.root: np.eye(4)}
    for name in robot.walk():
        for joint in robot.child_joints.get(name, []):
            if joint.child not in frames:
                motion = joint_motion(joint.axis, joint.type, q.get(joint.name, 0.0))
                frames[joint.child] = frames[name] @ joint.origin.matrix @ motion
    return frames

