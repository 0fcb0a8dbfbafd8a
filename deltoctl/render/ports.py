"""``deltoctl ports`` for people: each serial adapter, CAN interface and I2C adapter of this
computer, a few lines each, with what needs doing before a bus runs on it."""

from __future__ import annotations

import re
from typing import Any

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def _printable(value: Any) -> Any:
    """A string from a device (sysfs: manufacturer, product, serial) with its control
    characters shown as "?": an escape sequence would drive the terminal."""
    return _CONTROL.sub("?", value) if isinstance(value, str) else value


def ports_lines(found: dict[str, Any]) -> list[str]:
    """The lines of deltoctl.transport.adapters.inventory()."""
    lines: list[str] = []
    for a in found["serial"]:
        lines += _serial(a)
    for c in found["can"]:
        lines += _can(c)
    for i in ({k: _printable(v) for k, v in i.items()} for i in found["i2c"]):
        state = "" if i["access"] else ("  (no access)" if i["present"] else "  (no /dev node)")
        lines.append(f"{i['device']}  I2C  {i['adapter'] or '?'}{state}")
    if not lines:
        lines.append("no serial adapter, CAN interface or I2C adapter")
    return lines


def _serial(a: dict[str, Any]) -> list[str]:
    a = {k: _printable(v) for k, v in a.items()}
    ident = f"{a['vid']}:{a['pid']}" if a["vid"] else "on-board"
    names = " ".join(x for x in (a["manufacturer"], a["product"]) if x)
    known = f" = {a['known']}" if a["known"] else ""
    lines = [f"{a['device']}  {ident}{known}  {names}".rstrip()]
    lines.append(f"  stable     {a['stable']}" + (f"   or {a['usb']}" if a["usb"] else ""))
    lines.append(f"  serial     {a['serial'] or '-'}   driver {a['driver'] or '-'}")
    if a["latency_timer_ms"] is not None:
        note = "" if a["latency_timer_ms"] <= 1 else \
            "   (a sync loop needs 1 ms: deltoctl doctor --udev-rule)"
        lines.append(f"  latency    {a['latency_timer_ms']} ms{note}")
    rates = []
    if a["max_baud"]:
        rates.append(f"up to {a['max_baud']}")
    if a["refused_bauds"]:
        rates.append("refuses " + ", ".join(str(b) for b in a["refused_bauds"]))
    if rates:
        lines.append(f"  baud       {'; '.join(rates)}")
    access = "read/write" if a["access"] else "NO ACCESS (the dialout group?)"
    lines.append(f"  access     {access}   {a['owner'] or ''}".rstrip())
    if a["holders"]:
        lines.append(f"  held by    {', '.join(a['holders'])}")
    return lines


def _can(c: dict[str, Any]) -> list[str]:
    c = {k: _printable(v) for k, v in c.items()}
    usb = f"  {c['vid']}:{c['pid']}" if c["vid"] else ""
    known = f" = {c['known']}" if c["known"] else ""
    lines = [f"{c['name']}  CAN{usb}{known}  {'up' if c['up'] else 'DOWN'}"
             + (f"  {c['state']}" if c["state"] else "")]
    facts = [f"{k} {c[k]}" for k in ("kind", "driver", "bitrate", "restart_ms")
             if c[k] is not None]
    if c["tx_errors"] is not None:
        facts.append(f"errors tx {c['tx_errors']} rx {c['rx_errors']}")
    if c["bus_off"]:
        facts.append(f"bus-off {c['bus_off']}×")
    if facts:
        lines.append("  " + "   ".join(facts))
    return lines
