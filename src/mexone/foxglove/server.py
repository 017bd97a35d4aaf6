"""FoxgloveBridge: every bus topic live on the Foxglove WebSocket protocol (foxglove-sdk), for
Foxglove and Lichtblick, with the robot drawn in their 3D panel.

- each bus topic is a channel of its own name: images as Foxglove's `foxglove.RawImage`
  (protobuf, what the Image panel reads), everything else as JSON under its ROS 2 type name
  (`sensor_msgs/msg/JointState`, ...) with a JSON schema built from the bus message's fields
  (stamps `{sec, nsec}`, bytes base64), so Raw Messages and Plot panels read them;
- `/tf` as `foxglove.FrameTransforms`: world -> base and every joint's parent -> child link,
  where the simulation has them;
- `/robot_description` (std_msgs/msg/String, the URDF, re-sent every second while someone
  listens: the protocol has no latching) for the 3D panel's URDF layer, whose meshes
  (`package://...`) the server hands out through the protocol's asset fetch, from the robot's
  package folders only;
- sim time (the protocol's Time capability), messages stamped with it;
- only pages on this machine, and the origins given (`--foxglove-origin`, e.g. Foxglove's web
  app), may connect from a browser (foxglove/gate.py: the SDK's server sits behind it).

Channels send only while a client subscribes (polled between steps). Only the simulation thread
reads MuJoCo; the SDK sends from its own threads.
"""

from __future__ import annotations

import base64
import contextlib
import dataclasses
import logging
import os
import stat
import time
import typing
from collections.abc import Sequence
from pathlib import Path

from mexone.bus import msgs, ros_map
from mexone.bus.topics import Relay
from mexone.errors import InputError, MexoneError, install_extra, printable
from mexone.origins import origin_of

__all__ = ["FoxgloveBridge", "DEFAULT_PORT", "FOXGLOVE_INSTALL", "json_schema", "to_json"]

log = logging.getLogger("mexone.foxglove")

DEFAULT_PORT = 8765  # the Foxglove WebSocket protocol's usual port
FOXGLOVE_INSTALL = install_extra("foxglove")
_POLL = 0.25  # s of wall time between looks at who subscribes
_TIME_PERIOD = 0.02  # s of sim time between time broadcasts and /tf
_DESCRIPTION_EVERY = 1.0  # s of wall time between /robot_description messages


# ----- JSON schemas and messages, from the bus dataclasses -------------------------------------
_STAMP = {"type": "object", "properties": {"sec": {"type": "integer"},
                                            "nsec": {"type": "integer"}}}


def _schema_of(annotation) -> dict:
    origin = typing.get_origin(annotation)
    if annotation in (msgs.Time, msgs.Duration):
        return _STAMP
    if dataclasses.is_dataclass(annotation):
        return json_schema(annotation)
    if origin in (list, tuple):
        args = [a for a in typing.get_args(annotation) if a is not Ellipsis]
        return {"type": "array", "items": _schema_of(args[0]) if args else {}}
    return {float: {"type": "number"}, int: {"type": "integer"}, bool: {"type": "boolean"},
            str: {"type": "string"},
            bytes: {"type": "string", "contentEncoding": "base64"}}.get(annotation, {})


def json_schema(bus_type: type) -> dict:
    """The JSON schema of a bus message as `to_json` writes it (ROS 2's field names)."""
    hints = typing.get_type_hints(bus_type)
    props = {f.name: _schema_of(hints[f.name]) for f in dataclasses.fields(bus_type)
             if not (bus_type is msgs.Header and f.name == "seq")}  # ROS 2 headers have no seq
    return {"type": "object", "properties": props}


def to_json(value):
    """A bus message as plain JSON values (stamps {sec, nsec}, bytes base64)."""
    if isinstance(value, msgs.Time | msgs.Duration):
        return {"sec": value.secs, "nsec": value.nsecs}
    if isinstance(value, msgs.Header):
        return {"stamp": to_json(value.stamp), "frame_id": value.frame_id}
    if dataclasses.is_dataclass(value):
        return {f.name: to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, bytes | bytearray):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, list | tuple):
        return [to_json(v) for v in value]
    if hasattr(value, "item"):  # numpy scalars
        return value.item()
    return value


