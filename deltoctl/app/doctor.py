"""``deltoctl doctor``'s procedure: what stops a bring-up, found before any byte is sent.

The profile is valid; every bus has a target; and what the target's transport checks of it
(deltoctl.transport: a device node is there, this user may open it and no process holds it; a
host has a route from this one and accepts a connection). Without a profile: the targets
given, or what each transport finds on this host. A check is a dict (check, subject, ok,
detail, the fix to type, the exit code it stands for when it fails).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from deltoctl.errors import OK, USAGE, DeltoctlError
from deltoctl.transport.doctor import check

if TYPE_CHECKING:
    from deltoctl.profile.model import Profile
    from deltoctl.transport.adapters import SerialAdapter

Targets = dict[str, tuple[str, set[str], float]]  # bus → (its URL, its families, loop rate)
LOOP_HZ = 50.0  # the rate stream and record read a bus at unless the profile says another


def diagnose(profile: str | None, load: Callable[[], Profile], targets: Sequence[str] = (),
             hardware: Sequence[str] = (), sim: bool = False,
             timeout: float = 1.0) -> dict[str, Any]:
    """Every check of the set-up: ``{"profile", "ok", "checks"}``. ``profile``: the profile as
    named (None: none), read by ``load``; ``targets``: ``[BUS=]URL`` as given; ``sim``: each
    bus's simulator, started and stopped again here; ``timeout``: seconds each target has to
    accept a connection."""
    results: list[dict[str, Any]] = []
    prof = None
    with contextlib.ExitStack() as stack:
        if profile:
            prof = _profile_check(profile, load, results)
        found = (_targets(prof, targets, hardware, sim, stack, results) if prof
                 else _bare(targets))
        if not profile and not found:
            results += host_checks()
        for bus, (url, families, rate) in found.items():
            results += url_checks(bus, url, families, timeout, rate)
    return {"profile": getattr(prof, "name", profile),
            "ok": all(r["ok"] for r in results), "checks": results}


def exit_code(checks: list[dict[str, Any]]) -> int:
    """0 when every check passes; else 2 when the profile or a target is invalid, or the
    highest exit code of the checks that failed (4: a device cannot be reached or opened)."""
    failed = [r["exit_code"] for r in checks if not r["ok"]]
    if not failed:
        return OK
    return USAGE if USAGE in failed else max(failed)


# -- the profile and its targets ------------------------------------------------------------

def _profile_check(spec: str, load: Callable[[], Profile],
                   results: list[dict[str, Any]]) -> Profile | None:
    try:
        prof = load()
    except DeltoctlError as exc:
        results.append(check("profile", spec, False, exc.message,
                             f"deltoctl profile validate {spec}", USAGE))
        return None
    c = prof.counts()
    note = f"; {len(prof.warnings)} warning(s)" if prof.warnings else ""
    results.append(check("profile", prof.name, True, f"valid: {c['joints']} joints, "
                         f"{c['sensors']} sensors, {c['gpios']} GPIOs{note}"))
    return prof


def _targets(prof: Profile, given: Sequence[str], hardware: Sequence[str], sim: bool,
             stack: contextlib.ExitStack, results: list[dict[str, Any]]) -> Targets:
    """bus → (its URL, the families on it), for the selected blocks that use a transport."""
    from deltoctl import registry
    from deltoctl.core.system import parse_targets, select_blocks

    try:
        blocks = select_blocks(prof, list(hardware))
        named, bare = parse_targets(prof, list(given))
        if sim:
            from deltoctl.app.robot import serve_simulators

            named = serve_simulators(stack, prof, list(hardware))
    except DeltoctlError as exc:
        results.append(check("targets", prof.name, False, exc.message, None, USAGE))
        return {}
    targets: Targets = {}
    for hw in blocks:
        family = registry.of_block(prof.family_of(hw), hw.plugin)
        if family is None or not family.schemes:
            continue  # in-process: nothing to reach
        bus = hw.bus or hw.name
        url = named.get(bus) or (bare[0] if bare else prof.buses.get(bus))
        if not url:
            results.append(check("target", bus, False, f"{hw.name} has no URL",
                                 f"deltoctl -p {prof.name} -t {bus}=URL doctor", USAGE))
            continue
        _, families, rate = targets.get(bus, (url, set(), 0.0))
        families.add(family.name)
        targets[bus] = (url, families, max(rate, float(hw.rw_rate) or LOOP_HZ))
    return targets


def _bare(given: Sequence[str]) -> Targets:
    """Targets given without a profile, each checked for itself (named by its bus, or by
    the URL)."""
    targets: Targets = {}
    for item in given:
        name, found, url = item.partition("=")
        if not found or ":" in name:
            name, url = item, item
        targets[name] = (url, set(), 0.0)
    return targets


# -- one target -------------------------------------------------------------------------------

def url_checks(bus: str, url: str, families: set[str], timeout: float,
               rate_hz: float = 0.0) -> list[dict[str, Any]]:
    """The checks of one bus's URL: those its transport (by the URL's scheme) names, with
    the advice of the families on the bus for a device that refuses, and the rate a loop
    asks of the bus."""
    from deltoctl import registry
    from deltoctl.transport import Target

    hints = tuple(f.refused_hint for f in map(registry.get, sorted(families))
                  if f is not None and f.refused_hint)
    try:
        transport = registry.transport_of(url)
        transport.parse(url)
        return transport.checks(Target(bus, url, timeout, hints, rate_hz))
    except DeltoctlError as exc:
        return [check("target", bus, False, exc.message, exc.hint, exc.exit_code)]


# -- the host, when no profile is named -------------------------------------------------------

def host_checks() -> list[dict[str, Any]]:
    """Each transport's look at this host (the ports and buses of its kind it finds)."""
    from deltoctl import registry

    return [c for t in registry.transports().values() if t.host_checks
            for c in t.host_checks()]


