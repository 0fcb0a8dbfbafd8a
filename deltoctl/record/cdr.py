"""ROS 2 CDR (little-endian, XCDR1) encoding for the recorder's fixed-shape messages.

A recorder's messages keep their shape for a whole recording: the same names, the same array
lengths; only stamps and values change. ``CdrTemplate`` works out the layout and alignment once
and compiles the whole message into one struct: every constant part is a byte string field,
every changing one a named value (an interface name, or ``SEC``/``NANOSEC`` for the stamp).
The recorder fills it with one ``itemgetter`` over a row of values and one ``pack``.
Integer fields (an Image's packed cells) take their float values rounded and saturated.
``CdrWriter`` encodes free-form messages (diagnostics, once a second) field by field.
"""

from __future__ import annotations

import re
import struct
from typing import Any

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR, little-endian
SEC, NANOSEC = "@sec", "@nanosec"  # the stamp's fields in a template
_INT_RANGES = {"B": (0, 0xFF), "H": (0, 0xFFFF), "b": (-0x80, 0x7F), "h": (-0x8000, 0x7FFF)}
_CELL = re.compile(r"^cell_(\d+)_(\d+)$")


def grid_cells(interfaces: list[str]) -> tuple[int, int, list[str]] | None:
    """A tactile grid's shape from its ``cell_<row>_<col>`` interfaces: (rows, cols, the
    names row by row), or None unless they are exactly the cells of a full grid."""
    cells = {}
    for name in interfaces:
        match = _CELL.match(name)
        if match is None:
            return None
        cells[int(match[1]), int(match[2])] = name
    if not cells:
        return None
    rows = max(r for r, _ in cells) + 1
    cols = max(c for _, c in cells) + 1
    if len(cells) != rows * cols or rows * cols > 1 << 16:
        return None
    return rows, cols, [cells[r, c] for r in range(rows) for c in range(cols)]


def stream_grids(names: list[str]) -> dict[str, list[list[str]]]:
    """The tactile grids among streamed interfaces: each part whose streamed interfaces are
    all ``cell_<row>_<col>`` of a full grid → its interface names, row by row."""
    parts: dict[str, list[str]] = {}
    for name in names:
        part, _, interface = name.rpartition("/")
        parts.setdefault(part, []).append(interface)
    grids = {}
    for part, interfaces in parts.items():
        grid = grid_cells(interfaces) if interfaces[0].startswith("cell_") else None
        if grid is not None:
            rows, cols, cells = grid
            grids[part] = [[f"{part}/{c}" for c in cells[r * cols:(r + 1) * cols]]
                           for r in range(rows)]
    return grids


class IntFields(struct.Struct):
    """A layout some of whose values are integers filled from floats: each is rounded and
    saturated to its type's range (NaN, a missing value, gives 0)."""

    def __init__(self, fmt: str, runs: list[tuple[int, int, int, int]]) -> None:
        super().__init__(fmt)
        self.runs = runs  # (first index among the values, end, lowest, highest)

    def pack(self, *values: Any) -> bytes:  # floats; Any as in struct.Struct.pack
        v = list(values)
        for start, end, lo, hi in self.runs:
            v[start:end] = [0 if x != x else lo if x <= lo else hi if x >= hi else round(x)
                            for x in v[start:end]]
        return super().pack(*v)


def _string(text: str) -> bytes:
    data = text.encode() + b"\x00"
    return struct.pack("<I", len(data)) + data


