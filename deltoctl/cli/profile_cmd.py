"""``deltoctl profile list|show|validate|import|export``."""

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info, say, table
from deltoctl.errors import WARNINGS, DeltoctlError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.profile.model import Profile

app = typer.Typer(help="Browse, check and convert device profiles.", no_args_is_help=True)

ProfileArg = Annotated[str | None, typer.Argument(
    metavar="[PROFILE]", help="Catalog name or file; default: the --profile option.",
    autocompletion=lambda incomplete: _complete_profile(incomplete))]


def _summary(profile: Any) -> dict[str, Any]:
    return {
        "name": profile.name,
        "family": profile.family or ",".join(
            sorted({profile.family_of(h) or "?" for h in profile.hardware})),
        "model": profile.model,
        "status": profile.status,
        "description": profile.description,
        **profile.counts(),
        "source": profile.source,
    }


@app.command("list")
def list_profiles(ctx: typer.Context) -> None:
    """List the built-in profile catalog."""
    from deltoctl.profile.catalog import catalog_summaries

    summaries = catalog_summaries(_summary)
    if options(ctx).json:
        emit_json(summaries)
        return
    table(None, ["name", "family", "model", "joints", "sensors", "gpios", "status"],
          [[s["name"], s["family"], s["model"], s["joints"], s["sensors"], s["gpios"],
            s["status"]] for s in summaries])


def _range_text(lower: float | None, upper: float | None) -> str:
    low = "-inf" if lower is None else f"{lower:.4g}"
    high = "inf" if upper is None else f"{upper:.4g}"
    return f"[{low}, {high}]"


def _limits_text(joint: Any) -> str:
    """The hard position limits, and the soft ones (a <safety_controller>) beside them."""
    lim, soft = joint.limits, joint.soft_limits
    parts = []
    if lim is not None and (lim.lower is not None or lim.upper is not None):
        unit = "m" if joint.joint_type == "prismatic" else "rad"
        parts.append(f"{_range_text(lim.lower, lim.upper)} {unit}")
    if soft is not None:
        parts.append(f"soft {_range_text(soft.lower, soft.upper)}")
    return ", ".join(parts)


def _soft_limits_data(prof: Any) -> dict[str, dict[str, Any]]:
    """{block: {joint: soft limits}} for the joints that have them."""
    data: dict[str, dict[str, Any]] = {}
    for hw in prof.hardware:
        for joint in hw.joints:
            if joint.soft_limits is not None:
                data.setdefault(hw.name, {})[joint.name] = dict(vars(joint.soft_limits))
    return data


def _warn(prof: Any) -> None:
    for warning in prof.warnings:
        info(f"warning: {warning}")


def _completion_profile(ctx: typer.Context) -> "Profile | None":
    """The profile named on the command line being completed, or None.

    Completion runs while a command line is typed, on a file nobody chose to load yet: it
    reads YAML and plain URDF only, and never runs xacro (a ``.xacro`` file, or ``--xacro``
    on the line, completes nothing)."""
    from deltoctl.profile.catalog import load_profile

    root_params = ctx.find_root().params or {}
    spec = ctx.params.get("profile") or root_params.get("profile")
    if not spec:
        return None
    try:
        return load_profile(spec, xacro=bool(root_params.get("xacro")), expand=False)
    except DeltoctlError:
        return None


def complete_part(ctx: typer.Context, incomplete: str) -> list[str]:
    """Joint, sensor and GPIO names of the profile given on the command line."""
    prof = _completion_profile(ctx)
    if prof is None:
        return []
    return [c.name for _, c in prof.components() if c.name.startswith(incomplete)]


def complete_blocks(ctx: typer.Context, incomplete: str) -> list[str]:
    """The names of the profile's <ros2_control> blocks (for --hardware)."""
    prof = _completion_profile(ctx)
    if prof is None:
        return []
    return [hw.name for hw in prof.hardware if hw.name.startswith(incomplete)]


def complete_joints(ctx: typer.Context, incomplete: str) -> list[str]:
    """The profile's joint names only."""
    prof = _completion_profile(ctx)
    if prof is None:
        return []
    return [j.name for j in prof.joints() if j.name.startswith(incomplete)]


