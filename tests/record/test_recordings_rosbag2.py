"""Recordings are rosbag2-grade: every family's recording (through the CLI, against the
emulators) reads with rosbags — its AnyReader and its rosbag2 directory reader, which checks
the type hashes and QoS profiles — and with mcap's own readers and CRC checks; the `rosbag2`
metadata record is laid out as rosbag2's MCAP storage plugin writes it."""

from __future__ import annotations

import io
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import Footer
from mcap.stream_reader import StreamReader
from typer.testing import CliRunner

from deltoctl.cli.main import app
from deltoctl.profile.catalog import load_profile
from deltoctl.record.mcap_recorder import McapRecorder
from deltoctl.record.ros2_msgs import (
    GPIO_TYPES,
    MSGDEFS,
    QOS_PROFILES,
    rihs01,
    type_description,
    type_hash,
)
from tests.conftest import REPO, ros2_messages

FAMILIES = ["dg-5f-right", "mh5", "bioscara-arm", "rrbot-gpio", "dg-5f-bimanual", "dg-5f-s15-right"]

# rosbag2_storage's yaml.hpp, convert<…>::encode: the keys, in the order it writes them
BAG_KEYS = ["version", "storage_identifier", "duration", "starting_time", "message_count",
            "topics_with_message_count", "compression_format", "compression_mode",
            "relative_file_paths", "files", "custom_data", "ros_distro"]
TOPIC_INFORMATION_KEYS = ["topic_metadata", "message_count"]
TOPIC_METADATA_KEYS = ["name", "type", "serialization_format", "offered_qos_profiles",
                       "type_description_hash"]
FILE_KEYS = ["path", "starting_time", "duration", "message_count"]
QOS_KEYS = ["history", "depth", "reliability", "durability", "deadline", "lifespan",
            "liveliness", "liveliness_lease_duration", "avoid_ros_namespace_conventions"]
# a topic's QoS as rosbag2 (Iron, metadata version 8) records it: rosbag2's own test bag
# rosbag2_tests/resources/mcap/bag_with_topics_and_service_events/metadata.yaml
ROSBAG2_QOS_V8 = (
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: "
    "9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n"
    "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n"
    "  avoid_ros_namespace_conventions: false")


@pytest.fixture(scope="session")
def family_recordings(tmp_path_factory):
    """One short recording of each family's catalog profile, through `record --sim`."""
    folder = tmp_path_factory.mktemp("families")
    runner = CliRunner()
    paths = {}
    for profile in FAMILIES:
        out = folder / f"{profile}.mcap"
        result = runner.invoke(app, ["-p", profile, "--sim", "-q", "record", str(out),
                                     "--rate", "50", "--duration", "0.5"])
        assert result.exit_code == 0, (profile, result.stderr)
        paths[profile] = out
    return paths


@pytest.fixture(params=FAMILIES)
def recording(request, family_recordings) -> Path:
    return family_recordings[request.param]


