"""Checking a deployed design against the simulated robot (issue 32 item 4).

`compare` runs the robot from an initial deviation (and/or a reference step) under a deployed
controller and predicts the same run with the linear closed loop (python-control's
`forced_response`), sample for sample at the controller's period: the course's "model vs plant"
figure (`plot_comparison`) with the difference as a number. `measure_frequency_response` adds a
few sines (a multisine, each at a whole number of cycles over the window) to one reference of a
deployed controller, fits the measured signal's phasor per frequency by least squares, and
overlays it on the linear closed loop's response (`plot_frequency_response`), with the loop's
gain and phase margins.

The closed loop (discrete, at the controller's period) stacks the plant's deviation dx and the
controller's own state xc: a StateFeedback's u = -K (dx - r); a LinearController's
u = Cc xc + Dc e, xc+ = Ac xc + Bc e with e = r - S dx (S: the rows of dx it measures), or,
for create_statefbk_iosystem's controller, e = its inputs (xd, ud = r; x = S dx).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeAlias, TypeVar

import control
import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mexone.design.deploy import GainDesign, _Deployed
from mexone.errors import ArgumentTypeError, InputError
from mexone.ranges import COMPARE_DURATION, number_text

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure, SubFigure

    from mexone.lab import Lab

StateSpace: TypeAlias = Any  # control.StateSpace: python-control has no type information
T = TypeVar("T")

__all__ = ["compare", "Comparison", "plot_comparison", "measure_frequency_response",
           "FrequencyResponse", "plot_frequency_response", "closed_loop", "loop_gain", "margins"]


# ----- the linear closed loop ----------------------------------------------------------------
def _check(controller: object, plant: StateSpace) -> None:
    if not isinstance(controller, _Deployed):
        raise ArgumentTypeError("give the controller deploy() returned (a StateFeedback or "
                                f"LinearController), not {type(controller).__name__}")
    if getattr(plant, "linearization", None) is None:
        raise InputError("the plant is not a StateSpace made by mexone.design.linearize")
    if controller.design.point is None:
        raise InputError("this LinearController reads absolute joint readings; compare needs "
                         "one deployed with its plant (deviations from the point)")
    period = 1.0 / controller.rate
    if plant.dt in (0, None, True) or abs(float(plant.dt) - period) > 1e-9:
        raise InputError(f"the plant's dt ({plant.dt}) is not the controller's period "
                         f"{number_text(period)} s", hint="linearize(..., period=1/rate)")
    if tuple(plant.state_labels) != controller.design.point.states:
        raise InputError("the plant's states are not those the controller was deployed with")


def _parts(controller: _Deployed, plant: StateSpace) -> tuple[np.ndarray, ...]:
    """(Ac, Bc, Cc, Dc, G, H, E): the controller's matrices, e = G dx + H r, u = E uc."""
    nx = plant.nstates
    labels = list(plant.state_labels)
    inputs = list(plant.input_labels)
    d = controller.design
    if isinstance(d, GainDesign):  # a StateFeedback's
        E = np.zeros((plant.ninputs, len(d.joints)))
        for j, joint in enumerate(d.joints):
            E[inputs.index(f"{joint}:{d.interface}"), j] = 1.0
        return (np.zeros((0, 0)), np.zeros((0, nx)), np.zeros((len(d.joints), 0)), d.K,
                -np.eye(nx), np.eye(nx), E)
    m = len(d.inputs)
    G, H = np.zeros((m, nx)), np.zeros((m, m))
    for i, label in enumerate(d.inputs):
        if controller._kinds[i] == "x":
            G[i, labels.index(label)] = 1.0 if d.direct else -1.0
            if not d.direct:
                H[i, i] = 1.0
        elif controller._kinds[i] in ("xd", "ud"):
            H[i, i] = 1.0
        else:
            raise InputError(f"the controller's input {label!r} is an absolute reading; compare "
                             "needs the plant's states")
    E = np.zeros((plant.ninputs, len(d.joints)))
    for j, joint in enumerate(d.joints):
        label = f"{joint}:{d.interface}"
        if label not in inputs:
            raise InputError(f"the controller drives {label!r}, not an input of the plant")
        E[inputs.index(label), j] = 1.0
    return d.A, d.B, d.C, d.D, G, H, E


