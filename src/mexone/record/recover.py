"""Rebuild a bag whose recording was killed (SIGKILL, a crash, a routine's ``os._exit``).

A killed recording leaves ``BAG.active`` (see `mexone.record.bag`): every chunk written before
the kill, but no index, summary or footer, which is what readers look for first, so the
``mcap`` reader, ``rosbags`` and Foxglove all refuse it. Read front to back instead -- the mcap
library's stream reader walks a truncated file's chunks, and a ROS 1 bag is a plain sequence of
records -- every complete chunk is still there; its messages are written again to a valid bag.
A chunk cut by the kill fails its CRC (or its length) and is where recovery stops.
"""

from __future__ import annotations

import bz2
import struct
from dataclasses import dataclass
from pathlib import Path

from mexone.errors import InputError

__all__ = ["Recovered", "recover", "is_complete", "looks_truncated", "bag_suffix",
           "killed_recording", "bag_kind", "KIND_NAMES", "not_a_bag", "misnamed"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
BAG1_MAGIC = b"#ROSBAG V2.0\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"
KIND_NAMES = {".mcap": "an MCAP file", ".bag": "a ROS 1 bag"}


@dataclass
class Recovered:
    """What a recovery found: how many messages on how many topics, over which sim time."""

    messages: int = 0
    topics: int = 0
    first: float | None = None  # s, stamp of the first recovered message
    last: float | None = None

    def add(self, stamp_ns: int) -> None:
        self.messages += 1
        t = stamp_ns * 1e-9
        self.first = t if self.first is None else min(self.first, t)
        self.last = t if self.last is None else max(self.last, t)

    def describe(self) -> str:
        span = "" if self.first is None else f", sim time {self.first:.3f}-{self.last:.3f} s"
        return f"{self.messages} messages on {self.topics} topics{span}"


def bag_suffix(path: Path) -> str:
    """.mcap or .bag, also for a recording's BAG.active."""
    name = path.name.removesuffix(".active")
    return Path(name).suffix.lower()


def _head(path: Path) -> bytes:
    try:
        with path.open("rb") as handle:
            return handle.read(len(BAG1_MAGIC))
    except OSError:
        return b""


def bag_kind(path: Path) -> str | None:
    """What the file is by its first bytes, whatever its name: ".mcap" (MCAP's magic, b"\\x89MCAP"),
    ".bag" (ROS 1's "#ROSBAG V2.0") or None (neither)."""
    head = _head(path)
    if head.startswith(MCAP_MAGIC[:5]):
        return ".mcap"
    if head.startswith(BAG1_MAGIC[:-1]):
        return ".bag"
    return None


def not_a_bag(path: Path) -> InputError:
    """The error for a file that starts as neither kind of bag, saying what it is where known."""
    head = _head(path)
    if not head:
        what = "an empty file" if path.is_file() and path.stat().st_size == 0 else "not readable"
    elif head.startswith(_SQLITE_MAGIC[:len(head)]):
        return InputError("a ROS 2 SQLite bag (.db3), which mexone does not read", file=path,
                          hint="convert it: ros2 bag convert with storage_id: mcap")
    else:
        what = "not a bag (it starts with neither MCAP's magic bytes nor '#ROSBAG V2.0')"
    return InputError(what, file=path, hint="give a .mcap or .bag recorded by mexone or ROS")


def misnamed(path: Path) -> str | None:
    """'an MCAP file named .bag' when the file's content and its name disagree, else None."""
    kind, named = bag_kind(path), bag_suffix(path)
    if kind is None or kind == named:
        return None
    return f"{KIND_NAMES[kind]} named {named or 'without .mcap or .bag'}"


def _kind(path: Path) -> str:
    return bag_kind(path) or bag_suffix(path)


def is_complete(path: Path) -> bool:
    """Whether the format's own reader opens the bag (index and footer intact), by content."""
    try:
        if _kind(path) == ".bag":
            from rosbags.rosbag1 import Reader

            with Reader(path):
                return True
        from mcap.reader import make_reader

        with path.open("rb") as handle:
            return make_reader(handle).get_summary() is not None
    except Exception:  # each library has its own errors for a damaged file
        return False


def looks_truncated(path: Path) -> bool:
    """A bag that starts as one but does not open: a killed recording, not some other file."""
    return bag_kind(path) is not None and not is_complete(path)


def killed_recording(path: Path) -> Path | None:
    """The truncated file behind a bag's name: the BAG.active a killed recording left, or BAG
    itself if it starts as a bag but does not open (a copy of one, another recorder's)."""
    from mexone.record.bag import active_path

    active = path if path.name.endswith(".active") else active_path(path)
    if active.is_file():
        return active
    if path.is_file() and looks_truncated(path):
        return path
    return None


def recover(source: Path, output: Path) -> Recovered:
    """Write every complete message of the truncated bag `source` to a new, valid bag `output`
    (same format; output must not exist)."""
    kind = bag_kind(source)
    if kind is None:
        raise not_a_bag(source)
    if kind != bag_suffix(output):
        raise InputError(f"is {KIND_NAMES[kind]}: it cannot be recovered as "
                         f"'{output.suffix or output.name}'", file=source, hint=f"name it {kind}")
    return _recover_bag1(source, output) if kind == ".bag" else _recover_mcap(source, output)


def _recover_mcap(source: Path, output: Path) -> Recovered:
    from mcap.records import Channel, Header, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    found = Recovered()
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    with source.open("rb") as src, output.open("xb") as dst:
        writer = Writer(dst, compression=CompressionType.NONE)
        started = False
        records = StreamReader(src, validate_crcs=True, record_size_limit=1 << 30).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except Exception:  # the chunk the kill cut: the end of what can be recovered
                break
            if isinstance(record, Header) and not started:
                writer.start(profile=record.profile, library=record.library)
                started = True
            elif not started:
                break
            elif isinstance(record, Schema) and record.id not in schemas:
                schemas[record.id] = writer.register_schema(record.name, record.encoding,
                                                            record.data)
            elif isinstance(record, Channel) and record.id not in channels:
                channels[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schemas.get(record.schema_id, 0),
                    dict(record.metadata))
            elif isinstance(record, Message) and record.channel_id in channels:
                writer.add_message(channels[record.channel_id], log_time=record.log_time,
                                   data=record.data, publish_time=record.publish_time,
                                   sequence=record.sequence)
                found.add(record.log_time)
        if not started:
            writer.start(profile="ros2", library="mexone recover")
        writer.finish()
    found.topics = len(channels)
    return found


# ----- ROS 1 bags: records of <header length><header fields><data length><data> -------------------
_OP_MSG, _OP_CHUNK, _OP_CONNECTION = 0x02, 0x05, 0x07


def _fields(header: bytes) -> dict[str, bytes]:
    fields, pos = {}, 0
    while pos + 4 <= len(header):
        (size,) = struct.unpack_from("<I", header, pos)
        name, _, value = header[pos + 4:pos + 4 + size].partition(b"=")
        fields[name.decode(errors="replace")] = value  # a damaged name is no field we read
        pos += 4 + size
    return fields


def _records(data: bytes):
    """(fields, payload) of each complete record in data; stops at the first incomplete one."""
    pos = 0
    while pos + 4 <= len(data):
        (hlen,) = struct.unpack_from("<I", data, pos)
        if pos + 4 + hlen + 4 > len(data):
            return
        header = data[pos + 4:pos + 4 + hlen]
        (dlen,) = struct.unpack_from("<I", data, pos + 4 + hlen)
        start = pos + 8 + hlen
        if start + dlen > len(data):
            return
        yield _fields(header), data[start:start + dlen]
        pos = start + dlen


def _decompress(kind: bytes, data: bytes) -> bytes:
    if kind == b"none":
        return data
    if kind == b"bz2":
        return bz2.decompress(data)
    if kind == b"lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise ValueError(kind)


def _recover_bag1(source: Path, output: Path) -> Recovered:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys.msg import normalize_msgtype

    found = Recovered()
    writer = Writer(output)
    writer.open()
    connections: dict[int, object] = {}

    def connection(fields: dict[str, bytes], payload: bytes) -> None:
        cid = struct.unpack("<I", fields["conn"])[0]
        if cid in connections:
            return
        info = _fields(payload)
        latching = info.get("latching")
        connections[cid] = writer.add_connection(
            fields["topic"].decode(), normalize_msgtype(info["type"].decode()),
            msgdef=info.get("message_definition", b"").decode(), md5sum=info["md5sum"].decode(),
            callerid=info["callerid"].decode() if "callerid" in info else None,
            latching=int(latching) if latching else None)

    def chunk(fields: dict[str, bytes], payload: bytes) -> None:
        for sub, body in _records(_decompress(fields.get("compression", b"none"), payload)):
            op = sub.get("op", b"\0")[0]
            if op == _OP_CONNECTION:
                connection(sub, body)
            elif op == _OP_MSG and struct.unpack("<I", sub["conn"])[0] in connections:
                secs, nsecs = struct.unpack("<II", sub["time"])
                stamp = secs * 1_000_000_000 + nsecs
                writer.write(connections[struct.unpack("<I", sub["conn"])[0]], stamp, body)
                found.add(stamp)

    data = source.read_bytes()[len(BAG1_MAGIC):]
    for fields, payload in _records(data):
        op = fields.get("op", b"\0")[0]
        try:
            if op == _OP_CONNECTION:
                connection(fields, payload)
            elif op == _OP_CHUNK:
                chunk(fields, payload)
        except Exception:  # noqa: BLE001 -- a damaged record (a bad length, a codec's own
            break  # error for a damaged chunk): the end of what can be recovered
    writer.close()
    found.topics = len(connections)
    return found
