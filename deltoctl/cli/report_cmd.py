"""``deltoctl report``: the commissioning report — the acceptance sequence on a robot, one
self-contained HTML file and its JSON twin."""

from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import AllowMismatch, open_robot
from deltoctl.cli.output import emit_json, info, progress, say, table, warn
from deltoctl.errors import WARNINGS
from deltoctl.verb_help import DESCRIPTIONS


def register(root: typer.Typer) -> None:
    root.command("report", help=DESCRIPTIONS["report"])(report)


def report(
    ctx: typer.Context,
    output: Annotated[Path | None, typer.Option(
        "--output", "-o", metavar="FILE.html",
        help="The HTML report; its JSON twin is FILE.json (default: "
             "report-<profile>-<time>.html).")] = None,
    golden: Annotated[Path | None, typer.Option(
        metavar="SNAPSHOT", help="An approved config snapshot: each difference fails.")] = None,
    record: Annotated[float | None, typer.Option(
        metavar="SECONDS", help="Record that long (FILE.mcap) and plot it in the report.")
    ] = None,
    operator: Annotated[str, typer.Option(
        help="Who ran the acceptance (default: the user).")] = "",
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    from deltoctl.app.checks import fail_on
    from deltoctl.app.report import Plan, check_plan, report_paths, run_report, write_report
    from deltoctl.render.checks import check_rows, verdict_text
    from deltoctl.render.progress import stages
    from deltoctl.render.report_html import report_html

    opts = options(ctx)
    profile = opts.load_profile()
    html, twin, mcap = report_paths(output, profile.name)
    plan = Plan(golden, record, mcap if record is not None else None, operator, opts.yes)
    check_plan(plan)
    bar = progress(opts, elapsed=True)
    try:
        said = stages(bar, "report", None if opts.json else info)
        said("connect", 0.0)
        with open_robot(opts, allow_model_mismatch, profile) as robot:
            doc = run_report(robot, plan, said)
    finally:
        if bar is not None:
            bar.stop()
    write_report(doc, html, report_html)
    if opts.json:
        emit_json(doc)
    else:
        table(None, ["check", "value", "unit", "limit", "verdict"], check_rows(doc["checks"]))
        say(f"verdict: {verdict_text(doc)}")
    info(f"report: {html} and {twin.name}")
    fail_on(doc["checks"], "acceptance failed: ")
    if doc["verdict"] == "warn":
        for w in doc["warnings"]:
            warn(w)
        raise typer.Exit(WARNINGS)


def fleet_summary(runs: list[dict[str, Any]], as_json: bool, code: int) -> None:
    """``fleet run report``: every robot's report gathered in one fleet report (a table per
    robot, the worst first), fleet-report-<time>.html and its JSON twin; exits with the
    fleet's worst code."""
    from deltoctl.app.report import write_fleet_report
    from deltoctl.render.fleet import report_rows
    from deltoctl.render.report_html import fleet_html

    doc, html = write_fleet_report(runs, fleet_html)
    if as_json:
        emit_json(doc)
    else:
        table(None, ["robot", "verdict", "failed"], report_rows(doc))
    info(f"fleet report: {html} and {html.with_suffix('.json').name}")
    raise typer.Exit(code)
