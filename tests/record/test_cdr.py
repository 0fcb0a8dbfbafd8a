"""The recorder's precompiled CDR layouts give the same bytes as mcap-ros2-support's encoder."""

from __future__ import annotations

import io
import math

import pytest
from mcap_ros2._dynamic import serialize_dynamic

from deltoctl.profile.catalog import load_profile
from deltoctl.record.mcap_recorder import McapRecorder
from deltoctl.record.ros2_msgs import MSGDEFS

T_NS = 1_700_000_123_456_789_012


def _stamp():
    return {"stamp": {"sec": T_NS // 10**9, "nanosec": T_NS % 10**9}}


def _packed(recorder: McapRecorder, values: dict[str, float]) -> dict[str, bytes]:
    recorder.set_keys(list(values))
    row = [*values.values(), math.nan, T_NS // 10**9, T_NS % 10**9, *recorder._constants]
    return {topic: pack(*pick(row)) for topic, pack, pick in recorder._rows}


def _encode(schema: str, message: dict) -> bytes:
    return serialize_dynamic(schema, MSGDEFS[schema])[schema](message)


@pytest.mark.parametrize("name", ["dg-5f-right", "mh5"])
def test_every_topic_matches_the_reference_encoder(name):
    profile = load_profile(name)
    recorder = McapRecorder(io.BytesIO(), profile, {})
    joints = [j for j in profile.joints() if j.state("position")]
    values: dict[str, float] = {}
    for i, j in enumerate(joints):
        for k, itf in enumerate(j.state_interfaces):
            values[f"{j.name}/{itf.name}"] = i + k / 10
    values["system/connection_status"] = 1.0
    packed = _packed(recorder, values)  # the sensors' values are missing: NaN

    js = {"header": {**_stamp(), "frame_id": ""}, "name": [j.name for j in joints],
          **{kind: [values.get(f"{j.name}/{kind}", math.nan) for j in joints]
             for kind in ("position", "velocity", "effort")}}
    assert packed["/joint_states"] == _encode("sensor_msgs/msg/JointState", js)
    dyn = {"header": {**_stamp(), "frame_id": ""}, "joint_names": [j.name for j in joints],
           "interface_values": [
               {"interface_names": [i.name for i in j.state_interfaces],
                "values": [values[f"{j.name}/{i.name}"] for i in j.state_interfaces]}
               for j in joints]}
    assert packed["/dynamic_joint_states"] == _encode("control_msgs/msg/DynamicJointState", dyn)
    groups = [(g.name, [i.name for i in g.state_interfaces])
              for _, g in profile.components() if g.kind == "gpio"]
    groups += [(hw.name, ["connection_status"]) for hw in profile.hardware]  # each block's link
    groups.append(("system", ["connection_status"]))
    gpio = {"header": {**_stamp(), "frame_id": ""}, "interface_groups": [g for g, _ in groups],
            "interface_values": [{"interface_names": itfs,
                                  "values": [values.get(f"{g}/{i}", math.nan) for i in itfs]}
                                 for g, itfs in groups]}
    assert packed["/gpio"] == _encode("control_msgs/msg/DynamicInterfaceGroupValues", gpio)
    sensors = [t for t in packed if t.endswith(("/wrench", "/data_raw"))]
    assert len(sensors) == {"dg-5f-right": 5, "mh5": 1}[name]
    frames = {f"/{c.name}": c.params.get("frame_id", c.name) for _, c in profile.components()}
    for topic, data in packed.items():
        if topic.endswith("/data_raw"):
            nan3 = {"x": math.nan, "y": math.nan, "z": math.nan}
            imu = {"header": {**_stamp(), "frame_id": frames[topic.rsplit("/", 1)[0]]},
                   "orientation": {**nan3, "w": math.nan},
                   "orientation_covariance": [-1.0] + [0.0] * 8,
                   "angular_velocity": nan3, "angular_velocity_covariance": [0.0] * 9,
                   "linear_acceleration": nan3, "linear_acceleration_covariance": [0.0] * 9}
            assert data == _encode("sensor_msgs/msg/Imu", imu)
        if topic.endswith("/wrench"):
            nan3 = {"x": math.nan, "y": math.nan, "z": math.nan}
            wrench = {"header": {**_stamp(), "frame_id": frames[topic.rsplit("/", 1)[0]]},
                      "wrench": {"force": nan3, "torque": nan3}}
            assert data == _encode("geometry_msgs/msg/WrenchStamped", wrench)

