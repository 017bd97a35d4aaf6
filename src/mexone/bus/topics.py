"""In-process topics with ROS names: one Bus per simulation, typed like ROS topics.

Delivery is synchronous: publish() calls every subscriber's callback in the publishing
thread before it returns, which keeps a headless run deterministic. A topic's type is fixed
by its first publisher or subscriber; a mismatch is an error naming both types, as ROS does.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from mexone.bus.msgs import ROS_TYPES
from mexone.errors import InputError

__all__ = ["Bus", "Topic", "Subscription", "Relay", "resolve_name"]


def resolve_name(name: str, namespace: str = "/") -> str:
    """ROS name resolution for the cases routines use: absolute, relative to a namespace."""
    if not name:
        raise InputError("empty topic name")
    if name.startswith("/"):
        return name
    ns = namespace if namespace.endswith("/") else namespace + "/"
    return ns + name


@dataclass(eq=False)
class Subscription:
    topic: Topic
    callback: Callable[[object], None]
    bus: Bus | None = None
    node: str = ""  # who listens (a controller, a routine's node, the recorder), for the GUI

    def unregister(self) -> None:
        self.topic.remove(self)
        if self.bus is not None:
            self.bus._changed(self.topic)


@dataclass(eq=False)
class Topic:
    name: str
    type: type
    subscriptions: list[Subscription] = field(default_factory=list)
    publishers: int = 0
    count: int = 0  # messages published
    last: object | None = None  # the latest message, for GUIs and latched subscribers
    lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def ros_type(self) -> str:
        return ROS_TYPES.get(self.type, self.type.__name__)

    def remove(self, sub: Subscription) -> None:
        with self.lock:
            if sub in self.subscriptions:
                self.subscriptions.remove(sub)


class Bus:
    def __init__(self) -> None:
        self.topics: dict[str, Topic] = {}
        self._lock = threading.Lock()
        self.taps: list[Callable[[str, object], None]] = []  # see every message (recorders)
        # topic -> callbacks told the subscriber count when it changes (lazy publishers)
        self.listeners: dict[str, list[Callable[[int], None]]] = {}

    def add_tap(self, tap: Callable[[str, object], None]) -> None:
        """See every message (a recorder). Lazy publishers hear of it and start."""
        self.taps.append(tap)
        self._changed_all()

    def remove_tap(self, tap: Callable[[str, object], None]) -> None:
        if tap in self.taps:
            self.taps.remove(tap)
            self._changed_all()

    def _changed_all(self) -> None:
        for name in list(self.listeners):
            topic = self.topics.get(name)
            count = len(topic.subscriptions) if topic else 0
            for callback in self.listeners[name]:
                callback(count)

    def on_subscribers(self, name: str, callback: Callable[[int], None]) -> None:
        """Call `callback(count)` whenever the number of subscribers to `name` changes."""
        self.listeners.setdefault(name, []).append(callback)

    def _changed(self, topic: Topic) -> None:
        for callback in self.listeners.get(topic.name, []):
            callback(len(topic.subscriptions))

    def topic(self, name: str, msg_type: type) -> Topic:
        with self._lock:
            topic = self.topics.get(name)
            if topic is None:
                topic = self.topics[name] = Topic(name, msg_type)
            elif topic.type is not msg_type:
                raise InputError(f"topic {name} carries {topic.ros_type}, not "
                                 f"{ROS_TYPES.get(msg_type, msg_type.__name__)}",
                                 hint="use the topic's message type")
            return topic

    def wanted(self, name: str) -> bool:
        """Whether a message on `name` would reach anyone (a subscriber or a recorder): publishers
        that cost something skip building messages nobody reads, as ROS transports none."""
        topic = self.topics.get(name)
        return bool(self.taps or (topic is not None and topic.subscriptions))

    def advertise(self, name: str, msg_type: type) -> Topic:
        topic = self.topic(name, msg_type)
        topic.publishers += 1
        return topic

    def subscribe(self, name: str, msg_type: type, callback: Callable[[object], None],
                  latched: bool = False, node: str = "") -> Subscription:
        topic = self.topic(name, msg_type)
        sub = Subscription(topic, callback, self, node)
        with topic.lock:
            topic.subscriptions.append(sub)
        self._changed(topic)
        if latched and topic.last is not None:
            callback(topic.last)
        return sub

    def publish(self, name: str, msg: object) -> None:
        self.deliver(self.topic(name, type(msg)), msg)

    def deliver(self, topic: Topic, msg: object) -> None:
        """publish() on a Topic already looked up and typed (advertise's): a publisher on a hot
        path (the sensors' broadcasters) skips the lookup."""
        with topic.lock:
            topic.count += 1
            topic.last = msg
            subs = topic.subscriptions[:]
        if self.taps:
            name = topic.name
            for tap in self.taps:
                tap(name, msg)
        for sub in subs:
            sub.callback(msg)


class Relay:
    """A bus subscription held exactly while someone outside the bus listens: a bridge's
    mirror of one topic (ROS 1, ROS 2, Foxglove) says `want(...)` with whether its own
    subscribers exist, so a topic nobody outside reads costs nothing. Simulation thread."""

    def __init__(self, bus: Bus, topic: str, callback: Callable[[object], None], node: str) -> None:
        self.bus, self.topic, self.callback, self.node = bus, topic, callback, node
        self.sub: Subscription | None = None

    def want(self, wanted: bool) -> None:
        if wanted and self.sub is None:
            self.sub = self.bus.subscribe(self.topic, self.bus.topics[self.topic].type,
                                          self.callback, node=self.node)
        elif not wanted and self.sub is not None:
            self.sub.unregister()
            self.sub = None
