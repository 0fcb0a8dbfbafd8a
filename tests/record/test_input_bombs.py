"""Bounded input measured in memory: a hostile xacro expression, an MCAP chunk that unpacks to
gigabytes or lies about its size, a recording whose summary lies about its commands.

Each bomb runs as a real ``deltoctl`` command in a child of a small wrapper process, which
reports the peak memory (maxrss) of that child alone: the command must exit 2 with one clear
line naming the file and what was refused, and its peak must stay far below what the bomb
would take (a plain `info` or `profile show` peaks at about 30 MB, ``BASELINE`` below).
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path
from xml.sax.saxutils import quoteattr

import pytest

PEAK_MB = 300  # generous: ten times a plain command's peak, far below any bomb's
XACRO = ('<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
         '{body}\n</robot>\n')
_WRAPPER = """\
import json, resource, subprocess, sys
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"code": done.returncode, "stdout": done.stdout, "stderr": done.stderr,
                  "peak_mb": peak / 1024}))
"""


def deltoctl(*args: str) -> dict:
    """Run ``deltoctl ARGS`` in a fresh process: its exit code, output and peak memory (MB)."""
    wrapper = subprocess.run([sys.executable, "-c", _WRAPPER, sys.executable, "-m", "deltoctl",
                              *args], capture_output=True, text=True, timeout=300, check=True)
    return json.loads(wrapper.stdout)


def refused(result: dict, *words: str) -> str:
    """One line on stderr with ``words`` (and perhaps a hint), exit 2, no traceback, a
    bounded peak."""
    assert result["code"] == 2, result
    assert "Traceback" not in result["stderr"] and "internal error" not in result["stderr"]
    lines = result["stderr"].strip().splitlines()
    assert len(lines) == 1 or (len(lines) == 2 and "hint:" in lines[1]), result["stderr"]
    for word in words:
        assert word in lines[0], lines[0]
    assert result["peak_mb"] < PEAK_MB, result
    return lines[0]


# -- xacro ---------------------------------------------------------------------------------------

def _xacro(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "bomb.xacro"
    path.write_text(XACRO.format(body=body))
    return path


def test_a_profile_command_peaks_at_a_few_tens_of_megabytes(tmp_path):
    """The reference the bounds below are judged against."""
    path = _xacro(tmp_path, '<link name="${len(\'ab\' * 10)}"/>')
    result = deltoctl("-p", str(path), "profile", "validate")
    assert result["code"] == 2 and "no <ros2_control> block" in result["stderr"], result
    assert result["peak_mb"] < 100, result


@pytest.mark.parametrize(("expression", "what"), [
    ("len(('b'*1500).join('a'*1000000))", "str.join() of 1500998500 characters"),
    ("len(('a'*1000).join(['b']*2000))", "str.join()"),
    ("len('x'.ljust(999999999))", "a width of 999999999 characters"),
    ("len('1'.zfill(10**9))", "a width of"),
    ("len('x'.center(10**9))", "a width of"),
    ("len(('\\t'*100000).expandtabs(1000))", "str.expandtabs()"),
    ("len(('ab'*500000).replace('a', 'x'*1000))", "str.replace()"),
    ("len(list('a'*1000000))", "a list of 1000000 characters"),
    ("len(sorted('a'*1000000))", "a list of 1000000 characters"),
    ("len(('a '*500000).split())", "str.split() into 500000 pieces"),
    ("len(xacro.tokenize('a,'*500000))", "xacro.tokenize() into"),
    ("len('a'*10**9)", "repeating a str"),
    ("len([0]*10**9)", "repeating a list"),
    ("len('%0999999999d' % 1)", "'%' formatting"),
    ("3**100000", "an integer larger than 10000 bits"),
    ("(1<<9000)<<9000", "an integer larger than 10000 bits"),
    ("len(['\U0001F600'*1000000, '\U0001F600'*1000000, '\U0001F600'*1000000, "
     "'\U0001F600'*1000000, '\U0001F600'*1000000])", "values take more than 16 MiB"),
    # operands held while the right side is evaluated: each one small, together too large
    ("len(" + "('a'*500000+" * 40 + "'a'" + ")" * 41, "values take more than 16 MiB"),
])
def test_an_expression_that_would_make_a_large_value_is_refused_before_making_it(
        tmp_path, expression, what):
    value = quoteattr("${" + expression + "}")
    path = _xacro(tmp_path, f'<xacro:property name="x" value={value}/><link name="${{x}}"/>')
    line = refused(deltoctl("-p", str(path), "profile", "show"), str(path), what)
    assert "xacro failed" in line


def test_the_join_bomb_peaks_far_below_what_it_would_make(tmp_path):
    """400 bytes that would make a 1.5 GB string: refused from the operands' sizes."""
    path = _xacro(tmp_path, '<link name="${len((\'b\'*1500).join(\'a\'*1000000))}"/>')
    assert path.stat().st_size < 400
    result = deltoctl("-p", str(path), "profile", "show")
    refused(result, "str.join()", "beyond 1048576")
    assert result["peak_mb"] < 100, result