# ----- the bridge ------------------------------------------------------------------------------
class _Mirror:
    """One bus topic on one channel, subscribed on the bus while a client subscribes."""

    def __init__(self, bridge: FoxgloveBridge, topic: str, bus_type: type):
        import foxglove
        from foxglove.channels import RawImageChannel

        self.bridge, self.topic = bridge, topic
        self.relay = Relay(bridge.lab.bus, topic, self.forward, "Foxglove")
        self.image = bus_type is msgs.Image
        if self.image:
            self.channel = RawImageChannel(topic, context=bridge.context)
        else:
            schema = foxglove.Schema(name=ros_map.ros2_type(bus_type) or bus_type.__name__,
                                     encoding="jsonschema",
                                     data=_json_bytes(json_schema(bus_type)))
            self.channel = foxglove.Channel(topic, schema=schema, message_encoding="json",
                                            context=bridge.context)

    def update(self) -> None:  # simulation thread
        self.relay.want(self.channel.has_sinks())

    def forward(self, msg) -> None:
        log_time = self.bridge.lab.sim.time_ns
        if self.image:
            from foxglove.messages import RawImage, Timestamp

            stamp = msg.header.stamp
            self.channel.log(RawImage(timestamp=Timestamp(stamp.secs, stamp.nsecs),
                                      frame_id=msg.header.frame_id, width=msg.width,
                                      height=msg.height, encoding=msg.encoding, step=msg.step,
                                      data=bytes(msg.data)), log_time=log_time)
        else:
            self.channel.log(_json_bytes(to_json(msg)), log_time=log_time)


def _json_bytes(value) -> bytes:
    import json

    return json.dumps(value, separators=(",", ":"), allow_nan=True).encode()


