"""One report of a controller's robustness at a point (issue 38 item 5): `mexone certify`.

`certify(lab)` linearises the running Python controllers' closed loop (`linearize_loop`),
computes the margins per actuator and all at once (`margins`), checks the all-channel delay and
gain margins on the simulated robot (`simulate_onset`), adds the effort limits' view
(`saturation`) and the command noise the sensors' noise makes, and, for a state feedback, the
region of attraction on two axes (`region_of_attraction`). `Certificate.as_dict` is the JSON,
`write_html` the report with its figures.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from mexone.design.loop import LoopModel, linearize_loop
from mexone.design.margins import LoopMargins, Margins, loop_margins, plot_margins
from mexone.design.mismatch import Mismatch, describe, design_plant, mismatch, plot_mismatch
from mexone.design.onset import Onset, simulate_onset
from mexone.design.region import Region, plot_region, region_of_attraction
from mexone.design.saturation import Saturation, saturation
from mexone.design.twin import python_runners
from mexone.errors import InputError
from mexone.files import write_text
from mexone.ranges import number_text

if TYPE_CHECKING:
    import control
    from matplotlib.figure import Figure

    from mexone.design.deploy import StateFeedback
    from mexone.lab import Lab

__all__ = ["Certificate", "certify", "ENCODER_NOISE"]

ENCODER_NOISE = (1e-4, 1e-3)  # rad, rad/s: the noise the command-noise line assumes on q, dq
_STYLE = ("body{font-family:sans-serif;max-width:60em;margin:auto}"
          "td,th{padding:0 .6em;text-align:right}td:first-child{text-align:left}"
          "pre{background:#f4f4f4;padding:.5em}")


@dataclass(frozen=True)
class Certificate:
    """What certify found: the loop, its margins, the simulated onsets, the saturation view,
    the command noise per input from encoder noise, the region (or None), wall times (s)."""

    loop: LoopModel
    margins: Margins
    onsets: tuple[Onset, ...]
    saturation: Saturation | None
    command_noise: np.ndarray
    region: Region | None
    seconds: dict[str, float]
    notes: tuple[str, ...] = field(default=())
    mismatch: Mismatch | None = None

    @property
    def passed(self) -> bool:
        """Every simulated check agrees with its prediction."""
        return all(o.agrees for o in self.onsets)

    def as_dict(self) -> dict[str, Any]:
        """The certificate as plain JSON values (`mexone certify --json`)."""
        loop = self.loop
        return {"controllers": list(loop.controllers), "joints": list(loop.joints),
                "interface": loop.interface, "period": loop.period,
                "controller_states": list(loop.controller.state_labels),
                "margins": self.margins.as_dict(),
                "onsets": [o.as_dict() for o in self.onsets], "passed": self.passed,
                "saturation": None if self.saturation is None else self.saturation.as_dict(),
                "command_noise": dict(zip(loop.inputs, self.command_noise.tolist(), strict=True)),
                "encoder_noise": list(ENCODER_NOISE),
                "region": None if self.region is None else self.region.as_dict(),
                "mismatch": None if self.mismatch is None else self.mismatch.as_dict(),
                "seconds": self.seconds, "notes": list(self.notes)}

    def json(self) -> str:
        """The certificate as indented JSON text."""
        return json.dumps(self.as_dict(), indent=2)

    def lines(self) -> list[str]:
        """The summary a terminal shows."""
        m, loop = self.margins, self.loop
        out = [f"certify {', '.join(loop.controllers)} on {', '.join(loop.joints) or 'no joint'} "
               f"at {number_text(1 / loop.period)} Hz ({loop.controller.nstates} controller "
               f"states, {loop.plant.nstates} plant states)"]
        out.append(f"  {'break':<28}{'gain +':>9}{'gain -':>9}{'phase':>8}{'delay':>10}{'disk':>7}"
                   f"{'|S|':>7}")
        for item in (*m.loops, m.all):
            out.append("  " + _row(item))
        for onset in self.onsets:
            unit = "s" if onset.kind == "delay" else "x"
            out.append(f"  simulated {onset.kind}: onset {_g(onset.onset)} {unit}, "
                       f"predicted {_g(onset.predicted)} {unit}: "
                       f"{'agrees' if onset.agrees else 'DISAGREES'}"
                       + (f" ({onset.note})" if onset.note else ""))
        if self.saturation is not None:
            s = self.saturation
            k = int(np.argmin(s.onset))
            out.append(f"  saturation: a deviation of {_g(s.onset[k])} in "
                       f"{s.directions[k]} first saturates {s.first[k]}")
        noisy = int(np.argmax(self.command_noise))
        out.append(f"  command noise from encoder noise ({ENCODER_NOISE[0]:g} rad, "
                   f"{ENCODER_NOISE[1]:g} rad/s): up to {_g(self.command_noise[noisy])} "
                   f"on {loop.inputs[noisy]}")
        if self.region is not None:
            r = self.region
            out.append(f"  region of attraction over {r.axes[0]}, {r.axes[1]}: "
                       f"{100 * r.fraction:.0f} % of {r.back.size} starts came back")
        if self.mismatch is not None:
            out += ["  " + line for line in describe(self.mismatch)]
        out += [f"  note: {n}" for n in (*m.notes, *self.notes)]
        return out

    def write_html(self, path: Path, force: bool = False) -> None:
        """The report: the summary, the tables and the figures (embedded PNGs)."""
        import matplotlib

        matplotlib.use("Agg")
        figures = [_png(plot_margins(self.margins))]
        if self.region is not None:
            figures.append(_png(cast("Figure", plot_region(self.region))))  # no ax: its own
        if self.mismatch is not None:
            figures.append(_png(plot_mismatch(self.mismatch)))
        rows = "".join(f"<tr><td>{html.escape(i.name)}</td>{_cells(i)}</tr>"
                       for i in (*self.margins.loops, self.margins.all))
        onsets = "".join(f"<tr><td>{o.kind}</td><td>{_g(o.predicted)}</td>"
                         f"<td>{_g(o.onset)}</td><td>{_g(o.tolerance)}</td>"
                         f"<td>{'agrees' if o.agrees else 'DISAGREES'}</td></tr>"
                         for o in self.onsets)
        notes = "".join(f"<li>{html.escape(n)}</li>" for n in (*self.margins.notes, *self.notes))
        images = "".join(f'<img src="data:image/png;base64,{p}">' for p in figures)
        summary = html.escape("\n".join(self.lines()))
        title = html.escape(", ".join(self.loop.controllers))
        text = f"""<!doctype html>
