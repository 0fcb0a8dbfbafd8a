"""The commissioning report: one acceptance sequence on a robot, one document — identity of
every block, the bus scan, the configuration's fingerprint (and its differences from an
approved snapshot), link quality, motion checks where allowed, the sensors verified, plots of
a recording — each check with an id, a limit, a value, a unit and a verdict. ``run_report``
returns the JSON (the recording's figures as their sampled data); ``write_report`` writes it
and its self-contained HTML twin, which the caller renders (deltoctl.render.report_html)."""

from __future__ import annotations

import getpass
import hashlib
import json
import math
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.app.checks import FAIL, PASS, SEVERITY, SKIP, WARN, check, failed, overall
from deltoctl.errors import DeltoctlError, InvalidInput, Refused

if TYPE_CHECKING:
    from deltoctl.app.robot import Robot
    from deltoctl.core.system import Member

FORMAT = 1
# the limits a profile's `report:` section may change
# (home_repeatability and following_error: from the moves' settling tolerance, below)
DEFAULTS = {"rtt_p50_ms": 10.0, "rtt_p99_ms": 25.0, "error_rate_perc": 1.0,
            "loop_rate_ratio": 0.9, "jitter_p99_ms": 5.0, "homes": 3}
LINK_RATE = 100.0  # Hz of the link-quality stream
# the figures of a recording: title, the interfaces drawn, their unit (positions: the joints')
PLOTS = (("positions", "*/position", ""), ("forces", "*/force.*", "N"),
         ("accelerations", "*/linear_acceleration.*", "m/s²"))
MAX_SERIES = 8  # per plot
MAX_POINTS = 400  # per series, drawn
# what the sequence is doing and how much of it is done (0 to 1), for the caller to show
Said = Callable[[str, float], None]


@dataclass
class Plan:
    """What the operator asked for."""

    golden: Path | None = None
    record_seconds: float | None = None
    record_path: Path | None = None
    operator: str = ""
    motion: bool = False  # confirmed (--yes)
    link_seconds: float = 1.0


class Steps:
    """The sequence's progress told to ``said``: each stage as it starts, a stage's own
    steps (a joint's moves) as a fraction of it."""

    def __init__(self, said: Said | None, stages: int) -> None:
        self.said, self.stages, self.done = said, max(stages, 1), -1

    def stage(self, label: str) -> None:
        self.done += 1
        self.within(label, 0.0)

    def within(self, label: str, fraction: float) -> None:
        if self.said is not None:
            self.said(label, min(1.0, (max(self.done, 0) + fraction) / self.stages))


def report_paths(output: Path | None, profile: str) -> tuple[Path, Path, Path]:
    """The HTML, its JSON twin and the recording: beside each other, named from ``output``
    or from the profile and the time."""
    if output is None:
        stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
        output = Path(f"report-{profile}-{stamp}.html")
    if output.suffix.lower() not in (".html", ".htm"):
        raise InvalidInput(f"-o {output}: the report is an .html file (its JSON twin goes "
                           "beside it)")
    if not output.parent.is_dir():
        raise InvalidInput(f"-o {output}: {output.parent} is not a directory")
    return output, output.with_suffix(".json"), output.with_suffix(".mcap")


def check_plan(plan: Plan) -> None:
    if plan.record_seconds is not None and not (
            math.isfinite(plan.record_seconds) and 0 < plan.record_seconds <= 3600):
        raise InvalidInput(f"--record must be a positive number of seconds up to 3600, got "
                           f"{plan.record_seconds:g}")
    if plan.golden is not None and not plan.golden.is_file():
        raise InvalidInput(f"--golden {plan.golden}: no such file")
    if len(plan.operator) > 200:
        raise InvalidInput("--operator: at most 200 characters")