def complete_register_items(ctx: typer.Context, incomplete: str) -> list[str]:
    """Register item names of the profile's families that have registers (return_delay_time)."""
    from deltoctl import registry

    prof = _completion_profile(ctx)
    if prof is None:
        return []
    families = {registry.of_block(prof.family_of(hw), hw.plugin) for hw in prof.hardware}
    names = [n for f in families if f is not None for n in f.register_names()]
    return [n for n in dict.fromkeys(names) if n.startswith(incomplete.lower())]


def _complete_profile(incomplete: str) -> list[str]:
    from deltoctl.profile.catalog import catalog_names

    return [n for n in catalog_names() if n.startswith(incomplete)]


@app.command("show")
def show(
    ctx: typer.Context,
    profile: Annotated[str | None, typer.Argument(
        metavar="[PROFILE]", autocompletion=_complete_profile,
        help="Catalog name or file; default: the --profile option.")] = None,
    part: Annotated[str | None, typer.Argument(
        autocompletion=complete_part, help="Show only this joint, sensor or GPIO.")] = None,
) -> None:
    """Show a profile: hardware blocks, parts, interfaces and limits."""
    from deltoctl.profile.exporter import profile_data

    opts = options(ctx)
    if part is None and profile is not None and opts.profile and not _looks_like_profile(profile):
        profile, part = None, profile  # `-p dg-5f-right profile show rj_dg_1_1`
    prof = opts.load_profile(profile)
    _warn(prof)
    if part is not None:
        _show_part(prof, part, opts.json)
        return
    if opts.json:
        emit_json({**_summary(prof), "state_interfaces": prof.state_interfaces(),
                   "command_interfaces": prof.command_interfaces(),
                   "profile": profile_data(prof), "soft_limits": _soft_limits_data(prof),
                   "warnings": [str(w) for w in prof.warnings]})
        return
    say(f"{prof.name}: {prof.description}" + (" (discontinued)"
                                                  if prof.status == "discontinued" else ""))
    for bus, url in prof.buses.items():
        say(f"  bus {bus}: {url}")
    from deltoctl.profile.validate import part_address

    rows = []
    for hw, comp in prof.components():
        address = part_address(prof, hw, comp)
        rows.append([
            hw.name, comp.kind, comp.name,
            "" if address is None else str(address),
            ", ".join(i.name for i in comp.command_interfaces),
            ", ".join(i.name for i in comp.state_interfaces),
            _limits_text(comp) if comp.kind == "joint" else "",
        ])
    table(None, ["block", "kind", "name", "address", "commands", "states", "limits"], rows)


def _looks_like_profile(spec: str) -> bool:
    from deltoctl.profile.catalog import catalog_names

    return spec in catalog_names() or Path(spec).exists()


def _show_part(prof: Any, name: str, as_json: bool) -> None:
    from deltoctl.profile.exporter import component_data

    comp = prof.component(name)
    if comp is None:
        from deltoctl.suggest import did_you_mean

        names = [c.name for _, c in prof.components()]
        raise InvalidInput(f"{prof.name} has no joint, sensor or GPIO named {name!r}"
                           + did_you_mean(name, names))
    data = {"kind": comp.kind, **component_data(comp)}
    soft = comp.soft_limits if comp.kind == "joint" else None
    if soft is not None:
        data["soft_limits"] = dict(vars(soft))
    if as_json:
        emit_json(data)
        return
    hard = comp.limits
    hard_text = "" if hard is None else _range_text(hard.lower, hard.upper)
    say(f"{comp.kind} {comp.name}" + (f"  limits {hard_text}" if hard_text else ""))
    if soft is not None:
        say(f"  soft limits {_range_text(soft.lower, soft.upper)} "
            f"(k_position {soft.k_position:g}, k_velocity {soft.k_velocity:g})")
    rows = [["command", i.name, i.min, i.max, i.initial_value, i.data_type]
            for i in comp.command_interfaces]
    rows += [["state", i.name, i.min, i.max, i.initial_value, i.data_type]
             for i in comp.state_interfaces]
    table(None, ["direction", "interface", "min", "max", "initial", "type"], rows)


