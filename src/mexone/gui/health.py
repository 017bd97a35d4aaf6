"""What the status line must not hide: MuJoCo's warnings and a controller gone unstable.

MuJoCo counts its warnings in `data.warning` (and prints each kind once to the terminal); a
gain far beyond what the time step allows does not diverge when the motor saturates, it
chatters: the effort flips between its limits every few steps while the joint stands still.
Both are read here in the simulation thread and named on the page: the warnings once a
frame, the efforts' window every CHATTER_EVERY samples of the signal log (0.1 s of sim time).
"""

from __future__ import annotations

import mujoco
import numpy as np

from mexone.gui.plots import SignalLog

__all__ = ["Health", "WARNINGS", "CHATTER_WINDOW", "CHATTER_EVERY"]

WARNINGS = {  # MuJoCo's own words (engine_io.c), and what to do
    "mjWARN_INERTIA": "inertia matrix too close to singular: check the links' inertias",
    "mjWARN_CONTACTFULL": "too many contacts: the contact buffer is full",
    "mjWARN_CNSTRFULL": "insufficient memory for constraints: fewer contacts or a bigger arena",
    "mjWARN_VGEOMFULL": "too many visual geoms",
    "mjWARN_BADQPOS": "NaN, Inf or huge value in QPOS",
    "mjWARN_BADQVEL": "NaN, Inf or huge value in QVEL",
    "mjWARN_BADQACC": "NaN, Inf or huge value in QACC",
    "mjWARN_BADCTRL": "NaN, Inf or huge value in CTRL: a controller's output is not finite "
                      "(gains too high?)",
}
CHATTER_WINDOW = 0.3  # s of sim time looked at
CHATTER_EVERY = 10  #: log samples (0.1 s of sim time running) between two looks at the window
_AT_LIMIT = 0.9  # of the effort limit
_FLIPS = 0.3  # share of samples where the effort changes sign


class Health:
    def __init__(self, sim, log: SignalLog):
        self.sim, self.log = sim, log
        self.seen = np.zeros(len(sim.data.warning), dtype=int)
        joints = [s.name.split("/")[0] for s in log.signals if s.name.endswith("/effort")]
        self.effort_cols = np.array([log.index[f"{j}/effort"] for j in joints], dtype=int)
        self.joints = joints
        limits = []
        for j in joints:
            joint = sim.robot.joints.get(j)
            limit = joint.limit.effort if joint is not None and joint.limit else 0.0
            limits.append(limit if limit and limit > 0 else np.inf)
        self.limits = np.array(limits)
        self.warnings: dict[str, str] = {}
        self.chatter: str | None = None
        self._chatter_at = -CHATTER_EVERY  # the log's count when the window was last looked at

    def check(self) -> list[str]:
        """The problems that appeared since the last check (their text)."""
        new = []
        # one array for every kind (a view, copied): a list of MuJoCo's per-kind wrappers cost
        # ~0.25 ms a frame, the largest share of the page's own work
        counts = self.sim.data.warning.number.copy()
        if (counts < self.seen).any():  # a reset zeroes them
            self.seen = np.zeros_like(self.seen)
            self.warnings.clear()
        for i in np.flatnonzero(counts > self.seen):
            name = mujoco.mjtWarning(int(i)).name
            if name not in self.warnings:
                new.append(f"MuJoCo warning: {WARNINGS.get(name, name)}")
            self.warnings[name] = f"MuJoCo warning: {WARNINGS.get(name, name)} ({counts[i]}×)"
        self.seen = counts
        count = self.log.count
        if not 0 <= count - self._chatter_at < CHATTER_EVERY:  # 10 new samples, or a reset
            self._chatter_at = count
            chatter = self._chatter()
            if chatter and chatter != self.chatter:
                new.append(chatter)
            self.chatter = chatter
        return new

    @property
    def problems(self) -> list[str]:
        """What is wrong now: MuJoCo's warnings since the last reset, a chattering controller."""
        return [*self.warnings.values(), *([self.chatter] if self.chatter else [])]

    def _chatter(self) -> str | None:
        n = int(CHATTER_WINDOW / 0.01)
        if self.log.count < n or not self.effort_cols.size:
            return None
        rows = np.arange(self.log.count - n, self.log.count) % len(self.log.t)
        effort = self.log.values[rows[:, None], self.effort_cols].astype(float)
        at_limit = (np.abs(effort) >= _AT_LIMIT * self.limits).mean(axis=0)
        flips = (np.diff(np.sign(effort), axis=0) != 0).mean(axis=0)
        bad = np.flatnonzero((at_limit > 0.6) & (flips > _FLIPS))
        if bad.size == 0:
            return None
        names = ", ".join(self.joints[i] for i in bad[:4]) + (" …" if bad.size > 4 else "")
        return (f"unstable control: the effort of {names} flips between its limits "
                f"(±{self.limits[bad[0]]:g}) — the gains are too high for the time step")
