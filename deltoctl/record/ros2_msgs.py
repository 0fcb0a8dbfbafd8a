"""ROS 2 message definitions the recorder writes, and what rosbag2 keeps beside each topic.

``MSGDEFS``: the ros2msg text of each type with its dependencies (``MSG: pkg/Type`` sections,
as rosbag2 embeds them). The fields are those of ROS 2 Humble and Jazzy (common_interfaces,
control_msgs), which agree on every type here but one: control_msgs/msg/
DynamicInterfaceGroupValues exists from control_msgs 4.7 (Humble) and 5.3 (Jazzy) on. An
older control_msgs cannot play /gpio under that type, so the recorder can write it as
control_msgs/msg/DynamicJointState instead (``GPIO_TYPES``): the same fields under other
names, byte for byte the same CDR.

``type_hash``: the RIHS01 hash of a type (REP 2011), as rosidl_generator_type_description
computes it from the type's description: every field's name and type, of the type and of all
the types it refers to, as JSON, through SHA-256. Constants and default values do not count.

``QOS_PROFILES``: the offered QoS rosbag2 records for a publisher it discovered (history
unknown, reliable, volatile, automatic liveliness, no deadline or lifespan), with the policies
as numbers: the form Humble's and Iron's rosbag2 write, which Jazzy's reads too (Jazzy's own
names, ``keep_last`` …, stop Humble's player).
"""

from __future__ import annotations

import hashlib
import json
import re
from functools import cache
from typing import TypedDict

SEP = "=" * 80 + "\n"

TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
INTERFACE_VALUE = "MSG: control_msgs/InterfaceValue\nstring[] interface_names\nfloat64[] values\n"
KEY_VALUE = "MSG: diagnostic_msgs/KeyValue\nstring key\nstring value\n"
STATUS = ("MSG: diagnostic_msgs/DiagnosticStatus\nbyte OK=0\nbyte WARN=1\nbyte ERROR=2\n"
          "byte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\n"
          "diagnostic_msgs/KeyValue[] values\n")


def _join(main: str, *deps: str) -> str:
    return main + "".join(SEP + d for d in deps)


