"""Stability margins of a closed loop from `linearize_loop` (issue 38 item 3).

The loop is broken at the plant's input, at each actuator with the others closed and at all of
them at once (the same gain or delay on every channel, as a slower amplifier or a late bus would
act). Per break:

gain margins
    the factors on the command (above 1: `gain_increase`; below 1: `gain_reduction`, which a
    loop around an unstable plant has) at which a closed-loop pole reaches the unit circle: the
    discrete closed loop's eigenvalues, bisected, so exact for the linear model.
phase margin, delay margin
    where the loop's gain (its eigenvalues, all at once) crosses 1, the phase left to -180 deg
    and the delay it takes: min over crossings of ((arg L + pi) mod 2 pi) / w. Exact for a delay
    the loop sees as e^{-s tau}; within a period of a sampled one.
disk margin
    python-control's `disk_margins` (balanced, skew 0): the largest simultaneous gain and phase
    change the loop tolerates as a disk; all at once, an upper bound of the structured singular
    value of S - I/2 for one complex perturbation per loop (python-control's with slycot, else
    Perron scaling; `Margins.method` says which).
sensitivity
    S = (I + L)^-1 and T = I - S at the input: their peaks (largest singular value) and where.

A margin that does not exist (no gain crossover: no delay destabilises; a loop stable at every
gain) is `inf`, and `notes` says why in one line; nothing is returned as None silently.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import control
import numpy as np

from mexone.design.loop import LoopModel
from mexone.errors import InputError
from mexone.ranges import number_text

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["Margins", "LoopMargins", "loop_margins", "plot_margins", "frequency_response", "STABLE_TOL"]

STABLE_TOL = 1e-7  # a pole this far outside the unit circle is unstable (FD noise is ~1e-10)
_GAIN_CEILING = 1e3  # gains above this are "any gain"
_GAIN_RESOLUTION = 1.0005  # the bisection's last bracket (ratio)
_POINTS = 1500  # frequencies from 0.01 Hz to Nyquist


@dataclass(frozen=True)
class LoopMargins:
    """The margins of one break of the loop: `name` (the actuator's input, or "all" for every
    channel at once); `gain_increase`, `gain_reduction` (factors: stable for gains strictly
    between them; inf and 0 where there is no limit), `gain_frequency` (Hz of the pole that goes
    unstable at the upper one); `phase_margin` (deg) at `crossover` (Hz); `delay_margin` (s);
    `disk_margin` (alpha), `disk_gain` ((low, high) factors), `disk_phase` (deg); `peak_s`,
    `peak_t` with their frequencies (Hz); `notes`: why a margin is inf or 0."""

    name: str
    gain_increase: float
    gain_reduction: float
    gain_frequency: float
    phase_margin: float
    crossover: float
    delay_margin: float
    disk_margin: float
    disk_gain: tuple[float, float]
    disk_phase: float
    peak_s: float
    peak_s_frequency: float
    peak_t: float
    peak_t_frequency: float
    notes: tuple[str, ...] = field(default=())

    @property
    def gain_margin_db(self) -> float:
        """The upper gain margin in dB."""
        return 20 * math.log10(self.gain_increase) if self.gain_increase > 0 else -math.inf

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready (inf as "inf")."""
        out = {}
        for key in self.__dataclass_fields__:
            value = getattr(self, key)
            out[key] = _json(value)
        return out


@dataclass(frozen=True)
class Margins:
    """Every break of a LoopModel: `loops` one per channel, `all` every channel at once,
    `frequencies` (Hz) of the grid, the loop's `spectral_radius` (the largest closed-loop pole's
    magnitude),
    `notes` about the loop as a whole, and `method` of the MIMO disk margin."""

    loops: tuple[LoopMargins, ...]
    all: LoopMargins
    period: float
    spectral_radius: float
    frequencies: np.ndarray
    sigma_s: np.ndarray  # largest singular value of S per frequency (all channels)
    sigma_t: np.ndarray
    loop_response: np.ndarray  # (channels, frequencies): L_i per single-loop break
    method: str
    notes: tuple[str, ...] = field(default=())

    def loop(self, name: str) -> LoopMargins:
        """The margins of the break at one input (its label, or just the joint)."""
        for item in self.loops:
            if name in (item.name, item.name.rpartition(":")[0]):
                return item
        raise InputError(f"no loop named {name!r}", hint=", ".join(m.name for m in self.loops))

    def as_dict(self) -> dict[str, Any]:
        """The margins as plain JSON values (`mexone certify --json`)."""
        return {"period": self.period, "spectral_radius": self.spectral_radius,
                "method": self.method, "notes": list(self.notes),
                "all": self.all.as_dict(), "loops": [m.as_dict() for m in self.loops]}


