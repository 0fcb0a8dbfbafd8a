"""Record interface values to MCAP in ROS 2 encoding, so ros2 bag and Foxglove open it.

Topics: /joint_states (sensor_msgs/JointState), /dynamic_joint_states (every joint interface,
temperatures included, as ros2_control's broadcaster publishes them), /<sensor>/wrench
(geometry_msgs/WrenchStamped per F/T sensor), /<sensor>/data_raw (sensor_msgs/Imu without
orientation, per IMU), /gpio (control_msgs/DynamicInterfaceGroupValues, with
system/connection_status), /diagnostics (link events and loop statistics). The resolved
profile and the identify result are stored as metadata. ``close()`` always leaves a valid,
indexed file. Messages are CDR-encoded from precompiled layouts (record/cdr.py).
"""

from __future__ import annotations

from operator import itemgetter
from typing import Any, BinaryIO

from deltoctl.profile.model import Profile
from deltoctl.record.cdr import NANOSEC, SEC, CdrTemplate, CdrWriter
from deltoctl.record.ros2_msgs import MSGDEFS

FT_AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
OK, WARN, ERROR = 0, 1, 2
NAN = float("nan")
IMU_FIELDS = ("orientation.x", "orientation.y", "orientation.z", "orientation.w",
              "angular_velocity.x", "angular_velocity.y", "angular_velocity.z",
              "linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z")
UNKNOWN_COVARIANCE = [0.0] * 9
NO_ORIENTATION = [-1.0] + [0.0] * 8  # REP 145: the IMU gives no orientation estimate


def _imu_template(sensor: str, frame_id: str) -> CdrTemplate:
    fields = [f"{sensor}/{k}" for k in IMU_FIELDS]
    t = CdrTemplate().header(frame_id).var("d", fields[:4]).const_doubles(NO_ORIENTATION)
    t.var("d", fields[4:7]).const_doubles(UNKNOWN_COVARIANCE)
    return t.var("d", fields[7:]).const_doubles(UNKNOWN_COVARIANCE).done()


class McapRecorder:
    def __init__(self, stream: BinaryIO, profile: Profile, metadata: dict[str, dict[str, str]],
                 extra_states: tuple[str, ...] = ()):
        """``extra_states``: values (``joint/name``) a driver reads beyond the profile's state
        interfaces (a Bioscara joint's flags), recorded in /dynamic_joint_states."""
        from mcap.writer import Writer

        from deltoctl import __version__

        self.writer = Writer(stream)
        self.writer.start(profile="ros2", library=f"deltoctl {__version__}")
        self.schemas = {name: self.writer.register_schema(name, "ros2msg", text.encode())
                        for name, text in MSGDEFS.items()}
        self.channels: dict[str, int] = {}
        self.sequence: dict[str, int] = {}
        self.profile = profile
        self.extra_states = extra_states
        self.link_losses = 0
        self.connected: float | None = None
        self.closed = False
        for name, data in metadata.items():
            self.writer.add_metadata(name, data)
        self._plan()
        self.keys: list[str] = []
        self.set_keys([])

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
        groups = [(g.name, [i.name for i in g.state_interfaces])
                  for _, g in self.profile.components() if g.kind == "gpio"]
        groups += [(hw.name, ["connection_status"]) for hw in self.profile.hardware]
        groups.append(("system", ["connection_status"]))
        gpio = CdrTemplate().header().const_strings([g for g, _ in groups]).const_u32(len(groups))
        for group, itfs in groups:
            gpio.const_strings(itfs).var_doubles([f"{group}/{i}" for i in itfs])
        self._add("/gpio", "control_msgs/msg/DynamicInterfaceGroupValues", gpio.done())

    def _add(self, topic: str, schema: str, template: CdrTemplate) -> None:
        self._channel(topic, schema)
        self.topics.append((topic, template))

    def _channel(self, topic: str, schema: str) -> int:
        if topic not in self.channels:
            self.channels[topic] = self.writer.register_channel(
                topic, "cdr", self.schemas[schema])
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
        stamp, and the templates' constant bytes."""
        at = {key: i for i, key in enumerate(keys)}
        missing = len(keys)
        at[SEC], at[NANOSEC] = missing + 1, missing + 2
        constants: list[bytes] = []
        self._rows = []
        for topic, template in self.topics:
            picks = []
            for f in template.fields:
                if isinstance(f, bytes):
                    picks.append(missing + 3 + len(constants))
                    constants.append(f)
                else:
                    picks.append(at.get(f, missing))
            self._rows.append((topic, template.layout.pack, itemgetter(*picks)))
        self._constants = constants
        self._status_at = at.get("system/connection_status")
        self.keys = list(keys)

    def write(self, values: dict[str, float], t_ns: int) -> None:
        if len(values) != len(self.keys) or list(values) != self.keys:
            self.set_keys(list(values))
        self.write_row(list(values.values()), t_ns)

    def write_row(self, row: list[float], t_ns: int) -> None:
        """One cycle's values in ``set_keys`` order (the list is extended in place)."""
        row += (NAN, t_ns // 1_000_000_000, t_ns % 1_000_000_000)
        row += self._constants
        for topic, pack, pick in self._rows:
            self._emit(topic, pack(*pick(row)), t_ns)
        if self._status_at is None:
            return
        status = row[self._status_at]
        if self.connected is not None and status != self.connected:
            lost = status == 0.0
            self.link_losses += lost
            self.diagnostic(t_ns, ERROR if lost else OK, "link",
                            "link lost" if lost else "link restored", {})
        self.connected = status

    def diagnostic(self, t_ns: int, level: int, name: str, message: str,
                   values: dict[str, Any]) -> None:
        self.diagnostics(t_ns, [(level, name, message, values)])

    def diagnostics(self, t_ns: int,
                    statuses: list[tuple[int, str, str, dict[str, Any]]]) -> None:
        """One DiagnosticArray: a status per (level, name, message, key/values)."""
        self._channel("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
        w = CdrWriter().header(t_ns).u32(len(statuses))
        for level, name, message, values in statuses:
            w.u8(level).string(f"deltoctl/{name}").string(message).string(self.profile.name)
            w.u32(len(values))
            for key, value in values.items():
                w.string(key).string(str(value))
        self._emit("/diagnostics", w.bytes(), t_ns)

    def close(self, loop_summary: dict[str, Any] | None = None, t_ns: int = 0) -> None:
        """Finish the file; with the loop's final statistics, as a last diagnostic (a warning
        when the link was lost) and as the ``recording`` metadata."""
        if self.closed:
            return
        self.closed = True
        if loop_summary is not None:
            self.diagnostic(t_ns, WARN if self.link_losses else OK, "loop",
                            "record loop (final)", loop_summary)
            self.writer.add_metadata("recording", {
                "link_losses": str(self.link_losses),
                **{k: str(v) for k, v in loop_summary.items()}})
        self.writer.finish()