<html><head><meta charset="utf-8"><title>mexone certify: {title}</title>
<style>{_STYLE}</style></head><body>
<h1>Robustness of {title}</h1>
<pre>{summary}</pre>
<h2>Margins (loop broken at the plant's input)</h2>
<table><tr><th>break</th><th>gain increase</th><th>gain reduction</th><th>phase (deg)</th>
<th>crossover (Hz)</th><th>delay (ms)</th><th>disk alpha</th><th>disk gain</th><th>|S| peak</th>
<th>|T| peak</th></tr>{rows}</table>
<p>Multi-loop disk margin: {html.escape(self.margins.method)}.</p>
<h2>Checked on the simulated robot</h2>
<table><tr><th>margin</th><th>predicted</th><th>onset</th><th>tolerance</th><th></th></tr>{onsets}</table>
<h2>Notes</h2><ul>{notes}</ul>
{images}
</body></html>
"""
        write_text(Path(path), text, force)


def _g(value: float) -> str:
    return f"{value:.3g}" if math.isfinite(value) else ("inf" if value > 0 else "-inf")


def _row(item: LoopMargins) -> str:
    return (f"{item.name:<28}{_g(item.gain_increase):>9}{_g(item.gain_reduction):>9}"
            f"{_g(item.phase_margin):>8}{_g(1e3 * item.delay_margin) + ' ms':>10}"
            f"{_g(item.disk_margin):>7}{_g(item.peak_s):>7}")


def _cells(item: LoopMargins) -> str:
    values = (item.gain_increase, item.gain_reduction, item.phase_margin, item.crossover,
              1e3 * item.delay_margin, item.disk_margin)
    cells = "".join(f"<td>{_g(v)}</td>" for v in values)
    low, high = item.disk_gain
    return (cells + f"<td>{_g(low)}-{_g(high)}</td>"
            f"<td>{_g(item.peak_s)}</td><td>{_g(item.peak_t)}</td>")


def _png(fig: Figure) -> str:
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80)
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def command_noise(loop: LoopModel, noise: Sequence[float] = ENCODER_NOISE) -> np.ndarray:
    """RMS command per input that white encoder noise (std on every q, on every dq) makes in
    one update: sqrt(diag(D Sigma D')) of the controller's direct term (its filters only lower
    the part that follows)."""
    labels = list(loop.controller.input_labels)
    std = np.array([noise[0] if label.endswith(":q") else noise[1] if label.endswith(":dq")
                    else 0.0 for label in labels])
    d = np.asarray(loop.controller.D)
    return np.sqrt(np.einsum("ij,j,ij->i", d, std**2, d))


def certify(lab: Lab, controllers: Sequence[str] | None = None, verify: bool = True,
            region: Mapping[str, tuple[float, float]] | None = None,
            shape: tuple[int, int] = (16, 16), lyapunov: np.ndarray | None = None, backend: str = "threads",
            deviation: Mapping[str, float] | None = None) -> Certificate:
    """The report of the lab's running Python controllers (or those named) at the lab's
    current state. verify: check the predictions on the simulated robot; region: two state
    labels with ranges for the region of attraction; deviation: state labels and values for
    `mismatch`, compare's experiment decomposed (both for a StateFeedback alone)."""
    seconds: dict[str, float] = {}
    start = time.perf_counter()
    loop = linearize_loop(lab, controllers)
    seconds["linearize"] = time.perf_counter() - start
    mark = time.perf_counter()
    result = loop_margins(loop)
    seconds["margins"] = time.perf_counter() - mark
    onsets: list[Onset] = []
    if verify:
        mark = time.perf_counter()
        onsets = simulate_onset(lab, loop, result.all)
        seconds["simulated checks"] = time.perf_counter() - mark
    notes = []
    sat = None
    if loop.interface == "effort":
        sat = saturation(loop, result)
        notes += list(sat.notes)
    else:
        notes.append(f"the loop drives {loop.interface} setpoints: no effort limit in the model")
    found = decomposed = None
    if region is not None or deviation is not None:
        impl = _state_feedback(lab, controllers, "the region of attraction and the mismatch")
        if deviation is not None:
            mark = time.perf_counter()
            decomposed = mismatch(lab, impl, design_plant(lab, impl), deviation)
            seconds["mismatch"] = time.perf_counter() - mark
        if region is not None:
            mark = time.perf_counter()
            found = region_of_attraction(lab, impl, _plant_of(impl, loop), region, shape,
                                         lyapunov=lyapunov, backend=backend)
            seconds["region"] = time.perf_counter() - mark
    seconds["total"] = time.perf_counter() - start
    return Certificate(loop, result, tuple(onsets), sat, command_noise(loop), found, seconds,
                       tuple(notes), decomposed)


def _state_feedback(lab: Lab, controllers: Sequence[str] | None, what: str) -> StateFeedback:
    """The one StateFeedback certified (one line otherwise)."""
    from mexone.design.deploy import StateFeedback

    runners = python_runners(lab, controllers)
    if len(runners) != 1 or not isinstance(runners[0].impl, StateFeedback):
        names = ", ".join(r.name for r in runners)
        raise InputError(f"{what} run one StateFeedback; certified here: {names}",
                         hint="name it with --controller NAME, or leave --region/--mismatch out")
    return runners[0].impl


def _plant_of(controller: StateFeedback, loop: LoopModel) -> control.StateSpace:
    """The plant the StateFeedback was designed on, if the loop's model is it (the same states:
    a design on the whole robot); else one line."""
    states = tuple(controller.design.point.states)
    if tuple(loop.robot.state_labels) != states:
        raise InputError(f"controller '{controller.name}' was designed on a model of "
                         f"{len(states)} states, not the whole robot's {loop.robot.nstates}: "
                         "the region needs its own plant",
                         hint="from Python: region_of_attraction(lab, controller, plant)")
    return loop.robot


def _finite(value: float) -> float | str:
    return value if math.isfinite(value) else "inf"
