"""The page's Plots panel, rqt_plot's job: any signal of the robot, several at once, over a window
of sim time that the user sets, frozen while the simulation is paused, exported as CSV or PNG.

`SignalLog` samples every plottable signal (what joint_states, the controllers' commands and
the sensor topics carry) in sim time: every PLOT_PERIOD while running and after every single
step of Step N, so pausing keeps the history and Step N adds N samples. It lives in the
simulation thread; the panel only reads its arrays.

uPlot's labels cannot be formatted from Python (no JS callbacks through viser) and it prints
three decimals at most, so a pane whose values span less than 0.05 is drawn in milli- (or
micro-) units and says so in its axis label: 0.0041 and 0.0042 never both read "0.004".
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import viser
import viser.uplot as uplot

from mexone.lab import Lab
from mexone.sensors import ForceTorqueSensor, ImuSensor

__all__ = ["SignalLog", "PlotPanel", "PLOT_PERIOD", "MAX_WINDOW", "axis_scale", "PANES"]

PLOT_PERIOD = 0.01  # s of sim time between samples while running (100 Hz)
MAX_WINDOW = 60.0  # s of sim time a pane may show
CAPACITY = 20_000  # samples kept (Step N samples every physics step)
PANES = 3
_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf", "#e377c2")
_PREFIX = {1.0: "", 1e3: "×10⁻³ ", 1e6: "×10⁻⁶ ", 1e9: "×10⁻⁹ "}


def axis_scale(values: np.ndarray) -> float:
    """1, 1e3, 1e6 or 1e9: what to multiply `values` by so uPlot's three decimals tell the
    ticks apart (their span, or a tenth of their size when flat, at least 0.05)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return 1.0
    span = float(finite.max() - finite.min())
    span = span if span > 0 else 0.1 * float(np.abs(finite).max())
    factor = 1.0
    while 0 < span * factor < 0.05 and factor < 1e9:
        factor *= 1e3
    return factor


@dataclass(frozen=True)
class Signal:
    name: str  # "l_elbow/position": the joint_states field, the controller, the sensor
    unit: str


