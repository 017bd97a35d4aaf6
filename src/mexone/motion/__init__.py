"""Whole-body motion for humanoids: inverse kinematics (mink) on the simulated model, and the
routine commands built on it (reach, look_at, walk) and on the physics (push).

A front end: it drives the robot through the controllers' topics, as a student's routine does.
"""

from mexone.motion.commands import (
    follow_goals,
    joint_targets,
    look_at,
    push,
    reach,
    walk,
    walk_cmd_vel,
    walk_seconds,
)
from mexone.motion.frames import Frame, frames_for
from mexone.motion.ik import FrameError, WholeBodyIK
from mexone.motion.push import apply_wrench

__all__ = ["reach", "look_at", "push", "walk", "walk_cmd_vel", "walk_seconds", "joint_targets",
           "follow_goals",
           "WholeBodyIK", "FrameError", "Frame", "frames_for", "apply_wrench"]
