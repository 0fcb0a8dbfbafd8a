"""``deltoctl doctor [-p PROFILE]``: what stops a bring-up, found before any byte is sent.

One line per check, ✔ or ✘, and for each ✘ the fix to type: the profile is valid; every bus
has a target; and what the target's transport checks of it (deltoctl.transport: a device
node is there, this user may open it and no process holds it; a host has a route from this
one and accepts a connection). Exit 0 only when every check passes: 2 when the profile or a
target is invalid, 4 when a device cannot be reached or opened.
"""

from __future__ import annotations

import contextlib
from typing import Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.output import emit_json, say
from deltoctl.errors import USAGE, DeltoctlError
from deltoctl.transport.doctor import check


def register(app: typer.Typer) -> None:
    app.command("doctor")(doctor)


def doctor(
    ctx: typer.Context,
    timeout: Annotated[float, typer.Option(
        "--timeout", help="Seconds to wait for each target to accept a connection.")] = 1.0,
) -> None:
    """Check the set-up before a bring-up: profile, ports, buses, routes, targets.

    One line per check with the fix to type; exit 0 only when all pass. Without -p: the
    -t URLs, or what each transport finds on this host (its ports and buses)."""
    opts = options(ctx)
    results: list[dict[str, Any]] = []
    profile = None
    with contextlib.ExitStack() as stack:
        if opts.profile:
            profile = _profile_check(opts, results)
        targets = _targets(opts, profile, stack, results) if profile else _bare(opts)
        if not opts.profile and not targets:
            results += _host_checks()
        for bus, (url, families) in targets.items():
            results += url_checks(bus, url, families, timeout)
    _render(opts, profile, results)
    failed = [r["exit_code"] for r in results if not r["ok"]]
    if failed:
        raise typer.Exit(USAGE if USAGE in failed else max(failed))


def _render(opts: Options, profile: Any, results: list[dict[str, Any]]) -> None:
    if opts.json:
        emit_json({"profile": getattr(profile, "name", opts.profile),
                   "ok": all(r["ok"] for r in results), "checks": results})
        return
    width = max([len(r["subject"]) for r in results] + [0])
    for r in results:
        say(f"{'✔' if r['ok'] else '✘'} {r['subject']:<{width}}  {r['check']}: {r['detail']}")
        if r["fix"]:
            say(f"  {'':<{width}}  fix: {r['fix']}")
    passed = sum(r["ok"] for r in results)
    say(f"{passed} of {len(results)} checks passed")


# -- the profile and its targets ------------------------------------------------------------

def _profile_check(opts: Options, results: list[dict[str, Any]]) -> Any:
    try:
        prof = opts.load_profile()
    except DeltoctlError as exc:
        results.append(check("profile", str(opts.profile), False, exc.message,
                             f"deltoctl profile validate {opts.profile}", USAGE))
        return None
    c = prof.counts()
    note = f"; {len(prof.warnings)} warning(s)" if prof.warnings else ""
    results.append(check("profile", prof.name, True, f"valid: {c['joints']} joints, "
                         f"{c['sensors']} sensors, {c['gpios']} GPIOs{note}"))
    return prof


def _targets(opts: Options, prof: Any, stack: contextlib.ExitStack,
             results: list[dict[str, Any]]) -> dict[str, tuple[str, set[str]]]:
    """bus → (its URL, the families on it), for the selected blocks that use a transport."""
    from deltoctl import registry
    from deltoctl.core.system import parse_targets, select_blocks

    try:
        blocks = select_blocks(prof, opts.hardware)
        named, bare = parse_targets(prof, opts.target)
        if opts.sim:
            from deltoctl.app.robot import serve_simulators

            named = serve_simulators(stack, prof, opts.hardware)
    except DeltoctlError as exc:
        results.append(check("targets", prof.name, False, exc.message, None, USAGE))
        return {}
    targets: dict[str, tuple[str, set[str]]] = {}
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
        targets.setdefault(bus, (url, set()))[1].add(family.name)
    return targets


def _bare(opts: Options) -> dict[str, tuple[str, set[str]]]:
    """Targets given without a profile, each checked for itself (named by its bus, or by
    the URL)."""
    targets: dict[str, tuple[str, set[str]]] = {}
    for item in opts.target:
        name, found, url = item.partition("=")
        if not found or "://" in name:
            name, url = item, item
        targets[name] = (url, set())
    return targets


# -- one target -------------------------------------------------------------------------------

def url_checks(bus: str, url: str, families: set[str], timeout: float) -> list[dict[str, Any]]:
    """The checks of one bus's URL: those its transport (by the URL's scheme) names, with
    the advice of the families on the bus for a device that refuses."""
    from deltoctl import registry
    from deltoctl.transport import Target

    hints = tuple(f.refused_hint for f in map(registry.get, sorted(families))
                  if f is not None and f.refused_hint)
    try:
        transport = registry.transport_of(url)
        transport.parse(url)
        return transport.checks(Target(bus, url, timeout, hints))
    except DeltoctlError as exc:
        return [check("target", bus, False, exc.message, exc.hint, exc.exit_code)]


# -- the host, when no profile is named -------------------------------------------------------

def _host_checks() -> list[dict[str, Any]]:
    """Each transport's look at this host (the ports and buses of its kind it finds)."""
    from deltoctl import registry

    return [c for t in registry.transports().values() if t.host_checks
            for c in t.host_checks()]