class SignalLog:
    """Every signal, sampled in sim time into a ring of CAPACITY rows (simulation thread)."""

    def __init__(self, lab: Lab):
        self.lab = lab
        signals, readers = [], []
        manager = lab.controllers
        sim = lab.sim
        if manager is not None:
            hw = manager.hw
            joints = list(hw.joints)
            positional = [i for i, j in enumerate(joints)
                          if (c := manager.by_joint().get(j)) is not None and c.kind == "position"]
            signals += [Signal(f"{j}/{f}", u) for f, u in (("position", "rad"), ("velocity", "rad/s"),
                                                           ("effort", "N m"), ("command", ""))
                        for j in joints]
            signals += [Signal(f"{joints[i]}/error", "rad") for i in positional]
            rows = np.array(positional, dtype=int)

            def joint_values() -> np.ndarray:
                q, cmd = hw.position(), manager.setpoints()
                return np.concatenate((q, hw.velocity(), hw.effort(), cmd, cmd[rows] - q[rows]))
        else:
            joints = sim.joint_names
            signals += [Signal(f"{j}/{f}", u) for f, u in (("position", "rad"), ("velocity", "rad/s"),
                                                           ("effort", "N m")) for j in joints]

            def joint_values() -> np.ndarray:
                return np.concatenate((sim.joint_positions(), sim.joint_velocities(),
                                       sim.joint_efforts()))
        readers.append(joint_values)
        signals += [Signal("base/x", "m"), Signal("base/y", "m"), Signal("base/height", "m"),
                    Signal("base/tilt", "rad")]
        root = sim.compiled.root_body
        readers.append(lambda: np.r_[sim.data.xpos[root], sim.base_tilt])
        for name, sensor in lab.sensors.sensors.items():
            if isinstance(sensor, ImuSensor):
                signals += [Signal(f"{name}/angular_velocity/{a}", "rad/s") for a in "xyz"]
                signals += [Signal(f"{name}/linear_acceleration/{a}", "m/s²") for a in "xyz"]
                readers.append(lambda s=sensor: np.concatenate(s.read()[1:]))
            elif isinstance(sensor, ForceTorqueSensor):
                signals += [Signal(f"{name}/force/{a}", "N") for a in "xyz"]
                readers.append(lambda s=sensor: s.read()[0])
        self.signals: list[Signal] = signals
        self.index = {s.name: i for i, s in enumerate(signals)}
        self._readers: list[Callable[[], np.ndarray]] = readers
        self.t = np.zeros(CAPACITY)
        self.values = np.zeros((CAPACITY, len(signals)), dtype=np.float32)
        self.count = 0  # samples ever taken since the last clear (the ring's write position)
        self.next_sample = 0.0

    def clear(self) -> None:
        self.count, self.next_sample = 0, 0.0

    def due(self, sim_time: float) -> bool:
        return sim_time >= self.next_sample - 1e-9

    def sample(self) -> None:
        """One row now (the simulation thread); a jump back in time (a reset) starts afresh."""
        now = self.lab.sim.time
        if self.count:
            last = self.t[(self.count - 1) % CAPACITY]
            if now < last:
                self.clear()
            elif now == last:
                return
        row = self.count % CAPACITY
        self.t[row] = now
        self.values[row] = np.concatenate([read() for read in self._readers])
        self.count += 1
        self.next_sample = now + PLOT_PERIOD

    def window(self, seconds: float, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(t, values[len(names), n]) of the last `seconds` of sim time, oldest first."""
        n = min(self.count, CAPACITY)
        if n == 0:
            return np.zeros(0), np.zeros((len(names), 0))
        order = (np.arange(self.count - n, self.count)) % CAPACITY
        t = self.t[order]
        keep = t >= t[-1] - seconds - 1e-9
        cols = [self.index[name] for name in names]
        return t[keep], self.values[order[keep]][:, cols].T.astype(float)


class PlotPanel:
    """Panes of chosen signals over a window of sim time (uPlot, zoomable; double-click resets)."""

    def __init__(self, server: viser.ViserServer, log: SignalLog, do: Callable, refuse: Callable,
                 number: Callable, defaults: list[list[str]]):
        self.server, self.log, self.do, self.refuse = server, log, do, refuse
        self.seconds = 10.0
        self.chosen: list[list[str]] = [list(d) for d in defaults] + [[] for _ in range(PANES)]
        self.chosen = self.chosen[:PANES]
        self.hold = False
        self._shown: list[tuple] = [()] * PANES  # what each pane last drew (skip idle pushes)
        gui = server.gui
        names = tuple(s.name for s in log.signals)
        with gui.add_folder("Plots") as self.folder:
            self.signal = gui.add_dropdown("Signal", names, initial_value=names[0],
                                           hint="what joint_states, the controllers and the "
                                                "sensors carry")
            self.pane = gui.add_dropdown("Pane", tuple(f"pane {i + 1}" for i in range(PANES)),
                                         initial_value="pane 1")
            add = gui.add_button_group("", ("Add", "Remove", "Clear pane"))
            add.on_click(lambda e: self.do(lambda v=e.target.value: self._edit(v)))
            self.window_field = number("Window (s)", self.seconds, 0.1, MAX_WINDOW,
                                       self._set_window, hint="sim seconds shown")
            self.hold_box = gui.add_checkbox("Hold", False, hint="freeze the panes while the "
                                                                 "simulation runs (pausing does too)")
            self.hold_box.on_update(lambda e: setattr(self, "hold", bool(e.target.value)))
            exports = gui.add_button_group("Export", ("CSV", "PNG"))
            exports.on_click(lambda e: self.export(e.client, e.target.value))
            self.plots = [self._add_pane(i) for i in range(PANES)]

    def _add_pane(self, i: int) -> viser.GuiUplotHandle:
        names = self.chosen[i] or ["(nothing)"]
        return self.server.gui.add_uplot((np.zeros(1),) * (1 + len(names)), self._series(i, 1.0),
                                         title=f"pane {i + 1}", aspect=1.6,
                                         scales={"x": uplot.Scale(time=False), "y": uplot.Scale()},
                                         visible=bool(self.chosen[i]))

    def _series(self, i: int, factor: float) -> tuple:
        names = self.chosen[i] or ["(nothing)"]
        return (uplot.Series(label="sim time (s)"),
                *(uplot.Series(label=self._label(n, factor), stroke=_COLOURS[k % len(_COLOURS)],
                               width=2, scale="y") for k, n in enumerate(names)))

    def _label(self, name: str, factor: float) -> str:
        sig = self.log.signals[self.log.index[name]] if name in self.log.index else None
        unit = f" ({_PREFIX[factor]}{sig.unit})" if sig and sig.unit else \
            (f" ({_PREFIX[factor].strip()})" if factor != 1.0 else "")
        return name + unit

    def _axes(self, i: int, factor: float) -> tuple:
        units = sorted({self.log.signals[self.log.index[n]].unit for n in self.chosen[i]} - {""})
        label = _PREFIX[factor] + (", ".join(units) or "value")
        return (uplot.Axis(label="sim time (s)", size=40),
                uplot.Axis(label=label, size=70, scale="y"))

    # ----- edits (simulation thread) ----------------------------------------------------------
    def _edit(self, action: str) -> None:
        i = int(self.pane.value.split()[-1]) - 1
        name = self.signal.value
        if name not in self.log.index:  # a page may send anything
            raise ValueError(f"'{name}' is not a signal this robot has")
        if action == "Add" and name not in self.chosen[i]:
            self.chosen[i].append(name)
        elif action == "Remove" and name in self.chosen[i]:
            self.chosen[i].remove(name)
        elif action == "Clear pane":
            self.chosen[i].clear()
        self._shown[i] = ()
        self.update(force=True)

    def _set_window(self, seconds: float) -> None:
        self.seconds = seconds
        self._shown = [()] * PANES
        self.update(force=True)

    # ----- drawing (simulation thread, a few times a second) -------------------------------------
    def update(self, force: bool = False) -> None:
        if self.hold and not force:
            return
        for i, plot in enumerate(self.plots):
            names = self.chosen[i]
            plot.visible = bool(names)
            if not names:
                continue
            key = (self.log.count, self.seconds, tuple(names))
            if key == self._shown[i]:
                continue  # nothing new (paused): leave the page's zoom alone
            t, values = self.log.window(self.seconds, names)
            if t.size < 2:
                continue
            factor = axis_scale(values)
            self._shown[i] = key
            series = self._series(i, factor)
            axes = self._axes(i, factor)
            data = (t, *(v * factor for v in values))
            if plot.series != series or plot.axes != axes:
                # a new chart, not new options on the old one: the page's uPlot kept its old
                # y range (and stopped following the data) when series or axes changed under it
                order = plot.order
                plot.remove()
                with self.folder:
                    plot = self.plots[i] = self.server.gui.add_uplot(
                        data, series, axes=axes, title=f"pane {i + 1}", aspect=1.6, order=order,
                        scales={"x": uplot.Scale(time=False), "y": uplot.Scale()})
            else:
                plot.data = data

    # ----- export (any thread: reads a snapshot) ------------------------------------------------------
    def export(self, client, kind: str) -> None:
        if client is None:
            return
        names = [n for pane in self.chosen for n in pane]
        names = list(dict.fromkeys(names))
        if not names:
            self.refuse("Export: no signal is plotted")
            return
        t, values = self.log.window(self.seconds, names)
        if kind == "CSV":
            client.send_file_download("mexone_plot.csv", to_csv(t, values, names).encode())
        elif kind == "PNG":
            client.send_file_download("mexone_plot.png", self.png())

    def png(self) -> bytes:
        """The visible panes drawn by matplotlib on the server (works for headless browsers)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        panes = [p for p in self.chosen if p]
        fig, axes = plt.subplots(len(panes), 1, figsize=(7, 2.6 * len(panes)), squeeze=False)
        for ax, names in zip(axes[:, 0], panes, strict=True):
            t, values = self.log.window(self.seconds, names)
            for name, v in zip(names, values, strict=True):
                ax.plot(t, v, label=self._label(name, 1.0))
            ax.set_xlabel("sim time (s)")
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
        fig.tight_layout()
        out = io.BytesIO()
        fig.savefig(out, format="png", dpi=100)
        plt.close(fig)
        return out.getvalue()


def to_csv(t: np.ndarray, values: np.ndarray, names: list[str]) -> str:
    out = io.StringIO()
    writer = csv.writer(out)
    writer.writerow(["time", *names])
    for k in range(t.size):
        writer.writerow([f"{t[k]:.6f}", *(f"{v:.9g}" if math.isfinite(v) else "" for v in values[:, k])])
    return out.getvalue()