class CdrTemplate:
    """Build with ``.const_*``, ``.var*`` and ``.header``; ``.fields`` lists what ``.layout``
    packs, in order: bytes for a constant, a name for a value."""

    def __init__(self) -> None:
        self.fields: list[bytes | str] = [ENCAPSULATION]
        self._tokens = ["4s"]
        self._pos = 0  # offset from the start of the payload, after the encapsulation
        self._ints: list[tuple[int, int, int, int]] = []  # runs of integers from floats
        self.layout: struct.Struct | None = None

    def _const(self, data: bytes, align: int) -> CdrTemplate:
        pad = (-self._pos) % align
        if isinstance(self.fields[-1], bytes):  # zero padding joins the constant before it
            self.fields[-1] += bytes(pad) + data
            self._tokens[-1] = f"{len(self.fields[-1])}s"
        else:
            if pad:
                self._tokens.append(f"{pad}x")
            self.fields.append(data)
            self._tokens.append(f"{len(data)}s")
        self._pos += pad + len(data)
        return self

    def const_u8(self, value: int) -> CdrTemplate:
        return self._const(struct.pack("<B", value), 1)

    def const_u32(self, value: int) -> CdrTemplate:
        return self._const(struct.pack("<I", value), 4)

    def const_string(self, text: str) -> CdrTemplate:
        return self._const(_string(text), 4)

    def const_strings(self, texts: list[str]) -> CdrTemplate:
        self.const_u32(len(texts))
        for text in texts:
            self.const_string(text)
        return self

    def const_doubles(self, values: list[float]) -> CdrTemplate:
        """A fixed-size float64[N] that never changes (no length prefix)."""
        return self._const(struct.pack(f"<{len(values)}d", *values), 8)

    def var(self, code: str, names: list[str]) -> CdrTemplate:
        """Values of one struct ``code`` each, filled from ``names``."""
        size = struct.calcsize(code)
        pad = (-self._pos) % size
        if pad:
            self._tokens.append(f"{pad}x")
        self._tokens.append(f"{len(names)}{code}")
        self.fields += names
        self._pos += pad + size * len(names)
        return self

    def var_packed(self, code: str, names: list[str]) -> CdrTemplate:
        """A uint8[] (an Image's data) of a fixed length holding one little-endian value of
        integer struct ``code`` (B, H, b, h) per name: rounded and saturated floats."""
        size = struct.calcsize(code)
        self.const_u32(size * len(names))
        lo, hi = _INT_RANGES[code]
        start = len(self.fields)
        self._ints.append((start, start + len(names), lo, hi))
        # after its length the data starts 4-aligned: var() adds no padding inside it
        return self.var(code, names) if names else self

    def var_doubles(self, names: list[str]) -> CdrTemplate:
        """A float64[] of a fixed length: the count is constant, the values are not."""
        self.const_u32(len(names))
        return self.var("d", names) if names else self

    def header(self, frame_id: str = "") -> CdrTemplate:
        """std_msgs/Header: a changing stamp (sec, nanosec) and a fixed frame_id."""
        return self.var("i", [SEC]).var("I", [NANOSEC]).const_string(frame_id)

    def done(self) -> CdrTemplate:
        fmt = "<" + "".join(self._tokens)
        self.layout = IntFields(fmt, self._ints) if self._ints else struct.Struct(fmt)
        return self


class CdrWriter:
    """Field-by-field CDR for messages whose shape changes."""

    def __init__(self) -> None:
        self.buf = bytearray(ENCAPSULATION)

    def _align(self, n: int) -> None:
        self.buf += bytes((-(len(self.buf) - 4)) % n)

    def u8(self, value: int) -> CdrWriter:
        self.buf += struct.pack("<B", value)
        return self

    def i32(self, value: int) -> CdrWriter:
        self._align(4)
        self.buf += struct.pack("<i", value)
        return self

    def u32(self, value: int) -> CdrWriter:
        self._align(4)
        self.buf += struct.pack("<I", value)
        return self

    def string(self, text: str) -> CdrWriter:
        self._align(4)
        self.buf += _string(text)
        return self

    def header(self, t_ns: int, frame_id: str = "") -> CdrWriter:
        return self.i32(t_ns // 1_000_000_000).u32(t_ns % 1_000_000_000).string(frame_id)

    def bytes(self) -> bytes:
        return bytes(self.buf)