def _json(value: object) -> object:
    if isinstance(value, float | np.floating):
        value = float(value)
        return value if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, tuple):
        return [_json(v) for v in value]
    return value


def loop_margins(loop: LoopModel, frequencies: np.ndarray | None = None) -> Margins:
    """The margins of `loop` (see the module's docstring). frequencies: Hz (default a dense
    log grid up to the Nyquist frequency)."""
    dt = loop.period
    nyquist = 0.5 / dt
    f = np.geomspace(1e-2, nyquist * 0.999, _POINTS) if frequencies is None \
        else np.asarray(frequencies, dtype=float)
    ag, bg, cg = loop.series()
    radius = _radius(ag + bg @ cg)
    notes = list(loop.notes)
    if radius > 1 + STABLE_TOL:
        raise InputError(f"the closed loop is unstable at the point (a pole at |z| = "
                         f"{number_text(radius)}): it has no margins",
                         hint="certify a controller that holds the point")
    if radius > 1 - 1e-9:
        notes.append("the loop has modes on the unit circle (|z| = 1: the base sliding or turning "
                     "on friction alone, which no input moves); they are neither stable nor "
                     "counted as instability")
    level = max(1.0, radius) + STABLE_TOL
    z = np.exp(2j * np.pi * f * dt)
    full = frequency_response(ag, bg, -cg, z)  # (nf, m, m): L with every channel open
    eye = np.eye(loop.channels)
    sens = np.linalg.inv(eye[None] + full)
    comp = eye[None] - sens
    sigma_s = np.linalg.norm(sens, ord=2, axis=(1, 2))
    sigma_t = np.linalg.norm(comp, ord=2, axis=(1, 2))
    method, every = _all_at_once(loop, ag, bg, cg, f, z, full, sigma_s, sigma_t, level)
    singles, responses = [], []
    for i in range(loop.channels):
        item, response = _single(loop, i, ag, bg, cg, f, z, level)
        singles.append(item)
        responses.append(response)
    return Margins(tuple(singles), every, dt, radius, f, sigma_s, sigma_t, np.array(responses),
                   method, tuple(notes))


def _radius(a: np.ndarray) -> float:
    return float(np.abs(np.linalg.eigvals(a)).max(initial=0.0))


def frequency_response(a: np.ndarray, b: np.ndarray, c: np.ndarray, z: np.ndarray) -> np.ndarray:
    """C (zI - A)^-1 B at each z: (len(z), outputs, inputs), by Hessenberg-free chunked solves
    (the robot's models have defective modes at z = 1, so no eigenvector shortcut)."""
    n = a.shape[0]
    out = np.empty((z.size, c.shape[0], b.shape[1]), dtype=complex)
    eye = np.eye(n)
    for start in range(0, z.size, 128):
        zz = z[start:start + 128]
        m = zz[:, None, None] * eye[None] - a[None]
        x = np.linalg.solve(m, np.broadcast_to(b.astype(complex), (zz.size, *b.shape)))
        out[start:start + 128] = c[None] @ x
    return out


def _gain_limits(loop: LoopModel, ag: np.ndarray, bg: np.ndarray, cg: np.ndarray,
                 channels: np.ndarray, level: float) -> tuple[float, float, float]:
    """(upper factor, lower factor, Hz of the upper's critical pole) for a common gain on
    `channels` (the others at 1), bisected on the closed loop's spectral radius."""
    def unstable(k: float) -> bool:
        gains = np.ones(loop.channels)
        gains[channels] = k
        return _radius(ag + bg @ (gains[:, None] * cg)) > level

    high = math.inf
    if unstable(_GAIN_CEILING):
        lo, hi = 1.0, _GAIN_CEILING
        while hi / lo > _GAIN_RESOLUTION:
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
        high = hi
    low = 0.0
    if unstable(1e-6):
        lo, hi = 1e-6, 1.0
        while hi / lo > _GAIN_RESOLUTION:
            mid = math.sqrt(lo * hi)
            lo, hi = (mid, hi) if unstable(mid) else (lo, mid)
        low = lo
    freq = math.nan
    if math.isfinite(high):
        gains = np.ones(loop.channels)
        gains[channels] = high
        eig = np.linalg.eigvals(ag + bg @ (gains[:, None] * cg))
        worst = eig[np.argmax(np.abs(eig))]
        freq = abs(float(np.angle(worst))) / (2 * np.pi * loop.period)
    return high, low, freq


