"""The run figure: angles and speeds on separate axes, a unit in every axis label, every line of an
axis distinguishable (colour, dash), legends beside the data, never over it."""

from __future__ import annotations

from pathlib import Path

import pytest

from cotwin.plot import draw
from cotwin.twin.assembly.run import figure_panels, load, monitored_units

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ur5e():
    return load(ROOT / "examples" / "ur5e" / "cotwin.toml")


def test_monitored_variables_are_grouped_by_unit(ur5e):
    units = monitored_units(ur5e)
    assert units["q0"] == ("joint angle", "rad") and units["qd5"] == ("joint speed", "rad/s")
    panels = {label: names for label, names, _ in figure_panels(ur5e)}
    angles = next(names for label, names in panels.items() if label.endswith("joint angle [rad]"))
    speeds = next(names for label, names in panels.items() if label.endswith("joint speed [rad/s]"))
    assert angles == [f"{{mapping}}.mapping.q{i}" for i in range(6)]
    assert speeds == [f"{{mapping}}.mapping.qd{i}" for i in range(6)]


def test_a_walks_readings_take_their_sensors_units():
    walk = load(ROOT / "examples" / "turtlebot" / "live.toml")
    units = monitored_units(walk)
    assert units, "the walk monitors readings"
    assert {unit for _, unit in units.values()} <= {"m", "deg", "rad", "rad/s", "m/s"}, units


def test_every_axis_names_a_unit_lines_differ_and_legends_sit_beside_the_data(ur5e):
    panels = figure_panels(ur5e)
    columns = {name for _, names, _ in panels for name in names}
    cols = {"time": [0.0, 1.0, 2.0]} | {c: [0.0, float(k), 2.0 * k] for k, c in enumerate(sorted(columns))}
    fig = draw(cols, panels, "test")
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    axes = fig.axes
    assert len(axes) == len([p for p in panels if p[1]])
    for ax in axes:
        label = ax.get_ylabel()
        assert "[" in label and label.endswith("]"), label
        styles = [(line.get_color(), line.get_linestyle()) for line in ax.get_lines()]
        assert len(set(styles)) == len(styles), (label, styles)
        legend = ax.get_legend()
        assert legend is not None, label
        box, plotted = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
        assert box.x0 >= plotted.x1 - 1, f"{label}: the legend overlaps the plotted area"
    assert axes[-1].get_xlabel() == "time [s]"