# -- the udev rule ----------------------------------------------------------------------------

def udev_rule_text(profile: str | None, load: Callable[[], Profile],
                   targets: Sequence[str] = (), hardware: Sequence[str] = ()) -> str:
    """The udev rule of the profile's serial adapters (every USB one without a profile);
    Unreachable when there is none to name."""
    from deltoctl.errors import Unreachable
    from deltoctl.transport.adapters import udev_rule

    chosen = rule_adapters(profile, load, targets, hardware)
    if not chosen:
        raise Unreachable("no USB serial adapter to name",
                          hint="plug it in; deltoctl ports lists the adapters")
    return udev_rule(chosen)


def rule_adapters(profile: str | None, load: Callable[[], Profile],
                  targets: Sequence[str] = (),
                  hardware: Sequence[str] = ()) -> list[tuple[str, SerialAdapter]]:
    """(the /dev name to give, the adapter) of each serial bus of the profile, named
    PROFILE-BUS; without a profile, of every USB serial adapter, named deltoctl-SERIAL."""
    from deltoctl.transport.adapters import serial_adapters
    from deltoctl.transport.serial_port import adapter_of_target

    if not profile:
        return [(f"deltoctl-{a.serial or a.name}", a) for a in serial_adapters(holders=False)
                if a.vid]
    prof = load()
    results: list[dict[str, Any]] = []
    with contextlib.ExitStack() as stack:
        found = _targets(prof, targets, hardware, False, stack, results)
    chosen = []
    for bus, (url, _, _) in found.items():
        adapter = adapter_of_target(url)
        if adapter is not None and adapter.vid:
            chosen.append((f"{prof.name}-{bus}", adapter))
    return chosen


def install_udev_rule(text: str) -> list[str]:
    """Install the rule (root only), then have udev read it and apply it to the adapters
    plugged in now. What was done, one line each; Refused when this is not root."""
    import subprocess

    from deltoctl.errors import Refused
    from deltoctl.transport.adapters import RULES_FILE, root, under

    if os.geteuid() != 0:
        raise Refused(f"writing {RULES_FILE} needs root",
                      hint="sudo deltoctl doctor --write-udev-rule (with the same -p and -t), "
                           f"or: deltoctl doctor --udev-rule | sudo tee {RULES_FILE}")
    path = under(root(), RULES_FILE)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    done = [f"wrote {path}"]
    if root() != "/":
        return done  # a laid-out tree: no udev to tell
    for argv in (["udevadm", "control", "--reload"], ["udevadm", "trigger", "--action=add",
                                                      "--subsystem-match=tty",
                                                      "--subsystem-match=usb-serial"]):
        try:
            subprocess.run(argv, check=True, capture_output=True, timeout=30)
            done.append(" ".join(argv))
        except (OSError, subprocess.SubprocessError) as exc:
            done.append(f"{' '.join(argv)} failed ({exc}): run it by hand")
    return done
