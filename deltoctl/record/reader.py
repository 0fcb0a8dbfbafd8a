"""Reading recordings back, fast: what `deltoctl info` and `deltoctl plot` show.

A finished MCAP file ends with a summary: its channels, message counts, first and last times,
and an index of every chunk (where it is, which channels it holds, where each channel's
message index is). ``Recording`` reads that and nothing more, then opens only the chunks that
hold the channels asked for, and in a chunk only the messages its message index points to:

- ``info`` reads the summary, the metadata records and the /diagnostics messages (link lost
  and restored, gaps, loop statistics), each of which the recorder writes as a chunk of its
  own, so an hour at 1 kHz costs a few thousand small reads, not its gigabytes;
- ``series`` unpacks the chunks of the topics that carry the interfaces asked for and takes
  each value at its offset in every message at once (numpy): the recorder's messages keep
  their layout for a whole recording, so the layout is worked out once a chunk, from its first
  message, and used for every message of the same length (any other is decoded on its own).

A file without a summary (the recorder was killed) is read whole, record by record: slower,
and said so. Any other MCAP with these ROS 2 types reads too. A file that is missing, cut short
or not MCAP is an ``InvalidInput`` naming what is wrong (exit 2).

A recording is untrusted input: every size it declares is checked against a bound before
anything of that size is allocated. A chunk unpacks to at most ``MAX_CHUNK_BYTES``, and to
exactly the size it declares (the decompressor is told to stop one byte past it, so a frame
that lies about its size costs no more); the summary, the metadata and what a file without a
summary keeps in memory are bounded too. Anything beyond is one ``InvalidInput`` naming the
file and the record (exit 2).
"""

from __future__ import annotations

import fnmatch
import io
import json
import math
import multiprocessing
import os
import struct
import sys
import zlib
from array import array
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, cast

from deltoctl.errors import InvalidInput
from deltoctl.profile.files import MAX_PROFILE_BYTES
from deltoctl.record.command_topics import COMMAND_SUFFIX, COMMANDS_TOPIC

MAGIC = b"\x89MCAP0\r\n"
FOOTER_AND_MAGIC = 1 + 8 + 8 + 8 + 4 + 8  # opcode, length, two offsets, crc; the magic
OP_CHUNK, OP_MESSAGE_INDEX, OP_MESSAGE = 0x06, 0x07, 0x05
MESSAGE_HEAD = 1 + 8 + 2 + 4 + 8 + 8  # opcode, length, channel, sequence, log and publish time
DIAGNOSTICS = "/diagnostics"
MAX_WORKERS = 8  # processes that unpack chunks for ``series``
# a chunk unpacked: the recorder writes chunks of 1 MiB, rosbag2 and mcap's tools a few MiB
MAX_CHUNK_BYTES = 64 << 20
MAX_RECORD_BYTES = 2 * MAX_CHUNK_BYTES  # any record as stored: a chunk, compressed or not
# the summary (the index of ~200,000 chunks; an hour's has ~10,000), and the messages a file
# without one keeps in memory (beyond, they are read again): the bound of a profile file
MAX_SUMMARY_BYTES = MAX_KEPT_BYTES = MAX_PROFILE_BYTES
MAX_METADATA_BYTES = 2 * MAX_PROFILE_BYTES  # metadata, channel and schema records: a profile
# is recorded twice (YAML and JSON)
CHUNK_HINT = ("a recording from another tool may use larger chunks: rewrite it with smaller ones "
              "(`mcap compress --chunk-size`, the mcap CLI)")
CHUNKS_PER_WORKER = 64  # fewer chunks than this a process: not worth starting one


# -- CDR -----------------------------------------------------------------------------------------

class Cdr:
    """A cursor over one CDR message (little-endian, XCDR1) starting at ``start`` in ``buf``;
    alignment counts from the end of the 4-byte encapsulation header."""

    def __init__(self, buf: bytes | memoryview, start: int = 0) -> None:
        self.buf = buf
        self.base = start + 4
        self.pos = self.base

    def _align(self, n: int) -> None:
        self.pos += (-(self.pos - self.base)) % n

    def u8(self) -> int:
        self.pos += 1
        return self.buf[self.pos - 1]

    def u32(self) -> int:
        self._align(4)
        (value,) = struct.unpack_from("<I", self.buf, self.pos)
        self.pos += 4
        return int(value)

    def string(self) -> str:
        size = self.u32()
        text = bytes(self.buf[self.pos:self.pos + max(size - 1, 0)]).decode(errors="replace")
        self.pos += size
        return text

    def strings(self) -> list[str]:
        return [self.string() for _ in range(self.u32())]

    def doubles(self, count: int) -> int:
        """Skips ``count`` float64 and returns where the first one is."""
        if count:
            self._align(8)
        at = self.pos
        self.pos += 8 * count
        return at

    def stamp(self) -> int:
        """A std_msgs/Header: its stamp in ns (the frame_id is skipped)."""
        sec = self.u32()
        nanosec = self.u32()
        self.string()
        return (sec - (1 << 32) if sec >= 1 << 31 else sec) * 1_000_000_000 + nanosec


