"""EDS (and DCF) files, the object dictionary of a node, read with canopen's EDS parser.

An EDS is untrusted input like a profile: its size, its lines, its sections and the counts
that make the parser loop (comment lines, sub-objects) are bounded before it is parsed, and
whatever is wrong with it is one ``ProfileError`` naming ``file:line`` — never a traceback.
Nothing in it runs: canopen reads it as INI text without interpolation.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from deltoctl.errors import ProfileError

MAX_EDS_BYTES = 1 << 20
MAX_LINE = 4096
MAX_SECTIONS = 8192
MAX_COUNT = 254  # comment lines, entries of a compact array
# what deltoctl needs of a CiA 402 drive's dictionary
REQUIRED = {0x1000: "Device type", 0x1018: "Identity object", 0x6040: "Controlword",
            0x6041: "Statusword", 0x6060: "Modes of operation", 0x6064: "Position actual value",
            0x607A: "Target position"}
_COUNTED = {"lines", "nrofentries", "compactsubobj"}
_NUMBERS = {"objecttype", "datatype", "pdomapping", "subnumber"}  # integers, where they are
_SECTION = re.compile(r"^\s*\[([^\]]*)\]")


def read_text(path: Path) -> str:
    """The file's text, within the bounds (UTF-8, else Latin-1 as vendors' tools write)."""
    try:
        size = path.stat().st_size
        if size > MAX_EDS_BYTES:
            raise ProfileError(f"{size} bytes: larger than {MAX_EDS_BYTES >> 10} KiB, the limit "
                               "for an EDS", str(path))
        raw = path.read_bytes()
    except OSError as exc:
        raise ProfileError(f"cannot read the EDS: {exc.strerror}", str(path)) from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def scan(text: str, source: str) -> dict[str, int]:
    """Each section's line (lower case name → 1-based line), checking the bounds."""
    sections: dict[str, int] = {}
    current = None
    for number, line in enumerate(text.splitlines(), 1):
        if len(line) > MAX_LINE:
            raise ProfileError(f"a line of {len(line)} characters (at most {MAX_LINE})",
                               source, number)
        match = _SECTION.match(line)
        if match:
            current = match.group(1).strip().lower()
            sections.setdefault(current, number)
            if len(sections) > MAX_SECTIONS:
                raise ProfileError(f"more than {MAX_SECTIONS} sections", source, number)
            continue
        key, sep, value = line.partition("=")
        name = key.strip().lower()
        if sep and current is not None and name in _COUNTED | _NUMBERS:
            value = value.split(";")[0].strip()
            try:
                count = int(value, 0)
            except ValueError:
                raise ProfileError(f"{key.strip()}={value!r} is not a number", source,
                                   number) from None
            if name in _COUNTED and not 0 <= count <= MAX_COUNT:
                raise ProfileError(f"{key.strip()}={count}: at most {MAX_COUNT}", source,
                                   number)
    return sections


def load(path: Path, node_id: int | None = None, required: bool = True) -> Any:
    """The object dictionary of ``path`` for a node (``$NODEID`` resolved)."""
    import configparser
    import io

    from canopen.objectdictionary.eds import import_eds

    from deltoctl_canopen import quiet  # noqa: F401  (the library's log records)

    source = str(path)
    text = read_text(path)
    sections = scan(text, source)
    stream = io.StringIO(text)
    stream.name = source
    try:
        od = import_eds(stream, node_id)
    except configparser.Error as exc:
        line = getattr(exc, "lineno", None) or _line_of(exc, sections)
        message = exc.message if hasattr(exc, "message") else str(exc)
        raise ProfileError(f"not a valid EDS: {message.splitlines()[0]}", source, line) \
            from None
    except (KeyError, ValueError, TypeError, IndexError, AttributeError, OverflowError) as exc:
        raise ProfileError(f"not a valid EDS: {_what(exc)}", source, _line_of(exc, sections)) \
            from None
    if required:
        missing = [f"{i:#06x} {name}" for i, name in REQUIRED.items() if i not in od]
        if missing:
            raise ProfileError(f"not a CiA 402 drive's dictionary: no {', '.join(missing)}",
                               source)
    return od


def _what(exc: Exception) -> str:
    if isinstance(exc, KeyError):
        key = exc.args[0] if exc.args else "?"
        return f"refers to {key if isinstance(key, str) else hex(key)}, which it does not define"
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def _line_of(exc: BaseException, sections: dict[str, int]) -> int | None:
    """The line of the section an error is about, when the error names one."""
    section = getattr(exc, "section", None)
    if section:
        return sections.get(str(section).lower())
    return None
