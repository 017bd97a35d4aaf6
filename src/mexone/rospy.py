"""A rospy-shaped API over mexone's in-process topics and sim time.

A rospy routine ports by changing its imports::

    from mexone import rospy                 # was: import rospy
    from mexone.msgs import Float64          # was: from std_msgs.msg import Float64

and runs with ``mexone run my_routine.py`` (headless, as fast as physics allows) or from the GUI
(real time). Time is sim time, as for a node with use_sim_time.
"""

from __future__ import annotations

import math
import threading
from typing import Any

from mexone.bus import msgs as _msgs
from mexone.bus.topics import resolve_name
from mexone.routines.runtime import Shutdown, current

__all__ = [
    "init_node", "Publisher", "Subscriber", "Rate", "sleep", "spin", "is_shutdown",
    "signal_shutdown", "on_shutdown", "get_time", "get_rostime", "Time", "Duration",
    "loginfo", "logwarn", "logerr", "logdebug", "logfatal", "wait_for_message", "get_param",
    "set_param", "has_param", "get_name", "get_namespace", "ROSException",
    "ROSInterruptException", "ROSInitException",
]


class ROSException(Exception):
    """rospy's base exception: what a routine catches around a ROS call."""
    pass


class ROSInterruptException(ROSException, KeyboardInterrupt, Shutdown):
    """Raised in sleeps when the simulation ends, as rospy does on shutdown (a Shutdown, so the
    routine runner, below this module, knows it as the routine's clean end)."""


class ROSInitException(ROSException):
    """init_node was not called (or called twice), as rospy raises it."""
    pass


def _resolve(name: str) -> str:
    ctx = current()
    if name.startswith("~"):
        return resolve_name(name[1:], ctx.node_name)
    return resolve_name(name, "/")


_MISSING = object()


# ----- node -------------------------------------------------------------------------------
def init_node(name: str, anonymous: bool = False, **_ignored: Any) -> None:
    """Name the node (`__name:=n` on the command line renames it, anonymous then off, as rospy)
    and move its `_x:=v` arguments to its private ~x, where rospy sets them at init_node."""
    ctx = current()
    if ctx.name_remap:
        name, anonymous = ctx.name_remap, False
    old = ctx.node_name
    ctx.node_name = "/" + name.strip("/") + (f"_{threading.get_ident()}" if anonymous else "")
    for key, value in ctx.private.items():
        if ctx.params.get(f"{old}/{key}", _MISSING) is value:  # not changed by the routine since
            del ctx.params[f"{old}/{key}"]
        ctx.params[f"{ctx.node_name}/{key}"] = value


def get_name() -> str:
    """The routine's node name (`/name`, init_node's, or `__name:=` renamed)."""
    return current().node_name


def get_namespace() -> str:
    """The node's namespace: the root, as for a node rosrun starts."""
    return "/"


def is_shutdown() -> bool:
    """Whether the routine should end: its run is over or it called signal_shutdown."""
    ctx = current()
    return ctx.scheduler.stopped or ctx.shutdown_reason is not None


def signal_shutdown(reason: str) -> None:
    """End the routine (its loops see is_shutdown()), running its on_shutdown hooks."""
    ctx = current()
    ctx.shutdown_reason = reason
    for hook in ctx.shutdown_hooks:
        hook()


def on_shutdown(hook) -> None:
    """Run `hook()` when the routine is shut down (signal_shutdown)."""
    current().shutdown_hooks.append(hook)


# ----- time -------------------------------------------------------------------------------
class Time(_msgs.Time):
    """rospy's Time: a stamp in sim time (`Time.now()`)."""

    @staticmethod
    def now() -> _msgs.Time:
        """Sim time now."""
        return _msgs.Time.from_nsec(current().lab.sim.time_ns)


def Duration(secs: float = 0, nsecs: int = 0) -> _msgs.Duration:  # noqa: N802 - rospy's name
    """rospy's Duration: a span of sim time."""
    return _msgs.Duration.from_sec(secs + nsecs * 1e-9)


def get_time() -> float:
    """Sim time now, in seconds (the simulation's clock, /use_sim_time)."""
    return current().time


def get_rostime() -> _msgs.Time:
    """Sim time now, as a rospy Time."""
    return Time.now()


def _wait(wake: float, ready=None) -> None:
    ctx = current()
    if ctx.shutdown_reason is not None:
        raise ROSInterruptException(ctx.shutdown_reason)
    try:
        ctx.scheduler.wait(wake, ready)
    except Shutdown:
        raise ROSInterruptException("simulation ended") from None


def sleep(duration) -> None:
    """Wait `duration` s of sim time (a number or a Duration): the simulation runs meanwhile."""
    seconds = duration.to_sec() if hasattr(duration, "to_sec") else float(duration)
    if math.isnan(seconds):
        raise ROSException("rospy.sleep(nan): the duration is not a number")
    _wait(current().time + max(seconds, 0.0))


class Rate:
    """Sleeps to keep `hz` in sim time; if a loop overruns by more than a period, it restarts
    from now instead of bursting (rospy's behaviour)."""

    def __init__(self, hz: float):
        if not (hz > 0 and math.isfinite(hz)):
            raise ROSException(f"Rate({hz}): the rate must be a finite number > 0 Hz")
        self.period = 1.0 / hz
        self.last = current().time

    def sleep(self) -> None:
        """Sleep the rest of this period, in sim time (the simulation runs meanwhile)."""
        now = current().time
        wake = self.last + self.period
        if now - wake > self.period:
            wake = now
        self.last = wake
        _wait(max(wake, now))

    def remaining(self) -> _msgs.Duration:
        """What is left of this period, as a Duration."""
        return _msgs.Duration.from_sec(max(0.0, self.last + self.period - current().time))