@app.command("validate")
def validate_cmd(
    ctx: typer.Context,
    profiles: Annotated[list[str] | None, typer.Argument(
        metavar="[PROFILE]...", help="Catalog names or files; default: --profile.")] = None,
    strict: Annotated[bool, typer.Option(
        "--strict", help="Warnings (what ros2_control lets through but deltoctl thinks wrong) "
                         "are errors.")] = False,
) -> None:
    """Check profiles against ros2_control's rules and deltoctl's own (exit 2 if any fails,
    3 if any has warnings)."""
    from deltoctl.profile.validate import validate

    opts = options(ctx)
    specs = list(profiles or []) or ([opts.profile] if opts.profile else [])
    if not specs:
        raise InvalidInput("no profile given: name one, or pass --profile")
    results = []
    failed: DeltoctlError | None = None
    warned = False
    for spec in specs:
        try:
            prof = opts.load_profile(spec)
            if strict:
                validate(prof, strict=True)
            notes = [str(w) for w in prof.warnings]
            warned = warned or bool(notes)
            results.append({"profile": spec, "ok": True, **prof.counts(), "warnings": notes})
            if not opts.json:
                c = prof.counts()
                say(f"ok: {spec} ({c['joints']} joints, {c['sensors']} sensors, "
                    f"{c['gpios']} gpios)")
                for note in notes:
                    info(f"warning: {note}")
        except DeltoctlError as exc:
            results.append({"profile": spec, "ok": False, "error": exc.message})
            failed = failed or exc
            if not opts.json:
                info(f"invalid: {exc.message}")
    if opts.json:
        emit_json(results)
    if failed:
        raise typer.Exit(failed.exit_code)
    if warned:
        raise typer.Exit(WARNINGS)


def _write(text: str, output: Path | None) -> None:
    if output is None:
        typer.echo(text, nl=False)
        return
    try:
        output.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InvalidInput(f"cannot write {output}: {exc.strerror}") from None
    info(f"wrote {output}")


def _written(ctx: typer.Context, prof: Any, fmt: str, text: str, output: Path | None) -> None:
    """The converted profile: to the file or stdout; with --json, one document saying what was
    written (the text itself in ``content`` when no file was named)."""
    if not options(ctx).json:
        _write(text, output)
        return
    if output is not None:
        _write(text, output)
    c = prof.counts()
    emit_json({"profile": prof.name, "source": prof.source, "format": fmt,
               "output": None if output is None else str(output.resolve()),
               "bytes": len(text.encode("utf-8")),
               "blocks": [hw.name for hw in prof.hardware],
               "joints": c["joints"], "sensors": c["sensors"], "gpios": c["gpios"],
               "warnings": [str(w) for w in prof.warnings],
               **({"content": text} if output is None else {})})


OutputOpt = Annotated[Path | None, typer.Option(
    "--output", "-o", help="Write to this file instead of stdout.")]
FORMATS = ("urdf", "xacro", "yaml")


def _complete_format(incomplete: str) -> list[str]:
    return [f for f in FORMATS if f.startswith(incomplete)]


@app.command("import")
def import_cmd(
    ctx: typer.Context,
    source: Annotated[str, typer.Argument(help="A URDF or xacro file with <ros2_control>.")],
    output: OutputOpt = None,
) -> None:
    """Read a URDF/xacro's <ros2_control> blocks and write them as a YAML profile (with
    --json: one document naming what was written)."""
    from deltoctl.profile.exporter import to_yaml

    prof = options(ctx).load_profile(source)
    _written(ctx, prof, "yaml", to_yaml(prof), output)


@app.command("export")
def export_cmd(
    ctx: typer.Context,
    profile: ProfileArg = None,
    fmt: Annotated[str, typer.Option(
        "--format", "-f", autocompletion=_complete_format, help="urdf (a loadable URDF), "
        "xacro (a macro of the <ros2_control> blocks) or yaml.")] = "urdf",
    output: OutputOpt = None,
) -> None:
    """Write a profile as a <ros2_control> URDF, a xacro macro, or YAML (with --json: one
    document naming what was written)."""
    from deltoctl.profile.exporter import to_urdf, to_yaml

    if fmt not in FORMATS:
        from deltoctl.suggest import did_you_mean

        raise InvalidInput(f"unknown --format {fmt!r}{did_you_mean(fmt, FORMATS)}: expected "
                           "urdf, xacro or yaml")
    prof = options(ctx).load_profile(profile)
    text = to_yaml(prof) if fmt == "yaml" else to_urdf(prof, macro=fmt == "xacro")
    _written(ctx, prof, fmt, text, output)


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="profile")
