"""``deltoctl config snapshot|diff|restore``: every block's configuration in one YAML file,
compared with the live devices or another snapshot, and written back where it differs (the
model and its checks: deltoctl.app.config)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.output import emit_json, info, say, table, warn
from deltoctl.errors import WARNINGS

if TYPE_CHECKING:
    from deltoctl.app.config import Snapshot


def register(root: typer.Typer) -> None:
    config = typer.Typer(help="Snapshot every block's configuration, compare it, restore it.",
                         no_args_is_help=True)
    config.command("snapshot")(snapshot)
    config.command("diff")(diff)
    config.command("restore")(restore)
    root.add_typer(config, name="config")


# -- snapshot ----------------------------------------------------------------------------------


def snapshot(
    ctx: typer.Context,
    output: Annotated[str | None, typer.Option(
        "--output", "-o", metavar="FILE",
        help="Where to write it (a directory: the default name in it; -: stdout). Default: "
             "config-<profile>[-<address>]-<time>.yaml here.")] = None,
) -> None:
    """Read every configurable value of every block (--hardware narrows) into one YAML file:
    the whole control table of each servo, the Bioscara joints' parameters, the gripper's
    firmware and sensors, the IMU's registers. --json prints the document."""
    from deltoctl.app import config
    from deltoctl.cli.device_cmd import finish, open_robot

    opts = options(ctx)
    with open_robot(opts) as robot:
        doc, live = config.snapshot(robot.system)
    if output != "-":
        info(f"snapshot: {config.write_snapshot(doc, live, output)}")
    elif not opts.json:
        typer.echo(config.dump_yaml(doc), nl=False)
    if opts.json:
        emit_json(doc)
    elif output != "-":
        table(None, ["block", "family", "target", "parts", "items"],
              [[name, b["family"], b["target"] or "in-process", len(b["parts"]),
                sum(len(items) for items in b["parts"].values())] for name, b in live.items()])
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

    opts = options(ctx)
    snap = config.load_snapshot(snapshot_file)
    if other is not None:
        rows, notes = config.compare_files(snap, config.load_snapshot(other))
        against, column = str(other), "other"
    else:
        from deltoctl.cli.device_cmd import open_robot

        with open_robot(opts, profile=_profile(opts, snap)) as robot:
            rows, notes = config.compare_live(robot.system, snap)
        notes = robot.warnings() + notes
        against, column = "live", "live"
    if opts.json:
        emit_json({"snapshot": str(snapshot_file), "against": against, "same": not rows,
                   "differences": rows, "warnings": notes})
    elif rows:
        table(None, ["block", "part", "item", "snapshot", column, "unit"],
              [[r["block"], r["part"], r["item"], config.show(r["snapshot"]),
                config.show(r[column]), r["unit"] or ""] for r in rows])
    else:
        say(f"no differences between {snapshot_file} and "
            f"{'the live devices' if other is None else other}")
    for note in notes:
        warn(note)
    if rows or notes:
        raise typer.Exit(WARNINGS)


def _report(opts: Options, snapshot_file: Path, rows: list[dict[str, Any]],
            notes: list[str]) -> None:
    from deltoctl.app.config import show, status_counts

    counts = status_counts(rows)
    if opts.json:
        emit_json({"snapshot": str(snapshot_file), "items": rows, "summary": counts,
                   "warnings": notes})
    elif rows:
        table(None, ["block", "part", "item", "snapshot", "live", "status", "note"],
              [[r["block"], r["part"], r["item"], show(r["snapshot"]), show(r["live"]),
                r["status"], r["note"]] for r in rows])
        say(", ".join(f"{n} {status}" for status, n in counts.items()))
    else:
        say(f"nothing to restore: the devices match {snapshot_file}")
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
        help="Permit what a restore does not do unasked (repeatable): torque-off (switch a "
             "servo's torque off for its EEPROM writes, on again after), home-offset (write "
             "a joint's stored home offset), or a safety setting by its item name, e.g. "
             "max-position-limit (limits, shutdown, homing offset and modes are written "
             "only when named).")] = None,
) -> None:
    """Write back what differs from a snapshot, in the order each device requires, after
    confirmation (--yes skips it); each item is verified by reading it back. A value outside
    its item's documented range is exit 2, before anything is written. Exit 1 when a
    verification fails, 5 when refused for safety (EEPROM with torque on, a safety setting
    not named by --allow), 3 when some items could not be written (read-only)."""
    from deltoctl.app import config
    from deltoctl.cli.confirm import confirm
    from deltoctl.cli.device_cmd import open_robot

    opts = options(ctx)
    permitted = frozenset(config.permission(a) for a in allow or ())
    snap = config.load_snapshot(snapshot_file)  # a bad snapshot stops here, before any device
    with open_robot(opts, profile=_profile(opts, snap)) as robot:
        rows, notes = config.plan_restore(robot.system, snap, permitted)
        writes = [r for r in rows if r["status"] == "write"]
        refused = [r for r in rows if r["status"] == "refused"]
        if refused:
            _report(opts, snapshot_file, rows, notes)
            raise config.refusal(refused, permitted)
        if writes:
            confirm(ctx, config.description(writes))
            config.write_changes(robot.system, rows, permitted)
        notes = robot.warnings() + notes
    _report(opts, snapshot_file, rows, notes)
    left = config.restore_outcome(rows)  # refused 5, failed 1, not all restored 3
    if left:
        warn(left)
    if left or notes:
        raise typer.Exit(WARNINGS)