# Where each interface of a message is: [(interface name, offset of its float64)], offsets
# from the start of the message's data (its encapsulation header included).
Layout = list[tuple[str, int]]


def joint_state(c: Cdr, topic: str) -> Layout:
    """/joint_commands' fields are named ``<joint>/position_command`` …, apart from the
    states'."""
    c.stamp()
    names = c.strings()
    layout = []
    suffix = COMMAND_SUFFIX if topic == COMMANDS_TOPIC else ""
    for kind in ("position", "velocity", "effort"):
        count = c.u32()
        at = c.doubles(count)
        layout += [(f"{n}/{kind}{suffix}", at + 8 * i) for i, n in enumerate(names[:count])]
    return layout


def _interface_values(c: Cdr, topic: str) -> Layout:
    """DynamicJointState and DynamicInterfaceGroupValues: names, then InterfaceValue each."""
    c.stamp()
    names = c.strings()
    layout = []
    for name in names[:c.u32()]:
        itfs = c.strings()
        count = c.u32()
        at = c.doubles(count)
        layout += [(f"{name}/{itf}", at + 8 * i) for i, itf in enumerate(itfs[:count])]
    return layout


def _sensor(topic: str) -> str:
    return topic.strip("/").rpartition("/")[0] or topic.strip("/")


def _fixed(fields: tuple[str, ...]) -> Callable[[Cdr, str], Layout]:
    """A message of float64 fields after its header, named after the topic's sensor (None:
    a field skipped)."""
    def layout(c: Cdr, topic: str) -> Layout:
        c.stamp()
        at = c.doubles(len(fields))
        sensor = _sensor(topic)
        return [(f"{sensor}/{f}", at + 8 * i) for i, f in enumerate(fields) if f]
    return layout


_WRENCH = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
_IMU = ("orientation.x", "orientation.y", "orientation.z", "orientation.w", *[""] * 9,
        "angular_velocity.x", "angular_velocity.y", "angular_velocity.z", *[""] * 9,
        "linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z")

LAYOUTS: dict[str, Callable[[Cdr, str], Layout]] = {
    "sensor_msgs/msg/JointState": joint_state,
    "control_msgs/msg/DynamicJointState": _interface_values,
    "control_msgs/msg/DynamicInterfaceGroupValues": _interface_values,
    "geometry_msgs/msg/WrenchStamped": _fixed(_WRENCH),
    "sensor_msgs/msg/Imu": _fixed(_IMU),
}


@dataclass
class Status:
    """One diagnostic_msgs/DiagnosticStatus of /diagnostics."""

    t_ns: int
    level: int
    name: str
    message: str
    hardware_id: str
    values: dict[str, str]


def diagnostic_statuses(data: bytes | memoryview, log_time: int) -> list[Status]:
    c = Cdr(data)
    stamp = c.stamp()
    statuses = []
    for _ in range(c.u32()):
        level, name, message, hardware = c.u8(), c.string(), c.string(), c.string()
        values = {}
        for _ in range(c.u32()):
            key = c.string()
            values[key] = c.string()
        statuses.append(Status(stamp or log_time, level, name, message, hardware, values))
    return statuses


# -- the file ------------------------------------------------------------------------------------

@dataclass
class Channel:
    id: int
    topic: str
    type: str
    metadata: dict[str, str]
    count: int = 0


@dataclass
class Batch:
    """The messages of one channel in one chunk: their times, and where each message record
    starts in ``records`` (the chunk's records, unpacked)."""

    records: bytes
    log_times: array
    offsets: array


@dataclass
class Recording:
    path: Path
    size: int
    indexed: bool
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    messages: int = 0
    chunks: list[Any] = field(default_factory=list)  # mcap ChunkIndex, in time order
    # a file without a summary: the kept channels' messages (None: too many, read again)
    _scanned: dict[int, list[tuple[int, bytes]]] | None = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return max(self.end_ns - self.start_ns, 0) / 1e9

    def channel(self, topic: str) -> Channel | None:
        return next((c for c in self.channels.values() if c.topic == topic), None)

    def compressions(self) -> list[str]:
        return sorted({c.compression or "none" for c in self.chunks})

    def chunks_of(self, channel_id: int, start_ns: int | None = None,
                  end_ns: int | None = None) -> list[Any]:
        """The chunks that hold the channel's messages and overlap [start_ns, end_ns]."""
        return [c for c in self.chunks if channel_id in c.message_index_offsets and
                (start_ns is None or c.message_end_time >= start_ns) and
                (end_ns is None or c.message_start_time <= end_ns)]

    def batches(self, channel_id: int, start_ns: int | None = None,
                end_ns: int | None = None) -> Iterator[Batch]:
        """The channel's messages chunk by chunk (an indexed file), in time order."""
        yield from _batches(self.path, self.chunks_of(channel_id, start_ns, end_ns), channel_id)

    def read(self, channel_id: int) -> Iterator[tuple[int, memoryview]]:
        """(log time, data) of each message of a channel, in time order."""
        if not self.indexed:
            kept = None if self._scanned is None else self._scanned.get(channel_id)
            if kept is None:
                yield from _stream_channel(self.path, channel_id)
                return
            for t, data in kept:
                yield t, memoryview(data)
            return
        for batch in self.batches(channel_id):
            for t, at in zip(batch.log_times, batch.offsets):
                yield t, _data(batch.records, at)


