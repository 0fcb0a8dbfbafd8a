"""A cycle's messages into the chunk of mcap's ``Writer`` in one write.

mcap's ``Writer.add_message`` builds a record object and makes a dozen small writes and
bookkeeping calls per message (~4 µs): a recording of four hands, 23 messages a cycle, spent
most of its process's CPU there. Here a cycle's Message records, headers and CDR alike, come
out of one ``pack`` (``cycle_layout``), and ``CycleAppender`` appends them to the chunk in
progress at once, keeping the Writer's message index and statistics as ``add_message`` would:
the file is the same, byte for byte. It reaches into the Writer's private state, so
``CycleAppender.of`` gives None for a writer it does not know, and the recorder then adds
messages one by one.
"""

from __future__ import annotations

import struct
import sys
from array import array
from itertools import chain
from typing import Any

from mcap.records import MessageIndex

from deltoctl.record.cdr import IntFields

# A Message record's head: opcode, length, channel id, sequence, log time, publish time
HEAD = struct.Struct("<BQHIQQ")
MESSAGE_OPCODE = 0x05
MESSAGE_INDEX_OPCODE = 0x07
HEAD_FIELDS = 6


def cycle_layout(layouts: list[struct.Struct]) -> tuple[struct.Struct, list[int]]:
    """One little-endian struct of a Message record per layout, in order, and where each
    record starts. It packs, per record, the head's fields (opcode, length, channel,
    sequence, log time, publish time), then the layout's values."""
    tokens, starts, runs, at, values = ["<"], [], [], 0, 0
    for layout in layouts:
        if not layout.format.startswith("<"):
            raise ValueError(f"a CDR layout is little-endian and unaligned: {layout.format}")
        tokens += [HEAD.format[1:], layout.format[1:]]
        starts.append(at)
        at += HEAD.size + layout.size
        values += HEAD_FIELDS
        for start, end, lo, hi in getattr(layout, "runs", ()):
            runs.append((values + start, values + end, lo, hi))
        values += len(struct.unpack(layout.format, bytes(layout.size)))
    fmt = "".join(tokens)
    return (IntFields(fmt, runs) if runs else struct.Struct(fmt)), starts


def head_values(layout: struct.Struct, channel: int) -> tuple[int, int, int]:
    """A record's constant head fields for a message of ``layout`` on ``channel``."""
    return MESSAGE_OPCODE, HEAD.size - 9 + layout.size, channel


class FastMessageIndex(MessageIndex):
    """A MessageIndex record written in one piece (mcap's writes each entry as two calls)."""

    def write(self, stream: Any) -> None:
        entries = array("Q", chain.from_iterable(self.records))
        if sys.byteorder != "little":
            entries.byteswap()
        stream.write(struct.pack("<BQHI", MESSAGE_INDEX_OPCODE, 6 + 16 * len(self.records),
                                 self.channel_id, 16 * len(self.records)))
        stream.write(entries.tobytes())


class CycleAppender:
    """Appends a cycle's Message records (one log time) to a ``mcap.writer.Writer``'s chunk."""

    def __init__(self, writer: Any) -> None:
        self.builder = writer._Writer__chunk_builder
        self.statistics = writer._Writer__statistics
        self.chunk_size = writer._Writer__chunk_size
        self.end_chunk_if_full = writer._Writer__maybe_finalize_chunk
        self.records = self.builder.record_writer
        self.indices = self.builder.message_indices
        self.counts = self.statistics.channel_message_counts
        # the channels last appended to, the first one's index and each one's index's
        # records.append: valid while the chunk in progress is the same
        self._entries: tuple[list[int], MessageIndex, list[Any]] | None = None
        for owner, names in ((self.records, ("count", "write")),
                             (self.builder, ("num_messages", "message_start_time",
                                             "message_end_time")),
                             (self.statistics, ("message_count", "message_start_time",
                                                "message_end_time"))):
            for name in names:
                getattr(owner, name)  # AttributeError: not the Writer this was made for

    @classmethod
    def of(cls, writer: Any) -> CycleAppender | None:
        """The appender for mcap's own chunked Writer; None for anything else."""
        if type(writer).__module__ != "mcap.writer":  # the live view's, or another
            return None
        from mcap.writer import Writer

        if type(writer) is not Writer:
            return None
        try:
            appender = cls(writer)
        except AttributeError:  # another release of mcap keeps its state otherwise
            return None
        return appender if appender.builder is not None else None

    def append(self, t_ns: int, channels: list[int], starts: list[int], cycle: bytes) -> None:
        """The Message records of ``cycle`` (the one of ``channels[i]`` at ``starts[i]``) in
        the chunk in progress. Where they take it past its size, one by one, the chunk ended
        after the record that does, as mcap ends it."""
        if self.records.count + len(cycle) <= self.chunk_size:  # nearly always
            self._add(t_ns, channels, starts, cycle)
            return
        ends = [*starts[1:], len(cycle)]
        for channel, start, end in zip(channels, starts, ends):
            self._add(t_ns, [channel], [0], cycle[start:end])
            self.end_chunk_if_full()

    def _add(self, t_ns: int, channels: list[int], starts: list[int], cycle: bytes) -> None:
        records = self.records
        at = records.count
        indices, counts = self.indices, self.counts
        entries = self._entries
        if entries is None or entries[0] is not channels or \
                indices.get(channels[0]) is not entries[1]:  # a new chunk, or other channels
            entries = self._entries = (channels, self._index(channels[0]),
                                       [self._index(c).records.append for c in channels])
        for add, start in zip(entries[2], starts):
            add((t_ns, at + start))
        for channel in channels:
            counts[channel] += 1
        records.write(cycle)
        n = len(channels)
        stats, chunk = self.statistics, self.builder
        stats.message_start_time = t_ns if stats.message_count == 0 else \
            min(t_ns, stats.message_start_time)
        stats.message_end_time = max(t_ns, stats.message_end_time)
        stats.message_count += n
        chunk.message_start_time = t_ns if chunk.num_messages == 0 else \
            min(t_ns, chunk.message_start_time)
        chunk.message_end_time = max(t_ns, chunk.message_end_time)
        chunk.num_messages += n

    def _index(self, channel: int) -> MessageIndex:
        """The channel's message index in the chunk in progress (made, when it has none)."""
        index = self.indices.get(channel)
        if index is None:
            self.indices[channel] = index = FastMessageIndex(channel, [])
        return index