def limits_of(robot: Robot) -> dict[str, float]:
    """The profile's `report:` limits over the defaults. A move settles within the
    profile's home_tolerance, so two returns home may differ by twice it, and a move may end
    up to it away (half as much again for what the joint does after the stop)."""
    from deltoctl.core.envelope import DEFAULT_TOLERANCE

    tolerance = robot.profile.safety.home_tolerance or DEFAULT_TOLERANCE
    limits = {**DEFAULTS, "home_repeatability": 2 * tolerance,
              "following_error": 1.5 * tolerance, **robot.profile.report}
    bad = [k for k, v in limits.items() if not (math.isfinite(v) and v > 0)]
    if bad or not 1 <= limits["homes"] <= 20:
        raise InvalidInput(f"{robot.profile.name}: report: {', '.join(bad) or 'homes'} must be "
                           "positive (homes: 1 to 20)")
    return limits


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


# -- identity and the bus scan -------------------------------------------------------------------

def identity_section(robot: Robot, steps: Steps | None = None
                     ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    steps = steps or Steps(None, 1)
    steps.stage("identify")
    ident = {b["name"]: b for b in robot.identify()["blocks"]}
    steps.stage("detect")
    found = robot.detect()
    detected = found["blocks"]
    blocks = [{"name": m.name, "family": m.family.name, "target": m.url or None,
               "simulated": m.simulated is not None,
               "identity": ident.get(m.name, {}).get("identity", {}),
               "detect": next((b["summary"] for b in detected if b["name"] == m.name), None)}
              for m in robot.blocks]
    return {"blocks": blocks}, found["checks"]


# -- the configuration ---------------------------------------------------------------------------

def fingerprint(live: dict[str, dict[str, Any]]) -> str:
    """The SHA-256 of the configuration's canonical form: every item's value (readings and
    commands left out) by block/part/item, as sorted compact JSON."""
    from deltoctl.app.config import live_values

    values = {"/".join(k): v.value for k, v in live_values(live).items() if not v.state}
    return _sha256(json.dumps(values, sort_keys=True, separators=(",", ":"),
                              default=str).encode())


def configuration_section(robot: Robot, golden: Path | None
                          ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The live configuration's fingerprint; with ``golden``, each difference from that
    approved snapshot is a failed check."""
    from deltoctl.app.config import check_against, differences, live_values, load_snapshot

    live, unable = read_config(robot)
    section: dict[str, Any] = {"fingerprint": fingerprint(live), "blocks": sorted(live),
                               "not_reported": unable}
    checks = []
    if golden is not None:
        snap = load_snapshot(golden)
        section["golden"] = {"file": str(golden), "sha256": _sha256(golden.read_bytes()),
                             "notes": check_against(snap, live, robot.profile)}
        rows = differences(snap.values, live_values(live), both_ways=False)
        for r in rows:
            where = f"{r['block']}/{r['part']}/{r['item']}"
            checks.append(check(f"config.{where}", f"{where} as approved", r["other"],
                                r["unit"] or "", verdict=FAIL,
                                note=f"approved: {r['snapshot']}"))
        checks.append(check("config.golden", "items that differ from the approved snapshot",
                            len(rows), "", None, 0))
    return section, checks


def read_config(robot: Robot) -> tuple[dict[str, dict[str, Any]], list[str]]:
    from deltoctl.app.config import read_live

    return read_live(robot.system)


# -- link quality --------------------------------------------------------------------------------

def link_checks(m: Member, limits: dict[str, float], seconds: float) -> list[dict[str, Any]]:
    """One block read at LINK_RATE for ``seconds``: round trip p50/p99, error rate, the loop's
    rate and jitter, each against its limit."""
    from deltoctl.core.loop import CycleLoop, Histogram

    before = dict(m.driver.stats)
    rtt = Histogram()
    loop = CycleLoop(LINK_RATE, seconds)
    for _ in loop:
        start = time.perf_counter()
        m.driver.read()
        rtt.add(time.perf_counter() - start)
    s = loop.stats.summary()
    after = m.driver.stats
    packets = after["packets"] - before["packets"]
    errors = after["errors"] - before["errors"]
    rate = 100.0 * errors / packets if packets else 0.0
    n = m.name
    return [
        check(f"link.{n}.rtt_p50", f"{n}: round trip, median", rtt.percentile(50) * 1e3, "ms",
              None, limits["rtt_p50_ms"]),
        check(f"link.{n}.rtt_p99", f"{n}: round trip, p99", rtt.percentile(99) * 1e3, "ms",
              None, limits["rtt_p99_ms"]),
        check(f"link.{n}.error_rate", f"{n}: errors per packet", rate, "%", None,
              limits["error_rate_perc"], note=f"{errors} of {packets}"),
        check(f"link.{n}.loop_rate", f"{n}: loop rate at {LINK_RATE:g} Hz asked", s["real_rate"],
              "Hz", LINK_RATE * limits["loop_rate_ratio"], None),
        check(f"link.{n}.jitter_p99", f"{n}: period jitter, p99", s["period_jitter_p99_ms"],
              "ms", None, limits["jitter_p99_ms"]),
    ]


# -- motion --------------------------------------------------------------------------------------

def _range(joint: Any) -> tuple[float, float] | None:
    """Where a jog may go: the soft limits, else the limits, 2 % inside."""
    soft, hard = joint.soft_limits, joint.limits
    low = soft.lower if soft and soft.lower is not None else hard.lower if hard else None
    high = soft.upper if soft and soft.upper is not None else hard.upper if hard else None
    if low is None or high is None or not high > low:
        return None
    margin = 0.02 * (high - low)
    return low + margin, high - margin


def _move_in_steps(robot: Robot, targets: dict[str, float], step: float) -> dict[str, float]:
    """Move to ``targets`` in moves no larger than ``step``; each joint's final |error|."""
    while True:
        here = robot.read()
        moves = {j: here[f"{j}/position"] + max(-step, min(step, t - here[f"{j}/position"]))
                 for j, t in targets.items()}
        result = robot.move(moves)
        if all(abs(targets[j] - moves[j]) < 1e-9 for j in targets) or not result["settled"]:
            return {j: abs(v["target"] - v["position"]) for b in result["blocks"]
                    for j, v in b["joints"].items() if v["position"] is not None}


def motion_checks(robot: Robot, limits: dict[str, float], steps: Steps | None = None
                  ) -> list[dict[str, Any]]:
    """Every block that can jog: N returns to the home pose, each from a step away (their
    spread per joint), then each joint to its soft limits and back (the error where each
    move ends). A joint whose position is not read (it does not answer) is left out."""
    checks: list[dict[str, Any]] = []
    steps = steps or Steps(None, 1)
    for m in robot.system.able("jog"):
        steps.stage(f"motion: {m.name}")
        ranges = {j.name: r for j in m.hw.joints if (r := _range(j)) is not None}
        values = robot.read()
        for j in [j for j in ranges if f"{j}/position" not in values]:
            del ranges[j]  # its detect check fails
            checks.append(check(f"motion.{j}", f"{j}: motion", None, verdict=SKIP,
                                note="no position read: not moved"))
        if not ranges:
            continue
        try:
            m.driver.check_motion(list(ranges))
        except Refused as exc:
            checks.append(check(f"motion.{m.name}", f"{m.name}: motion", None, verdict=SKIP,
                                note=exc.message))
            continue
        checks += _block_motion(robot, m.name, ranges, limits, steps)
    return checks


def _block_motion(robot: Robot, block: str, ranges: dict[str, tuple[float, float]],
                  limits: dict[str, float], steps: Steps) -> list[dict[str, Any]]:
    """One block's returns home and moves to the soft limits and back, its joints' checks."""
    profile, checks = robot.profile, []
    step = profile.safety.max_jog_step or 0.2
    home = {j: min(max(profile.safety.home_pose.get(j, 0.0), lo), hi)
            for j, (lo, hi) in ranges.items()}
    seen: dict[str, list[float]] = {j: [] for j in ranges}
    homes = int(limits["homes"])
    for i in range(homes):
        steps.within(f"motion: {block}: return home {i + 1} of {homes}", i / (homes + 2))
        away = {j: min(max(h + (step / 2 if i % 2 else -step / 2), ranges[j][0]),
                       ranges[j][1]) for j, h in home.items()}
        _move_in_steps(robot, away, step)
        _move_in_steps(robot, home, step)
        values = robot.read()
        for j in ranges:
            seen[j].append(values[f"{j}/position"])
    errors: dict[str, float] = {}
    for side, side_name in enumerate(("lower", "upper")):
        steps.within(f"motion: {block}: {len(ranges)} joints to their {side_name} soft limits",
                     (homes + side) / (homes + 2))
        ends = _move_in_steps(robot, {j: r[side] for j, r in ranges.items()}, step)
        errors = {j: max(errors.get(j, 0.0), e) for j, e in ends.items()}
    ends = _move_in_steps(robot, home, step)
    for j in ranges:
        checks.append(check(f"motion.{j}.home_repeatability",
                            f"{j}: spread of {len(seen[j])} returns home",
                            max(seen[j]) - min(seen[j]), "rad", None,
                            limits["home_repeatability"]))
        checks.append(check(f"motion.{j}.following_error",
                            f"{j}: error at its soft limits and back",
                            max(errors.get(j, 0.0), ends.get(j, 0.0)), "rad", None,
                            limits["following_error"]))
    return checks


# -- sensors -------------------------------------------------------------------------------------

def sensor_checks(robot: Robot, actuate: bool) -> list[dict[str, Any]]:
    """Each IMU's gravity check, and with ``actuate`` (--yes) its self-test; each F/T
    sensor's residual after a tare, with ``actuate`` only: a tare and a self-test write to
    the devices, and a report without --yes only reads."""
    from deltoctl.app import imu_calibration
    from deltoctl.app.calibrate import tare_ft, verify_ft

    checks, skipped = [], []
    for m in robot.system.able("calibrate_imu"):
        if actuate:
            checks += imu_calibration.self_test_checks(m.driver)
        else:
            skipped.append("each IMU's self-test")
        checks += imu_calibration.gravity_checks(m.driver, 50)
    if any(s.state("force.x") for m in robot.system.able("calibrate_ft") for s in m.hw.sensors):
        if actuate:
            checks += verify_ft(robot.system, tare_ft(robot.system, samples=20))
        else:
            skipped.append("each F/T sensor's tare")
    if skipped:
        runs = " and ".join(sorted(set(skipped)))
        checks.append(check("sensors.actuated", "sensor checks that write", None, verdict=SKIP,
                            note=f"not asked for (--yes runs {runs})"))
    return checks


# -- the recording and its plots -----------------------------------------------------------------

def _finite_or_none(value: float) -> float | None:
    """A value as JSON holds it: NaN and infinities (not JSON numbers) as null."""
    return value if math.isfinite(value) else None


def position_unit(robot: Robot, names: list[str]) -> str:
    """The unit of these joints' positions: rad, m (prismatic), or both."""
    units = []
    for name in names:
        joint = robot.profile.component(name.rsplit("/", 1)[0])
        unit = "m" if joint is not None and joint.joint_type == "prismatic" else "rad"
        if unit not in units:
            units.append(unit)
    return ", ".join(units)


def plots(path: Path, robot: Robot | None = None) -> list[dict[str, Any]]:
    """A figure per kind of interface the recording carries (positions, forces,
    accelerations): its unit, range and duration, and each series's samples (seconds from
    the figure's start, values; null where not finite), read with the standard library."""
    from deltoctl.record.reader import interfaces, read_recording, sampled_series, select

    rec = read_recording(path, keep=None)
    available = interfaces(rec)
    figures = []
    for title, glob, unit in PLOTS:
        wanted = select(available, [glob])[:MAX_SERIES]
        if not wanted:
            continue
        data = sampled_series(rec, wanted, MAX_POINTS)
        times = [t for ts, _ in data.values() for t in ts]
        if not times:
            continue
        finite = [v for _, vs in data.values() for v in vs if math.isfinite(v)]
        t0, t1 = min(times), max(times)
        if not unit:
            unit = position_unit(robot, wanted) if robot is not None else "rad"
        figures.append({
            "title": title, "unit": unit,
            "low": min(finite) if finite else None, "high": max(finite) if finite else None,
            "seconds": round((t1 - t0) / 1e9, 3),
            "series": [{"name": n, "t": [round((t - t0) / 1e9, 4) for t in data[n][0]],
                        "v": [_finite_or_none(v) for v in data[n][1]]} for n in wanted]})
    return figures


def recording_section(robot: Robot, seconds: float, path: Path) -> dict[str, Any]:
    result = robot.record(path, 100.0, seconds)
    return {"file": str(path), "seconds": seconds, "sha256": _sha256(path.read_bytes()),
            "cycles": result.get("stats", {}).get("cycles") if isinstance(
                result.get("stats"), dict) else None,
            "plots": plots(path, robot)}


# -- the whole sequence ---------------------------------------------------------------------------

def _stage(name: str, run: Any, checks: list[dict[str, Any]]) -> Any:
    """One stage; a device error in it is that stage's failed check, and the sequence goes
    on (invalid input and refusals end it)."""
    try:
        return run()
    except (InvalidInput, Refused):
        raise
    except DeltoctlError as exc:
        checks.append(check(f"{name}.ran", f"the {name} stage ran", exc.message,
                            verdict=FAIL))
        return None


def _stages(robot: Robot, plan: Plan) -> int:
    """How many stages the sequence runs (for its progress)."""
    recording = plan.record_seconds is not None and plan.record_path is not None
    motion = len(list(robot.system.able("jog"))) if plan.motion else 0
    return 4 + len(robot.blocks) + motion + recording


def run_report(robot: Robot, plan: Plan, said: Said | None = None) -> dict[str, Any]:
    """The acceptance sequence; the report's JSON, its own hash last. ``said`` is told
    each stage as it starts (and how much of the sequence is done)."""
    check_plan(plan)
    limits = limits_of(robot)
    start, start_ns = _now(), time.time_ns()
    sections: dict[str, Any] = {}
    checks: list[dict[str, Any]] = []
    steps = Steps(said, _stages(robot, plan))

    found = _stage("identity", lambda: identity_section(robot, steps), checks)
    if found:
        sections["identity"], more = found
        checks += more
    steps.stage("configuration")
    found = _stage("configuration", lambda: configuration_section(robot, plan.golden), checks)
    if found:
        sections["configuration"], more = found
        checks += more
    for m in robot.blocks:
        steps.stage(f"link quality: {m.name}")
        checks += _stage("link", lambda m=m: link_checks(m, limits, plan.link_seconds),
                         checks) or []
    if plan.motion:
        checks += _stage("motion", lambda: motion_checks(robot, limits, steps), checks) or []
    else:
        checks.append(check("motion", "motion checks", None, verdict=SKIP,
                            note="not asked for (--yes runs them where the profile allows)"))
    steps.stage("sensors")
    checks += _stage("sensors", lambda: sensor_checks(robot, plan.motion), checks) or []
    if plan.record_seconds is not None and plan.record_path is not None:
        steps.stage(f"recording {plan.record_seconds:g} s")
        sections["recording"] = _stage(
            "recording", lambda: recording_section(robot, plan.record_seconds,
                                                   plan.record_path), checks)
    steps.within("done", 1.0)
    return _document(robot, plan, checks, sections, limits, (start, start_ns))


def _document(robot: Robot, plan: Plan, checks: list[dict[str, Any]],
              sections: dict[str, Any], limits: dict[str, float],
              started: tuple[str, int]) -> dict[str, Any]:
    """The report's JSON, its own hash last: SIMULATED when a block was simulated, so that
    a rehearsal is never taken for an acceptance."""
    from deltoctl.version import __version__

    start, start_ns = started
    warnings = robot.warnings()
    verdict = overall(checks)
    if verdict == PASS and warnings:
        verdict = WARN
    simulated = [m.name for m in robot.blocks if m.simulated is not None]
    source = robot.profile.source
    profile_hash = _sha256(Path(source).read_bytes()) if source and Path(source).is_file() \
        else None
    doc = {
        "kind": "deltoctl_report", "format": FORMAT,
        "header": {"profile": {"name": robot.profile.name, "file": source,
                               "sha256": profile_hash},
                   "deltoctl": __version__, "host": socket.gethostname(),
                   "operator": plan.operator or _user(), "start": start, "end": _now(),
                   "start_ns": start_ns, "limits": limits},
        "verdict": verdict, "simulated": simulated, "failed": failed(checks),
        "warnings": warnings,
        "sections": sections,
        "checks": sorted(checks, key=lambda c: SEVERITY[c["verdict"]]),
    }
    doc["report_sha256"] = report_hash(doc)
    return doc


def report_hash(doc: dict[str, Any]) -> str:
    """The SHA-256 of the report's canonical JSON, its own hash left out."""
    body = {k: v for k, v in doc.items() if k != "report_sha256"}
    return _sha256(json.dumps(body, sort_keys=True, separators=(",", ":"),
                              default=str).encode())


def _user() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return "unknown"


def fleet_report(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Each robot's report (``fleet run report``: robot, exit_code, output, error) in one
    document, the worst first; a robot without one fails."""
    robots = []
    for run in runs:
        doc = run.get("output")
        ok = isinstance(doc, dict) and doc.get("kind") == "deltoctl_report"
        robots.append({"robot": run["robot"], "exit_code": run.get("exit_code"),
                       "verdict": doc.get("verdict", FAIL) if ok else FAIL,
                       "failed": doc.get("failed", []) if ok else [],
                       "error": run.get("error"), "report": doc if ok else None})
    robots.sort(key=lambda r: (SEVERITY.get(r["verdict"], 0), r["robot"]))
    verdicts = [r["verdict"] for r in robots]
    verdict = FAIL if FAIL in verdicts else WARN if WARN in verdicts else PASS
    doc = {"kind": "deltoctl_fleet_report", "format": FORMAT, "verdict": verdict,
           "time": _now(), "robots": robots}
    doc["report_sha256"] = report_hash(doc)
    return doc


def _write(html: Path, text: str, doc: dict[str, Any]) -> Path:
    html.write_text(text, encoding="utf-8")
    twin = html.with_suffix(".json")
    twin.write_text(json.dumps(doc, indent=2, default=str) + "\n", encoding="utf-8")
    return twin


Render = Callable[[dict[str, Any]], str]  # a document → its HTML page


def write_report(doc: dict[str, Any], html: Path, render: Render) -> Path:
    """Write a report as ``html`` (the page ``render`` makes of it) and its JSON twin
    beside it; returns the twin."""
    return _write(html, render(doc), doc)


def write_fleet_report(runs: list[dict[str, Any]], render: Render
                       ) -> tuple[dict[str, Any], Path]:
    """Every robot's report (``fleet run report``'s runs, each report taken out of the
    JSON envelope it may come in) in one fleet report, written as
    fleet-report-<time>.html here (the page ``render`` makes of it) and its JSON twin; the
    document and the HTML file."""
    for run in runs:
        out = run.get("output")
        if isinstance(out, dict) and out.get("verb") == "report" and "result" in out:
            run["output"] = out["result"]
    doc = fleet_report(runs)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    html = Path(f"fleet-report-{stamp}.html")
    _write(html, render(doc), doc)
    return doc, html
