"""The commissioning report's HTML twin, and the fleet's: one self-contained HTML5 page each
(Jinja2 templates shipped in the package, inline CSS, the recording's figures as inline SVG
drawn by svg_plot): nothing is fetched when it is opened."""

from __future__ import annotations

from typing import Any

from deltoctl.render import svg_plot
from deltoctl.render.identity import label, word

VERDICTS = ("pass", "fail", "warn", "skip")


def _number(value: Any) -> Any:
    """A figure as people read it: six significant digits at most."""
    if isinstance(value, float):
        return f"{value:.6g}"
    return value


def _figure(plot: dict[str, Any]) -> Any:
    """A figure of the report's recording section as an ``<svg>`` element (marked safe:
    svg_plot escapes every text it draws)."""
    from markupsafe import Markup

    series = [(s["name"], s["t"], s["v"]) for s in plot["series"]]
    return Markup(svg_plot.figure(plot["title"], plot.get("unit", ""), series))


def _environment() -> Any:
    import jinja2

    env = jinja2.Environment(loader=jinja2.PackageLoader("deltoctl.render", "templates"),
                             autoescape=True, trim_blocks=True, lstrip_blocks=True)
    env.filters["num"] = lambda value: _number(word(value))
    env.filters["label"] = label
    env.filters["figure"] = _figure
    return env


def report_html(doc: dict[str, Any]) -> str:
    """A report (deltoctl.app.report.run_report's document) as one HTML5 page."""
    counts = {v: sum(c["verdict"] == v for c in doc["checks"]) for v in VERDICTS}
    return _environment().get_template("report.html.j2").render(r=doc, counts=counts)


def fleet_html(doc: dict[str, Any]) -> str:
    """A fleet report (deltoctl.app.report.fleet_report's document) as one HTML5 page."""
    return _environment().get_template("fleet.html.j2").render(f=doc)
