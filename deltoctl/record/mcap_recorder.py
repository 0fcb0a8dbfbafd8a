"""Record interface values to MCAP in ROS 2 encoding, so ros2 bag and Foxglove open it.

Topics: /joint_states (sensor_msgs/JointState), /dynamic_joint_states (every joint interface,
temperatures included, as ros2_control's broadcaster publishes them), /<sensor>/wrench
(geometry_msgs/WrenchStamped per F/T sensor), /<sensor>/data_raw (sensor_msgs/Imu without
orientation, per IMU), sensor_msgs/Image per tactile grid (its ``topic`` param, e.g.
/tactile/finger_1), /gpio (control_msgs/DynamicInterfaceGroupValues, or DynamicJointState
for an older control_msgs, with each block's and the system's connection_status),
/diagnostics (link lost and restored, gaps between cycles, loop statistics).

What rosbag2 writes is there too: each channel's ``offered_qos_profiles`` and
``topic_type_hash``, and at the end the ``rosbag2`` metadata record (the bag's metadata.yaml).
The resolved profile (YAML and JSON) and each block's identify result (JSON) are metadata.
``close()`` always leaves a valid, indexed file. Messages are CDR-encoded from precompiled
layouts (record/cdr.py); chunks are LZ4-compressed (read four times faster than zstd's, for
`deltoctl plot` of long recordings), and each /diagnostics message is a chunk of its own, so
`deltoctl info` reads them without unpacking the cycles' chunks.

``McapFile`` is the output file as the recorder process writes it: a readable MCAP at every
moment, also when a write fails (disk full, file too large) or the process is killed.
"""

from __future__ import annotations

import json
import os
from itertools import chain
from operator import itemgetter
from typing import Any, BinaryIO

from deltoctl.profile.model import Profile
from deltoctl.record.cdr import NANOSEC, SEC, CdrTemplate, CdrWriter, grid_cells
from deltoctl.record.ros2_msgs import GPIO_TYPES, MSGDEFS, QOS_PROFILES, type_hash

FT_AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
OK, WARN, ERROR = 0, 1, 2
NAN = float("nan")
IMU_FIELDS = ("orientation.x", "orientation.y", "orientation.z", "orientation.w",
              "angular_velocity.x", "angular_velocity.y", "angular_velocity.z",
              "linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z")
UNKNOWN_COVARIANCE = [0.0] * 9
NO_ORIENTATION = [-1.0] + [0.0] * 8  # REP 145: the IMU gives no orientation estimate
# A gap: no cycle for GAP_PERIODS of the usual period, and at least GAP_MIN_NS
GAP_PERIODS = 10
GAP_MIN_NS = 20_000_000
GAP_LEARN = 20  # cycles whose periods give the usual one
ROSBAG2_VERSION = 8  # the metadata layout whose QoS Humble, Iron and Jazzy all read


def _imu_template(sensor: str, frame_id: str) -> CdrTemplate:
    fields = [f"{sensor}/{k}" for k in IMU_FIELDS]
    t = CdrTemplate().header(frame_id).var("d", fields[:4]).const_doubles(NO_ORIENTATION)
    t.var("d", fields[4:7]).const_doubles(UNKNOWN_COVARIANCE)
    return t.var("d", fields[7:]).const_doubles(UNKNOWN_COVARIANCE).done()


def _image(sensor: Any, frame_id: str) -> tuple[str, CdrTemplate] | None:
    """A tactile grid (``cell_<row>_<col>`` interfaces) as sensor_msgs/Image: mono8 (uint8
    cells) or mono16 (little-endian uint16), on its ``topic`` param or /<sensor>/image."""
    grid = grid_cells([i.name for i in sensor.state_interfaces])
    if grid is None:
        return None
    rows, cols, cells = grid
    wide = sensor.params.get("encoding", "mono16") != "mono8"
    t = CdrTemplate().header(frame_id).const_u32(rows).const_u32(cols)
    t.const_string("mono16" if wide else "mono8").const_u8(0).const_u32(cols * (1 + wide))
    t.var_packed("H" if wide else "B", [f"{sensor.name}/{c}" for c in cells])
    topic = sensor.params.get("topic", "").strip("/")
    if not topic or not all(part.isidentifier() and part.isascii() for part in topic.split("/")):
        topic = f"{sensor.name}/image"
    return f"/{topic}", t.done()