def damaged(path: Path, what: str) -> InvalidInput:
    return InvalidInput(f"{path} is damaged: {what}",
                        "a copy cut short or a disk error; `mcap recover` (the mcap CLI) "
                        "rebuilds what it can")


def open_recording(path: Path, keep: Iterable[str] | None = (DIAGNOSTICS,)) -> Recording:
    """The recording's summary and metadata. ``keep``: the topics whose messages a file
    without a summary keeps while it is read whole (None: all; an indexed file reads them on
    demand)."""
    path = _the_file(path)
    with path.open("rb") as f:
        size = _check_ends(f, path)
        from mcap.reader import SeekingReader

        _check_summary_size(f, path, size)
        try:
            reader = SeekingReader(f, record_size_limit=MAX_RECORD_BYTES)
            summary = reader.get_summary()
            if summary is None:
                return _scan(f, path, size, None if keep is None else set(keep))
            recording = Recording(path, size, True)
            stats = summary.statistics
            counts = stats.channel_message_counts if stats else {}
            for cid, ch in summary.channels.items():
                schema = summary.schemas.get(ch.schema_id)
                recording.channels[cid] = Channel(cid, ch.topic, schema.name if schema else "",
                                                  dict(ch.metadata), counts.get(cid, 0))
            recording.metadata = _metadata(f, path, summary.metadata_indexes)
        except InvalidInput:
            raise
        except Exception as exc:  # mcap's errors, struct's, a record cut short: one sentence
            raise damaged(path, f"{type(exc).__name__}: {exc}") from None
    recording.chunks = sorted(summary.chunk_indexes, key=lambda c: c.message_start_time)
    if stats is not None:
        recording.messages = stats.message_count
        recording.start_ns, recording.end_ns = stats.message_start_time, stats.message_end_time
    return recording


def _the_file(path: Path) -> Path:
    """The MCAP file: ``path``, or the one .mcap in a rosbag2 directory."""
    if path.is_dir():
        found = sorted(path.glob("*.mcap"))
        if len(found) != 1:
            raise InvalidInput(f"{path} is a directory with {len(found)} .mcap files; "
                               "name the file")
        return found[0]
    if not path.exists():
        raise InvalidInput(f"{path}: no such file")
    return path


def _check_ends(f: BinaryIO, path: Path) -> int:
    """The file starts and ends as an MCAP file does; returns its size."""
    try:
        size = f.seek(0, 2)
        f.seek(0)
        head = f.read(len(MAGIC))
        if size >= FOOTER_AND_MAGIC + len(MAGIC):
            f.seek(-len(MAGIC), 2)
            tail = f.read(len(MAGIC))
        else:
            tail = b""
        f.seek(0)
    except OSError as exc:
        raise InvalidInput(f"cannot read {path}: {exc.strerror or exc}") from None
    if size == 0:
        raise InvalidInput(f"{path} is empty, not an MCAP recording")
    if head != MAGIC:
        raise InvalidInput(f"{path} is not an MCAP file (it does not start with MCAP's "
                           "magic bytes)")
    if tail != MAGIC:
        raise InvalidInput(f"{path} is truncated: it does not end as an MCAP file does "
                           f"({size} bytes; cut while copied, or the disk filled up?)",
                           "`mcap recover` (the mcap CLI) rebuilds what it can")
    return size


def _check_summary_size(f: BinaryIO, path: Path, size: int) -> None:
    """The footer's summary start, checked before mcap's reader reads the summary whole."""
    f.seek(size - FOOTER_AND_MAGIC + 9)  # the footer's opcode and length, then the start
    (start,) = struct.unpack("<Q", f.read(8))
    if start and size - start > MAX_SUMMARY_BYTES:
        raise InvalidInput(f"{path}: its summary is {size - start} bytes, more than the "
                           f"{MAX_SUMMARY_BYTES >> 20} MiB deltoctl reads (an index of about "
                           "200,000 chunks)")
    f.seek(0)


