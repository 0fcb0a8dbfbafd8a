"""The report's figures: inline SVG from the standard library, parsed as XML — a path per
series broken where a value is not finite, round ticks, every text escaped."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from deltoctl.render.svg_plot import figure, nice_ticks

SVG = "{http://www.w3.org/2000/svg}"


def parse(text: str) -> ET.Element:
    return ET.fromstring(text)  # raises on anything that is not well-formed XML


def texts(svg: ET.Element) -> list[str]:
    return [t.text or "" for t in svg.iter(f"{SVG}text")]


def test_a_path_per_series_with_axes_ticks_unit_and_legend():
    t = [i / 10 for i in range(11)]
    svg = parse(figure("forces", "N", [("a/force.x", t, [math.sin(x) for x in t]),
                                        ("a/force.y", t, [2.0] * 11)]))
    paths = svg.findall(f"{SVG}path")
    assert [p.get("data-name") for p in paths] == ["a/force.x", "a/force.y"]
    assert paths[0].get("d").startswith("M") and paths[0].get("d").count("L") == 10
    labels = texts(svg)
    assert {"time [s]", "N", "a/force.x", "a/force.y", "0", "0.5", "1"} <= set(labels)
    assert svg.find(f"{SVG}title").text == "forces"


def test_not_finite_values_break_the_line_and_an_empty_series_says_so():
    t = [0.0, 1.0, 2.0, 3.0, 4.0]
    svg = parse(figure("p", "rad", [("j/position", t, [0.0, 1.0, math.nan, 2.0, math.inf]),
                                    ("k/position", t, [None] * 5), ("e/position", [], [])]))
    broken, empty, none = svg.findall(f"{SVG}path")
    assert broken.get("d") == broken.get("d").strip() and broken.get("d").count("M") == 2
    assert "nan" not in broken.get("d").lower() and "inf" not in broken.get("d").lower()
    assert empty.get("d") == "" and none.get("d") == ""
    assert "k/position (no finite values)" in texts(svg)


def test_nothing_to_draw_is_still_a_figure():
    svg = parse(figure("p", "rad", [("j/position", [0.0, 1.0], [math.nan, math.nan])]))
    assert "no finite values recorded" in texts(svg)
    assert parse(figure("p", "", []))  # no series at all


def test_a_flat_series_and_one_instant_get_a_range():
    svg = parse(figure("p", "rad", [("j/position", [5.0], [0.25])]))
    (path,) = svg.findall(f"{SVG}path")
    x, y = path.get("d")[1:].split()
    assert all(math.isfinite(float(v)) for v in (x, y))


def test_names_and_units_are_escaped():
    name = 'a<b>&"c\'/position'
    text = figure("<t>", "N·m & <x>", [(name, [0.0, 1.0], [0.0, 1.0])])
    svg = parse(text)
    assert "<b>" not in text and svg.find(f"{SVG}path").get("data-name") == name
    assert "N·m & <x>" in texts(svg) and name in texts(svg)


def test_ticks_are_round_and_cover_the_range():
    assert [round(v, 9) for v in nice_ticks(0, 1)] == [0, 0.2, 0.4, 0.6, 0.8, 1.0]
    ticks = nice_ticks(-0.13, 0.07)
    assert ticks[0] >= -0.13 and ticks[-1] <= 0.07 and 0.0 in ticks
    assert nice_ticks(3, 3) == [3] and nice_ticks(math.nan, 1) == []


def test_every_point_lies_in_the_plot_area():
    t = [i * 0.01 for i in range(200)]
    svg = parse(figure("p", "rad", [("a", t, [math.sin(x * 7) * 3 for x in t]),
                                    ("b", t, [-5.0 + x for x in t])]))
    width, height = (float(v) for v in svg.get("viewBox").split()[2:])
    for path in svg.findall(f"{SVG}path"):
        numbers = path.get("d").replace("M", " ").replace("L", " ").split()
        xs, ys = [float(v) for v in numbers[::2]], [float(v) for v in numbers[1::2]]
        assert min(xs) >= 0 and max(xs) <= width and min(ys) >= 0 and max(ys) <= height
