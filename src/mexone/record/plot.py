"""Plots and CSV of a recorded run: command vs actual, tracking error and effort per joint; or
any numeric fields of any topics (rqt_plot's topic paths), one pane per message field group."""

from __future__ import annotations

import csv
from pathlib import Path

from mexone.errors import InputError
from mexone.record.reader import FieldSeries, JointSeries

__all__ = ["plot_joints", "write_csv", "pick_joints", "plot_fields", "write_fields_csv"]


def pick_joints(series: dict[str, JointSeries], wanted: list[str] | None) -> list[JointSeries]:
    if wanted:
        missing = [j for j in wanted if j not in series]
        if missing:
            raise InputError(f"the bag has no joint {', '.join(missing)}",
                             hint="joints: " + ", ".join(series))
        return [series[j] for j in wanted]
    commanded = [s for s in series.values() if s.command is not None]
    return commanded or list(series.values())[:4]


def _panes(rows: int, columns: int, height: float):
    """A figure of rows x columns panes sharing the time axis (Agg: no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(rows, columns, figsize=(12, height * rows + 0.6), squeeze=False,
                        sharex=True)


def _save(fig, axes, out: Path, title: str) -> None:
    import matplotlib.pyplot as plt

    for ax in axes[-1]:
        ax.set_xlabel("sim time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def plot_joints(joints: list[JointSeries], out: Path, title: str) -> None:
    fig, axes = _panes(len(joints), 2, 2.8)
    for row, s in zip(axes, joints, strict=True):
        left, right = row
        if s.command is not None:
            left.step(s.t, s.command, where="post", color="#1f77b4", label="command")
        left.plot(s.t, s.position, color="#d62728", label="actual")
        left.set_ylabel(f"{s.name}\nposition (rad)")
        left.legend(loc="upper right", fontsize=8)
        left.grid(alpha=0.3)
        if s.command is not None:
            right.plot(s.t, s.command - s.position, color="#2ca02c", label="error")
        right.set_ylabel("error (rad)")
        right.grid(alpha=0.3)
        effort_axis = right.twinx()
        effort_axis.plot(s.t, s.effort, color="#9467bd", alpha=0.8, label="effort")
        effort_axis.set_ylabel("effort (N m)")
        handles = right.get_legend_handles_labels()[0] + effort_axis.get_legend_handles_labels()[0]
        right.legend(handles, [h.get_label() for h in handles], loc="upper right", fontsize=8)
    _save(fig, axes, out, title)


def write_csv(joints: list[JointSeries], out: Path) -> int:
    rows = 0
    with out.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time_s", "joint", "command_rad", "position_rad", "error_rad",
                         "velocity_rad_s", "effort_Nm"])
        for s in joints:
            for k, t in enumerate(s.t):
                cmd = "" if s.command is None else f"{s.command[k]:.9g}"
                err = "" if s.command is None else f"{s.command[k] - s.position[k]:.9g}"
                writer.writerow([f"{t:.6f}", s.name, cmd, f"{s.position[k]:.9g}", err,
                                 f"{s.velocity[k]:.9g}", f"{s.effort[k]:.9g}"])
                rows += 1
    return rows


def plot_fields(series: list[FieldSeries], out: Path, title: str) -> None:
    """One pane per group of sibling fields (x, y, z of a vector together), in sim time."""
    groups: dict[str, list[FieldSeries]] = {}
    for s in series:
        groups.setdefault(s.path.rsplit("/", 1)[0], []).append(s)
    fig, axes = _panes(len(groups), 1, 2.4)
    for ax, (group, members) in zip(axes[:, 0], groups.items(), strict=True):
        for s in members:
            ax.plot(s.t, s.values, label=s.path.rsplit("/", 1)[1], linewidth=1.0)
        ax.set_ylabel(group, fontsize=8)
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    _save(fig, axes, out, title)


def write_fields_csv(series: list[FieldSeries], out: Path) -> int:
    rows = 0
    with out.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time_s", "field", "value"])
        for s in series:
            for t, value in zip(s.t.tolist(), s.values.tolist(), strict=True):
                writer.writerow([f"{t:.6f}", s.path, f"{value:.9g}"])
                rows += 1
    return rows
