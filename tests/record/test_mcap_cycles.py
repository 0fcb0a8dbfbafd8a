"""A cycle's messages written into the chunk at once make the file mcap's Writer makes message
by message, byte for byte: chunk boundaries, message indexes, statistics, diagnostics."""

from __future__ import annotations

import io
import math

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from deltoctl.benchmarks.loop import robot_of
from deltoctl.profile.catalog import load_profile
from deltoctl.record.mcap_cycles import CycleAppender
from deltoctl.record.mcap_recorder import McapRecorder
from tests.conftest import ros2_messages

T0 = 1_700_000_000_000_000_000


def _names(profile) -> list[str]:
    names = [f"{c.name}/{i.name}" for hw in profile.hardware for c in hw.components()
             for i in c.state_interfaces]
    return names + [f"{hw.name}/connection_status" for hw in profile.hardware] + \
        ["system/connection_status"]


def _record(profile, chunk_size: int, at_once: bool, cycles: int = 120) -> bytes:
    """``cycles`` cycles of changing values, a link lost and restored, a flush, an interface
    that appears halfway and one that goes missing."""
    out = io.BytesIO()
    writer = Writer(out, compression=CompressionType.LZ4, chunk_size=chunk_size)
    recorder = McapRecorder(out, profile, {}, writer=writer)
    assert (recorder._appender is not None) is True
    if not at_once:
        recorder._appender = None
    names = _names(profile)
    for k in range(cycles):
        values = {n: (k * 7 + j) % 251 + 0.25 for j, n in enumerate(names)}
        values["system/connection_status"] = 0.0 if 40 <= k < 45 else 1.0
        if k >= 60:
            values["extra/state"] = float(k)  # the set of interfaces changes
        if k == 90:
            del values[names[0]]  # missing this cycle: NaN
        recorder.write(values, T0 + k * 1_000_000 + (500_000_000 if k > 100 else 0))
        if k == 30:
            recorder.flush()
    recorder.close({"cycles": cycles}, T0 + cycles * 1_000_000)
    return out.getvalue()


@pytest.mark.parametrize("chunk_size", [1 << 20, 6000, 700])
@pytest.mark.parametrize("name", ["dg-5f-right", "dg-5f-s-right"])  # F/T; tactile images
def test_cycles_at_once_make_the_same_file_as_message_by_message(name, chunk_size):
    profile = robot_of(load_profile(name), 2)
    at_once = _record(profile, chunk_size, True)
    assert at_once == _record(profile, chunk_size, False)
    summary = make_reader(io.BytesIO(at_once)).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == sum(summary.statistics.channel_message_counts
                                                   .values())
    if chunk_size == 700:  # every cycle ends a chunk, some in the middle of the cycle
        assert summary.statistics.chunk_count > 120


def test_a_recorded_cycle_reads_back_with_its_values(tmp_path):
    profile = robot_of(load_profile("dg-5f-right"), 2)
    path = tmp_path / "r.mcap"
    path.write_bytes(_record(profile, 1 << 20, True, cycles=95))
    names = _names(profile)
    joint = profile.hardware[1].joints[2].name
    seen = [m for topic, m in ros2_messages(path, ["/joint_states"])]
    assert len(seen) == 95
    at = names.index(f"{joint}/position")
    state = seen[50]
    assert state.name[len(profile.hardware[0].joints) + 2] == joint
    assert state.position[len(profile.hardware[0].joints) + 2] == (50 * 7 + at) % 251 + 0.25
    assert state.header.stamp.nanosec == 50 * 1_000_000
    first = profile.hardware[0].joints[0].name
    assert names[0] == f"{first}/position"
    assert math.isnan(seen[90].position[0])  # missing that cycle


def test_only_mcaps_own_writer_gets_cycles_at_once():
    class Other:
        def __getattr__(self, name):
            raise AttributeError(name)

    assert CycleAppender.of(Other()) is None
    assert CycleAppender.of(Writer(io.BytesIO(), use_chunking=False)) is None
    assert CycleAppender.of(Writer(io.BytesIO())) is not None


def test_the_hand_over_keeps_each_value_under_its_name(tmp_path):
    """The recorder process gets a cycle as its values in the last cycle's order; a cycle
    whose interfaces come in another order, or lack one, is recorded by name all the same."""
    from deltoctl.record.recorder_process import RecorderProcess

    profile = load_profile("dg-5f-right")
    names = _names(profile)
    first, second = (names.index(f"{j.name}/position") for j in profile.hardware[0].joints[:2])
    path = tmp_path / "h.mcap"
    with RecorderProcess(path, profile, {}) as recorder:
        for k in range(6):
            values = {n: k * 1000.0 + j for j, n in enumerate(names)}
            if k == 2:
                values = dict(reversed(values.items()))
            if k == 4:
                del values[names[first]]
            recorder.write(values, T0 + k * 1_000_000)
    states = [m for _, m in ros2_messages(path, ["/joint_states"])]
    assert [s.position[1] for s in states] == [k * 1000.0 + second for k in range(6)]
    assert states[2].position[0] == 2000.0 + first and math.isnan(states[4].position[0])
