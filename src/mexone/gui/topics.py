"""The Topics panel (rostopic list / hz / echo) and Record (rosbag record) on the page.

Rates are messages per second of simulation time over the last refresh, as `rostopic hz` counts
them under /use_sim_time (so a 50 Hz topic reads 50 Hz whatever the real-time factor). Many
topics publish only while someone listens (joint_states, /tf, sensors): echoing one subscribes
to it, so it starts. A recording goes to a new file in the folder mexone was started in; an
existing file is never replaced (the BagRecorder refuses it), and the page only ever sends a
file name, never a path.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import viser

from mexone.errors import InputError
from mexone.gui.panels import Panel, register_panel
from mexone.record.bag import BAG_SUFFIXES, BagRecorder

__all__ = ["TopicsPanel", "RecordPanel", "echo_text", "recording_path", "subscriber_names"]

RATE_WINDOW = 0.5  # s of wall time between two counts, at least (rostopic hz: a window)

_ECHO_CHARS = 1500


def echo_text(msg) -> str:
    """A message as rostopic echo prints it (YAML-ish), arrays shortened."""
    def walk(value, indent: str) -> list[str]:
        if dataclasses.is_dataclass(value):
            out = []
            for f in dataclasses.fields(value):
                inner = getattr(value, f.name)
                if dataclasses.is_dataclass(inner):
                    out += [f"{indent}{f.name}:", *walk(inner, indent + "  ")]
                else:
                    out.append(f"{indent}{f.name}: {_short(inner)}")
            return out
        return [indent + _short(value)]
    return "\n".join(walk(msg, ""))[:_ECHO_CHARS]


def _short(value) -> str:
    if isinstance(value, list | tuple | np.ndarray):
        items = list(value)
        shown = ", ".join(_short(v) for v in items[:8])
        return f"[{shown}{', …' if len(items) > 8 else ''}]"
    if isinstance(value, float | np.floating):
        return f"{value:.6g}"
    if dataclasses.is_dataclass(value):
        return "{" + ", ".join(f"{f.name}: {_short(getattr(value, f.name))}"
                               for f in dataclasses.fields(value)) + "}"
    return str(value)


@register_panel
class TopicsPanel(Panel):
    """rostopic list/hz/info/echo for the lab's bus (a plug-in panel: gui/panels.py)."""

    name = "topics"
    order = 10
    period = 30

    def build(self) -> None:
        lab = self.lab
        self._counts: dict[str, int] = {}
        self._last = time.monotonic()
        self._last_sim = lab.sim.time
        self.rates: dict[str, float] = {}
        self.echo_sub = None
        gui = self.server.gui
        with gui.add_folder("Topics", expand_by_default=False):
            self.table = gui.add_markdown("")
            names = tuple(sorted(lab.bus.topics)) or ("(none)",)
            self.choice = gui.add_dropdown("Echo", names, initial_value=names[0])
            self.echoing = gui.add_checkbox("Echo on", False, hint="subscribes to the topic")
            self.echoing.on_update(lambda _: self.do(self._resubscribe))
            self.choice.on_update(lambda _: self.do(self._resubscribe))
            self.echo_view = gui.add_markdown("")

    def unload(self) -> None:
        if self.echo_sub is not None:
            self.echo_sub.unregister()
            self.echo_sub = None

    def _resubscribe(self) -> None:
        if self.echo_sub is not None:
            self.echo_sub.unregister()
            self.echo_sub = None
        topic = self.lab.bus.topics.get(self.choice.value)  # never a name the page made up
        if self.echoing.value and topic is not None:
            self.echo_sub = self.lab.bus.subscribe(topic.name, topic.type, lambda _msg: None,
                                                   node="mexone GUI (echo)")
        self.echo_view.content = ""

    def update(self) -> None:
        """Once a second or so (simulation thread)."""
        bus, now, sim_now = self.lab.bus, time.monotonic(), self.lab.sim.time
        span = sim_now - self._last_sim
        # two updates close together would count next to nothing; a paused simulation publishes
        # nothing, so the rates shown stay those of the last window it ran in; a reset starts anew
        fresh = now - self._last >= RATE_WINDOW and span > 0
        restart = fresh or span < 0
        if restart:
            self._last, self._last_sim = now, sim_now
        rows = []  # a list, not a table: the panel is narrow and the names are long
        for name in sorted(bus.topics):
            topic = bus.topics[name]
            if fresh and name in self._counts:
                self.rates[name] = (topic.count - self._counts[name]) / span
            self.rates.setdefault(name, 0.0)
            if restart or name not in self._counts:
                self._counts[name] = topic.count
            rate = self.rates[name]
            rows.append(f"- `{name}` {topic.ros_type}, {rate:.0f} Hz, {topic.publishers} pub, "
                        f"subscribers: {subscriber_names(topic)}")
        self.table.content = "\n".join(rows)
        names = tuple(sorted(bus.topics))
        if names and tuple(self.choice.options) != names:
            self.choice.options = names
        topic = bus.topics.get(self.choice.value)
        if self.echoing.value and topic is not None and topic.last is not None:
            self.echo_view.content = f"```\n{echo_text(topic.last)}\n```"