class FoxgloveBridge:
    """Serve (`__init__`), attach the lab (`attach`), `pump` between steps, `shutdown`."""

    def __init__(self, port: int = DEFAULT_PORT, host: str = "127.0.0.1",
                 origins: Sequence[str] = ()):
        try:
            import cryptography  # noqa: F401 - the gate's certificate (the foxglove extra)
            import foxglove
        except ImportError:
            raise MexoneError("foxglove-sdk is not installed",
                              hint=f"install it with: {FOXGLOVE_INSTALL}") from None
        from mexone.foxglove.gate import Gate, loopback_certificate

        trusted = [origin_of(o) for o in origins]  # a bad --foxglove-origin: one line, first
        self.context = foxglove.Context()
        self._roots: dict[str, Path] = {}
        certificate, key = loopback_certificate()
        try:  # the SDK's server: loopback, TLS; only the gate (which checks Origin) gets in
            self.server = foxglove.start_server(
                name="mexone", host="127.0.0.1", port=0, context=self.context,
                capabilities=[foxglove.Capability.Time], asset_handler=self._asset,
                tls_cert=certificate, tls_key=key)
        except Exception as exc:  # noqa: BLE001 - the SDK's error for a taken or bad address
            raise InputError(f"cannot serve Foxglove: {exc}") from None
        try:
            self.gate = Gate(host, port, self.server.port, certificate, trusted)
        except BaseException:
            self.server.stop()
            raise
        self.host, self.port = host, self.gate.port
        self.lab = None

    def where(self) -> str:
        return f"Foxglove at ws://{self.host}:{self.port}"

    def attach(self, lab, urdf_text: str) -> None:
        import foxglove
        from foxglove.channels import FrameTransformsChannel

        self.lab = lab
        self._mirrors: dict[str, _Mirror] = {}
        self._known_topics = -1
        self._last_poll = self._last_description = 0.0
        self._urdf = urdf_text
        self._roots = _package_roots(lab)
        self.tf = FrameTransformsChannel("/tf", context=self.context)
        schema = foxglove.Schema(name="std_msgs/msg/String", encoding="jsonschema",
                                 data=_json_bytes({"type": "object",
                                                   "properties": {"data": {"type": "string"}}}))
        self.description = foxglove.Channel("/robot_description", schema=schema,
                                            message_encoding="json", context=self.context)
        self._timer = lab.sim.add_periodic(_TIME_PERIOD, self._tick)
        self.sync_topics()

    def sync_topics(self) -> None:
        bus = self.lab.bus
        if len(bus.topics) == self._known_topics:
            return
        self._known_topics = len(bus.topics)
        for name, topic in list(bus.topics.items()):
            if name not in self._mirrors and name not in ("/tf", "/robot_description") \
                    and topic.publishers:
                self._mirrors[name] = _Mirror(self, name, topic.type)

    def _tick(self, sim) -> None:  # simulation thread, every _TIME_PERIOD of sim time
        self.server.broadcast_time(sim.time_ns)
        if self.tf.has_sinks():
            from foxglove.messages import (
                FrameTransform,
                FrameTransforms,
                Quaternion,
                Timestamp,
                Vector3,
            )

            stamp = Timestamp(*divmod(sim.time_ns, 1_000_000_000))
            self.tf.log(FrameTransforms(transforms=[
                FrameTransform(timestamp=stamp, parent_frame_id=t.header.frame_id,
                               child_frame_id=t.child_frame_id,
                               translation=Vector3(x=float(t.translation[0]),
                                                   y=float(t.translation[1]),
                                                   z=float(t.translation[2])),
                               rotation=Quaternion(w=float(t.rotation[0]), x=float(t.rotation[1]),
                                                   y=float(t.rotation[2]), z=float(t.rotation[3])))
                for t in self.lab.transforms()]), log_time=sim.time_ns)

    def pump(self, sim=None) -> None:
        """Between steps (simulation thread): new topics, who subscribes, the URDF, and the
        time while paused."""
        self.sync_topics()
        now = time.perf_counter()
        if now - self._last_poll >= _POLL:
            self._last_poll = now
            for mirror in self._mirrors.values():
                mirror.update()
            if self.lab.sim.paused:
                self.server.broadcast_time(self.lab.sim.time_ns)
        if now - self._last_description >= _DESCRIPTION_EVERY and self.description.has_sinks():
            self._last_description = now
            self.description.log(_json_bytes({"data": self._urdf}),
                                 log_time=self.lab.sim.time_ns)

    def _asset(self, uri: str) -> bytes | None:
        """package://<pkg>/<path> from the robot's package folders, nothing else (SDK thread):
        None (not found) for anything outside them or not a regular file (a FIFO would hold the
        SDK's thread); an error that cannot be read names the URI, never the folder it is in."""
        if not uri.startswith("package://"):
            return None
        package, _, rest = uri[len("package://"):].partition("/")
        root = self._roots.get(package)
        if root is None:
            return None
        try:
            path = (root / rest).resolve()
        except (OSError, RuntimeError):  # a symbolic link loop: its message names the folder
            raise OSError(f"{printable(uri, 200)}: a symbolic link loop") from None
        if not path.is_relative_to(root):
            return None
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise OSError(f"{printable(uri, 200)}: {exc.strerror or 'cannot be read'}") from None
        with os.fdopen(fd, "rb") as handle:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                return None
            try:
                return handle.read()
            except OSError as exc:
                raise OSError(f"{printable(uri, 200)}: {exc.strerror or 'cannot be read'}") \
                    from None

    def shutdown(self) -> None:
        if self.lab is not None:
            self.lab.sim.remove_periodic(self._timer)
        self.gate.close()
        with contextlib.suppress(Exception):  # already stopped
            self.server.stop()


def _package_roots(lab) -> dict[str, Path]:
    """ROS package name -> folder, for meshes: the built-in robot's, the model's own package (its
    package.xml's folder) and ROS_PACKAGE_PATH's packages."""
    from mexone.robots import mex_one

    roots = {"mex_rb": mex_one.package_dir().resolve()}
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        base = Path(entry) if entry else None
        if base is None or not base.is_dir():
            continue
        for xml in [base / "package.xml", *base.glob("*/package.xml")]:
            if xml.is_file():
                roots.setdefault(xml.parent.name, xml.parent.resolve())
    source = getattr(lab.sim.robot, "source", None)
    if source:
        for parent in Path(source).resolve().parents:
            if (parent / "package.xml").is_file():
                roots.setdefault(parent.name, parent)
                break
    return roots