def _metadata(f: BinaryIO, path: Path, indexes: list[Any]) -> dict[str, dict[str, str]]:
    """The metadata records the summary points to, each read after its length is checked
    against what is left of MAX_METADATA_BYTES (a summary may point many times at one)."""
    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Metadata

    found: dict[str, dict[str, str]] = {}
    left = MAX_METADATA_BYTES
    for index in indexes:
        f.seek(index.offset)
        opcode, length = struct.unpack("<BQ", f.read(9))
        if opcode != Opcode.METADATA:
            raise damaged(path, f"no metadata record at byte {index.offset}")
        left -= length
        if left < 0:
            raise InvalidInput(f"{path}: metadata records of more than "
                               f"{MAX_METADATA_BYTES >> 20} MiB (the metadata at byte "
                               f"{index.offset}); deltoctl reads no more")
        record = Metadata.read(ReadDataStream(io.BytesIO(f.read(length))))
        found[record.name] = dict(record.metadata)
    return found


def _batches(path: Path, chunks: list[Any], channel_id: int) -> Iterator[Batch]:
    """One batch a chunk, unpacked straight from the file mapped in memory (no copy)."""
    import contextlib
    import mmap

    with path.open("rb") as f:
        mapped = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    whole = memoryview(mapped)
    try:
        for chunk in chunks:
            end = chunk.chunk_start_offset + chunk.chunk_length + chunk.message_index_length
            if end > len(mapped):
                raise damaged(path, f"it ends inside the chunk at byte {chunk.chunk_start_offset}")
            try:
                batch = _batch(whole[chunk.chunk_start_offset:end], chunk, channel_id, path)
            except (struct.error, IndexError, ValueError, UnicodeDecodeError) as exc:
                raise damaged(path, f"the chunk at byte {chunk.chunk_start_offset}: "
                                     f"{type(exc).__name__}: {exc}") from None
            yield batch
    finally:
        whole.release()
        with contextlib.suppress(BufferError):  # a view an error's traceback holds: GC closes it
            mapped.close()


def _batch(raw: memoryview, chunk: Any, channel_id: int, path: Path) -> Batch:
    """The channel's messages in a chunk (``raw``: the chunk and its message indexes)."""
    if raw[0] != OP_CHUNK:
        raise damaged(path, f"no chunk at byte {chunk.chunk_start_offset}")
    pos = 9 + 8 + 8  # opcode, length, start and end time
    uncompressed_size, _crc, name_length = struct.unpack_from("<QII", raw, pos)
    pos += 16
    compression = bytes(raw[pos:pos + name_length]).decode()
    pos += name_length
    (length,) = struct.unpack_from("<Q", raw, pos)
    records = _unpack(raw[pos + 8:pos + 8 + length], compression, uncompressed_size, path,
                      chunk.chunk_start_offset)
    at = chunk.message_index_offsets[channel_id] - chunk.chunk_start_offset
    if raw[at] != OP_MESSAGE_INDEX:
        raise damaged(path, f"no message index at byte {chunk.message_index_offsets[channel_id]}")
    (entries,) = struct.unpack_from("<I", raw, at + 9 + 2)
    if entries % 16 or entries // 16 > len(records) // MESSAGE_HEAD:
        raise damaged(path, f"the message index at byte {chunk.message_index_offsets[channel_id]}"
                             f" lists more messages than its chunk holds")
    pairs = array("Q")
    pairs.frombytes(raw[at + 15:at + 15 + entries])
    if sys.byteorder == "big":
        pairs.byteswap()
    offsets = pairs[1::2]
    if offsets and max(offsets) > len(records) - MESSAGE_HEAD:
        raise damaged(path, f"the message index at byte {chunk.message_index_offsets[channel_id]}"
                             " points past the end of its chunk")
    return Batch(records, pairs[0::2], offsets)


def _unpack(data: memoryview, compression: str, size: int, path: Path, at: int) -> bytes:
    """A chunk's records: exactly the ``size`` bytes it declares, at most MAX_CHUNK_BYTES,
    refused before they are allocated, and never more however the frame lies."""
    if size > MAX_CHUNK_BYTES:
        raise InvalidInput(f"{path}: the chunk at byte {at} declares {size} bytes unpacked, more "
                           f"than the {MAX_CHUNK_BYTES >> 20} MiB deltoctl unpacks", CHUNK_HINT)
    try:
        records = _decompress(data, compression, size, path)
    except (RuntimeError, ValueError, MemoryError) as exc:  # lz4's, zstandard's ZstdError
        raise damaged(path, f"the chunk at byte {at} does not unpack: {exc}") from None
    if len(records) != size:
        more = "more" if len(records) > size else "fewer"
        raise InvalidInput(f"{path}: the chunk at byte {at} unpacks to {more} than the {size} "
                           "bytes it declares; deltoctl reads no further",
                           "a damaged or forged recording")
    return records


