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

import bisect
import csv
import dataclasses
import io
import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import viser
import viser.uplot as uplot

from mexone.gui.panels import Panel, register_panel
from mexone.lab import Lab
from mexone.ranges import PLOT_WINDOW

__all__ = ["SignalLog", "PlotPanel", "Pane", "PLOT_PERIOD", "MAX_WINDOW",
           "axis_scale", "PANES", "numeric_fields", "field_value", "first_joint"]

PLOT_PERIOD = 0.01  # s of sim time between samples while running (100 Hz)
MAX_WINDOW = PLOT_WINDOW.high  # s of sim time a pane may show
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


MAX_ITEMS = 32  # array elements offered per field (a Float64MultiArray, joint_states' position)
_INDEX = re.compile(r"^(\w+)\[(\d+)\]$")


def numeric_fields(msg, prefix: str = "") -> list[str]:
    """rqt_plot's field paths of a message's numbers: "linear_acceleration/z", "position[3]"."""
    out: list[str] = []
    if not dataclasses.is_dataclass(msg):
        return out
    for f in dataclasses.fields(msg):
        value, path = getattr(msg, f.name), prefix + f.name
        if isinstance(value, bool | str | bytes | bytearray | memoryview):
            continue
        if isinstance(value, int | float | np.number):
            out.append(path)
        elif dataclasses.is_dataclass(value):
            out += numeric_fields(value, path + "/")
        elif isinstance(value, list | tuple | np.ndarray):
            for i, item in enumerate(list(value)[:MAX_ITEMS]):
                if isinstance(item, bool | str | bytes):
                    break
                if isinstance(item, int | float | np.number):
                    out.append(f"{path}[{i}]")
                elif dataclasses.is_dataclass(item):
                    out += numeric_fields(item, f"{path}[{i}]/")
    return out


def field_value(msg, path: str) -> float:
    """The number at `path` in `msg` (NaN where the message has none: a shorter array)."""
    value = msg
    for part in path.split("/"):
        match = _INDEX.match(part)
        try:
            value = getattr(value, match.group(1))[int(match.group(2))] if match \
                else getattr(value, part)
        except (AttributeError, IndexError, TypeError):
            return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


@dataclass(frozen=True)
class Signal:
    name: str  # "l_elbow/position": the joint_states field, the controller, the sensor
    unit: str