def _metadata(path: Path) -> dict[str, dict[str, str]]:
    with path.open("rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def _summary(path: Path):
    with path.open("rb") as f:
        return make_reader(f).get_summary()


def _bag(path: Path) -> dict:
    return yaml.safe_load(_metadata(path)["rosbag2"]["serialized_metadata"])


def _as_rosbag2_directory(path: Path, where: Path) -> Path:
    """A rosbag2 bag directory: the file and its metadata.yaml, which is the `rosbag2`
    record's YAML under rosbag2_bagfile_information."""
    where.mkdir()
    shutil.copy(path, where / path.name)
    (where / "metadata.yaml").write_text(yaml.safe_dump(
        {"rosbag2_bagfile_information": _bag(path)}, sort_keys=False))
    return where


# -- mcap's own reading ------------------------------------------------------------------------

def test_every_record_reads_with_its_crcs_checked(recording):
    with recording.open("rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    assert isinstance(records[-1], Footer)
    summary = _summary(recording)
    with recording.open("rb") as f:
        count = sum(1 for _ in make_reader(f).iter_messages())
    assert summary.statistics.message_count == count > 0
    assert {c.compression for c in summary.chunk_indexes} == {"lz4"}
    assert sum(1 for _ in ros2_messages(recording)) == count  # mcap-ros2-support decodes all


def test_channels_carry_what_rosbag2_writes(recording):
    summary = _summary(recording)
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
        assert schema.data.decode() == MSGDEFS[schema.name]
        assert channel.metadata == {"offered_qos_profiles": QOS_PROFILES,
                                    "topic_type_hash": type_hash(schema.name)}
        assert re.fullmatch(r"RIHS01_[0-9a-f]{64}", channel.metadata["topic_type_hash"])


# -- rosbags -----------------------------------------------------------------------------------

def test_rosbags_anyreader_reads_every_message(recording):
    from rosbags.highlevel import AnyReader

    summary = _summary(recording)
    counts = {summary.channels[c].topic: n
              for c, n in summary.statistics.channel_message_counts.items()}
    seen: dict[str, int] = {}
    with AnyReader([recording]) as reader:
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            assert msg.header.stamp.sec > 0
            seen[connection.topic] = seen.get(connection.topic, 0) + 1
    assert seen == counts


def test_rosbags_rosbag2_directory_reader_checks_hashes_and_qos(recording, tmp_path):
    """metadata.yaml beside the file: rosbags' rosbag2 reader matches each topic of it to the
    file's channel by type, QoS and type hash, and AnyReader recomputes every type's RIHS01
    hash from the embedded definitions and refuses a mismatch."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability, QosReliability
    from rosbags.rosbag2 import Reader

    bag = _as_rosbag2_directory(recording, tmp_path / "bag")
    summary = _summary(recording)
    with Reader(bag) as reader:
        assert reader.message_count == summary.statistics.message_count
        assert reader.duration == summary.statistics.message_end_time - \
            summary.statistics.message_start_time + 1
        assert sum(1 for _ in reader.messages()) == reader.message_count
        for connection in reader.connections:
            qos = connection.ext.offered_qos_profiles
            assert len(qos) == 1 and qos[0].reliability == QosReliability.RELIABLE
            assert qos[0].durability == QosDurability.VOLATILE
            assert connection.digest == type_hash(connection.msgtype)
    with AnyReader([bag]) as reader:
        assert sum(1 for _ in reader.messages()) == summary.statistics.message_count


def test_definitions_and_hashes_are_those_of_humble_and_jazzy():
    """Every type but control_msgs' (which rosbags does not ship) has the fields of the
    distributions' own definitions, and the same RIHS01 hash."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    for store in (Stores.ROS2_HUMBLE, Stores.ROS2_JAZZY):
        typestore = get_typestore(store)
        for name, text in MSGDEFS.items():
            ours = get_types_from_msg(text, name)
            for sub, fields in ours.items():
                if not sub.startswith("control_msgs/"):
                    assert typestore.fielddefs[sub] == fields, (store, sub)
            if not name.startswith("control_msgs/"):
                assert type_hash(name) == typestore.hash_rihs01(name), (store, name)


def test_type_hash_matches_a_hash_ros2_computed():
    """rosbag2's test bag (Iron) names rosbag2_interfaces/msg/WriteSplitEvent, as it then was
    (two strings), with this hash."""
    text = "# closed\nstring closed_file\n\n# opened\nstring opened_file\n"
    assert rihs01(type_description("rosbag2_interfaces/msg/WriteSplitEvent", text)) == \
        "RIHS01_5ef58f7106a5cff8f5a794028c18117ee21015850ddcc567df449f41932960f8"


def test_control_msgs_definitions_as_their_msg_files_are_written():
    """The .msg files as control_msgs ships them (comments, a type of the same package named
    bare) hash as our definitions do."""
    from deltoctl.record.ros2_msgs import HEADER, SEP, TIME

    interface_value = ("# List of resource interface names\nstring[] interface_names\n"
                       "# Values corresponding to the list of interfaces\nfloat64[] values\n")
    for name, names in (("DynamicJointState", "joint_names"),
                        ("DynamicInterfaceGroupValues", "interface_groups")):
        text = (f"std_msgs/Header header\n\n# List of names\nstring[] {names}\n# Key-value "
                "pairs\nInterfaceValue[] interface_values\n" + SEP +
                "MSG: control_msgs/InterfaceValue\n" + interface_value + SEP + HEADER + SEP + TIME)
        full = f"control_msgs/msg/{name}"
        assert rihs01(type_description(full, text)) == type_hash(full)


# -- the rosbag2 record --------------------------------------------------------------------------

def test_the_rosbag2_record_is_laid_out_as_rosbag2_writes_it(recording):
    meta = _metadata(recording)
    assert list(meta["rosbag2"]) == ["serialized_metadata"]
    text = meta["rosbag2"]["serialized_metadata"]
    bag = yaml.safe_load(text)
    assert list(bag) == BAG_KEYS
    stats = _summary(recording).statistics
    start, end = stats.message_start_time, stats.message_end_time
    assert bag["version"] == 8 and bag["storage_identifier"] == "mcap"
    assert bag["duration"] == {"nanoseconds": end - start}
    assert bag["starting_time"] == {"nanoseconds_since_epoch": start}
    assert bag["message_count"] == stats.message_count
    assert bag["compression_format"] == "" and bag["compression_mode"] == ""
    assert bag["relative_file_paths"] == [recording.name]
    assert bag["files"] == [{"path": recording.name, "starting_time": bag["starting_time"],
                             "duration": bag["duration"], "message_count": stats.message_count}]
    assert all(list(f) == FILE_KEYS for f in bag["files"])
    assert isinstance(bag["custom_data"], dict) and bag["ros_distro"] == ""
    summary = _summary(recording)
    channels = {c.topic: c for c in summary.channels.values()}
    counts = {summary.channels[c].topic: n for c, n in stats.channel_message_counts.items()}
    assert [t["topic_metadata"]["name"] for t in bag["topics_with_message_count"]] == \
        list(channels)
    for topic in bag["topics_with_message_count"]:
        assert list(topic) == TOPIC_INFORMATION_KEYS
        tm = topic["topic_metadata"]
        assert list(tm) == TOPIC_METADATA_KEYS
        channel = channels[tm["name"]]
        assert tm["type"] == summary.schemas[channel.schema_id].name
        assert tm["serialization_format"] == "cdr"
        assert tm["offered_qos_profiles"] == channel.metadata["offered_qos_profiles"]
        assert tm["type_description_hash"] == channel.metadata["topic_type_hash"]
        assert topic["message_count"] == counts.get(tm["name"], 0)


def test_qos_profiles_are_written_as_rosbag2_writes_them():
    assert QOS_PROFILES == ROSBAG2_QOS_V8
    (qos,) = yaml.safe_load(QOS_PROFILES)
    assert list(qos) == QOS_KEYS


# -- metadata ----------------------------------------------------------------------------------

def test_profile_and_identities_are_json_metadata(recording):
    meta = _metadata(recording)
    name = recording.stem
    profile = load_profile(name)
    as_json = json.loads(meta["profile"]["json"])
    as_yaml = yaml.safe_load(meta["profile"]["yaml"])
    assert meta["profile"]["name"] == as_json["name"] == as_yaml["name"] == name
    blocks = [b["name"] for b in as_json["ros2_control"]]
    assert blocks == [b["name"] for b in as_yaml["ros2_control"]]
    assert set(blocks) <= {hw.name for hw in profile.hardware}
    for block, text in meta["identify"].items():
        identity = json.loads(text)
        assert block in blocks and identity["family"] and "target" in identity


def test_gpio_has_a_fallback_type_every_control_msgs_has(tmp_path):
    """--gpio-type joint-state: /gpio as control_msgs/msg/DynamicJointState, the same fields
    (the groups as joint_names)."""
    from rosbags.highlevel import AnyReader

    profile = load_profile("rrbot-gpio")
    buf = io.BytesIO()
    recorder = McapRecorder(buf, profile, {}, gpio_type="joint-state")
    recorder.write({"system/connection_status": 1.0}, 1_000_000_000)
    recorder.close({"cycles": 1}, 1_000_000_001)
    assert GPIO_TYPES["joint-state"] == "control_msgs/msg/DynamicJointState"
    path = tmp_path / "fallback.mcap"
    path.write_bytes(buf.getvalue())
    with AnyReader([path]) as reader:
        (gpio,) = [c for c in reader.connections if c.topic == "/gpio"]
        assert gpio.msgtype == "control_msgs/msg/DynamicJointState"
        msg = reader.deserialize(next(reader.messages([gpio]))[2], gpio.msgtype)
        assert msg.joint_names[-1] == "system"
        assert list(msg.interface_values[-1].values) == [1.0]
    with pytest.raises(ValueError, match="gpio_type"):
        McapRecorder(io.BytesIO(), profile, {}, gpio_type="nope")


# -- dependencies --------------------------------------------------------------------------------

def test_mcap_ros2_support_is_a_test_dependency_only():
    for source in (REPO / "deltoctl").rglob("*.py"):
        assert "mcap_ros2" not in source.read_text(), source
    text = (REPO / "pyproject.toml").read_text()
    runtime = text.split("dependencies = [", 1)[1].split("]", 1)[0]
    test_extra = re.search(r"^test = \[(.*?)\]", text, re.S | re.M)[1]
    assert "mcap-ros2-support" not in runtime
    assert "mcap-ros2-support" in test_extra and "rosbags" in test_extra


def test_record_runs_without_mcap_ros2(tmp_path):
    out = tmp_path / "plain.mcap"
    code = ("import sys; sys.modules['mcap_ros2'] = None; from deltoctl.cli.main import main; "
            f"sys.argv = ['deltoctl', '-p', 'dg-4f', '--sim', '-q', 'record', {str(out)!r}, "
            "'--rate', '20', '--duration', '0.2']; main()")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert _summary(out).statistics.message_count > 0
