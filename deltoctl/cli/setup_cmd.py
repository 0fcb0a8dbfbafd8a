"""``deltoctl setup [JOINT]``: the servos (and CANopen drives) given the profile's IDs and rates,
one at a time or in place, planned, confirmed, applied and verified (deltoctl.app.setup)."""

from __future__ import annotations

import sys
from typing import Annotated, Any

import typer

from deltoctl.cli.confirm import confirm, on_terminal
from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info, show, warn
from deltoctl.errors import WARNINGS, InvalidInput


def register(app: typer.Typer) -> None:
    app.command("setup")(setup)


def setup(ctx: typer.Context,
          joint: Annotated[str | None, typer.Argument(
              help="The joint whose part is to be set up (default: each in turn).")] = None,
          in_place: Annotated[bool, typer.Option(
              "--in-place", help="IDs unique but not the profile's: readdress them all.")] = False,
          maps: Annotated[list[str] | None, typer.Option(
              "--map", metavar="ID=JOINT", help="In place: the servo at ID is JOINT's.")] = None,
          dry_run: Annotated[bool, typer.Option("--dry-run", help="The plan only.")] = False,
          reset: Annotated[str | None, typer.Option(
              "--factory-reset", metavar="all|keep-id|keep-id-baud",
              help="Factory reset first (Dynamixel; with --allow factory-reset).")] = None,
          allow: Annotated[list[str] | None, typer.Option(
              "--allow", metavar="NAME",
              help="Permit a factory reset, or a pinned safety setting.")] = None,
          wait: Annotated[float, typer.Option("--wait", min=0.001, max=1.0,
                                              help="Seconds a probe waits.")] = 0.01,
          ) -> None:
    """Give each servo the profile's ID and baud rate, each CANopen drive its node ID (LSS):
    one at a time (new servos, all at one ID: each joint's connected alone, found at any rate
    and protocol, its model checked; a drive by its serial, or the only one without a node
    ID) or --in-place. The plan is confirmed (--yes) before anything is written; each part is
    verified at its new ID and rate, then the items its joint's params pin (Operating Mode …)
    written where they differ and read back. Colliding replies: exit 5, nothing written."""
    from deltoctl.app import setup as app
    from deltoctl.render.setup import setup_parts

    opts = options(ctx)
    app.reset_allowed(reset, allow or [])
    mapping = app.parse_map(maps or [])
    if in_place and (joint or reset):
        raise InvalidInput("--in-place readdresses every servo: no JOINT, no --factory-reset")
    prof = opts.load_profile()
    with app.open_setup(prof, opts.target, sim=opts.sim_of(prof),
                        hardware=opts.hardware, reuse=not opts.sim_fresh, notice=info,
                        warn=warn, wait=wait, allow=allow or []) as run:
        if in_place:
            result = _apply(ctx, run.plan_in_place(mapping), run.apply_in_place, dry_run)
        elif joint:
            if run.connect_alone(joint) is not None:
                info(f"the simulator connected {joint} alone")
            result = _apply(ctx, run.plan_one(joint, reset), lambda p: run.apply_one(joint, p),
                            dry_run)
        else:
            result = _walk(ctx, run, reset, dry_run)
    if opts.json:
        emit_json(result)
    else:
        show(setup_parts(result))
    missing = [r["joint"] for r in result["joints"] if r["status"] == "missing"]
    if missing:
        warn(f"not found, left alone: {', '.join(missing)}")
        raise typer.Exit(WARNINGS)


def _apply(ctx: typer.Context, plan: Any, apply: Any, dry_run: bool) -> dict[str, Any]:
    """The plan shown and confirmed, then applied (the dry run's: the plan)."""
    from deltoctl.render.setup import step_lines

    if dry_run or not plan.steps:
        return (plan if dry_run else apply(plan)).as_dict()
    for line in step_lines(plan.as_dict()):
        info(line)
    confirm(ctx, f"write {len(plan.steps)} steps to the servos above")
    return apply(plan).as_dict()


def _walk(ctx: typer.Context, run: Any, reset: str | None, dry_run: bool) -> dict[str, Any]:
    """Each joint in the profile's order: connected alone (asked, or by the simulator)."""
    from deltoctl.render.setup import joint_lines, step_lines

    run.check_reset(reset)
    plan = run.wanted_plan()
    if dry_run:
        return plan.as_dict()
    if run.controls is None and not on_terminal() and any(map(run.asks_to_connect,
                                                             run.joints())):
        raise InvalidInput("setup asks for each servo to be connected alone: run it on a "
                           "terminal, or name the joint (setup JOINT) in a script")
    for line in joint_lines(plan.as_dict()) + step_lines(plan.as_dict()):
        info(line)
    if run.factory_last():
        info(run.factory_last())
    first = f"a factory reset ({reset}) of each, then " if reset else ""
    confirm(ctx, f"{first}give these {len(plan.joints)} servos their IDs and rates, one at "
                 "a time")

    def ask(w: Any, simulated: str | None) -> None:
        if simulated is not None:
            info(f"the simulator connected {w.joint} alone")
            return
        sys.stderr.write(run.ask_line(w.joint))
        sys.stderr.flush()
        if not sys.stdin.readline():  # the input closed: nobody is there to connect it
            warn(f"input closed: setup stopped before {w.joint}")
            raise typer.Exit(130)

    return run.walk(ask, reset, lambda row: info(joint_lines({"joints": [row]})[0])).as_dict()