def _crossings(f: np.ndarray, response: np.ndarray) -> tuple[float, float, float, list[str]]:
    """(phase margin deg, its crossover Hz, delay margin s) from a loop's eigenvalues per
    frequency (nf, k): where an eigenvalue's magnitude crosses 1, the phase to -180 deg and the
    delay that closes it."""
    mags = np.abs(response)
    notes = []
    best_delay, best_pm, best_f = math.inf, math.inf, math.nan
    for i in range(len(f) - 1):
        above_now = np.sort(mags[i]) > 1
        above_next = np.sort(mags[i + 1]) > 1
        if np.count_nonzero(above_now) == np.count_nonzero(above_next):
            continue
        # the eigenvalue nearest |lambda| = 1 on either side, interpolated in log frequency
        j0 = int(np.argmin(np.abs(np.log(mags[i]))))
        j1 = int(np.argmin(np.abs(np.log(mags[i + 1]))))
        m0, m1 = math.log(mags[i, j0]), math.log(mags[i + 1, j1])
        w = 0.5 if m0 == m1 else min(1.0, max(0.0, m0 / (m0 - m1)))
        freq = math.exp((1 - w) * math.log(f[i]) + w * math.log(f[i + 1]))
        a0, a1 = np.angle(response[i, j0]), np.angle(response[i + 1, j1])
        angle = a0 + w * ((a1 - a0 + np.pi) % (2 * np.pi) - np.pi)
        lead = (angle + np.pi) % (2 * np.pi)  # phase to spare before -180 deg
        pm = math.degrees(lead if lead <= np.pi else lead - 2 * np.pi)
        delay = lead / (2 * np.pi * freq)
        if delay < best_delay:
            best_delay = delay
        if abs(pm) < abs(best_pm):
            best_pm, best_f = pm, freq
    if not math.isfinite(best_delay):
        notes.append("the loop gain never crosses 1: no phase margin, and no delay destabilises it "
                     "(delay margin inf)")
    return best_pm, best_f, best_delay, notes


def _disk(response: np.ndarray, system: control.StateSpace | None, f: np.ndarray) \
        -> tuple[float, tuple[float, float], float, str]:
    """The balanced disk margin (skew 0, python-control's `disk_margins` definition): alpha =
    1 / max |S - I/2|, its (low, high) gain factors and phase (deg), and the method. One loop:
    exact from the loop's response. Several (`system` given): python-control's with slycot
    (SLICOT's AB13MD bound of the structured singular value), else the same bound by Perron
    scaling."""
    method = "exact (one loop)"
    if response.ndim == 1:
        worst = float(np.abs(0.5 * (1 - response) / (1 + response)).max())
        alpha = 1.0 / worst if worst > 0 else math.inf
    else:
        try:
            import slycot  # noqa: F401 - python-control's MIMO disk margin needs it
            alpha = float(control.disk_margins(system, 2 * np.pi * f, skew=0.0)[0])
            method = "python-control disk_margins: structured singular value bound (slycot)"
        except ImportError:
            alpha = _disk_scaled(response)
            method = "structured singular value bound by Perron scaling"
    if alpha >= 2:
        low, high = 0.0, math.inf
    else:
        low, high = (2 - alpha) / (2 + alpha), (2 + alpha) / (2 - alpha)
    phase = math.degrees(2 * math.atan(alpha / 2))
    return alpha, (low, high), phase, method


def _disk_scaled(response: np.ndarray) -> float:
    """1 / max over frequency of an upper bound of mu(S - I/2) for a diagonal complex
    perturbation (one per loop): min(sigma(M), sigma(D M D^-1)) with D from the Perron vectors
    of |M| (Safonov's scaling)."""
    eye = np.eye(response.shape[1])
    m = np.linalg.inv(eye[None] + response) - 0.5 * eye[None]
    plain = np.linalg.norm(m, ord=2, axis=(1, 2))
    mag = np.abs(m) + 1e-300
    right = _perron(mag)
    left = _perron(np.transpose(mag, (0, 2, 1)))
    d = np.sqrt(left / right)
    scaled = np.linalg.norm(d[:, :, None] * m / d[:, None, :], ord=2, axis=(1, 2))
    worst = float(np.minimum(plain, np.where(np.isfinite(scaled), scaled, plain)).max())
    return 1.0 / worst if worst > 0 else math.inf


