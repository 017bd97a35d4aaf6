"""The effort limits in the analysis (issue 38 item 4): when a deviation saturates an input, and
what the saturation does to the loop.

From a `LoopModel`, the closed loop's response to a unit deviation of each controlled joint
(its angle, then, as a push, its velocity) gives each input's peak command per unit; an input's
headroom (its effort limit less what it spends holding the point, on the tighter side) over
that peak is the deviation at which it first saturates. The describing-function view: a
saturation passes a sinusoid of amplitude A > a (the headroom) with the gain
N(A) = (2 / pi) (asin(a / A) + (a / A) sqrt(1 - (a / A)^2)), so the loop behaves as if its gain
dropped to N(A). A loop around an unstable plant (a balance) needs a gain above its lower gain
margin k_low: the command amplitude A* with N(A*) = k_low is where saturation may cost it its
balance (a limit cycle or a fall), and A* over the peak per unit the deviation that asks for it.
A loop that is stable with no feedback (k_low = 0) is only slowed by saturation, in this view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mexone.design.loop import LoopModel
from mexone.design.margins import Margins
from mexone.errors import InputError
from mexone.ranges import number_text

__all__ = ["Saturation", "saturation", "saturation_gain", "critical_amplitude"]


def saturation_gain(ratio: float | np.ndarray) -> np.ndarray:
    """N(A) of a unit-slope saturation at a / A = `ratio` (1 inside the limit: ratio >= 1)."""
    r = np.clip(np.asarray(ratio, dtype=float), 0.0, 1.0)
    return (2 / np.pi) * (np.arcsin(r) + r * np.sqrt(1 - r**2))


def critical_amplitude(k_low: float) -> float:
    """A* / a where the saturation's gain N falls to `k_low` (inf when k_low <= 0: never)."""
    if k_low <= 0:
        return math.inf
    if k_low >= 1:
        return 1.0
    lo, hi = 1e-9, 1.0  # in r = a / A, N is increasing
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if saturation_gain(mid) < k_low else (lo, mid)
    return 1.0 / hi


@dataclass(frozen=True)
class Saturation:
    """`directions` (the deviations tried: `<joint>:q` and `<joint>:dq`), `inputs`,
    `headroom` per input (N m), `peak` (directions x inputs: the largest command deviation per unit
    deviation), `onset` per direction (the deviation at which the first input saturates) with
    `first` (that input), `k_low` (the loop's lower gain margin, all channels), `amplitude`
    (A*/a: the command amplitude, in headrooms, where saturation takes the loop's gain down to
    k_low; inf: never) and `critical` per direction (the deviation that asks for it)."""

    directions: tuple[str, ...]
    inputs: tuple[str, ...]
    headroom: np.ndarray
    peak: np.ndarray
    onset: np.ndarray
    first: tuple[str, ...]
    k_low: float
    amplitude: float
    critical: np.ndarray
    notes: tuple[str, ...] = field(default=())

    def as_dict(self) -> dict[str, Any]:
        """The saturation analysis as plain JSON values."""
        def num(x: float) -> float | str:
            return float(x) if math.isfinite(x) else "inf"
        return {"k_low": self.k_low, "amplitude": num(self.amplitude), "notes": list(self.notes),
                "inputs": list(self.inputs), "headroom": [num(h) for h in self.headroom],
                "directions": [{"deviation": d, "saturates_at": num(o), "first": f,
                                "critical": num(c)}
                               for d, o, f, c in zip(self.directions, self.onset, self.first,
                                                     self.critical, strict=True)]}


def saturation(loop: LoopModel, margins: Margins | None = None, horizon: float = 2.0) -> Saturation:
    """The saturation view of `loop` (see the module's docstring); `margins` gives k_low (else
    the loop is taken to be stable without feedback)."""
    if loop.interface != "effort":
        raise InputError(f"the loop's inputs are {loop.interface} setpoints: no effort limit "
                         "applies to them in the model", hint="the PIDs behind them clamp")
    closed = loop.closed()
    states = list(loop.plant.state_labels)
    directions = [f"{j}:{kind}" for kind in ("q", "dq") for j in loop.joints if f"{j}:{kind}" in states]
    steps = max(2, round(horizon / loop.period))
    a, c = np.asarray(closed.A), np.asarray(closed.C)[:loop.channels]
    limits = loop.limits
    headroom = np.minimum(limits - loop.u0, limits + loop.u0)
    notes = []
    if np.any(headroom <= 0):
        worst = loop.inputs[int(np.argmin(headroom))]
        notes.append(f"{worst} is at its effort limit at the point already")
    peaks = np.zeros((len(directions), loop.channels))
    for k, label in enumerate(directions):
        x = np.zeros(a.shape[0])
        x[states.index(label)] = 1.0
        peak = np.zeros(loop.channels)
        for _ in range(steps):
            peak = np.maximum(peak, np.abs(c @ x))
            x = a @ x
        peaks[k] = peak
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(peaks > 0, np.maximum(headroom, 0)[None, :] / peaks, np.inf)
    onset = per.min(axis=1)
    first = tuple(loop.inputs[int(i)] for i in per.argmin(axis=1))
    k_low = 0.0 if margins is None else float(margins.all.gain_reduction)
    amplitude = critical_amplitude(k_low)
    critical = onset * amplitude if math.isfinite(amplitude) else np.full(len(directions), np.inf)
    if k_low <= 0:
        notes.append("the loop is stable without feedback: saturation slows it, and by the "
                     "describing function cannot destabilise it")
    else:
        notes.append(f"the loop needs at least {number_text(k_low)} of its gain: a command "
                     f"{number_text(amplitude)}x its headroom brings a saturating input's gain "
                     "there")
    return Saturation(tuple(directions), loop.inputs, headroom, peaks, onset, first, k_low,
                      amplitude, critical, tuple(notes))
