"""A cycle's messages into the chunk of mcap's ``Writer`` in one write.

mcap's ``Writer.add_message`` builds a record object and makes a dozen small writes and
bookkeeping calls per message (~4 µs): a recording of four hands, 23 messages a cycle, spent
most of its process's CPU there. ``CycleAppender`` lays out every Message record of a cycle
with one ``pack`` each, appends them to the chunk in progress at once and keeps the Writer's
chunk index and statistics as ``add_message`` would, so the file is the same, byte for byte.
It reaches into the Writer's private state: ``CycleAppender.of`` gives None for a writer that
is not the one it knows, and the recorder then adds messages one by one.
"""

from __future__ import annotations

import struct
import sys
from array import array
from itertools import chain
from typing import Any

from mcap.records import MessageIndex

# A Message record: opcode, length, channel id, sequence, log time, publish time, then data
HEAD = struct.Struct("<BQHIQQ")
MESSAGE_OPCODE = 0x05
MESSAGE_INDEX_OPCODE = 0x07
HEAD_FIELDS = HEAD.size - 9  # the record's length counts what follows opcode and length


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
    """Appends one cycle's messages (same log time) to a ``mcap.writer.Writer``'s chunk."""

    def __init__(self, writer: Any) -> None:
        self.builder = writer._Writer__chunk_builder
        self.statistics = writer._Writer__statistics
        self.chunk_size = writer._Writer__chunk_size
        self.end_chunk_if_full = writer._Writer__maybe_finalize_chunk
        self.records = self.builder.record_writer
        self.indices = self.builder.message_indices
        self.counts = self.statistics.channel_message_counts
        for owner, names in ((self.records, ("count", "write")),
                             (self.builder, ("num_messages", "message_start_time")),
                             (self.statistics, ("message_count", "message_start_time"))):
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

    def append(self, t_ns: int, channels: list[int], sequences: list[int],
               datas: list[bytes]) -> None:
        """The messages (one per channel) in the chunk in progress. Where they take it past
        its size, one by one, the chunk ended after the message that does, as mcap ends it."""
        size = sum(map(len, datas)) + HEAD.size * len(datas)
        if self.records.count + size <= self.chunk_size:  # nearly always
            self._add(t_ns, channels, sequences, datas)
            return
        for message in zip(channels, sequences, datas):
            self._add(t_ns, *([part] for part in message))
            self.end_chunk_if_full()

    def _add(self, t_ns: int, channels: list[int], sequences: list[int],
             datas: list[bytes]) -> None:
        records = self.records
        at = records.count
        indices, counts, parts = self.indices, self.counts, []
        pack, add = HEAD.pack, parts.append
        for channel, sequence, data in zip(channels, sequences, datas):
            index = indices.get(channel)
            if index is None:
                indices[channel] = index = FastMessageIndex(channel, [])
            index.records.append((t_ns, at))
            size = len(data)
            add(pack(MESSAGE_OPCODE, HEAD_FIELDS + size, channel, sequence, t_ns, t_ns))
            add(data)
            at += HEAD.size + size
            counts[channel] += 1
        records.write(b"".join(parts))
        n = len(datas)
        stats, chunk = self.statistics, self.builder
        stats.message_start_time = t_ns if stats.message_count == 0 else \
            min(t_ns, stats.message_start_time)
        stats.message_end_time = max(t_ns, stats.message_end_time)
        stats.message_count += n
        chunk.message_start_time = t_ns if chunk.num_messages == 0 else \
            min(t_ns, chunk.message_start_time)
        chunk.message_end_time = max(t_ns, chunk.message_end_time)
        chunk.num_messages += n
