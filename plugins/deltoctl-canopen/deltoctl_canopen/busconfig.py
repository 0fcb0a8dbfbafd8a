"""ros2_canopen's ``bus.yml``: the nodes of a CAN bus, their node IDs, EDS files, unit scaling,
the ``sdo:`` writes applied at start-up and their PDO mappings.

Both layouts ros2_control users have are read: every node at the top level beside ``master``
and ``options`` (flat), or ``defaults:`` merged under each of ``nodes:``. A node's keys are
those of ros2_canopen's Cia402Driver (``node_id``, ``dcf``, ``scale_pos_to_dev`` …); the EDS is
found beside the bus file (or in ``options: dcf_path``, when it is a directory that exists).

The file is untrusted input like a profile (read with the profile's bounded YAML loader);
whatever is wrong is one ``ProfileError`` with ``file:line``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from deltoctl.errors import ProfileError

MAX_BUS_BYTES = 1 << 20
MAX_NODES = 127
MAX_SDO = 256
RESERVED = ("options", "master", "defaults", "nodes")
SCALES = {  # ros2_canopen's defaults (node_canopen_402_driver)
    "scale_pos_to_dev": 1000.0, "scale_pos_from_dev": 0.001, "scale_vel_to_dev": 1000.0,
    "scale_vel_from_dev": 0.001, "scale_eff_from_dev": 0.001, "offset_pos_to_dev": 0.0,
    "offset_pos_from_dev": 0.0}
NODE_KEYS = {
    "node_id", "dcf", "driver", "package", "period", "position_mode", "velocity_mode",
    "torque_mode", "revision_number", "product_code", "vendor_id", "serial_number",
    "switching_state", "heartbeat_producer", "heartbeat_consumer", "heartbeat_multiplier",
    "polling", "sdo", "tpdo", "rpdo", "namespace", "boot_timeout_ms", "enable_lazy_load",
    "homing_timeout_seconds", "sdo_timeout_ms", "reset_communication", "boot", "mandatory",
    "diagnostics", "channels", "dcf_path", "error_behavior", *SCALES}


@dataclass
class SdoWrite:
    index: int
    subindex: int
    value: int | float
    line: int | None = None


@dataclass
class PdoConfig:
    number: int  # 1..512
    enabled: bool
    transmission: int | None = None
    mapping: list[tuple[int, int]] = field(default_factory=list)


@dataclass
class NodeConfig:
    name: str
    node_id: int
    dcf: Path | None
    scales: dict[str, float]
    sdo: list[SdoWrite] = field(default_factory=list)
    tpdo: list[PdoConfig] = field(default_factory=list)
    rpdo: list[PdoConfig] = field(default_factory=list)
    heartbeat_producer: int = 0  # ms; 0: node guarding instead
    position_mode: int = 1
    homing_timeout: int = 0  # s (homing_timeout_seconds); 0: the profile's home_timeout
    identity: dict[str, int] = field(default_factory=dict)  # vendor_id, product_code …
    line: int | None = None

    def to_dev(self, position: float) -> int:
        s = self.scales
        return round(position * s["scale_pos_to_dev"] + s["offset_pos_to_dev"])

    def from_dev(self, raw: int) -> float:
        s = self.scales
        return raw * s["scale_pos_from_dev"] + s["offset_pos_from_dev"]

    def vel_to_dev(self, velocity: float) -> int:
        return round(velocity * self.scales["scale_vel_to_dev"])

    def vel_from_dev(self, raw: int) -> float:
        return raw * self.scales["scale_vel_from_dev"]


@dataclass
class BusConfig:
    source: str
    nodes: dict[str, NodeConfig]
    sync_period_us: int = 0

    def by_id(self) -> dict[int, NodeConfig]:
        return {n.node_id: n for n in self.nodes.values()}


def load_bus(path: Path) -> BusConfig:
    from deltoctl.profile.yaml_loader import load_data, read_text

    source = str(path)
    data = load_data(read_text(path, "YAML", MAX_BUS_BYTES, "bus configuration"), source)
    if not isinstance(data, dict):
        raise ProfileError("a bus.yml is a mapping (master:, nodes: or one key per node)",
                           source)
    r = _Reader(source, path.parent, data)
    return r.bus()


class _Reader:
    def __init__(self, source: str, base: Path, data: Any) -> None:
        self.source, self.base, self.data = source, base, data

    def fail(self, message: str, where: Any = None, key: Any = None) -> ProfileError:
        line = None
        if key is not None and hasattr(where, "lines"):
            lines = where.lines
            line = lines.get(key) if isinstance(lines, dict) else (
                lines[key] if isinstance(key, int) and key < len(lines) else None)
        if line is None:
            line = getattr(where, "line", None) or None
        return ProfileError(message, self.source, line)

    def mapping(self, value: Any, what: str, where: Any, key: Any) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise self.fail(f"{what} must be a mapping", where, key)
        return value

    def bus(self) -> BusConfig:
        data = self.data
        options = self.mapping(data.get("options"), "options", data, "options")
        master = self.mapping(data.get("master"), "master", data, "master")
        dcf_dir = self.base
        dcf_path = options.get("dcf_path")
        if isinstance(dcf_path, str) and "@" not in dcf_path:
            candidate = (self.base / dcf_path)
            if candidate.is_dir():
                dcf_dir = candidate
        if "nodes" in data:
            defaults = self.mapping(data.get("defaults"), "defaults", data, "defaults")
            nodes = self.mapping(data["nodes"], "nodes", data, "nodes")
            entries = {name: (self.mapping(body, f"node {name}", nodes, name), nodes)
                       for name, body in nodes.items()}
        else:
            defaults = {}
            entries = {name: (self.mapping(body, f"node {name}", data, name), data)
                       for name, body in data.items() if name not in RESERVED}
        if len(entries) > MAX_NODES:
            raise self.fail(f"{len(entries)} nodes: a CANopen bus has at most {MAX_NODES}", data)
        result: dict[str, NodeConfig] = {}
        taken: dict[int, str] = {}
        for name, (body, parent) in entries.items():
            node = self.node(str(name), {**defaults, **body}, body, parent, dcf_dir)
            if node.node_id in taken:
                raise self.fail(f"node {name}: node_id {node.node_id} is {taken[node.node_id]}'s "
                                "too", body, "node_id")
            taken[node.node_id] = node.name
            result[node.name] = node
        period = master.get("sync_period", 0)
        return BusConfig(self.source, result, period if isinstance(period, int) else 0)

    def node(self, name: str, merged: dict, body: Any, parent: Any, dcf_dir: Path) -> NodeConfig:
        unknown = sorted(str(k) for k in merged if k not in NODE_KEYS)
        if unknown:
            raise self.fail(f"node {name}: unknown key {', '.join(unknown)}", body, unknown[0])
        node_id = merged.get("node_id")
        if isinstance(node_id, bool) or not isinstance(node_id, int) or not 1 <= node_id <= 127:
            raise self.fail(f"node {name}: node_id must be 1 to 127, got {node_id!r}", body,
                            "node_id" if "node_id" in body else None) if body else \
                self.fail(f"node {name}: node_id must be 1 to 127", parent, name)
        scales = dict(SCALES)
        for key in SCALES:
            if key in merged:
                value = merged[key]
                if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                        value != value or abs(value) in (float("inf"),):
                    raise self.fail(f"node {name}: {key} must be a finite number", body, key)
                scales[key] = float(value)
        if scales["scale_pos_to_dev"] == 0 or scales["scale_pos_from_dev"] == 0:
            raise self.fail(f"node {name}: a position scale of 0", body)
        dcf = merged.get("dcf")
        eds_path = None
        if dcf is not None:
            if not isinstance(dcf, str) or not dcf.lower().endswith((".eds", ".dcf")):
                raise self.fail(f"node {name}: dcf names an .eds or .dcf file, got {dcf!r}",
                                body, "dcf")
            eds_path = dcf_dir / dcf
        identity = {k: merged[k] for k in ("vendor_id", "product_code", "revision_number",
                                            "serial_number")
                    if isinstance(merged.get(k), int) and not isinstance(merged.get(k), bool)}
        return NodeConfig(
            name, node_id, eds_path, scales, self.sdo(name, merged.get("sdo"), body),
            self.pdos(name, "tpdo", merged.get("tpdo"), body),
            self.pdos(name, "rpdo", merged.get("rpdo"), body),
            self.integer(name, merged, "heartbeat_producer", 0, 0, 65535, body),
            self.integer(name, merged, "position_mode", 1, -128, 127, body),
            self.integer(name, merged, "homing_timeout_seconds", 0, 0, 3600, body),
            identity, getattr(body, "line", None))

    def integer(self, name: str, merged: dict, key: str, default: int, low: int, high: int,
                where: Any) -> int:
        value = merged.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise self.fail(f"node {name}: {key} must be an integer {low} to {high}", where, key)
        return value

    def sdo(self, name: str, items: Any, where: Any) -> list[SdoWrite]:
        if items is None:
            return []
        if not isinstance(items, list) or len(items) > MAX_SDO:
            raise self.fail(f"node {name}: sdo is a list of at most {MAX_SDO} "
                            "{index, sub_index, value}", where, "sdo")
        writes = []
        for i, item in enumerate(items):
            line = item.line if hasattr(item, "line") else None
            if not isinstance(item, dict) or set(item) - {"index", "sub_index", "value"}:
                raise ProfileError(f"node {name}: each sdo item is {{index, sub_index, value}}",
                                   self.source, line or getattr(items, "line", None))
            index, sub, value = item.get("index"), item.get("sub_index", 0), item.get("value")
            if not (_int(index) and 0x1000 <= index <= 0xFFFF and _int(sub) and 0 <= sub <= 255
                    and isinstance(value, (int, float)) and not isinstance(value, bool)
                    and value == value):
                raise ProfileError(f"node {name}: sdo item {i + 1}: index 0x1000-0xFFFF, "
                                   "sub_index 0-255 and a number value", self.source, line)
            writes.append(SdoWrite(index, sub, value, line))
        return writes

    def pdos(self, name: str, kind: str, items: Any, where: Any) -> list[PdoConfig]:
        if items is None:
            return []
        if not isinstance(items, dict):
            raise self.fail(f"node {name}: {kind} is a mapping of PDO numbers", where, kind)
        result = []
        for number, body in items.items():
            line_at = items
            if not _int(number) or not 1 <= number <= 512 or not isinstance(body, dict):
                raise self.fail(f"node {name}: {kind} {number!r}: a PDO number 1-512 with "
                                "enabled, transmission, mapping", line_at, number)
            mapping = []
            for entry in body.get("mapping") or []:
                index, sub = (entry.get("index"), entry.get("sub_index", 0)) \
                    if isinstance(entry, dict) else (None, None)
                if not (_int(index) and _int(sub) and 0x1000 <= index <= 0xFFFF and
                        0 <= sub <= 255):
                    raise self.fail(f"node {name}: {kind} {number}: each mapping item is "
                                    "{index, sub_index}", body, "mapping")
                mapping.append((index, sub))
            if len(mapping) > 8:
                raise self.fail(f"node {name}: {kind} {number}: at most 8 objects", body,
                                "mapping")
            transmission = body.get("transmission")
            if transmission is not None and not (_int(transmission) and
                                                 0 <= transmission <= 255):
                raise self.fail(f"node {name}: {kind} {number}: transmission is 0-255", body,
                                "transmission")
            result.append(PdoConfig(number, bool(body.get("enabled", False)), transmission,
                                    mapping))
        return result


def _int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)