class SignalLog:
    """Every signal, sampled in sim time into a ring of CAPACITY rows (simulation thread)."""

    def __init__(self, lab: Lab):
        self.lab = lab
        signals, readers = [], []
        manager = lab.manager
        sim = lab.sim
        if manager is not None:
            hw = manager.hw
            joints = list(hw.joints)
            positional = [i for i, j in enumerate(joints)
                          if (c := manager.by_joint().get(j)) is not None and c.holds_position]
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

        readers.append(lambda: np.append(sim.data.xpos[root], sim.base_tilt))
        for sensor in lab.sensors.sensors.values():  # each sensor type's plot signals
            if sensor.state_type is not None and sensor.plot:
                signals += [Signal(n, u) for n, u in sensor.signals()]
                readers.append(sensor.values)
        self.signals: list[Signal] = signals
        self.index = {s.name: i for i, s in enumerate(signals)}
        self._readers: list[Callable[[], np.ndarray]] = readers
        self.t = np.zeros(CAPACITY)
        self.values = np.zeros((CAPACITY, len(signals)), dtype=np.float32)
        self.count = 0  # samples ever taken since the last clear (the ring's write position)
        self.next_sample = 0.0
        self.watched: dict = {}  # topic -> the plots' subscription (lazy publishers start)
        self.plotted: set[str] = set()  # topics with a field in the log: watched for good
        # a sim-time timer, so the samples fall every PLOT_PERIOD exactly while MuJoCo steps
        # the rest in C: the page's loop then paces once a frame, not once a sample
        self._timer = sim.add_periodic(PLOT_PERIOD, self._on_timer)

    def _on_timer(self, _sim) -> None:
        self.sample()

    # ----- any topic's numbers (rqt_plot's /topic/field paths) -----------------------------------
    def watch(self, topic: str) -> None:
        """Subscribe to `topic`, so it publishes and its latest message is kept (simulation
        thread); a topic browsed before and never plotted is let go."""
        bus = self.lab.bus
        if topic not in bus.topics:
            raise ValueError(f"Plot: '{topic}' is not a topic on the bus")
        for other in [t for t in self.watched if t != topic and t not in self.plotted]:
            self.watched.pop(other).unregister()  # only browsed: a camera stops rendering
        if topic not in self.watched:
            self.watched[topic] = bus.subscribe(topic, bus.topics[topic].type, lambda _m: None,
                                                node="mexone GUI (plots)")

    def add_topic_field(self, topic: str, path: str) -> str:
        """A new signal "<topic>/<path>": the field of the topic's latest message, sampled with
        the rest (held between messages); earlier rows read NaN. Returns its name."""
        self.watch(topic)
        bus_topic = self.lab.bus.topics[topic]
        if bus_topic.last is None or path not in numeric_fields(bus_topic.last):
            raise ValueError(f"Plot: '{path}' is not a numeric field of {topic}'s messages")
        name = f"{topic}/{path}"
        self.plotted.add(topic)
        if name in self.index:
            return name
        self.signals.append(Signal(name, ""))
        self.index[name] = len(self.signals) - 1
        self._readers.append(lambda: np.array([field_value(bus_topic.last, path)]))
        self.values = np.concatenate((self.values, np.full((CAPACITY, 1), np.nan, np.float32)),
                                     axis=1)
        return name

    def close(self) -> None:
        """Stop sampling and let go of the topics watched (the robot is unloaded)."""
        self.lab.sim.remove_periodic(self._timer)
        for sub in self.watched.values():
            sub.unregister()
        self.watched.clear()

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
        t, oldest = self.t, self.count - n
        # the ring's times only grow (sample() starts afresh on a jump back): a binary search
        # finds the window's first row, and only its rows of the named columns are copied
        first = bisect.bisect_left(range(n), t[(self.count - 1) % CAPACITY] - seconds - 1e-9,
                                   key=lambda i: t[(oldest + i) % CAPACITY])
        rows = np.arange(oldest + first, self.count) % CAPACITY
        cols = [self.index[name] for name in names]
        return t[rows], self.values[rows[:, None], cols].T.astype(float)


class Pane:
    """One uPlot chart of some of the log's signals over the last `seconds` of sim time (the
    one plot implementation: the Plots panel's panes and the Sensors panel's charts)."""

    def __init__(self, server: viser.ViserServer, log: SignalLog, folder, title: str,
                 names: list[str], aspect: float = 1.6):
        self.server, self.log, self.folder, self.title, self.aspect = server, log, folder, title, aspect
        self.names = list(names)
        self._shown: tuple = ()  # what the pane last drew (skip idle pushes)
        self._look: tuple = ((),)  # (scale, names, signals), and the series and axes for them
        shown = self.names or ["(nothing)"]
        self.plot = server.gui.add_uplot((np.zeros(1),) * (1 + len(shown)), self._series(1.0),
                                         title=title, aspect=aspect,
                                         scales={"x": uplot.Scale(time=False), "y": uplot.Scale()},
                                         visible=bool(self.names))

    def _series(self, factor: float) -> tuple:
        names = self.names or ["(nothing)"]
        return (uplot.Series(label="sim time (s)"),
                *(uplot.Series(label=self.label(n, factor), stroke=_COLOURS[k % len(_COLOURS)],
                               width=2, scale="y") for k, n in enumerate(names)))

    def label(self, name: str, factor: float) -> str:
        sig = self.log.signals[self.log.index[name]] if name in self.log.index else None
        unit = f" ({_PREFIX[factor]}{sig.unit})" if sig and sig.unit else \
            (f" ({_PREFIX[factor].strip()})" if factor != 1.0 else "")
        return name + unit

    def _axes(self, factor: float) -> tuple:
        units = sorted({self.log.signals[self.log.index[n]].unit for n in self.names} - {""})
        label = _PREFIX[factor] + (", ".join(units) or "value")
        return (uplot.Axis(label="sim time (s)", size=40),
                uplot.Axis(label=label, size=70, scale="y"))

    def changed(self) -> None:
        self._shown = ()

    def update(self, seconds: float) -> None:
        """Draw the last `seconds` if anything new arrived (simulation thread)."""
        plot = self.plot
        plot.visible = bool(self.names)
        if not self.names:
            return
        key = (self.log.count, seconds, tuple(self.names), len(self.log.signals))
        if key == self._shown:
            return  # nothing new (paused): leave the page's zoom alone
        t, values = self.log.window(seconds, self.names)
        if t.size < 2:
            return
        factor = axis_scale(values)
        self._shown = key
        look = (factor, tuple(self.names), len(self.log.signals))
        if self._look[0] != look:  # labels and axes only change with the scale or the names
            self._look = (look, self._series(factor), self._axes(factor))
        _, series, axes = self._look
        data = (t, *(v * factor for v in values))
        if plot.series != series or plot.axes != axes:
            # a new chart, not new options on the old one: the page's uPlot kept its old
            # y range (and stopped following the data) when series or axes changed under it
            order = plot.order
            plot.remove()
            with self.folder:
                self.plot = self.server.gui.add_uplot(
                    data, series, axes=axes, title=self.title, aspect=self.aspect, order=order,
                    scales={"x": uplot.Scale(time=False), "y": uplot.Scale()})
        else:
            plot.data = data


