"""Record interface values to MCAP in ROS 2 encoding, so ros2 bag and Foxglove open it.

Topics: /joint_states (sensor_msgs/JointState), /dynamic_joint_states (every joint interface,
temperatures included, as ros2_control's broadcaster publishes them), /<sensor>/wrench
(geometry_msgs/WrenchStamped per F/T sensor), /<sensor>/data_raw (sensor_msgs/Imu without
orientation, per IMU), /gpio (control_msgs/DynamicInterfaceGroupValues, with
system/connection_status), /diagnostics (link events and loop statistics). The resolved
profile and the identify result are stored as metadata. ``close()`` always leaves a valid,
indexed file. Messages are CDR-encoded from precompiled layouts (record/cdr.py): the recorder
runs inside the cycle loop.
"""

from __future__ import annotations

from collections.abc import Callable
from operator import itemgetter
from typing import Any, BinaryIO

from deltoctl.profile.model import Profile
from deltoctl.record.cdr import CdrTemplate, CdrWriter
from deltoctl.record.ros2_msgs import MSGDEFS

FT_AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
OK, WARN, ERROR = 0, 1, 2
NAN = float("nan")
IMU_FIELDS = ("orientation.x", "orientation.y", "orientation.z", "orientation.w",
              "angular_velocity.x", "angular_velocity.y", "angular_velocity.z",
              "linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z")
UNKNOWN_COVARIANCE = [0.0] * 9
NO_ORIENTATION = [-1.0] + [0.0] * 8  # REP 145: the IMU gives no orientation estimate


def _imu_template(frame_id: str) -> CdrTemplate:
    t = CdrTemplate().header(frame_id).var("d", 4).const_doubles(NO_ORIENTATION)
    t.var("d", 3).const_doubles(UNKNOWN_COVARIANCE)
    return t.var("d", 3).const_doubles(UNKNOWN_COVARIANCE).done()


def _picker(keys: list[str]) -> Callable[[dict], tuple]:
    """Values of ``keys`` from a dict as a tuple, at C speed (KeyError when one is missing)."""
    if len(keys) > 1:
        return itemgetter(*keys)
    if keys:
        key = keys[0]
        return lambda values: (values[key],)
    return lambda values: ()


class McapRecorder:
    def __init__(self, stream: BinaryIO, profile: Profile, metadata: dict[str, dict[str, str]],
                 extra_states: tuple[str, ...] = ()):
        """``extra_states``: values a driver reads for every joint beyond the profile's state
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

    def _plan(self) -> None:
        """Per topic: its message layout and the interface names that fill it, in order."""
        joints = [j for j in self.profile.joints() if j.state("position")]
        names = [j.name for j in joints]
        self.topics: list[tuple[str, CdrTemplate, list[str], Callable]] = []
        n = len(names)
        js = CdrTemplate().header().const_strings(names)
        js.var_doubles(n).var_doubles(n).var_doubles(n).done()
        self._add("/joint_states", "sensor_msgs/msg/JointState", js,
                  [f"{j}/{k}" for k in ("position", "velocity", "effort") for j in names])
        dyn = CdrTemplate().header().const_strings(names).const_u32(n)
        keys = []
        for j in joints:
            itfs = [i.name for i in j.state_interfaces] + list(self.extra_states)
            dyn.const_strings(itfs).var_doubles(len(itfs))
            keys += [f"{j.name}/{i}" for i in itfs]
        self._add("/dynamic_joint_states", "control_msgs/msg/DynamicJointState", dyn.done(), keys)
        for _, sensor in self.profile.components():
            if sensor.kind == "sensor" and sensor.state("force.x"):
                wrench = CdrTemplate().header(sensor.params.get("frame_id", sensor.name))
                wrench.var("d", 6).done()
                self._add(f"/{sensor.name}/wrench", "geometry_msgs/msg/WrenchStamped", wrench,
                          [f"{sensor.name}/{axis}" for axis in FT_AXES])
            if sensor.kind == "sensor" and sensor.state("angular_velocity.x"):
                self._add(f"/{sensor.name}/data_raw", "sensor_msgs/msg/Imu",
                          _imu_template(sensor.params.get("frame_id", sensor.name)),
                          [f"{sensor.name}/{k}" for k in IMU_FIELDS])
        groups = [(g.name, [i.name for i in g.state_interfaces])
                  for _, g in self.profile.components() if g.kind == "gpio"]
        groups.append(("system", ["connection_status"]))
        gpio = CdrTemplate().header().const_strings([g for g, _ in groups]).const_u32(len(groups))
        for _, itfs in groups:
            gpio.const_strings(itfs).var_doubles(len(itfs))
        self._add("/gpio", "control_msgs/msg/DynamicInterfaceGroupValues", gpio.done(),
                  [f"{g}/{i}" for g, itfs in groups for i in itfs])

    def _add(self, topic: str, schema: str, template: CdrTemplate, keys: list[str]) -> None:
        self._channel(topic, schema)
        self.topics.append((topic, template, keys, _picker(keys)))

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

    def write(self, values: dict[str, float], t_ns: int) -> None:
        get = values.get
        stamp = (t_ns // 1_000_000_000, t_ns % 1_000_000_000)
        for topic, template, keys, getter in self.topics:
            try:
                picked = getter(values)  # C speed; a missing value falls back to NaN below
            except KeyError:
                picked = [get(k, NAN) for k in keys]
            self._emit(topic, template.pack((*stamp, *picked)), t_ns)
        status = get("system/connection_status", NAN)
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
