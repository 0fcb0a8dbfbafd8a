"""``deltoctl profile list|show|validate|import|export|tests``."""

from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.completions import complete_part, complete_profile
from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info, say, table
from deltoctl.errors import InvalidInput
from deltoctl.verb_help import DESCRIPTIONS

app = typer.Typer(help="Browse, check and convert device profiles.", no_args_is_help=True)

ProfileArg = Annotated[str | None, typer.Argument(
    metavar="[PROFILE]", help="Catalog name or file; default: the --profile option.",
    autocompletion=complete_profile)]


@app.command("list")
def list_profiles(ctx: typer.Context) -> None:
    """List the built-in profile catalog."""
    from deltoctl.profile.catalog import catalog_summaries
    from deltoctl.profile.summary import summary
    from deltoctl.render.profile import catalog_table

    summaries = catalog_summaries(summary)
    if options(ctx).json:
        emit_json(summaries)
        return
    table(None, *catalog_table(summaries))


@app.command("show")
def show(
    ctx: typer.Context,
    profile: ProfileArg = None,
    part: Annotated[str | None, typer.Argument(
        autocompletion=complete_part, help="Show only this joint, sensor or GPIO.")] = None,
) -> None:
    """Show a profile: hardware blocks, parts, interfaces and limits."""
    from deltoctl.profile import summary
    from deltoctl.profile.catalog import catalog_names
    from deltoctl.render import profile as render

    opts = options(ctx)
    if part is None and profile is not None and opts.profile \
            and profile not in catalog_names() and not Path(profile).exists():
        profile, part = None, profile  # `-p dg-5f-right profile show rj_dg_1_1`
    prof = opts.load_profile(profile)
    for warning in prof.warnings:
        info(f"warning: {warning}")
    comp = None if part is None else summary.part(prof, part)
    if opts.json:
        emit_json(summary.show_data(prof) if comp is None else summary.part_data(comp))
        return
    for line in render.heading(prof) if comp is None else render.part_heading(comp):
        say(line)
    table(None, *(render.parts_table(prof) if comp is None else render.interfaces_table(comp)))


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
    from deltoctl.profile.summary import validation
    from deltoctl.render.profile import validation_lines

    opts = options(ctx)
    specs = list(profiles or []) or ([opts.profile] if opts.profile else [])
    if not specs:
        raise InvalidInput("no profile given: name one, or pass --profile")
    checked = []
    for spec in specs:
        result, code = validation(spec, opts.load_profile, strict)
        checked.append((result, code))
        for to_stdout, line in [] if opts.json else validation_lines(spec, result):
            (say if to_stdout else info)(line)
    if opts.json:
        emit_json([result for result, _ in checked])
    failed = [code for result, code in checked if not result["ok"]]
    code = failed[0] if failed else max(code for _, code in checked)
    if code:
        raise typer.Exit(code)


def _written(ctx: typer.Context, prof: Any, fmt: str, text: str, output: Path | None) -> None:
    """The converted profile: to the file or stdout; with --json, one document saying what was
    written (the text itself in ``content`` when no file was named)."""
    as_json = options(ctx).json
    if output is not None:
        try:
            output.write_text(text, encoding="utf-8")
        except OSError as exc:
            raise InvalidInput(f"cannot write {output}: {exc.strerror}") from None
        info(f"wrote {output}")
    elif not as_json:
        typer.echo(text, nl=False)
    if as_json:
        from deltoctl.profile.summary import written

        emit_json(written(prof, fmt, text, output))


OutputOpt = Annotated[Path | None, typer.Option(
    "--output", "-o", help="Write to this file instead of stdout.")]
FORMATS = ("urdf", "xacro", "yaml")


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
        "--format", "-f", autocompletion=lambda incomplete: [
            f for f in FORMATS if f.startswith(incomplete)], help="urdf (a loadable URDF), "
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


@app.command("tests", help=DESCRIPTIONS["profile tests"])
def tests_cmd(
    ctx: typer.Context,
    profile: ProfileArg = None,
    output: Annotated[Path, typer.Option(
        "--output", "-o", help="The folder of the tests (made if missing).")] = Path("tests"),
    force: Annotated[bool, typer.Option("--force", help="Overwrite the files.")] = False,
) -> None:
    from deltoctl.app.suite import write_suite

    opts = options(ctx)
    spec = profile or opts.profile
    if not spec:
        raise InvalidInput("no profile given: name one, or pass --profile")
    suite = write_suite(spec, output, force)
    if opts.json:
        emit_json(suite.data())
        return
    for path in (suite.test_file, suite.golden):
        if path is not None:
            info(f"wrote {path}")
    say(f"{len(suite.tests)} tests: {', '.join(suite.tests)}")


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="profile")