def _decompress(data: memoryview, compression: str, size: int, path: Path) -> bytes:
    """Up to ``size`` + 1 bytes of the frame: one past tells a frame larger than declared."""
    if compression == "lz4":
        import lz4.frame

        return cast(bytes, lz4.frame.LZ4FrameDecompressor().decompress(  # lz4 has no types
            data, max_length=size + 1))
    if compression == "zstd":
        import zstandard

        # the window a streamed frame asks for is bounded too; read() fills what it can
        reader = zstandard.ZstdDecompressor(max_window_size=MAX_CHUNK_BYTES).stream_reader(data)
        parts, got = [], 0
        while got <= size:
            part = reader.read(size + 1 - got)
            if not part:
                break
            parts.append(part)
            got += len(part)
        return b"".join(parts)
    if compression == "":
        return bytes(data[:size + 1])
    raise InvalidInput(f"{path}: chunks compressed with {compression!r}, which deltoctl "
                       "cannot unpack (lz4, zstd or none)")


def _scan(f: BinaryIO, path: Path, size: int, keep: set[str] | None) -> Recording:
    """A file without a summary, read record by record: channels, counts, times, metadata,
    and the messages of the ``keep`` topics while they fit in MAX_KEPT_BYTES (past that, a
    channel's messages are read from the file again when asked for)."""
    from mcap.records import Channel as McapChannel
    from mcap.records import Message, Metadata, Schema

    recording = Recording(path, size, False)
    schemas: dict[int, str] = {}
    first, last = None, 0
    kept, described = 0, 0
    for record in _records(f, path):
        if isinstance(record, Message):
            channel = recording.channels.get(record.channel_id)
            if channel is None:
                continue
            channel.count += 1
            first = record.log_time if first is None else min(first, record.log_time)
            last = max(last, record.log_time)
            scanned = recording._scanned
            if scanned is not None and channel.id in scanned:
                kept += len(record.data) + MESSAGE_HEAD
                if kept > MAX_KEPT_BYTES:
                    recording._scanned = None  # too many to hold: read again on demand
                else:
                    scanned[channel.id].append((record.log_time, record.data))
            continue
        described += _described_size(record)
        if described > MAX_METADATA_BYTES:
            raise InvalidInput(f"{path}: metadata, channel and schema records of more than "
                               f"{MAX_METADATA_BYTES >> 20} MiB; deltoctl reads no more")
        if isinstance(record, Schema):
            schemas[record.id] = record.name
        elif isinstance(record, McapChannel):
            recording.channels[record.id] = Channel(
                record.id, record.topic, schemas.get(record.schema_id, ""),
                dict(record.metadata))
            if recording._scanned is not None and (keep is None or record.topic in keep):
                recording._scanned.setdefault(record.id, [])
        elif isinstance(record, Metadata):
            recording.metadata[record.name] = dict(record.metadata)
    recording.messages = sum(c.count for c in recording.channels.values())
    recording.start_ns, recording.end_ns = first or 0, last
    return recording


def _described_size(record: Any) -> int:
    """About the memory a schema, channel or metadata record's strings are kept in."""
    texts = [getattr(record, name, "") for name in ("name", "topic")]
    texts += [x for kv in (getattr(record, "metadata", None) or {}).items() for x in kv]
    return sum(len(t) for t in texts if isinstance(t, str)) + 64


def _records(f: BinaryIO, path: Path) -> Iterator[Any]:
    """The file's records in order (mcap's reader checks each CRC), each chunk unpacked by
    ``_unpack`` and its records given in its place."""
    from mcap.exceptions import RecordLengthLimitExceeded
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    f.seek(0)
    reader = StreamReader(f, emit_chunks=True, validate_crcs=True,
                          record_size_limit=MAX_RECORD_BYTES)
    try:
        for record in reader.records:
            if isinstance(record, Chunk):
                # where the chunk starts: the reader has just read it (and nothing past it)
                at = f.tell() - 9 - 8 * 4 - 4 - len(record.compression.encode()) - 4 - \
                    len(record.data)
                yield from _chunk_records(record, path, at)
            else:
                yield record
    except RecordLengthLimitExceeded as exc:
        raise InvalidInput(f"{path}: {exc} (deltoctl reads records of at most "
                           f"{MAX_RECORD_BYTES >> 20} MiB)", CHUNK_HINT) from None


def _chunk_records(chunk: Any, path: Path, at: int) -> Iterator[Any]:
    """The schema, channel and message records of a chunk, one at a time."""
    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Channel as McapChannel
    from mcap.records import Message, Schema

    data = _unpack(memoryview(chunk.data), chunk.compression, chunk.uncompressed_size, path, at)
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise damaged(path, f"the chunk at byte {at} fails its CRC check")
    stream = ReadDataStream(io.BytesIO(data))
    while stream.count < len(data):
        opcode, length = stream.read1(), stream.read8()
        if opcode == Opcode.MESSAGE:
            yield Message.read(stream, length)
        elif opcode == Opcode.CHANNEL:
            yield McapChannel.read(stream)
        elif opcode == Opcode.SCHEMA:
            yield Schema.read(stream)
        else:
            stream.read(length)