MSGDEFS = {
    "sensor_msgs/msg/JointState": _join(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n", HEADER, TIME),
    "geometry_msgs/msg/WrenchStamped": _join(
        "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n",
        "MSG: geometry_msgs/Wrench\ngeometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque\n",
        VECTOR3, HEADER, TIME),
    "sensor_msgs/msg/Imu": _join(
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
        "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
        "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
        "float64[9] linear_acceleration_covariance\n",
        HEADER, TIME, "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\n"
        "float64 w 1\n", VECTOR3),
    "control_msgs/msg/DynamicJointState": _join(
        "std_msgs/Header header\nstring[] joint_names\n"
        "control_msgs/InterfaceValue[] interface_values\n", INTERFACE_VALUE, HEADER, TIME),
    "control_msgs/msg/DynamicInterfaceGroupValues": _join(
        "std_msgs/Header header\nstring[] interface_groups\n"
        "control_msgs/InterfaceValue[] interface_values\n", INTERFACE_VALUE, HEADER, TIME),
    "sensor_msgs/msg/Image": _join(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data\n", HEADER, TIME),
    "diagnostic_msgs/msg/DiagnosticArray": _join(
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n",
        STATUS, KEY_VALUE, HEADER, TIME),
}

# /gpio's type: the one made for it (control_msgs 4.7+/5.3+), or the one every control_msgs has
GPIO_TYPES = {
    "group-values": "control_msgs/msg/DynamicInterfaceGroupValues",
    "joint-state": "control_msgs/msg/DynamicJointState",
}

_INFINITE = "\n    sec: 9223372036\n    nsec: 854775807"  # RMW_DURATION_INFINITE
QOS_PROFILES = (
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n"
    f"  deadline:{_INFINITE}\n  lifespan:{_INFINITE}\n  liveliness: 1\n"
    f"  liveliness_lease_duration:{_INFINITE}\n  avoid_ros_namespace_conventions: false")


# -- type description hashes (REP 2011) --------------------------------------------------------

# type_description_interfaces/msg/FieldType: the id of each primitive; arrays add 48, bounded
# sequences 96, unbounded ones 144
FIELD_TYPE_IDS = {
    "nested": 1, "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7,
    "int64": 8, "uint64": 9, "float32": 10, "float64": 11, "char": 3, "bool": 15, "byte": 16,
    "string": 17, "wstring": 18, "bounded_string": 21, "bounded_wstring": 22,
}
ARRAY, BOUNDED_SEQUENCE, UNBOUNDED_SEQUENCE = 48, 96, 144


class FieldType(TypedDict):
    type_id: int
    capacity: int
    string_capacity: int
    nested_type_name: str


class Field(TypedDict):
    name: str
    type: FieldType


class TypeDescription(TypedDict):  # IndividualTypeDescription
    type_name: str
    fields: list[Field]


_FIELD = re.compile(r"^(?P<type>[\w/]+)(?:<=(?P<strmax>\d+))?(?:\[(?P<bound><=)?(?P<size>\d*)\])?"
                    r"\s+(?P<name>\w+)(?:\s+(?P<default>.+))?$")


def _field_type(text: str, strmax: str | None, bound: str | None, size: str | None,
                package: str, is_array: bool) -> FieldType:
    """A field's FieldType: type_id, capacity, string_capacity, nested_type_name."""
    nested = ""
    if text in FIELD_TYPE_IDS and text != "nested":
        base = text
        if strmax and text in ("string", "wstring"):
            base = "bounded_" + text
    else:
        base = "nested"
        pkg, _, name = text.rpartition("/")
        nested = f"{pkg or package}/msg/{name}"
    type_id = FIELD_TYPE_IDS[base]
    capacity = 0
    if is_array:
        if not size:
            type_id += UNBOUNDED_SEQUENCE
        elif bound:
            type_id, capacity = type_id + BOUNDED_SEQUENCE, int(size)
        else:
            type_id, capacity = type_id + ARRAY, int(size)
    return {"type_id": type_id, "capacity": capacity,
            "string_capacity": int(strmax) if strmax else 0, "nested_type_name": nested}


def parse_msg(type_name: str, text: str) -> TypeDescription:
    """One ros2msg section → its IndividualTypeDescription (without default values, which the
    hash leaves out)."""
    package = type_name.split("/")[0]
    fields: list[Field] = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        head, _, rest = line.partition(" ")
        if "=" in rest.split(" ", 1)[0] or re.match(r"^\w+\s*=", rest.strip()):
            continue  # a constant: not a field
        match = _FIELD.match(line)
        if match is None:
            raise ValueError(f"{type_name}: cannot read the field {raw!r}")
        fields.append({"name": match["name"], "type": _field_type(
            match["type"], match["strmax"], match["bound"], match["size"], package,
            "[" in head)})
    if not fields:  # what rosidl gives an empty message
        fields.append({"name": "structure_needs_at_least_one_member", "type": _field_type(
            "uint8", None, None, None, package, False)})
    return {"type_name": type_name, "fields": fields}


def _sections(full_name: str, text: str) -> dict[str, str]:
    """A definition with its dependencies → {pkg/msg/Type: its own text}."""
    parts = text.split(SEP)
    sections = {full_name: parts[0]}
    for part in parts[1:]:
        header, _, body = part.partition("\n")
        pkg, _, name = header.removeprefix("MSG: ").strip().rpartition("/")
        sections[f"{pkg.split('/')[0]}/msg/{name}"] = body
    return sections


def type_description(type_name: str, text: str) -> dict[str, object]:
    """The TypeDescription: the type and every type it refers to, sorted by name."""
    described = {name: parse_msg(name, body) for name, body in _sections(type_name, text).items()}
    referenced: set[str] = set()
    pending = [type_name]
    while pending:
        for field in described[pending.pop()]["fields"]:
            nested = field["type"]["nested_type_name"]
            if nested and nested not in referenced:
                if nested not in described:
                    raise ValueError(f"{type_name}: no definition of {nested}")
                referenced.add(nested)
                pending.append(nested)
    return {"type_description": described[type_name],
            "referenced_type_descriptions": [described[n] for n in sorted(referenced)]}


def rihs01(description: dict[str, object]) -> str:
    """RIHS01_<sha256>: the description as JSON, spaced as Python's json module spaces it
    with separators (', ', ': ') — what rosidl hashes."""
    text = json.dumps(description, ensure_ascii=True, separators=(", ", ": "))
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()


@cache
def type_hash(type_name: str) -> str:
    """The RIHS01 hash of one of ``MSGDEFS``' types."""
    return rihs01(type_description(type_name, MSGDEFS[type_name]))
