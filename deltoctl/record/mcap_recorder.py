"""Record interface values to MCAP in ROS 2 encoding, so ros2 bag and Foxglove open it.

Topics: /joint_states (sensor_msgs/JointState), /dynamic_joint_states (every joint interface,
temperatures included, as ros2_control's broadcaster publishes them), /<sensor>/wrench
(geometry_msgs/WrenchStamped per F/T sensor), /gpio (control_msgs/DynamicInterfaceGroupValues,
with system/connection_status), /diagnostics (link events and loop statistics). The resolved
profile and the identify result are stored as metadata. ``close()`` always leaves a valid,
indexed file.
"""

from __future__ import annotations

from typing import Any, BinaryIO

from deltoctl.profile.model import Profile
from deltoctl.record.ros2_msgs import MSGDEFS, header

FT_AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
OK, WARN, ERROR = 0, 1, 2


class McapRecorder:
    def __init__(self, stream: BinaryIO, profile: Profile, metadata: dict[str, dict[str, str]]):
        from mcap_ros2.writer import Writer

        self.writer = Writer(stream)
        self.schemas = {name: self.writer.register_msgdef(name, text)
                        for name, text in MSGDEFS.items()}
        self.profile = profile
        self.joints = [j for j in profile.joints() if j.state("position")]
        self.ft_sensors = [s for _, s in profile.components()
                           if s.kind == "sensor" and s.state("force.x")]
        self.gpios = [g for _, g in profile.components() if g.kind == "gpio"]
        for name, data in metadata.items():
            self.writer.add_metadata(name, data)
        self.counts: dict[str, int] = {}
        self.connected: float | None = None
        self.link_losses = 0
        self.closed = False

    def _write(self, topic: str, schema: str, message: dict, t_ns: int) -> None:
        seq = self.counts.get(topic, 0)
        self.writer.write_message(topic, self.schemas[schema], message, log_time=t_ns,
                                  publish_time=t_ns, sequence=seq)
        self.counts[topic] = seq + 1

    def write(self, values: dict[str, float], t_ns: int) -> None:
        nan = float("nan")
        get = values.get
        names = [j.name for j in self.joints]
        self._write("/joint_states", "sensor_msgs/msg/JointState", {
            "header": header(t_ns), "name": names,
            "position": [get(f"{n}/position", nan) for n in names],
            "velocity": [get(f"{n}/velocity", nan) for n in names],
            "effort": [get(f"{n}/effort", nan) for n in names],
        }, t_ns)
        self._write("/dynamic_joint_states", "control_msgs/msg/DynamicJointState", {
            "header": header(t_ns), "joint_names": names,
            "interface_values": [
                {"interface_names": [i.name for i in j.state_interfaces],
                 "values": [get(f"{j.name}/{i.name}", nan) for i in j.state_interfaces]}
                for j in self.joints],
        }, t_ns)
        for sensor in self.ft_sensors:
            v = [get(f"{sensor.name}/{axis}", nan) for axis in FT_AXES]
            self._write(f"/{sensor.name}/wrench", "geometry_msgs/msg/WrenchStamped", {
                "header": header(t_ns, sensor.params.get("frame_id", sensor.name)),
                "wrench": {"force": {"x": v[0], "y": v[1], "z": v[2]},
                           "torque": {"x": v[3], "y": v[4], "z": v[5]}},
            }, t_ns)
        groups = [(g.name, [i.name for i in g.state_interfaces]) for g in self.gpios]
        groups.append(("system", ["connection_status"]))
        self._write("/gpio", "control_msgs/msg/DynamicInterfaceGroupValues", {
            "header": header(t_ns), "interface_groups": [g for g, _ in groups],
            "interface_values": [{"interface_names": names_,
                                  "values": [get(f"{g}/{n}", nan) for n in names_]}
                                 for g, names_ in groups],
        }, t_ns)
        status = get("system/connection_status", nan)
        if self.connected is not None and status != self.connected:
            lost = status == 0.0
            self.link_losses += lost
            self.diagnostic(t_ns, ERROR if lost else OK, "link",
                            "link lost" if lost else "link restored", {})
        self.connected = status

    def diagnostic(self, t_ns: int, level: int, name: str, message: str,
                   values: dict[str, Any]) -> None:
        self._write("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", {
            "header": header(t_ns),
            "status": [{"level": level, "name": f"deltoctl/{name}", "message": message,
                        "hardware_id": self.profile.name,
                        "values": [{"key": k, "value": str(v)} for k, v in values.items()]}],
        }, t_ns)

    def close(self, summary: dict[str, str] | None = None) -> None:
        if self.closed:
            return
        self.closed = True
        if summary:
            self.writer.add_metadata("recording", summary)
        self.writer.finish()
