"""Read a recorded bag back into joint time series (for plots and CSV), with rosbags."""

from __future__ import annotations

import logging
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from mexone.errors import InputError
from mexone.record.bag import typestore_for

__all__ = ["JointSeries", "read_joint_series"]

log = logging.getLogger(__name__)


@dataclass
class JointSeries:
    """One joint's measured state and, where a position controller commanded it, the command
    (held between command messages, as the controller holds it)."""

    name: str
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    command: np.ndarray | None = None
    command_times: list[float] = field(default_factory=list)


def read_joint_series(path: Path | str) -> dict[str, JointSeries]:
    """The joints of a bag; a killed recording's (BAG.active, or a truncated BAG) is read from a
    recovered copy, with a one-line note saying how to repair the file itself."""
    from mexone.record.recover import killed_recording, looks_truncated, recover

    path = Path(path)
    if path.is_dir() or (path.is_file() and not path.name.endswith(".active")
                         and not looks_truncated(path)):
        return _read(path)
    killed = killed_recording(path)
    if killed is None:
        raise InputError("no such file", file=path, hint="record one with --record FILE")
    with tempfile.TemporaryDirectory(prefix="mexone-recover-") as folder:
        copy = Path(folder) / killed.name.removesuffix(".active")
        found = recover(killed, copy)
        bag = killed.with_name(copy.name)
        log.warning(f"{killed}: an unfinished recording (killed?); read the {found.describe()} "
                    f"recovered from it; 'mexone record --recover {bag}' repairs it on disk")
        try:
            return _read(copy)
        except InputError as exc:  # about the user's file, not our temporary copy
            raise InputError(exc.what, file=killed, hint=exc.hint) from None


def _read(path: Path) -> dict[str, JointSeries]:
    try:
        reader = AnyReader([path], default_typestore=typestore_for(path.suffix == ".bag"))
        reader.open()
    except Exception as exc:  # rosbags raises its own error types for damaged or foreign files
        raise InputError(f"not a readable bag: {exc}", file=path,
                         hint="give a .mcap or .bag recorded by mexone or ROS") from None
    states: list[tuple[float, object]] = []
    commands: dict[str, list[tuple[float, float]]] = {}
    try:
        for conn, stamp, raw in reader.messages():
            if conn.msgtype == "sensor_msgs/msg/JointState":
                states.append((stamp * 1e-9, reader.deserialize(raw, conn.msgtype)))
            elif conn.msgtype == "std_msgs/msg/Float64" and conn.topic.endswith(
                    "_position_controller/command"):
                joint = conn.topic.rsplit("/", 2)[-2].removesuffix("_position_controller")
                commands.setdefault(joint, []).append(
                    (stamp * 1e-9, float(reader.deserialize(raw, conn.msgtype).data)))
    finally:
        reader.close()
    if not states:
        raise InputError("the bag has no sensor_msgs/JointState messages", file=path,
                         hint="record a run that has a joint_state_controller")
    names = list(states[0][1].name)
    t = np.array([s for s, _ in states])
    out = {}
    for i, name in enumerate(names):
        series = JointSeries(name, t, np.array([m.position[i] for _, m in states]),
                             np.array([m.velocity[i] for _, m in states]),
                             np.array([m.effort[i] for _, m in states]))
        if name in commands:
            ct = np.array([c for c, _ in commands[name]])
            cv = np.array([v for _, v in commands[name]])
            idx = np.searchsorted(ct, t, side="right") - 1
            series.command = np.where(idx >= 0, cv[np.maximum(idx, 0)], 0.0)
            series.command_times = ct.tolist()
        out[name] = series
    return out