def closed_loop(controller: _Deployed, plant: StateSpace) -> StateSpace:
    """The linear closed loop of a deployed controller on its plant: states [dx, xc], inputs the
    controller's references (`controller.reference`), outputs dx (the plant's states)."""
    _check(controller, plant)
    Ac, Bc, Cc, Dc, G, H, E = _parts(controller, plant)
    A, B = np.asarray(plant.A), np.asarray(plant.B)
    nx, nc = A.shape[0], Ac.shape[0]
    top = np.hstack([A + B @ E @ Dc @ G, B @ E @ Cc])
    bottom = np.hstack([Bc @ G, Ac])
    a = np.vstack([top, bottom]) if nc else top
    b = np.vstack([B @ E @ Dc @ H, Bc @ H]) if nc else B @ E @ Dc @ H
    c = np.hstack([np.eye(nx), np.zeros((nx, nc))])
    return control.ss(a, b, c, np.zeros((nx, b.shape[1])), plant.dt,
                      states=list(plant.state_labels) + [f"controller:{i}" for i in range(nc)],
                      outputs=list(plant.state_labels), name="closed loop")


def loop_gain(controller: _Deployed, plant: StateSpace,
              channel: int | None = None) -> StateSpace | None:
    """The loop transfer L(z) broken at the plant's input (one input: a SISO loop, the
    negative-feedback convention: the closed loop is 1/(1 + L)); None for several inputs,
    unless `channel` picks one: the loop broken there, every other input's loop closed."""
    _check(controller, plant)
    Ac, Bc, Cc, Dc, G, H, E = _parts(controller, plant)
    m = E.shape[1]
    if m != 1 and channel is None:
        return None
    i = 0 if channel is None else channel
    A, B = np.asarray(plant.A), np.asarray(plant.B) @ E
    nx, nc = A.shape[0], Ac.shape[0]
    a = np.block([[A, np.zeros((nx, nc))], [Bc @ G, Ac]]) if nc else A
    b = np.vstack([B, np.zeros((nc, m))]) if nc else B
    c = np.hstack([Dc @ G, Cc]) if nc else Dc @ G
    others = np.ones(m)
    others[i] = 0.0
    a = a + b @ (others[:, None] * c)  # the other loops closed
    return control.ss(a, b[:, [i]], -c[[i]], np.zeros((1, 1)), plant.dt, name="loop")


# ----- running the robot ---------------------------------------------------------------------
def _on_sim(lab: Lab, fn: Callable[[], T]) -> T:
    sim = lab.sim
    return sim.work.call(fn) if sim.loop_elsewhere() else fn()