@register_panel
class PlotPanel(Panel):
    """Panes of chosen signals over a window of sim time (uPlot, zoomable; double-click resets):
    the robot's own signals, and any numeric field of any topic on the bus. At first pane 1
    shows the first held joint's command and position, pane 2 its effort (`first_joint`)."""

    name = "plots"
    order = 4

    def build(self) -> None:
        self.log = log = self.host.log
        joint = first_joint(self.lab)
        defaults = [[f"{joint}/command", f"{joint}/position"], [f"{joint}/effort"]]
        chosen = [[n for n in pane if n in log.index] for pane in defaults]
        chosen = (chosen + [[] for _ in range(PANES)])[:PANES]
        self.seconds = 10.0
        self.hold = False
        server, gui, number = self.server, self.server.gui, self.host.fields.add
        names = tuple(s.name for s in log.signals)
        with gui.add_folder("Plots") as self.folder:
            self.signal = gui.add_dropdown("Signal", names, initial_value=names[0],
                                           hint="what joint_states, the controllers and the "
                                                "sensors carry")
            self.pane = gui.add_dropdown("Pane", tuple(f"pane {i + 1}" for i in range(PANES)),
                                         initial_value="pane 1")
            add = gui.add_button_group("", ("Add", "Remove", "Clear pane"))
            add.on_click(lambda e: self.do(lambda v=e.target.value: self._edit(v)))
            with gui.add_folder("Any topic", expand_by_default=False):
                topics = tuple(sorted(log.lab.bus.topics)) or ("(none)",)
                self.topic = gui.add_dropdown("Topic", topics, initial_value=topics[0],
                                              hint="picking one subscribes to it")
                self.topic.on_update(lambda _: self.do(self._browse))
                self.field = gui.add_dropdown("Field", ("(pick a topic)",),
                                              hint="numeric fields of its latest message")
                gui.add_button("Add field to pane").on_click(lambda _: self.do(self._add_field))
                self.field_note = gui.add_markdown("")
            self.window_field = number("Window (s)", self.seconds, PLOT_WINDOW,
                                       self._set_window, hint="sim seconds shown")
            self.hold_box = gui.add_checkbox("Hold", False, hint="freeze the panes while the "
                                                                 "simulation runs (pausing does too)")
            self.hold_box.on_update(lambda e: setattr(self, "hold", bool(e.target.value)))
            exports = gui.add_button_group("Export", ("CSV", "PNG"))
            exports.on_click(lambda e: self.export(e.client, e.target.value))
            self.panes = [Pane(server, log, self.folder, f"pane {i + 1}", chosen[i])
                          for i in range(PANES)]

    @property
    def chosen(self) -> list[list[str]]:
        return [pane.names for pane in self.panes]

    @property
    def plots(self) -> list[viser.GuiUplotHandle]:
        return [pane.plot for pane in self.panes]

    def show(self, i: int, names: list[str]) -> None:
        self.panes[i].names = list(names)
        self.panes[i].changed()
        self.update(force=True)

    def show_joint(self, joint: str) -> None:
        """Pane 1 shows `joint`'s command and position (the step response's joint)."""
        self.show(0, [n for n in (f"{joint}/command", f"{joint}/position") if n in self.log.index])

    # ----- edits (simulation thread) ----------------------------------------------------------
    def _pane_index(self) -> int:
        return int(self.pane.value.split()[-1]) - 1

    def _edit(self, action: str) -> None:
        pane = self.panes[self._pane_index()]
        name = self.signal.value
        if name not in self.log.index:  # a page may send anything
            raise ValueError(f"'{name}' is not a signal this robot has")
        if action == "Add" and name not in pane.names:
            pane.names.append(name)
        elif action == "Remove" and name in pane.names:
            pane.names.remove(name)
        elif action == "Clear pane":
            pane.names.clear()
        pane.changed()
        self.update(force=True)

    def _browse(self) -> None:
        """The Topic dropdown moved: subscribe, list the fields once a message is there."""
        name = self.topic.value
        if name not in self.log.lab.bus.topics:
            raise ValueError(f"Plot: '{name}' is not a topic on the bus")
        self.log.watch(name)
        self._list_fields()

    def _list_fields(self) -> None:
        topic = self.log.lab.bus.topics.get(self.topic.value)
        if topic is None:
            return
        paths = numeric_fields(topic.last) if topic.last is not None else []
        if paths:
            if tuple(self.field.options) != tuple(paths):
                self.field.options = tuple(paths)
            self.field_note.content = ""
        else:
            self.field_note.content = f"*waiting for a message on `{topic.name}`…*"

    def _add_field(self) -> None:
        topic, path = self.topic.value, self.field.value
        name = self.log.add_topic_field(topic, path)  # checks both against the bus
        pane = self.panes[self._pane_index()]
        if name not in pane.names:
            pane.names.append(name)
        names = tuple(s.name for s in self.log.signals)
        if tuple(self.signal.options) != names:
            self.signal.options = names
        pane.changed()
        self.update(force=True)

    def _set_window(self, seconds: float) -> None:
        self.seconds = seconds
        for pane in self.panes:
            pane.changed()
        self.update(force=True)

    # ----- drawing (simulation thread, a few times a second) -------------------------------------
    def update(self, force: bool = False) -> None:
        topics = tuple(sorted(self.log.lab.bus.topics))
        if topics and tuple(self.topic.options) != topics:  # /clock, /tf appear when listened to
            self.topic.options = topics
        if self.field_note.content:
            self._list_fields()
        if self.hold and not force:
            return
        for pane in self.panes:
            pane.update(self.seconds)

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
                ax.plot(t, v, label=self.panes[0].label(name, 1.0))
            ax.set_xlabel("sim time (s)")
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
        fig.tight_layout()
        out = io.BytesIO()
        fig.savefig(out, format="png", dpi=100)
        plt.close(fig)
        return out.getvalue()


def first_joint(lab: Lab) -> str | None:
    """The joint a page shows first (plots, step response): the first a running position
    controller holds, in the configuration's order; else the robot's first moving joint."""
    manager = lab.manager
    held = [j for c in (manager.controllers.values() if manager else ())
            if c.running and c.holds_position for j in c.joints]
    joints = held or lab.sim.joint_names
    return joints[0] if joints else None


def to_csv(t: np.ndarray, values: np.ndarray, names: list[str]) -> str:
    out = io.StringIO()
    writer = csv.writer(out)
    writer.writerow(["time", *names])
    for k in range(t.size):
        writer.writerow([f"{t[k]:.6f}", *(f"{v:.9g}" if math.isfinite(v) else "" for v in values[:, k])])
    return out.getvalue()