class McapRecorder:
    def __init__(self, stream: BinaryIO | None, profile: Profile,
                 metadata: dict[str, dict[str, str]], extra_states: tuple[str, ...] = (),
                 gpio_type: str = "group-values", writer: Any = None,
                 commands: bool = False):
        """``extra_states``: values (``joint/name``) a driver reads beyond the profile's state
        interfaces (a Bioscara joint's flags), recorded in /dynamic_joint_states.
        ``gpio_type``: /gpio's message type, a key of ``GPIO_TYPES``. ``writer``: what takes
        the records instead of mcap's Writer on ``stream`` (the same methods: the live view's
        ``FoxgloveWriter``). ``commands``: a /joint_commands topic too, each cycle's
        setpoints (``record.command_topics``: ``<joint>/position_command`` …)."""
        from deltoctl.record.mcap_cycles import CycleAppender
        from deltoctl.version import __version__

        if gpio_type not in GPIO_TYPES:
            raise ValueError(f"gpio_type {gpio_type!r}: one of {', '.join(GPIO_TYPES)}")
        self.stream = stream
        if writer is None:
            from mcap.writer import CompressionType, Writer

            writer = Writer(stream, compression=CompressionType.LZ4)
        self.writer = writer
        self._appender = CycleAppender.of(writer)  # a cycle's messages at once, where it can
        self.writer.start(profile="ros2", library=f"deltoctl {__version__}")
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.types: dict[str, str] = {}  # topic → message type
        self.sequence: dict[str, int] = {}
        self.first_ns: int | None = None
        self.last_ns = 0
        self.profile = profile
        self.extra_states = extra_states
        self.gpio_type = GPIO_TYPES[gpio_type]
        self.link_losses = 0
        self.gaps = 0
        self.connected: float | None = None
        self.closed = False
        for name, data in _with_profile(metadata, profile).items():
            self.writer.add_metadata(name, data)
        self._plan()
        if commands:
            self._plan_commands()
        self.keys: list[str] = []
        self.set_keys([])
        self._previous_ns: int | None = None
        self._learning: list[int] = []  # the first periods, to learn the usual one from
        self._period_ns = 0.0  # the usual time between cycles

    def _plan(self) -> None:
        """Per topic: its message layout, with the interface names that fill it."""
        joints = [j for j in self.profile.joints() if j.state("position")]
        names = [j.name for j in joints]
        self.topics: list[tuple[str, CdrTemplate]] = []
        js = CdrTemplate().header().const_strings(names)
        for kind in ("position", "velocity", "effort"):
            js.var_doubles([f"{j}/{kind}" for j in names])
        self._add("/joint_states", "sensor_msgs/msg/JointState", js.done())
        dyn = CdrTemplate().header().const_strings(names).const_u32(len(names))
        for j in joints:
            itfs = [i.name for i in j.state_interfaces] + [
                e.partition("/")[2] for e in self.extra_states if e.startswith(j.name + "/")]
            dyn.const_strings(itfs).var_doubles([f"{j.name}/{i}" for i in itfs])
        self._add("/dynamic_joint_states", "control_msgs/msg/DynamicJointState", dyn.done())
        for _, sensor in self.profile.components():
            frame_id = sensor.params.get("frame_id", sensor.name)
            if sensor.kind == "sensor" and sensor.state("force.x"):
                wrench = CdrTemplate().header(frame_id)
                wrench.var("d", [f"{sensor.name}/{axis}" for axis in FT_AXES])
                self._add(f"/{sensor.name}/wrench", "geometry_msgs/msg/WrenchStamped",
                          wrench.done())
            if sensor.kind == "sensor" and sensor.state("angular_velocity.x"):
                self._add(f"/{sensor.name}/data_raw", "sensor_msgs/msg/Imu",
                          _imu_template(sensor.name, frame_id))
            image = _image(sensor, frame_id) if sensor.kind == "sensor" else None
            if image is not None:
                self._add(image[0], "sensor_msgs/msg/Image", image[1])
        groups = [(g.name, [i.name for i in g.state_interfaces])
                  for _, g in self.profile.components() if g.kind == "gpio"]
        groups += [(hw.name, ["connection_status"]) for hw in self.profile.hardware]
        groups.append(("system", ["connection_status"]))
        # DynamicJointState has the same fields as DynamicInterfaceGroupValues: one layout
        gpio = CdrTemplate().header().const_strings([g for g, _ in groups]).const_u32(len(groups))
        for group, itfs in groups:
            gpio.const_strings(itfs).var_doubles([f"{group}/{i}" for i in itfs])
        self._add("/gpio", self.gpio_type, gpio.done())

    def _plan_commands(self) -> None:
        """/joint_commands: a JointState of each joint's setpoints (NaN: not commanded)."""
        from deltoctl.record.command_topics import COMMANDS_TOPIC, command_key, commanded_joints

        names = [j.name for j in commanded_joints(self.profile)]
        js = CdrTemplate().header().const_strings(names)
        for kind in ("position", "velocity", "effort"):
            js.var_doubles([command_key(j, kind) for j in names])
        self._add(COMMANDS_TOPIC, "sensor_msgs/msg/JointState", js.done())

    def _add(self, topic: str, schema: str, template: CdrTemplate) -> None:
        self._channel(topic, schema)
        self.topics.append((topic, template))

    def _channel(self, topic: str, schema: str) -> int:
        """The topic's channel, with the QoS and type hash rosbag2 keeps beside it."""
        if topic not in self.channels:
            if schema not in self.schemas:
                self.schemas[schema] = self.writer.register_schema(
                    schema, "ros2msg", MSGDEFS[schema].encode())
            self.channels[topic] = self.writer.register_channel(
                topic, "cdr", self.schemas[schema],
                {"offered_qos_profiles": QOS_PROFILES, "topic_type_hash": type_hash(schema)})
            self.types[topic] = schema
            self.sequence[topic] = 0
        return self.channels[topic]

    def _emit(self, topic: str, data: bytes, t_ns: int) -> None:
        seq = self.sequence[topic]
        self.writer.add_message(self.channels[topic], log_time=t_ns, data=data,
                                publish_time=t_ns, sequence=seq)
        self.sequence[topic] = seq + 1

    @property
    def counts(self) -> dict[str, int]:
        return {t: n for t, n in self.sequence.items() if n}

    def set_keys(self, keys: list[str]) -> None:
        """The interfaces, in the order ``write_row`` gets their values. Each topic's fields
        become positions in a row: the values, then NaN (for a name not among the keys), the
        stamp, the templates' constant bytes and, with mcap's Writer, the records' constant
        head fields, the log time and each topic's sequence number."""
        at = {key: i for i, key in enumerate(keys)}
        missing = len(keys)
        at[SEC], at[NANOSEC] = missing + 1, missing + 2
        constants: list[bytes | int] = []

        def constant(value: bytes | int) -> int:
            constants.append(value)
            return missing + 2 + len(constants)

        self._rows, picks = [], []
        for topic, template in self.topics:
            fields = [constant(f) if isinstance(f, bytes) else at.get(f, missing)
                      for f in template.fields]
            self._rows.append((topic, template.layout.pack, itemgetter(*fields)))
            picks.append(fields)
        self._row_topics = [topic for topic, _, _ in self._rows]
        self._cycle = None
        if self._appender is not None and self.topics:
            from deltoctl.record.mcap_cycles import cycle_layout, head_values

            layout, self._cycle_starts = cycle_layout([t.layout for _, t in self.topics])
            heads = [[constant(v) for v in head_values(t.layout, self.channels[topic])]
                     for topic, t in self.topics]
            stamp = missing + 3 + len(constants)  # then the sequence numbers, topic by topic
            self._cycle = (layout.pack, itemgetter(*chain.from_iterable(
                [*head, stamp + 1 + k, stamp, stamp, *fields]
                for k, (head, fields) in enumerate(zip(heads, picks)))))
            self._row_channels = [self.channels[topic] for topic in self._row_topics]
        self._constants = constants
        self._status_at = at.get("system/connection_status")
        self._block_status = [(key.rpartition("/")[0], i) for key, i in at.items()
                              if key.endswith("/connection_status") and
                              key != "system/connection_status"]
        self.keys = list(keys)

    def write(self, values: dict[str, float], t_ns: int) -> None:
        if len(values) != len(self.keys) or list(values) != self.keys:
            self.set_keys(list(values))
        self.write_row(list(values.values()), t_ns)

    def write_row(self, row: list[float], t_ns: int) -> None:
        """One cycle's values in ``set_keys`` order (the list is extended in place)."""
        if self.first_ns is None:
            self.first_ns = t_ns
        self.last_ns = t_ns
        self._watch_gap(t_ns)
        row += (NAN, t_ns // 1_000_000_000, t_ns % 1_000_000_000)
        row += self._constants
        if self._cycle is not None:  # every record of the cycle in one pack and one write
            sequence = self.sequence
            row.append(t_ns)
            for topic in self._row_topics:  # (two blocks' sensors may share a topic)
                seq = sequence[topic]
                row.append(seq)
                sequence[topic] = seq + 1
            pack, pick = self._cycle
            self._appender.append(t_ns, self._row_channels, self._cycle_starts,
                                  pack(*pick(row)))
        else:
            for topic, pack, pick in self._rows:
                self._emit(topic, pack(*pick(row)), t_ns)
        if self._status_at is None:
            return
        status = row[self._status_at]
        if self.connected is not None and status != self.connected:
            lost = status == 0.0
            self.link_losses += lost
            down = [block for block, i in self._block_status if row[i] == 0.0]
            self.diagnostic(t_ns, ERROR if lost else OK, "link",
                            "link lost" if lost else "link restored",
                            {"blocks_down": ",".join(down)})
        self.connected = status

    def skipped(self) -> None:
        """Cycles left out on purpose (the live view's, with no client): not a gap."""
        self._previous_ns = None

    def _watch_gap(self, t_ns: int) -> None:
        """A diagnostic when no cycle came for GAP_PERIODS usual periods (GAP_MIN_NS at
        least): the loop stalled, and the recording has a hole there. The usual period is
        the median of the first GAP_LEARN ones, then follows the rate slowly (a gap moves it
        by 1 % at most)."""
        previous, self._previous_ns = self._previous_ns, t_ns
        if previous is None:
            return
        dt = t_ns - previous
        if not self._period_ns:
            self._learning.append(dt)
            if len(self._learning) == GAP_LEARN:
                self._period_ns = float(sorted(self._learning)[GAP_LEARN // 2])
            return
        if dt > max(GAP_PERIODS * self._period_ns, GAP_MIN_NS):
            self.gaps += 1
            self.diagnostic(t_ns, WARN, "gap", f"no cycle for {dt / 1e9:.3f} s", {
                "start_ns": previous, "end_ns": t_ns, "seconds": round(dt / 1e9, 6)})
        self._period_ns = 0.99 * self._period_ns + 0.01 * min(dt, 2 * self._period_ns)

    def diagnostic(self, t_ns: int, level: int, name: str, message: str,
                   values: dict[str, Any]) -> None:
        self.diagnostics(t_ns, [(level, name, message, values)])

    def diagnostics(self, t_ns: int,
                    statuses: list[tuple[int, str, str, dict[str, Any]]]) -> None:
        """One DiagnosticArray: a status per (level, name, message, key/values), in a chunk
        of its own (readers find them by the chunk index, without unpacking the cycles)."""
        self.flush()
        self._channel("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
        w = CdrWriter().header(t_ns).u32(len(statuses))
        for level, name, message, values in statuses:
            w.u8(level).string(f"deltoctl/{name}").string(message).string(self.profile.name)
            w.u32(len(values))
            for key, value in values.items():
                w.string(key).string(str(value))
        self._emit("/diagnostics", w.bytes(), t_ns)
        if self.first_ns is None:
            self.first_ns = t_ns
        self.last_ns = max(self.last_ns, t_ns)
        self.flush()

    def flush(self) -> None:
        """Write the chunk in progress: what is recorded is on disk within a flush."""
        flush = getattr(self.writer, "flush", None)  # older mcap releases lack it
        if flush is not None:
            flush()

    def close(self, loop_summary: dict[str, Any] | None = None, t_ns: int = 0) -> None:
        """Finish the file; with the loop's final statistics, as a last diagnostic (a warning
        when the link was lost) and as the ``recording`` metadata; then the ``rosbag2``
        record. A ``McapFile`` that failed keeps the end it has: a whole file with every
        record written before the failure."""
        if self.closed:
            return
        self.closed = True
        if getattr(self.stream, "error", None) is not None:
            return
        if loop_summary is not None:
            self.diagnostic(t_ns, WARN if self.link_losses else OK, "loop",
                            "record loop (final)", loop_summary)
            self.writer.add_metadata("recording", {
                "link_losses": str(self.link_losses), "gaps": str(self.gaps),
                **{k: str(v) for k, v in loop_summary.items()},
                "json": json.dumps({"link_losses": self.link_losses, "gaps": self.gaps,
                                    "loop": loop_summary}, default=str)})
        self.writer.add_metadata("rosbag2", {"serialized_metadata": self.rosbag2_metadata()})
        finishing = getattr(self.stream, "finishing", None)
        if finishing is not None:  # the last chunk while the file still ends validly
            self.flush()
            finishing()
        self.writer.finish()

    def rosbag2_metadata(self) -> str:
        """The bag's metadata as rosbag2's MCAP storage plugin writes it in its ``rosbag2``
        record (rosbag2_storage's BagMetadata as YAML, the keys in its order)."""
        import yaml

        from deltoctl.version import __version__

        start = self.first_ns or 0
        duration = {"nanoseconds": max(self.last_ns - start, 0)}
        starting = {"nanoseconds_since_epoch": start}
        count = sum(self.sequence.values())
        path = os.path.basename(str(getattr(self.stream, "path", "")
                                    or getattr(self.stream, "name", "") or "recording.mcap"))
        topics = [{"topic_metadata": {
            "name": topic, "type": self.types[topic], "serialization_format": "cdr",
            "offered_qos_profiles": QOS_PROFILES,
            "type_description_hash": type_hash(self.types[topic])},
            "message_count": self.sequence[topic]} for topic in self.channels]
        bag = {
            "version": ROSBAG2_VERSION, "storage_identifier": "mcap", "duration": duration,
            "starting_time": starting, "message_count": count,
            "topics_with_message_count": topics, "compression_format": "",
            "compression_mode": "", "relative_file_paths": [path],
            "files": [{"path": path, "starting_time": starting, "duration": duration,
                       "message_count": count}],
            "custom_data": {"recorded_by": f"deltoctl {__version__}",
                            "profile": self.profile.name},
            "ros_distro": ""}
        return yaml.safe_dump(bag, sort_keys=False, width=1 << 16)


def _with_profile(metadata: dict[str, dict[str, str]],
                  profile: Profile) -> dict[str, dict[str, str]]:
    """The metadata with the ``profile`` record whole: name, YAML and JSON (what the caller
    gave is kept)."""
    from deltoctl.profile.exporter import profile_data, to_yaml

    given = metadata.get("profile", {})
    record = {"name": profile.name,
              "yaml": given.get("yaml") or to_yaml(profile),
              "json": json.dumps(profile_data(profile), default=str), **given}
    return {"profile": record, **{k: v for k, v in metadata.items() if k != "profile"}}


MAGIC = b"\x89MCAP0\r\n"


def _provisional_end() -> bytes:
    """Data End, a Footer that points to no summary, the magic: what makes the records before
    it a whole MCAP file (readers then scan the records; make_reader does)."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer

    builder = RecordBuilder()
    DataEnd(0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return builder.end() + MAGIC


def _pwrite_all(fd: int, data: bytes, offset: int) -> None:
    view = memoryview(data)
    while view:
        n = os.pwrite(fd, view, offset)
        view, offset = view[n:], offset + n


class McapFile:
    """The output file as mcap's Writer sees it (``write``, ``tell``, ``flush``), a readable
    MCAP at every moment.

    Each group of records the Writer hands over (a chunk, its message indexes, a metadata
    record) is followed on disk by a provisional end, which the next group overwrites; the
    provisional end goes first, beyond the group, so even a process killed between the two
    writes leaves a file that reads. A group that cannot be written (disk full, file too large,
    an I/O error) is taken back whole and the provisional end put back, so the file keeps every
    group written before it; the error is raised then and by every later write. ``finishing``
    turns the provisional ends off for the Writer's own summary and footer.
    """

    def __init__(self, path: str) -> None:
        self.path = path
        self.fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0),
                          0o666)
        self.tail = _provisional_end()
        self.end = 0  # the Writer's bytes on disk
        self.tail_at: int | None = None  # where the provisional end on disk starts
        self.provisional = True
        self.error: OSError | None = None
        self.removed = False  # the file was unlinked (its directory removed) while written

    def tell(self) -> int:
        return self.end

    def flush(self) -> None:
        """Nothing is buffered: every write goes to the file at once."""

    def write(self, data: bytes) -> int:
        if self.error is not None:
            raise self.error
        at, size = self.end, len(data)
        if not size:
            return 0
        try:
            if self.provisional and at + size > len(MAGIC):  # a header on disk: end it
                _pwrite_all(self.fd, self.tail, at + size)
                _pwrite_all(self.fd, data, at)
                self.tail_at = at + size
            else:
                _pwrite_all(self.fd, data, at)
        except OSError as exc:
            self.error = exc
            self._take_back()
            raise
        self.end = at + size
        self.removed = os.fstat(self.fd).st_nlink == 0
        return size

    def _take_back(self) -> None:
        """The file as it was before the failed group: its provisional end rewritten in place
        (on blocks it already had, so a full disk cannot refuse it)."""
        try:
            if self.tail_at is None:
                os.ftruncate(self.fd, self.end)
            else:
                os.ftruncate(self.fd, self.tail_at + len(self.tail))
                _pwrite_all(self.fd, self.tail, self.tail_at)
        except OSError:
            pass  # nothing more can be done; the error already raised says why

    def finishing(self) -> None:
        """The Writer's summary and footer come next: no provisional ends between them."""
        self.provisional = False

    @property
    def readable(self) -> bool:
        """The file on disk is a whole MCAP: its header was written, so an end follows."""
        return self.tail_at is not None

    def _trim(self) -> None:
        """A finished file loses the provisional end that followed its own."""
        if not self.provisional and self.error is None:
            os.ftruncate(self.fd, self.end)

    def close(self) -> None:
        if self.fd < 0:
            return
        try:
            self._trim()
        finally:
            os.close(self.fd)
            self.fd = -1

    def save_copy(self) -> str:
        """Copy the file, removed while written, to its directory if that is still there,
        else to the temporary directory, under a name not taken; returns the copy's path."""
        import shutil
        import tempfile

        folder, name = os.path.split(os.path.abspath(self.path))
        if not os.path.isdir(folder):
            folder = tempfile.gettempdir()
        stem, ext = os.path.splitext(name)
        self._trim()
        for n in range(1000):
            target = os.path.join(folder, name if n == 0 else f"{stem}-{n}{ext}")
            try:
                fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            except FileExistsError:
                continue
            os.lseek(self.fd, 0, os.SEEK_SET)
            try:
                with open(self.fd, "rb", closefd=False) as src, open(fd, "wb") as dst:
                    shutil.copyfileobj(src, dst, 1 << 20)
            except OSError:
                os.unlink(target)  # no half copy that looks like a recording
                raise
            return target
        raise FileExistsError(f"no free name for {name} in {folder}")