def subscriber_names(topic) -> str:
    """Who listens, as `rostopic info` lists them: each node once, with a count if several."""
    counts: dict[str, int] = {}
    for sub in list(topic.subscriptions):
        node = sub.node or "(unnamed)"
        counts[node] = counts.get(node, 0) + 1
    if not counts:
        return "none"
    return ", ".join(f"{node}" + (f" ×{n}" if n > 1 else "") for node, n in sorted(counts.items()))


def recording_path(name: str, folder: Path) -> Path:
    """The file a page asked to record to: a plain name ending .mcap or .bag, in `folder`."""
    name = str(name).strip()
    if not name or Path(name).name != name or name in (".", ".."):
        raise InputError(f"Record: '{name}' must be a file name (no folders)",
                         hint="e.g. run1.mcap; it is saved in the folder mexone was started in")
    if not name.endswith(BAG_SUFFIXES):
        raise InputError(f"Record: '{name}' must end with .mcap or .bag")
    return folder / name


@register_panel
class RecordPanel(Panel):
    """Record every topic to a bag from the page (a plug-in panel: gui/panels.py)."""

    name = "record"
    order = 20
    period = 5

    def build(self) -> None:
        folder = self.host.settings.record_folder
        self.folder = Path.cwd() if folder is None else folder
        self.recorder: BagRecorder | None = None
        self.last: Path | None = None
        gui = self.server.gui
        with gui.add_folder("Record", expand_by_default=False):
            self.name = gui.add_text("File", initial_value="recording.mcap",
                                     hint="a new .mcap or .bag in the folder mexone started in")
            self.toggle = gui.add_button("Start recording", icon=viser.Icon.PLAYER_RECORD)
            self.toggle.on_click(lambda _: self.do(self.flip))
            download = gui.add_button("Download last recording")
            download.on_click(lambda e: self.download(e.client))
            self.status = gui.add_markdown("*not recording*")

    def unload(self) -> None:
        self.stop()  # the old robot's recording ends with it

    def flip(self) -> None:
        if self.recorder is None:
            self.start(self.name.value)
        else:
            self.stop()

    def start(self, name: str) -> None:
        """Simulation thread: refuses an existing file (never overwrites)."""
        path = recording_path(name, self.folder)
        self.recorder = BagRecorder(self.lab, path, force=False)
        self.toggle.label = "Stop recording"
        self.toggle.icon = viser.Icon.PLAYER_STOP

    def stop(self) -> None:
        recorder, self.recorder = self.recorder, None
        if recorder is None:
            return
        recorder.close()
        self.last = Path(recorder.path)
        self.toggle.label = "Start recording"
        self.toggle.icon = viser.Icon.PLAYER_RECORD
        total = sum(recorder.counts.values())
        self.status.content = (f"saved `{self.last.name}`: {total} messages on "
                               f"{len(recorder.counts)} topics, "
                               f"{self.last.stat().st_size / 1024:.0f} kB")

    def update(self) -> None:
        recorder = self.recorder
        if recorder is None:
            return
        total = sum(recorder.counts.values())
        self.status.content = f"**recording** `{Path(recorder.path).name}`: {total} messages"

    def download(self, client) -> None:
        if client is None or self.last is None or not self.last.exists():
            self.refuse("Record: nothing recorded yet")
            return
        client.send_file_download(self.last.name, self.last.read_bytes())