def _perron(mag: np.ndarray) -> np.ndarray:
    """The Perron vector (positive, of the largest eigenvalue) of each nonnegative matrix."""
    values, vectors = np.linalg.eig(mag)
    top = np.argmax(np.abs(values), axis=1)
    vector = np.abs(np.take_along_axis(vectors, top[:, None, None], axis=2)[:, :, 0])
    return np.maximum(vector, 1e-12)


def _all_at_once(loop: LoopModel, ag: np.ndarray, bg: np.ndarray, cg: np.ndarray, f: np.ndarray,
                 z: np.ndarray, full: np.ndarray, sigma_s: np.ndarray, sigma_t: np.ndarray,
                 level: float) -> tuple[str, LoopMargins]:
    everything = np.arange(loop.channels)
    high, low, gain_f = _gain_limits(loop, ag, bg, cg, everything, level)
    eig = np.linalg.eigvals(full)
    pm, crossover, delay, notes = _crossings(f, eig)
    alpha, disk_gain, disk_phase, method = _disk(full, loop.loop(), f)
    notes += _gain_notes(high, low)
    i_s, i_t = int(np.argmax(sigma_s)), int(np.argmax(sigma_t))
    return method, LoopMargins("all", high, low, gain_f, pm, crossover, delay, alpha, disk_gain,
                               disk_phase, float(sigma_s[i_s]), float(f[i_s]), float(sigma_t[i_t]),
                               float(f[i_t]), tuple(notes))


def _single(loop: LoopModel, i: int, ag: np.ndarray, bg: np.ndarray, cg: np.ndarray,
            f: np.ndarray, z: np.ndarray, level: float) -> tuple[LoopMargins, np.ndarray]:
    high, low, gain_f = _gain_limits(loop, ag, bg, cg, np.array([i]), level)
    system = loop.loop_at(i)
    response = frequency_response(np.asarray(system.A), np.asarray(system.B),
                                  np.asarray(system.C), z)[:, 0, 0]
    pm, crossover, delay, notes = _crossings(f, response[:, None])
    alpha, disk_gain, disk_phase, _ = _disk(response, None, f)
    notes += _gain_notes(high, low)
    s = np.abs(1 / (1 + response))
    t = np.abs(response / (1 + response))
    i_s, i_t = int(np.argmax(s)), int(np.argmax(t))
    return LoopMargins(loop.inputs[i], high, low, gain_f, pm, crossover, delay, alpha, disk_gain,
                       disk_phase, float(s[i_s]), float(f[i_s]), float(t[i_t]), float(f[i_t]),
                       tuple(notes)), response


def _gain_notes(high: float, low: float) -> list[str]:
    notes = []
    if not math.isfinite(high):
        notes.append(f"stable for every gain increase up to {number_text(_GAIN_CEILING)}x "
                     "(gain margin inf)")
    if low == 0.0:
        notes.append("stable down to no feedback at all on this break (no lower gain margin: the "
                     "plant is stable without it)")
    return notes


def plot_margins(result: Margins, fig: Figure | None = None) -> Figure:
    """Nyquist-style loop gains per break, and S and T against frequency; returns the Figure."""
    import matplotlib.pyplot as plt

    if fig is None:
        fig = plt.figure(figsize=(9, 4))
    left, right = fig.subplots(1, 2)
    theta = np.linspace(0, 2 * np.pi, 200)
    left.plot(np.cos(theta) - 0, np.sin(theta), color="grey", lw=0.6)
    for item, response in zip(result.loops, result.loop_response, strict=True):
        left.plot(response.real, response.imag, lw=1, label=item.name)
    left.plot([-1], [0], "r+", markersize=12)
    left.set_xlim(-3, 2)
    left.set_ylim(-2.5, 2.5)
    left.set_aspect("equal")
    left.set_title("loop gain L_i (one break, others closed)")
    left.legend(fontsize="x-small")
    left.grid(True)
    f = result.frequencies
    right.loglog(f, result.sigma_s, label="S (largest singular value)")
    right.loglog(f, result.sigma_t, label="T")
    right.axhline(1.0, color="grey", lw=0.6)
    right.set_xlabel("frequency (Hz)")
    right.set_title(f"all channels: |S| peak {result.all.peak_s:.2f}, |T| peak {result.all.peak_t:.2f}")
    right.legend(fontsize="small")
    right.grid(True, which="both")
    fig.tight_layout()
    return fig
