"""ROS 2 CDR (little-endian, XCDR1) encoding for the recorder's fixed-shape messages.

A recorder's messages keep their shape for a whole recording: the same names, the same array
lengths; only stamps and values change. ``CdrTemplate`` works out the layout and alignment once,
folds every constant field into bytes, and packs each message with a few precompiled structs.
``CdrWriter`` encodes free-form messages (diagnostics, once a second) field by field.
"""

from __future__ import annotations

import struct

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR, little-endian


def _string(text: str) -> bytes:
    data = text.encode() + b"\x00"
    return struct.pack("<I", len(data)) + data


class CdrTemplate:
    """Build once: ``.const_*`` for fixed fields, ``.var(code, count)`` for changing ones."""

    def __init__(self) -> None:
        self.parts: list[bytes | tuple[struct.Struct, int]] = []
        self._const = bytearray(ENCAPSULATION)
        self._fmt = ""
        self._items = 0
        self._pos = 0  # offset from the start of the payload, after the encapsulation

    def _pad(self, align: int) -> None:
        pad = (-self._pos) % align
        if pad:
            if self._fmt:
                self._fmt += f"{pad}x"
            else:
                self._const += bytes(pad)
            self._pos += pad

    def _flush_var(self) -> None:
        if self._fmt:
            self.parts.append((struct.Struct("<" + self._fmt), self._items))
            self._fmt, self._items = "", 0

    def _flush_const(self) -> None:
        if self._const:
            self.parts.append(bytes(self._const))
            self._const = bytearray()

    def const_u32(self, value: int) -> CdrTemplate:
        self._pad(4)
        self._flush_var()
        self._const += struct.pack("<I", value)
        self._pos += 4
        return self

    def const_string(self, text: str) -> CdrTemplate:
        self._pad(4)
        self._flush_var()
        data = _string(text)
        self._const += data
        self._pos += len(data)
        return self

    def const_strings(self, texts: list[str]) -> CdrTemplate:
        self.const_u32(len(texts))
        for text in texts:
            self.const_string(text)
        return self

    def const_doubles(self, values: list[float]) -> CdrTemplate:
        """A fixed-size float64[N] that never changes (no length prefix)."""
        self._pad(8)
        self._flush_var()
        self._const += struct.pack(f"<{len(values)}d", *values)
        self._pos += 8 * len(values)
        return self

    def var(self, code: str, count: int = 1) -> CdrTemplate:
        size = struct.calcsize(code)
        self._pad(size)
        self._flush_const()
        self._fmt += f"{count}{code}" if count != 1 else code
        self._items += count
        self._pos += size * count
        return self

    def var_doubles(self, count: int) -> CdrTemplate:
        """A float64[] of a fixed length: the count is constant, the values are not."""
        self.const_u32(count)
        return self.var("d", count) if count else self

    def header(self, frame_id: str = "") -> CdrTemplate:
        """std_msgs/Header: a changing stamp (sec, nanosec) and a fixed frame_id."""
        return self.var("i").var("I").const_string(frame_id)

    def done(self) -> CdrTemplate:
        self._flush_var()
        self._flush_const()
        return self

    def pack(self, values: tuple | list) -> bytes:
        out = []
        i = 0
        for part in self.parts:
            if isinstance(part, bytes):
                out.append(part)
            else:
                layout, count = part
                out.append(layout.pack(*values[i:i + count]))
                i += count
        return b"".join(out)


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