def _stream_channel(path: Path, channel_id: int) -> Iterator[tuple[int, memoryview]]:
    """(log time, data) of each message of a channel, the file read again from its start."""
    from mcap.records import Message

    with path.open("rb") as f:
        for record in _records(f, path):
            if isinstance(record, Message) and record.channel_id == channel_id:
                yield record.log_time, memoryview(record.data)


def read_recording(path: Path, keep: Iterable[str] | None = (DIAGNOSTICS,)) -> Recording:
    """``open_recording`` with the errors of a file read half-way said as damage."""
    try:
        return open_recording(path, keep)
    except InvalidInput:
        raise
    except Exception as exc:
        raise damaged(path, f"{type(exc).__name__}: {exc}") from None


# -- info ----------------------------------------------------------------------------------------

def _json_or_text(text: str) -> Any:
    try:
        return json.loads(text)
    except ValueError:
        return text  # an older recording wrote a Python repr


def describe(path: Path) -> dict[str, Any]:
    """What `deltoctl info` reports: times, blocks, topics, link losses, gaps, the loop."""
    rec = read_recording(path)
    statuses = _statuses(rec)
    link_losses, gaps = _link_losses(statuses, rec.end_ns), _gaps(statuses)
    duration = rec.duration_s
    topics = [{"topic": c.topic, "type": c.type, "messages": c.count,
               "rate_hz": round(c.count / duration, 3) if duration else None,
               "type_hash": c.metadata.get("topic_type_hash") or None}
              for c in sorted(rec.channels.values(), key=lambda c: c.id)]
    meta = rec.metadata
    rosbag2 = None
    if "rosbag2" in meta:
        import yaml

        bag = yaml.safe_load(meta["rosbag2"].get("serialized_metadata", "")) or {}
        rosbag2 = {"version": bag.get("version"),
                   "storage_identifier": bag.get("storage_identifier")}
    return {
        "file": str(rec.path), "bytes": rec.size, "indexed": rec.indexed,
        "start_ns": rec.start_ns, "end_ns": rec.end_ns, "duration_s": round(duration, 6),
        "messages": rec.messages, "compression": rec.compressions(), "chunks": len(rec.chunks),
        "profile": _profile(meta.get("profile", {})),
        "blocks": _blocks(meta),
        "topics": topics,
        "link_losses": link_losses,
        "gaps": gaps,
        "loop": _loop(meta, statuses),
        "buses": _buses(statuses),
        "deltoctl": meta.get("deltoctl", {}).get("version"),
        "rosbag2": rosbag2,
    }


def _statuses(rec: Recording) -> list[Status]:
    channel = rec.channel(DIAGNOSTICS)
    if channel is None:
        return []
    found = []
    for t, data in rec.read(channel.id):
        try:
            found += diagnostic_statuses(data, t)
        except (struct.error, IndexError):
            continue  # a message that is not a DiagnosticArray: not ours to explain
    return found


def _link_losses(statuses: list[Status], end_ns: int) -> list[dict[str, Any]]:
    """Each "link lost" with the "link restored" after it (None: lost until the end)."""
    losses: list[dict[str, Any]] = []
    for s in statuses:
        if s.name != "deltoctl/link":
            continue
        if s.message == "link lost":
            blocks = [b for b in s.values.get("blocks_down", "").split(",") if b]
            losses.append({"lost_ns": s.t_ns, "restored_ns": None, "blocks": blocks,
                           "seconds": None})
        elif s.message == "link restored" and losses and losses[-1]["restored_ns"] is None:
            losses[-1]["restored_ns"] = s.t_ns
    for loss in losses:
        until = loss["restored_ns"] if loss["restored_ns"] is not None else end_ns
        loss["seconds"] = round(max(until - loss["lost_ns"], 0) / 1e9, 6)
    return losses


def _gaps(statuses: list[Status]) -> list[dict[str, Any]]:
    gaps = []
    for s in statuses:
        if s.name == "deltoctl/gap":
            try:
                start, end = int(s.values["start_ns"]), int(s.values["end_ns"])
            except (KeyError, ValueError):
                continue
            gaps.append({"start_ns": start, "end_ns": end, "seconds": round((end - start) / 1e9,
                                                                              6)})
    return gaps