def _check_limits(model: mujoco.MjModel, qpos: np.ndarray, dofs: np.ndarray) -> None:
    """A deviation that puts a limited joint past its range is refused before the state is
    touched: the run would start inside a stop (or diverge), and the comparison mean nothing."""
    for dof in dofs:
        joint = int(model.dof_jntid[dof])
        if not model.jnt_limited[joint] or int(model.jnt_type[joint]) not in (
                int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            continue
        low, high = model.jnt_range[joint]
        value = qpos[model.jnt_qposadr[joint]]
        if not low <= value <= high:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
            raise InputError(f"deviation puts {name} at {number_text(value)}, outside its limits "
                             f"[{number_text(low)}, {number_text(high)}]",
                             hint="a deviation the linear model holds is small: a few hundredths")


def _start(lab: Lab, controller: _Deployed, dx0: np.ndarray | None, duration: float) -> None:
    """Put the robot at the point + dx0 (the model's coordinates; the joints outside the model
    as they are) and clear the controller's state; it records `duration` s of updates."""
    sim, point = lab.sim, controller.design.point
    assert point is not None  # _check: compare needs a controller deployed with its plant

    def set_state() -> None:
        model, data = sim.model, sim.data
        if dx0 is not None:
            nv = point.qvel.size
            qpos = data.qpos.copy()
            qpos[point.qpos_index] = point.qpos
            v = np.zeros(model.nv)
            v[point.qvel_index] = dx0[:nv]
            mujoco.mj_integratePos(model, qpos, v, 1.0)
            _check_limits(model, qpos, point.qvel_index[dx0[:nv] != 0])
            qvel = data.qvel.copy()
            qvel[point.qvel_index] = point.qvel + dx0[nv:2 * nv]
            sim.set_state(qpos, qvel)
        controller.reset()
        controller.trace_full.clear()
        controller.trace_length = max(2, round(duration * controller.rate))
        controller.trace = []
    _on_sim(lab, set_state)


def _run(lab: Lab, controller: _Deployed, duration: float) -> list[Any]:
    """`duration` s of the controller's updates: simulated here, or, while another thread runs
    the loop (the page, a notebook's live lab), waited for as it runs them."""
    sim = lab.sim
    if sim.loop_elsewhere():
        if not controller.trace_full.wait(timeout=30.0 + 20.0 * duration):
            controller.trace = None
            raise InputError("the simulation did not run the controller's updates in time "
                             "(is it paused?)", hint="resume it, then check again")
    else:
        sim.run(duration)
    trace = list(controller.trace or [])[:controller.trace_length]
    controller.trace = None
    return trace


def _vector(values: Mapping[str, float] | ArrayLike | None, labels: list[str], what: str) -> np.ndarray:
    out = np.zeros(len(labels))
    if values is None:
        return out
    if isinstance(values, Mapping):
        for label, value in values.items():
            if label not in labels:
                raise InputError(f"{what} names {label!r}, not one of the signals",
                                 hint=", ".join(labels[:8]) + (", ..." if len(labels) > 8 else ""))
            out[labels.index(label)] = float(value)
    else:
        arr = np.asarray(values, dtype=float).reshape(-1)
        if arr.shape != out.shape:
            raise InputError(f"{what} has {arr.size} values; the signals are {len(labels)}")
        out[:] = arr
    if not np.all(np.isfinite(out)):
        raise InputError(f"{what} has a NaN or inf")
    return out


# ----- model vs plant ------------------------------------------------------------------------
@dataclass(frozen=True)
class Comparison:
    """A run of the robot and the linear prediction of it, per controller update: `t` (s from
    the start), `measured` and `predicted` (len(t) x nx, the plant's state deviations), `labels`,
    `rms` per state, and `relative`: the RMS over time of the position-state difference's norm
    divided by the norm of the initial position deviation (or of the reference, for a step)."""

    t: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    labels: tuple[str, ...]
    rms: np.ndarray
    relative: float
    reference: np.ndarray

    def signal(self, label: str) -> tuple[np.ndarray, np.ndarray]:
        """(measured, predicted) of one state."""
        i = self.labels.index(label)
        return self.measured[:, i], self.predicted[:, i]


def compare(lab: Lab, controller: _Deployed, plant: StateSpace,
            deviation: Mapping[str, float] | ArrayLike | None = None,
            reference: Mapping[str, float] | ArrayLike | None = None,
            duration: float = 1.0) -> Comparison:
    """Run the robot under `controller` (from deploy, on `plant`) from the point plus
    `deviation` (a mapping of state labels, e.g. {"l_elbow:q": 0.05}, or an nx vector), with
    its reference stepped to `reference` (mapping of the controller's signals), for `duration`
    s, and predict the same with the linear closed loop."""
    _check(controller, plant)
    labels = list(plant.state_labels)
    dx0 = _vector(deviation, labels, "deviation")
    design = controller.design
    ref_labels = labels if isinstance(design, GainDesign) else list(design.inputs)
    r = _vector(reference, ref_labels, "reference")
    COMPARE_DURATION.check(duration, "duration")
    _start(lab, controller, dx0, duration)
    controller.reference = r.copy()
    trace = _run(lab, controller, duration)
    controller.reference = np.zeros_like(r)
    if len(trace) < 2:
        raise InputError("the controller ran fewer than two updates (is it running?)")
    t = np.array([row[0] for row in trace])
    t = t - t[0]
    measured = np.array([row[1] for row in trace])
    sys = closed_loop(controller, plant)
    x0 = np.concatenate([measured[0], np.zeros(sys.nstates - plant.nstates)])
    response = control.forced_response(sys, T=np.arange(len(t)) * float(plant.dt),
                                       U=np.tile(r[:, None], (1, len(t))), X0=x0)
    predicted = np.asarray(response.outputs).T.reshape(len(t), -1)
    diff = measured - predicted
    npos = plant.linearization.qvel.size
    scale = np.linalg.norm(measured[0, :npos]) or np.linalg.norm(r[:npos] if r.size >= npos else r)
    relative = float(np.sqrt(np.mean(np.sum(diff[:, :npos] ** 2, axis=1))) / scale) if scale else float("nan")
    return Comparison(t, measured, predicted, tuple(labels), np.sqrt(np.mean(diff**2, axis=0)),
                      relative, r)


def plot_comparison(result: Comparison, labels: Sequence[str] | None = None,
                    ax: Axes | None = None) -> Figure | SubFigure:
    """The "model vs plant" figure: the chosen states (default: the positions that move most)
    measured (solid) and predicted (dashed); returns the matplotlib Figure."""
    import matplotlib.pyplot as plt

    if labels is None:
        npos = len(result.labels) // 2
        moved = np.abs(result.measured[:, :npos]).max(axis=0)
        labels = [result.labels[i] for i in np.argsort(moved)[::-1][:4]]
    fig: Figure | SubFigure
    if ax is None:
        fig, ax = plt.subplots(figsize=(7, 4))
    else:
        fig = ax.figure
    for label in labels:
        measured, predicted = result.signal(label)
        (line,) = ax.plot(result.t, measured, label=f"{label} robot")
        ax.plot(result.t, predicted, "--", color=line.get_color(), label=f"{label} model")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("deviation from the point")
    ax.set_title(f"model vs robot: RMS difference {100 * result.relative:.2g} % of the deviation")
    ax.legend(fontsize="small")
    ax.grid(True)
    return fig


# ----- frequency response --------------------------------------------------------------------
@dataclass(frozen=True)
class FrequencyResponse:
    """The closed loop from one reference to one signal: `frequencies` (Hz), `measured` and
    `model` (complex gains), their magnitudes (dB) and phases (deg), the model's `bandwidth`
    (Hz, -3 dB), the loop's `gain_margin` (dB), `phase_margin` (deg) and their crossover
    frequencies (Hz; with several inputs the smallest over the breaks at each; None where the
    loop never crosses, `margins_note` says why), and the worst `magnitude_error` (dB) and
    `phase_error` (deg) at the frequencies up to the bandwidth."""

    frequencies: np.ndarray
    measured: np.ndarray
    model: np.ndarray
    bandwidth: float
    gain_margin: float | None
    phase_margin: float | None
    gain_crossover: float | None
    phase_crossover: float | None
    magnitude_error: float
    phase_error: float
    system: control.StateSpace  # the closed loop's SISO model (reference -> signal)
    margins_note: str = ""  # where the margins come from, or why one is None

    @property
    def measured_db(self) -> np.ndarray:
        """The measured gain at each frequency, in dB."""
        return 20 * np.log10(np.abs(self.measured))

    @property
    def measured_phase(self) -> np.ndarray:
        """The measured phase at each frequency, in degrees."""
        return np.degrees(np.angle(self.measured))

    @property
    def model_db(self) -> np.ndarray:
        """The linear closed loop's gain at each frequency, in dB."""
        return 20 * np.log10(np.abs(self.model))

    @property
    def model_phase(self) -> np.ndarray:
        """The linear closed loop's phase at each frequency, in degrees."""
        return np.degrees(np.angle(self.model))


def measure_frequency_response(lab: Lab, controller: _Deployed, plant: StateSpace, signal: str,
                               output: str | None = None,
                               frequencies: Sequence[float] = (1, 2, 3, 5, 8, 13),
                               amplitude: float = 0.01, settle: float = 0.5,
                               duration: float = 1.0) -> FrequencyResponse:
    """Add sines of `amplitude` each at `frequencies` (Hz; each a whole number of cycles over
    `duration` s) to the controller's reference `signal`, let the loop settle for `settle` s,
    and fit the phasor of `output` (a state of the plant; default `signal`) at each frequency
    over `duration` s; returns it with the linear closed loop's response and the loop's
    margins. The robot starts at the design's point."""
    _check(controller, plant)
    freqs = np.asarray(frequencies, dtype=float).reshape(-1)
    if freqs.size == 0 or not np.all(np.isfinite(freqs)) or np.any(freqs <= 0):
        raise InputError("frequencies must be positive numbers of Hz")
    nyquist = controller.rate / 2
    if freqs.max() >= nyquist:
        raise InputError(f"frequency {number_text(freqs.max())} Hz is not below the controller's "
                         f"Nyquist frequency {number_text(nyquist)} Hz")
    design = controller.design
    ref_labels = list(plant.state_labels) if isinstance(design, GainDesign) else list(design.inputs)
    if signal not in ref_labels:
        raise InputError(f"signal {signal!r} is not one of the controller's references",
                         hint=", ".join(ref_labels[:8]))
    output = output or signal
    labels = list(plant.state_labels)
    if output not in labels:
        raise InputError(f"output {output!r} is not a state of the plant", hint=", ".join(labels[:8]))
    i, o = ref_labels.index(signal), labels.index(output)
    _start(lab, controller, np.zeros(plant.nstates), settle + duration)
    omega = 2 * np.pi * freqs
    unit = np.zeros(len(ref_labels))
    unit[i] = amplitude

    def excite(t: float) -> np.ndarray:  # phases from t = 0: the fit's too
        return unit * float(np.sin(omega * t).sum())

    controller.excitation = excite
    try:
        trace = _run(lab, controller, settle + duration)
    finally:
        controller.excitation = None
    t = np.array([row[0] for row in trace])
    y = np.array([row[1][o] for row in trace])
    window = t >= t[0] + settle - 1e-9
    t, y = t[window], y[window]
    columns = [np.sin(np.outer(t, omega)), np.cos(np.outer(t, omega)), np.ones((t.size, 1))]
    coef, *_ = np.linalg.lstsq(np.hstack(columns), y, rcond=None)
    n = freqs.size
    measured = (coef[:n] + 1j * coef[n:2 * n]) / amplitude
    full = closed_loop(controller, plant)
    siso = full[o, i]
    model = np.asarray(siso(np.exp(1j * omega * float(plant.dt)))).reshape(-1)
    bandwidth = _bandwidth(siso)
    gm, pm, wcg, wcp, note = _worst_margins(controller, plant)
    inside = freqs <= bandwidth * (1 + 1e-9)
    mag_err = np.abs(20 * np.log10(np.abs(measured) / np.abs(model)))
    phase_err = np.abs(np.degrees(np.angle(measured / model)))
    return FrequencyResponse(freqs, measured, model, bandwidth, gm, pm, wcp, wcg,
                             float(mag_err[inside].max(initial=0.0)),
                             float(phase_err[inside].max(initial=0.0)), siso, note)


def _worst_margins(controller: _Deployed, plant: StateSpace
                   ) -> tuple[float | None, float | None, float | None, float | None, str]:
    """(gm, pm, phase-crossover Hz, gain-crossover Hz, note): the loop's margins, or with several
    inputs the smallest over the breaks at each (the others closed), the note naming where; a
    margin the loop does not have is None and the note says why."""
    inputs = len(controller.design.joints)
    found = []
    for i in range(inputs):
        found.append((i, *margins(loop_gain(controller, plant, i if inputs > 1 else None))))
    notes = []
    gains = [f for f in found if f[1] is not None]
    phases = [f for f in found if f[2] is not None]
    gm = wcg = pm = wcp = None
    name = [f"{j}:{controller.design.interface}" for j in controller.design.joints]
    if gains:
        best = min(gains, key=lambda f: float(f[1] or 0.0))
        gm, wcg = best[1], best[3]
        if inputs > 1:
            notes.append(f"gain margin: the smallest of the {inputs} single-input breaks "
                         f"({name[best[0]]})")
    else:
        notes.append("no gain margin: the loop's phase never reaches -180 deg (any gain increase "
                     "keeps it stable)")
    if phases:
        best = min(phases, key=lambda f: float(f[2] or 0.0))
        pm, wcp = best[2], best[4]
        if inputs > 1:
            notes.append(f"phase margin: the smallest of the breaks ({name[best[0]]}); all at "
                         "once: mexone.design.loop_margins(linearize_loop(lab))")
    else:
        notes.append("no phase margin: the loop's gain never crosses 1 (no delay destabilises "
                     "it)")
    return gm, pm, wcg, wcp, "; ".join(notes)


def margins(loop: control.StateSpace) -> tuple[float | None, float | None, float | None,
                                               float | None]:
    """(gain margin dB, phase margin deg, phase-crossover Hz, gain-crossover Hz) of a discrete
    SISO loop gain, read off a dense frequency grid up to the Nyquist frequency (python-control's
    `margin` falls back to an inaccurate method on the tens of lightly damped states of a robot
    model); None where the loop never crosses."""
    dt = float(loop.dt)
    f = np.geomspace(1e-2, 0.5 / dt, 3000)
    h = np.asarray(loop(np.exp(2j * np.pi * f * dt))).reshape(-1)
    gain, phase = np.abs(h), np.unwrap(np.angle(h))
    gm = pm = wcg = wcp = None
    down = np.flatnonzero((gain[:-1] >= 1) & (gain[1:] < 1))
    if down.size:
        k = down[0]
        wcp = float(f[k])
        pm = float(np.degrees(phase[k]) % 360 - 180)
    cross = np.flatnonzero(np.diff(np.floor((phase + np.pi) / (2 * np.pi))) != 0)
    if cross.size:
        k = cross[0]
        wcg = float(f[k])
        gm = float(-20 * np.log10(gain[k]))
    else:  # the phase may reach -180 deg at the Nyquist frequency itself, where L is real
        at_nyquist = complex(np.asarray(loop(-1.0)).reshape(-1)[0])
        if at_nyquist.real < 0 and abs(at_nyquist.imag) <= 1e-9 * max(1.0, abs(at_nyquist)):
            wcg, gm = 0.5 / dt, float(-20 * np.log10(abs(at_nyquist)))
    return gm, pm, wcg, wcp


def _bandwidth(siso: control.StateSpace) -> float:
    """Hz where the closed loop's gain first falls 3 dB below its low-frequency gain."""
    dt = float(siso.dt)
    f = np.geomspace(0.01, 0.5 / dt, 4000)
    gain = np.abs(np.asarray(siso(np.exp(2j * np.pi * f * dt))).reshape(-1))
    below = np.flatnonzero(gain < gain[0] / np.sqrt(2))
    return float(f[below[0]]) if below.size else float(f[-1])


def plot_frequency_response(result: FrequencyResponse, fig: Figure | None = None) -> Figure:
    """The model's Bode plot (lines) with the measured points (markers), the bandwidth and the
    loop's margins in the title; returns the matplotlib Figure."""
    import matplotlib.pyplot as plt

    if fig is None:
        fig, (mag, phase) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
    else:
        mag, phase = fig.subplots(2, 1, sharex=True)
    dt = float(result.system.dt)
    f = np.geomspace(min(result.frequencies.min() / 3, 0.1), 0.5 / dt, 600)
    h = np.asarray(result.system(np.exp(2j * np.pi * f * dt))).reshape(-1)
    mag.semilogx(f, 20 * np.log10(np.abs(h)), label="model")
    mag.semilogx(result.frequencies, result.measured_db, "o", label="robot (measured)")
    phase.semilogx(f, np.degrees(np.unwrap(np.angle(h))), label="model")
    phase.semilogx(result.frequencies, result.measured_phase, "o", label="robot (measured)")
    for ax in (mag, phase):
        ax.axvline(result.bandwidth, color="grey", linestyle=":")
        ax.grid(True, which="both")
    mag.set_ylabel("magnitude (dB)")
    phase.set_ylabel("phase (deg)")
    phase.set_xlabel("frequency (Hz)")
    mag.legend(fontsize="small")
    margins = []
    if result.gain_margin is not None:
        margins.append(f"GM {result.gain_margin:.1f} dB")
    if result.phase_margin is not None:
        margins.append(f"PM {result.phase_margin:.0f} deg")
    mag.set_title(f"closed loop: bandwidth {result.bandwidth:.2g} Hz" +
                  (", " + ", ".join(margins) if margins else ""))
    return fig