def spin() -> None:
    """Handle callbacks until the routine is shut down."""
    while not is_shutdown():
        _wait(float("inf"))


# ----- topics -----------------------------------------------------------------------------
class Publisher:
    """rospy's Publisher on the lab's bus: `publish(msg)` (or the message's fields); a command
    topic nobody subscribes to is said once in the console."""

    def __init__(self, name: str, data_class: type, queue_size: int | None = None,
                 latch: bool = False, **_ignored: Any):
        self.name = _resolve(name)
        self.data_class = data_class
        self._context = current()
        self._bus = self._context.lab.bus
        self._bus.advertise(self.name, data_class)

    def publish(self, *args: Any, **kwargs: Any) -> None:
        """Publish a message (or build one from its fields), as rospy."""
        ctx = self._context
        if ctx.abandoned:
            raise Shutdown
        msg = args[0] if len(args) == 1 and not kwargs and isinstance(args[0], self.data_class) \
            else self.data_class(*args, **kwargs)
        if self.name not in ctx.warned_topics and self.name.endswith("/command") \
                and not self.get_num_connections():
            ctx.warned_topics.add(self.name)
            manager = ctx.lab.manager
            topics = [manager.topic(c.name) for c in manager.controllers.values()
                      if c.running and c.drives_joints] if manager else []
            notice = (f"{self.name} has no subscriber; this robot's command topics are: "
                      + (", ".join(topics) or "none"))
            ctx.notices.append(notice)
            ctx.log("WARN", notice)
        self._bus.publish(self.name, msg)

    def get_num_connections(self) -> int:
        """How many subscribe to the topic."""
        topic = self._bus.topics.get(self.name)
        return len(topic.subscriptions) if topic else 0

    def unregister(self) -> None:
        """Stop publishing (nothing to undo on the lab's bus)."""
        pass


class Subscriber:
    """rospy's Subscriber on the lab's bus: `callback(msg[, callback_args])` runs in the
    routine's own thread, between its calls to sleep, as rospy's would."""

    def __init__(self, name: str, data_class: type, callback=None, callback_args=None,
                 queue_size: int | None = None, **_ignored: Any):
        self.name = _resolve(name)
        self.callback = callback
        ctx = current()

        def run(msg):  # in the routine's thread, while it waits
            if callback_args is None:
                callback(msg)
            else:
                callback(msg, callback_args)

        def deliver(msg):  # in the publisher's thread: queue only
            if callback is not None:
                ctx.deliver(run, msg)

        self._sub = ctx.lab.bus.subscribe(self.name, data_class, deliver, node=ctx.node_name)

    def unregister(self) -> None:
        """Stop receiving the topic's messages."""
        self._sub.unregister()


def wait_for_message(topic: str, topic_type: type, timeout: float | None = None):
    """The next message on `topic` (sim time timeout, in seconds)."""
    box: list = []
    ctx = current()
    sub = ctx.lab.bus.subscribe(_resolve(topic), topic_type, lambda msg: ctx.deliver(box.append, msg),
                                node=ctx.node_name)
    try:
        deadline = current().time + (timeout if timeout is not None else float("inf"))
        _wait(deadline, ready=lambda: bool(box))
    finally:
        sub.unregister()
    if not box:
        raise ROSException(f"timeout exceeded while waiting for a message on {topic}")
    return box[0]


# ----- parameters and logging -------------------------------------------------------------
def get_param(name: str, default: Any = KeyError) -> Any:
    """A parameter from the routine's parameter server (the controller YAML and its
    arguments), or `default`; a KeyError without one, as rospy."""
    key = _resolve(name)
    params = current().params
    if key in params:
        return params[key]
    prefix = key.rstrip("/") + "/"
    tree: dict = {}
    for k, v in params.items():
        if k.startswith(prefix):  # a namespace: rebuild the nested dict rospy returns
            *parents, leaf = k[len(prefix):].split("/")
            node = tree
            for part in parents:
                node = node.setdefault(part, {})
            node[leaf] = v
    if tree:
        return tree
    if default is KeyError:
        raise KeyError(name)
    return default


def set_param(name: str, value: Any) -> None:
    """Set a parameter on the routine's parameter server."""
    current().params[_resolve(name)] = value


def has_param(name: str) -> bool:
    """Whether the parameter server holds `name`."""
    try:
        get_param(name)
    except KeyError:
        return False
    return True


def _log(level: str, text: str, *args: Any) -> None:
    current().log(level, text % args if args else str(text))


def loginfo(msg: str, *args: Any, **_kw: Any) -> None:
    """Log at INFO in the routine's console (`msg % args`, as rospy)."""
    _log("INFO", msg, *args)


def logwarn(msg: str, *args: Any, **_kw: Any) -> None:
    """Log at WARN in the routine's console."""
    _log("WARN", msg, *args)


def logerr(msg: str, *args: Any, **_kw: Any) -> None:
    """Log at ERROR in the routine's console."""
    _log("ERROR", msg, *args)


def logdebug(msg: str, *args: Any, **_kw: Any) -> None:
    """Log at DEBUG in the routine's console."""
    _log("DEBUG", msg, *args)


def logfatal(msg: str, *args: Any, **_kw: Any) -> None:
    """Log at FATAL in the routine's console."""
    _log("FATAL", msg, *args)
