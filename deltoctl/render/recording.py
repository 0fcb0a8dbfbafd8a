"""What a recording holds, for people: ``deltoctl info``'s summary (record/reader.py's
``describe``) as lines and tables, in the order they are read."""

from __future__ import annotations

from typing import Any

from deltoctl.render.identity import Table
from deltoctl.units import utc_time


def recorded_lines(result: dict[str, Any], robot: str | None = None) -> list[str]:
    """A recording written (by ``record``, or of a remote ``robot``): its file, messages,
    topics and cycles; where its gaps are marked, when a link was lost."""
    loop, counts = result["loop"], result["messages"]
    cycles = f"{loop['cycles']} cycles" + (f" of robot {robot}" if robot else "")
    lines = [f"wrote {result['output']}: {sum(counts.values())} messages on {len(counts)} "
             f"topics, {cycles} at {loop['real_rate']} Hz"
             + (" (its cycle times)" if robot else "")]
    return lines + (["the gaps are marked on /diagnostics"] if result["link_losses"] else [])


def recording_status(name: str, cycles: int, size: int, link: float | None) -> str:
    """The status line people watch while recording (the time so far is the bar's)."""
    state = "" if link is None else " · link up" if link else " · [red]link lost[/]"
    return f"recording {name}: {cycles} cycles, {size / 1e6:.1f} MB{state}"


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return str(n)


def _identity_text(identity: Any) -> str:
    """The scalar facts of an identify result, one line."""
    if not isinstance(identity, dict):
        return "" if identity is None else str(identity)
    return "; ".join(f"{k}={v}" for k, v in identity.items()
                     if isinstance(v, (str, int, float, bool)))


def summary(r: dict[str, Any]) -> list[str | Table]:
    """The recording's times, size, profile, blocks, topics, link losses, gaps and loops:
    each a line or a table."""
    out: list[str | Table] = [
        f"{r['file']}: {r['duration_s']:.3f} s from {utc_time(r['start_ns'])} to "
        f"{utc_time(r['end_ns'])}, {r['messages']} messages, {_size(r['bytes'])} "
        f"({', '.join(r['compression']) or 'no chunks'}, {r['chunks']} chunks)",
        ", ".join(_facts(r))]
    if r["blocks"]:
        out.append(("blocks", ["block", "family", "target", "identity"],
                    [[b["name"], b.get("family"), b.get("target"),
                      _identity_text(b.get("identity"))] for b in r["blocks"]]))
    out.append(("topics", ["topic", "type", "messages", "rate (Hz)"],
                [[t["topic"], t["type"], t["messages"],
                  "-" if t["rate_hz"] is None else f"{t['rate_hz']:.2f}"] for t in r["topics"]]))
    out.append(("link losses", ["lost", "restored", "seconds", "blocks down"],
                [[utc_time(x["lost_ns"]), utc_time(x["restored_ns"]) if x["restored_ns"] else
                  "not restored", f"{x['seconds']:.3f}", ", ".join(x["blocks"])]
                 for x in r["link_losses"]]) if r["link_losses"] else "link losses: none")
    out.append(("gaps (no cycle)", ["from", "to", "seconds"],
                [[utc_time(g["start_ns"]), utc_time(g["end_ns"]), f"{g['seconds']:.3f}"]
                 for g in r["gaps"]]) if r["gaps"] else "gaps: none")
    loop = r["loop"]
    if loop:
        out.append(f"loop: {loop.get('real_rate')} Hz of {loop.get('requested_rate')} asked, "
                   f"{loop.get('cycles')} cycles, {loop.get('deadline_misses')} deadline "
                   f"misses; lateness p50 {loop.get('lateness_p50_ms')} ms, p99 "
                   f"{loop.get('lateness_p99_ms')} ms; period jitter p50 "
                   f"{loop.get('period_jitter_p50_ms')} ms, p99 "
                   f"{loop.get('period_jitter_p99_ms')} ms")
    out += [f"bus loop {name}: " + ", ".join(f"{k} {v}" for k, v in bus.items())
            for name, bus in r["buses"].items()]
    return out


def _facts(r: dict[str, Any]) -> list[str]:
    """The profile, the model, what recorded it."""
    profile = r["profile"] or {}
    facts = [f"profile {profile.get('name') or '?'}"]
    if profile.get("model"):
        facts.append(f"model {profile['model']}")
    if r["deltoctl"]:
        facts.append(f"recorded by deltoctl {r['deltoctl']}")
    if r["rosbag2"]:
        facts.append(f"rosbag2 metadata v{r['rosbag2']['version']}")
    return facts