def _number(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _loop(meta: dict[str, dict[str, str]], statuses: list[Status]) -> dict[str, Any] | None:
    """The loop's final statistics: the ``recording`` metadata, else the last loop status."""
    record = meta.get("recording")
    if record and "json" in record:
        loop = _json_or_text(record["json"])
        if isinstance(loop, dict) and isinstance(loop.get("loop"), dict):
            return dict(loop["loop"])
    if record:
        return {k: _number(v) for k, v in record.items() if k not in ("link_losses", "gaps")}
    last = [s for s in statuses if s.name == "deltoctl/loop"]
    return {k: _number(v) for k, v in last[-1].values.items()} if last else None


def _buses(statuses: list[Status]) -> dict[str, dict[str, Any]]:
    """Each bus loop's last report (the MH5's sync loops)."""
    return {s.name.removeprefix("deltoctl/"): {k: _number(v) for k, v in s.values.items()}
            for s in statuses if s.message == "bus loop"}


def _profile(record: dict[str, str]) -> dict[str, Any] | None:
    if not record:
        return None
    data = _json_or_text(record.get("json", "")) if record.get("json") else {}
    profile = {"name": record.get("name") or (data.get("name") if isinstance(data, dict)
                                              else None)}
    if isinstance(data, dict):
        profile.update({k: data[k] for k in ("description", "family", "model") if k in data})
    return profile


def _blocks(meta: dict[str, dict[str, str]]) -> list[dict[str, Any]]:
    """The profile's blocks with what each identified itself as."""
    profile = _json_or_text(meta.get("profile", {}).get("json", "null") or "null")
    identities = {name: _json_or_text(text) for name, text in meta.get("identify", {}).items()}
    blocks = []
    names = [b.get("name") for b in profile.get("ros2_control", [])] \
        if isinstance(profile, dict) else []
    for name in names + [n for n in identities if n not in names]:
        spec = next((b for b in profile.get("ros2_control", []) if b.get("name") == name), {}) \
            if isinstance(profile, dict) else {}
        identity = identities.get(name)
        block = {"name": name, "plugin": spec.get("plugin"), "bus": spec.get("bus")}
        if isinstance(identity, dict):
            block.update(family=identity.get("family"), target=identity.get("target"),
                         identity={k: v for k, v in identity.items()
                                   if k not in ("family", "target")})
        elif identity is not None:
            block["identity"] = identity
        blocks.append(block)
    return blocks


# -- series --------------------------------------------------------------------------------------

def interfaces(rec: Recording) -> dict[str, int]:
    """Every interface the recording carries → the channel it is read from (the first
    channel that carries it: /joint_states before /dynamic_joint_states)."""
    found: dict[str, int] = {}
    for channel in sorted(rec.channels.values(), key=lambda c: c.id):
        layout_of = LAYOUTS.get(channel.type)
        if layout_of is None or not channel.count:
            continue
        first = next(rec.read(channel.id), None)  # the first chunk only
        if first is None:
            continue
        try:
            layout = layout_of(Cdr(first[1]), channel.topic)
        except (struct.error, IndexError):
            continue
        for name, _ in layout:
            found.setdefault(name, channel.id)
    return found


def _data(records: bytes, at: int) -> memoryview:
    (length,) = struct.unpack_from("<Q", records, at + 1)
    return memoryview(records)[at + MESSAGE_HEAD:at + 9 + length]


def select(available: Iterable[str], patterns: list[str]) -> list[str]:
    """The interfaces that match any of the globs, in the recording's order."""
    return [name for name in available
            if any(fnmatch.fnmatchcase(name, p) for p in patterns)]


def keep_freed_memory() -> None:
    """Each chunk is unpacked into a fresh megabyte; glibc would give each back to the kernel
    when freed and fault it in again, 4 KiB at a time: half the time of an hour's plot. Told
    to keep what is freed (up to 256 MiB), it hands the same pages out again. glibc only."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(-1, 256 << 20)  # M_TRIM_THRESHOLD
        libc.mallopt(-3, 64 << 20)  # M_MMAP_THRESHOLD: a chunk comes from the heap
    except (OSError, AttributeError):
        pass  # another C library: slower, not wrong


def series(rec: Recording, wanted: list[str], start_ns: int | None = None,
           end_ns: int | None = None) -> dict[str, tuple[Any, Any]]:
    """{interface: (times in ns, values)} as numpy arrays, reading only the channels that
    carry them (and, in an indexed file, only the chunks that overlap the time window)."""
    import numpy as np

    where = interfaces(rec)
    by_channel: dict[int, list[str]] = {}
    for name in wanted:
        by_channel.setdefault(where[name], []).append(name)
    result = {}
    for cid, names in by_channel.items():
        channel = rec.channels[cid]
        parts = _indexed_parts(rec, channel, names, start_ns, end_ns) if rec.indexed \
            else _scanned_parts(rec, channel, LAYOUTS[channel.type], names)
        for name in names:
            times = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
            values = np.concatenate([p[1][name] for p in parts]) if parts else np.zeros(0)
            window = np.ones(len(times), bool)
            if start_ns is not None:
                window &= times >= start_ns
            if end_ns is not None:
                window &= times <= end_ns
            result[name] = (times[window], values[window])
    return result


def sampled_series(rec: Recording, wanted: list[str], points: int
                   ) -> dict[str, tuple[list[int], list[float]]]:
    """{interface: (times in ns, values)} as lists, about ``points`` of each taken evenly
    through the recording (every n-th message), with the standard library alone: what a
    figure draws, on an install without numpy."""
    where = interfaces(rec)
    by_channel: dict[int, list[str]] = {}
    for name in wanted:
        by_channel.setdefault(where[name], []).append(name)
    result: dict[str, tuple[list[int], list[float]]] = {}
    for cid, names in by_channel.items():
        channel = rec.channels[cid]
        layout_of = LAYOUTS[channel.type]
        every = max(1, channel.count // max(points, 1)) if channel.count else 1
        layouts: dict[int, dict[str, int]] = {}  # by message length: one shape each
        times: list[int] = []
        values: dict[str, list[float]] = {n: [] for n in names}
        for i, (t, data) in enumerate(rec.read(cid)):
            if i % every:
                continue
            layout = layouts.get(len(data))
            if layout is None:
                layout = layouts[len(data)] = dict(layout_of(Cdr(data), channel.topic))
            times.append(int(t))
            for name in names:
                values[name].append(struct.unpack_from("<d", data, layout[name])[0]
                                    if name in layout else math.nan)
        for name in names:
            result[name] = (times, values[name])
    return result


def _indexed_parts(rec: Recording, channel: Channel, names: list[str], start_ns: int | None,
                   end_ns: int | None) -> list[tuple[Any, dict[str, Any]]]:
    """The chunks unpacked by a process per CPU (LZ4 is most of the time), each a stretch of
    them in time order."""
    chunks = rec.chunks_of(channel.id, start_ns, end_ns)
    workers = min(os.cpu_count() or 1, MAX_WORKERS, len(chunks) // CHUNKS_PER_WORKER)
    job = (rec.path, channel.id, channel.type, channel.topic, names)
    if workers <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        return [_extract(chunks, *job)]
    from concurrent.futures import ProcessPoolExecutor

    share = -(-len(chunks) // workers)
    stretches = [chunks[i:i + share] for i in range(0, len(chunks), share)]
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
        return list(pool.map(_extract, stretches, *[[x] * len(stretches) for x in job]))


def _extract(chunks: list[Any], path: Path, channel_id: int, type_name: str, topic: str,
             names: list[str]) -> tuple[Any, dict[str, Any]]:
    """Per chunk, each interface's values taken at their offsets in every message of the
    first message's length at once; joined."""
    import numpy as np

    layout_of = LAYOUTS[type_name]
    eight = np.arange(8)
    times_parts: list[Any] = []  # numpy arrays, joined at the end
    value_parts: dict[str, list[Any]] = {n: [] for n in names}
    for batch in _batches(path, chunks, channel_id):
        if not len(batch.offsets):
            continue
        raw = np.frombuffer(batch.records, np.uint8)
        offsets = np.frombuffer(batch.offsets, np.uint64).astype(np.int64)
        lengths = raw[(offsets + 1)[:, None] + eight].view("<u8").ravel()
        layout = dict(layout_of(Cdr(_data(batch.records, int(offsets[0]))), topic))
        same = lengths == lengths[0]
        data_at = offsets + MESSAGE_HEAD
        times_parts.append(np.frombuffer(batch.log_times, np.uint64).astype(np.int64))
        for name in names:
            column = np.full(len(offsets), np.nan)
            if name in layout:
                picked = data_at[same] + layout[name]
                column[same] = raw[picked[:, None] + eight].view("<f8").ravel()
            value_parts[name].append(column)
        for i in np.flatnonzero(~same):  # a message of another shape: decoded on its own
            own = dict(layout_of(Cdr(_data(batch.records, int(offsets[i]))), topic))
            for name in names:
                value_parts[name][-1][i] = struct.unpack_from(
                    "<d", batch.records, int(data_at[i]) + own[name])[0] \
                    if name in own else np.nan
    if not times_parts:
        return np.zeros(0, np.int64), {n: np.zeros(0) for n in names}
    return np.concatenate(times_parts), {n: np.concatenate(v) for n, v in value_parts.items()}


def _scanned_parts(rec: Recording, channel: Channel, layout_of: Callable[[Cdr, str], Layout],
                   names: list[str]) -> list[tuple[Any, dict[str, Any]]]:
    import numpy as np

    times: list[int] = []
    values: dict[str, list[float]] = {n: [] for n in names}
    for t, data in rec.read(channel.id):
        layout = dict(layout_of(Cdr(data), channel.topic))
        times.append(t)
        for name in names:
            values[name].append(struct.unpack_from("<d", data, layout[name])[0]
                                if name in layout else float("nan"))
    if not times:
        return []
    return [(np.array(times, np.int64), {n: np.array(v) for n, v in values.items()})]
