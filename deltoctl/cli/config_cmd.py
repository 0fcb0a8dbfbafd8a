"""``deltoctl config snapshot|diff|restore``: every block's configuration in one YAML file,
compared with the live devices or another snapshot, and written back where it differs (the
model and its checks: deltoctl.app.config)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.output import emit_json, info, say, show, table, warn
from deltoctl.errors import WARNINGS
from deltoctl.verb_help import DESCRIPTIONS, OPTION_HELP

if TYPE_CHECKING:
    from deltoctl.app.config import Snapshot


def register(root: typer.Typer) -> None:
    config = typer.Typer(help="Snapshot every block's configuration, compare it, restore it.",
                         no_args_is_help=True)
    config.command("snapshot", help=DESCRIPTIONS["config snapshot"])(snapshot)
    config.command("diff")(diff)
    config.command("restore", help=DESCRIPTIONS["config restore"])(restore)
    root.add_typer(config, name="config")


# -- snapshot ----------------------------------------------------------------------------------


def snapshot(
    ctx: typer.Context,
    output: Annotated[str | None, typer.Option(
        "--output", "-o", metavar="FILE",
        help="Where to write it (a directory: the default name in it; -: stdout). Default: "
             "config-<profile>[-<address>]-<time>.yaml here.")] = None,
) -> None:
    from deltoctl.app import config
    from deltoctl.cli.device_cmd import finish, open_robot
    from deltoctl.render.config import snapshot_table

    opts = options(ctx)
    with open_robot(opts) as robot:
        doc, live = robot.config_read()
    if output != "-":
        info(f"snapshot: {config.write_snapshot(doc, live, output)}")
    elif not opts.json:
        typer.echo(config.dump_yaml(doc), nl=False)
    if opts.json:
        emit_json(doc)
    elif output != "-":
        table(*snapshot_table(live))
    finish(robot)


def _profile(opts: Options, snap: Snapshot) -> Any:
    """The profile named by -p, else the catalog profile the snapshot names."""
    from deltoctl.app.config import snapshot_profile

    name = snapshot_profile(snap, opts.profile)
    if name:
        info(f"profile {name} (from the snapshot)")
    return opts.load_profile(name)


def diff(
    ctx: typer.Context,
    snapshot_file: Annotated[Path, typer.Argument(metavar="SNAPSHOT",
                                                  help="A snapshot file.")],
    other: Annotated[Path | None, typer.Argument(
        metavar="[OTHER]", help="Another snapshot (default: the live devices).")] = None,
) -> None:
    """Compare a snapshot with the live devices (or with another snapshot): one row per
    item that differs. Exit 3 when they differ, 0 when they are the same."""
    from deltoctl.app import config
    from deltoctl.render.config import diff_table

    opts = options(ctx)
    snap = config.load_snapshot(snapshot_file)
    if other is not None:
        rows, notes = config.compare_files(snap, config.load_snapshot(other))
        against, column = str(other), "other"
    else:
        from deltoctl.cli.device_cmd import open_robot

        with open_robot(opts, profile=_profile(opts, snap)) as robot:
            rows = robot.config_diff(snap)
        notes, against, column = robot.warnings(), "live", "live"
    if opts.json:
        emit_json({"snapshot": str(snapshot_file), "against": against, "same": not rows,
                   "differences": rows, "warnings": notes})
    elif rows:
        table(*diff_table(rows, column))
    else:
        say(f"no differences between {snapshot_file} and "
            f"{'the live devices' if other is None else other}")
    for note in notes:
        warn(note)
    if rows or notes:
        raise typer.Exit(WARNINGS)


def _report(opts: Options, snapshot_file: Path, rows: list[dict[str, Any]],
            notes: list[str]) -> None:
    from deltoctl.app.config import status_counts
    from deltoctl.render.config import restore_parts

    counts = status_counts(rows)
    if opts.json:
        emit_json({"snapshot": str(snapshot_file), "items": rows, "summary": counts,
                   "warnings": notes})
    else:
        show(restore_parts(rows, counts, str(snapshot_file)))
    for note in notes:
        warn(note)


def _complete_allow(incomplete: str) -> list[str]:
    from deltoctl.app.config import permission_names

    return [n for n in permission_names() if n.startswith(incomplete)]


def restore(
    ctx: typer.Context,
    snapshot_file: Annotated[Path, typer.Argument(metavar="SNAPSHOT",
                                                  help="The snapshot to restore.")],
    allow: Annotated[list[str] | None, typer.Option(
        "--allow", metavar="WHAT", autocompletion=_complete_allow,
        help=OPTION_HELP["config restore --allow"])] = None,
) -> None:
    from deltoctl.app import config
    from deltoctl.cli.confirm import confirm
    from deltoctl.cli.device_cmd import open_robot
    from deltoctl.errors import Refused

    opts = options(ctx)
    for name in allow or ():
        config.permission(name)  # an unknown one stops here, before any device
    snap = config.load_snapshot(snapshot_file)  # a bad snapshot stops here, before any device
    with open_robot(opts, profile=_profile(opts, snap)) as robot:
        try:
            rows = robot.config_restore(snap, allow or (), lambda what: confirm(ctx, what))
        except Refused as exc:
            if hasattr(exc, "rows"):  # refused by the plan: its table first
                _report(opts, snapshot_file, exc.rows, exc.notes)
            raise
        notes = robot.warnings()
    _report(opts, snapshot_file, rows, notes)
    left = config.restore_outcome(rows)  # refused 5, failed 1, not all restored 3
    if left:
        warn(left)
    if left or notes:
        raise typer.Exit(WARNINGS)