@pytest.mark.parametrize("substitution", ["$(optenv HOME x)", "$(optenv HOME)", "$(env HOME)",
                                          "$(optenv DELTOCTL_NOT_SET a default)"])
def test_an_environment_variable_is_refused_saying_why(tmp_path, substitution):
    path = _xacro(tmp_path, f'<link name="{substitution}"/>')
    line = refused(deltoctl("-p", str(path), "profile", "show"), str(path),
                   f"{substitution} is refused", "does not read environment variables",
                   "--arg")
    assert "TypeError" not in line and "<class" not in line


# -- MCAP chunks ---------------------------------------------------------------------------------

GIB = 1 << 30
BLOCK = 1 << 20


def _message(channel_id: int, t_ns: int, data_size: int) -> bytes:
    """A message record's head; its ``data_size`` bytes of data follow."""
    return struct.pack("<BQHIQQ", 0x05, 2 + 4 + 8 + 8 + data_size, channel_id, 0, t_ns, t_ns)


def _compressed(compression: str, head: bytes, zeros: int, content_size: bool = True) -> bytes:
    """``head`` and ``zeros`` zero bytes compressed as one frame, a megabyte at a time (the
    test never holds what the bomb unpacks to)."""
    import lz4.frame
    import zstandard

    total = len(head) + zeros
    if compression == "zstd":
        packer = zstandard.ZstdCompressor(write_content_size=content_size).compressobj(
            size=total if content_size else -1)
        parts = [packer.compress(head)]
        flush = packer.flush
    else:
        packer = lz4.frame.LZ4FrameCompressor()
        parts = [packer.begin(source_size=total if content_size else 0), packer.compress(head)]
        flush = packer.flush
    block = bytes(BLOCK)
    for _ in range(zeros // BLOCK):
        parts.append(packer.compress(block))
    parts.append(packer.compress(bytes(zeros % BLOCK)))
    parts.append(flush())
    return b"".join(parts)


def _record(record) -> bytes:
    from mcap.data_stream import RecordBuilder

    builder = RecordBuilder()
    record.write(builder)
    return builder.end()


def bomb_mcap(path: Path, compression: str, declared: int, zeros: int,
              content_size: bool = True, summary: bool = True,
              topic: str = "/diagnostics", schema: str = "diagnostic_msgs/msg/DiagnosticArray"
              ) -> Path:
    """An MCAP file with one chunk holding one message of ``zeros`` bytes on ``topic``,
    compressed, the chunk declaring ``declared`` bytes unpacked; with a summary that indexes
    the chunk, or (``summary=False``) none, as a recorder killed before it wrote one leaves."""
    from mcap.records import (
        Channel,
        Chunk,
        ChunkIndex,
        DataEnd,
        Footer,
        Header,
        MessageIndex,
        Schema,
        Statistics,
    )

    magic = b"\x89MCAP0\r\n"
    head = _message(1, 1_000, zeros)
    records = [Schema(id=1, name=schema, encoding="ros2msg", data=b""),
               Channel(id=1, schema_id=1, topic=topic, message_encoding="cdr", metadata={})]
    out = bytearray(magic + _record(Header(profile="ros2", library="bombs")))
    for r in records:
        out += _record(r)
    data = _compressed(compression, head, zeros, content_size)
    chunk_at = len(out)
    out += _record(Chunk(compression=compression, data=data, message_start_time=1_000,
                         message_end_time=1_000, uncompressed_crc=0,
                         uncompressed_size=declared))
    chunk_length = len(out) - chunk_at
    index_at = len(out)
    out += _record(MessageIndex(channel_id=1, records=[(1_000, 0)]))
    out += _record(DataEnd(data_section_crc=0))
    summary_at = 0
    if summary:
        summary_at = len(out)
        for r in records:
            out += _record(r)
        out += _record(Statistics(message_count=1, schema_count=1, channel_count=1,
                                  attachment_count=0, metadata_count=0, chunk_count=1,
                                  message_start_time=1_000, message_end_time=1_000,
                                  channel_message_counts={1: 1}))
        out += _record(ChunkIndex(message_start_time=1_000, message_end_time=1_000,
                                  chunk_start_offset=chunk_at, chunk_length=chunk_length,
                                  message_index_offsets={1: index_at},
                                  message_index_length=summary_at - index_at - 13,
                                  compression=compression, compressed_size=len(data),
                                  uncompressed_size=declared))
    out += _record(Footer(summary_start=summary_at, summary_offset_start=0, summary_crc=0))
    path.write_bytes(bytes(out + magic))
    return path


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
@pytest.mark.parametrize("summary", [True, False], ids=["indexed", "no-summary"])
def test_a_chunk_that_declares_a_gibibyte_is_refused_before_it_is_unpacked(
        tmp_path, compression, summary):
    """33 kB (zstd) or 4.4 MB (LZ4) that unpack to 1 GiB: `info` peaked at 1.04 GB (zstd) and
    2.07 GB (LZ4); now the declared size is refused before anything is allocated."""
    path = bomb_mcap(tmp_path / "bomb.mcap", compression, GIB, GIB, summary=summary)
    line = refused(deltoctl("info", str(path)), str(path), "the chunk at byte 139",
                   "declares 1073741824 bytes unpacked", "more than the 64 MiB")
    assert "MemoryError" not in line


def test_a_zstd_chunk_without_its_content_size_claiming_a_tebibyte_is_refused(tmp_path):
    """Was `internal error: MemoryError` (exit 1)."""
    path = bomb_mcap(tmp_path / "bomb.mcap", "zstd", 1 << 40, 64 << 20, content_size=False)
    refused(deltoctl("info", str(path)), str(path), "declares 1099511627776 bytes unpacked")


@pytest.mark.parametrize(("compression", "content_size"), [
    ("zstd", True), ("zstd", False), ("lz4", True), ("lz4", False)])
@pytest.mark.parametrize("summary", [True, False], ids=["indexed", "no-summary"])
def test_a_chunk_that_unpacks_to_more_than_it_declares_stops_at_its_declared_size(
        tmp_path, compression, content_size, summary):
    """A chunk declaring 1 MiB whose frame holds 256 MiB (and says so, or not): unpacking
    stops one byte past the declared size (zstd followed the frame's own size: 1.04 GB)."""
    path = bomb_mcap(tmp_path / "bomb.mcap", compression, 1 << 20, 256 << 20,
                     content_size=content_size, summary=summary)
    result = deltoctl("info", str(path))
    refused(result, str(path), "the chunk at byte 139",
            "unpacks to more than the 1048576 bytes it declares")
    assert result["peak_mb"] < 100, result


@pytest.mark.parametrize("summary", [True, False], ids=["indexed", "no-summary"])
def test_a_chunk_that_unpacks_to_what_it_declares_reads(tmp_path, summary):
    """The same files, honest: read as before (the bounds refuse only what lies or is huge)."""
    path = bomb_mcap(tmp_path / "small.mcap", "zstd", 31 + 1000, 1000, summary=summary)
    result = deltoctl("info", str(path), "--json")
    assert result["code"] in (0, 3), result
    assert json.loads(result["stdout"])["result"]["topics"][0]["messages"] == 1


def test_plot_is_bounded_as_info_is(tmp_path):
    path = bomb_mcap(tmp_path / "bomb.mcap", "lz4", 1 << 20, 256 << 20, content_size=False,
                     topic="/joint_states", schema="sensor_msgs/msg/JointState")
    refused(deltoctl("plot", str(path), "--json"), str(path), "unpacks to more than")


# -- replay --------------------------------------------------------------------------------------

def _joint_state(names: list[str], *arrays: list[float]) -> bytes:
    """A sensor_msgs/JointState in CDR: a zero stamp, no frame, the names, three arrays."""
    body = bytearray(struct.pack("<III", 0, 0, 1) + b"\0")

    def align(n: int) -> None:
        body.extend(bytes(-len(body) % n))

    align(4)
    body += struct.pack("<I", len(names))
    for name in names:
        align(4)
        body += struct.pack("<I", len(name) + 1) + name.encode() + b"\0"
    for values in arrays:
        align(4)
        body += struct.pack("<I", len(values))
        if values:
            align(8)
            body += struct.pack(f"<{len(values)}d", *values)
    return b"\0\1\0\0" + bytes(body)


def commands_mcap(path: Path, rows: int, joints: int = 1, counted: int | None = None,
                  summary: bool = True) -> Path:
    """A recording of ``rows`` command rows of ``joints`` DG-3F-M-like joints at 200 Hz, with
    their /joint_states; its summary counts ``counted`` rows (None: the truth), or there is no
    summary (a recorder killed before it wrote one)."""
    from mcap.records import DataEnd, Footer
    from mcap.writer import CompressionType, Writer

    names = [f"j_dg_{i // 4 + 1}_{i % 4 + 1}" for i in range(joints)]
    nan = float("nan")
    command = _joint_state(names, [0.1] * joints, [nan] * joints, [nan] * joints)
    state = _joint_state(names, [0.1] * joints, [0.0] * joints, [0.0] * joints)
    with path.open("wb") as f:
        writer = Writer(f, compression=CompressionType.LZ4)
        writer.start(profile="ros2", library="bombs")
        schema = writer.register_schema("sensor_msgs/msg/JointState", "ros2msg", b"")
        commands = writer.register_channel("/joint_commands", "cdr", schema)
        states = writer.register_channel("/joint_states", "cdr", schema)
        for i in range(rows):
            t = 1_000_000_000 + i * 5_000_000
            writer.add_message(states, t, state, t)
            writer.add_message(commands, t, command, t)
        if counted is not None:  # the summary lies
            writer._Writer__statistics.channel_message_counts[commands] = counted
        writer.finish()
    if not summary:  # cut at the data section's end, and a footer that points at no summary
        data = path.read_bytes()
        end = data.rindex(b"\x0f" + struct.pack("<Q", 4))  # the DataEnd record
        path.write_bytes(data[:end] + _record(DataEnd(data_section_crc=0)) +
                         _record(Footer(summary_start=0, summary_offset_start=0,
                                        summary_crc=0)) + b"\x89MCAP0\r\n")
    return path


def test_a_recording_whose_summary_lies_about_its_commands_is_refused_as_they_are_read(
        tmp_path):
    """The summary says one row; 200,001 and more follow: they are counted as they are read,
    and refused at the bound (was: every row read, 2.9 GB and a MemoryError at 2,031,708)."""
    path = commands_mcap(tmp_path / "lies.mcap", 200_100, counted=1)
    refused(deltoctl("replay", str(path)), str(path),
            "more than 200000 /joint_commands messages", "more than a replay takes")


def test_a_recording_of_too_many_joint_setpoints_is_refused_as_they_are_read(tmp_path):
    """Fewer rows than the bound, each of 12 joints: 500,000 setpoints at most."""
    path = commands_mcap(tmp_path / "wide.mcap", 50_000, joints=12, counted=1)
    refused(deltoctl("replay", str(path)), str(path), "more than 500000 joint setpoints")


def test_a_recording_without_a_summary_is_refused_from_its_count_keeping_little(tmp_path):
    """No summary: the file is read once to count its rows, keeping at most 16 MiB of them
    (was: every message kept, 2.08 GB before the refusal)."""
    path = commands_mcap(tmp_path / "killed.mcap", 200_100, summary=False)
    result = deltoctl("replay", str(path))
    refused(result, str(path), "200100 recorded commands, more than the 200000")
    assert result["peak_mb"] < 150, result


def test_a_file_without_a_summary_beyond_what_is_kept_is_read_again_whole(tmp_path):
    """40 MB of messages without a summary: 16 MiB are kept, the rest read again from the
    file when plotted; every value is there."""
    path = commands_mcap(tmp_path / "killed.mcap", 150_000, summary=False)
    result = deltoctl("plot", str(path), "j_dg_1_1/position", "--json")
    assert result["code"] in (0, 3), result
    (plotted,) = json.loads(result["stdout"])["result"]["interfaces"]
    assert plotted["count"] == 150_000 and plotted["max"] == 0.1
    assert result["peak_mb"] < PEAK_MB, result
