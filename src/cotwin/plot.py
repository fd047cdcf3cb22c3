"""A figure like the paper's Fig. 16 from a Maestro-format outputs.csv: commands and their arguments,
the d-model's operation calls, and the joint angles over time.

Every axis names its unit; variables of different units are on different axes (the twin chooses the
panels, cotwin.twin.assembly.run.figure_panels); within an axis each line has its own colour and, past ten
lines, its own dash pattern; legends sit beside the axes, never over the data."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .files import output  # noqa: E402


def read_csv(path: str | Path) -> dict[str, list]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, data = rows[0], rows[1:]
    columns: dict[str, list] = {h: [] for h in header}
    for row in data:
        for h, v in zip(header, row):
            columns[h].append(1.0 if v == "true" else 0.0 if v == "false" else float(v) if v else float("nan"))
    return columns


COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442",
           "#8C564B", "#7F7F7F")  # Okabe-Ito (colour-blind safe), then two of tab10's
DASHES = ("-", "--", "-.", ":")


def line_style(k: int) -> dict:
    """The k-th line of an axis: a colour of its own, and a dash pattern of its own past ten lines."""
    return {"color": COLOURS[k % len(COLOURS)], "linestyle": DASHES[(k // len(COLOURS)) % len(DASHES)]}


def legend_beside(ax, handles: int) -> None:
    """The axis' legend to its right, outside the plotted area: it never hides a line."""
    if handles:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0,
                  ncol=1 if handles <= 8 else 2, frameon=False)


def labelled(label: str) -> str:
    """A panel's label with a unit: one given in brackets is kept, else the values are the model's own."""
    return label if "[" in label else f"{label} [model units]"


def figure(csv_path: str | Path, png_path: str | Path, panels: list[tuple[str, list[str], str]],
           title: str = "") -> Path:
    """A figure like the paper's Fig. 16 from a Maestro-format outputs.csv: one panel per (label,
    columns, draw style); the twin chooses the columns from its models (see `figure_panels`)."""
    fig = draw(read_csv(csv_path), panels, title)
    with output(png_path) as f:  # a new file: never through a link left where the figure goes
        fig.savefig(f, format="png", dpi=90)
    plt.close(fig)
    return Path(png_path)


def draw(cols: dict[str, list], panels: list[tuple[str, list[str], str]], title: str = ""):
    """The matplotlib Figure of `figure`, from columns already read."""
    t = cols["time"]
    panels = [(label, [c for c in names if c in cols], style) for label, names, style in panels]
    panels = [p for p in panels if p[1]] or [("(no variables) [-]", [], "default")]
    fig, axes = plt.subplots(len(panels), 1, figsize=(11, 2.1 * len(panels) + 0.8), sharex=True, squeeze=False,
                             layout="constrained")
    for ax, (label, names, style) in zip(axes[:, 0], panels):
        for k, name in enumerate(names):
            ax.plot(t, cols[name], drawstyle=style, label=name.split(".")[-1], linewidth=1.2, **line_style(k))
        ax.set_ylabel(labelled(label), fontsize=8)
        ax.grid(True, alpha=0.3)
        legend_beside(ax, len(names))
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title)
    return fig


def twin_figure(pt_csv: str | Path, dt_csv: str | Path, alarms: list[dict], png_path: str | Path,
                variables: list[str], title: str = "", units: dict[str, str] | None = None) -> Path:
    """The live twin's figure: each monitored variable of the PT (solid) and the DT (dashed) over time,
    on its own axis labelled with its unit (`units`: short name -> unit), deviation alarms shaded from
    raised to cleared."""
    pt, dt = read_csv(pt_csv), read_csv(dt_csv)
    units = units or {}
    names = [v for v in variables if v in pt and v in dt]
    fig, axes = plt.subplots(max(len(names), 1), 1, figsize=(10, 1.7 * max(len(names), 1) + 1.2), sharex=True,
                             squeeze=False, layout="constrained")
    end = pt["time"][-1] if pt["time"] else 0.0
    for ax, name in zip(axes[:, 0], names):
        short = name.split(".")[-1]
        ax.plot(pt["time"], pt[name], label="PT", color=COLOURS[0])
        ax.plot(dt["time"], dt[name], label="DT", color=COLOURS[1], linestyle="--")
        raised = {}
        for e in alarms:
            if e["variable"] != short:
                continue
            if e["state"] == "raised":
                raised[short] = e["time"]
            elif short in raised:
                ax.axvspan(raised.pop(short), e["time"], color="tab:red", alpha=0.2)
        if short in raised:
            ax.axvspan(raised.pop(short), end, color="tab:red", alpha=0.2)
        ax.set_ylabel(f"{short} [{units.get(short) or 'model units'}]", fontsize=8)
        ax.grid(True, alpha=0.3)
    legend_beside(axes[0, 0], 2)
    axes[-1, 0].set_xlabel("time [s] (red: deviation alarm)")
    if title:
        fig.suptitle(title, fontsize=10)
    with output(png_path) as f:  # a new file: never through a link left where the figure goes
        fig.savefig(f, format="png", dpi=90)
    plt.close(fig)
    return Path(png_path)


def top_view(csv_path: str | Path, png_path: str | Path, world, columns: tuple[str, str], title: str = "",
             radius: float | None = None) -> Path:
    """A mobile robot's path seen from above among a world's obstacles (cotwin.pmodel.world): walls and
    boxes as outlines, cylinders as circles, the path coloured by time from its start (o) to its end (x)."""
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle, Polygon

    cols = read_csv(csv_path)
    t, x, y = cols["time"], cols[columns[0]], cols[columns[1]]
    fig, ax = plt.subplots(figsize=(7, 6.2))
    for o in world.obstacles:
        if o.kind == "cylinder":
            ax.add_patch(Circle((o.x, o.y), o.size[0], color="tab:blue", alpha=0.6))
        else:
            ax.add_patch(Polygon(o.outline(), closed=True, color="tab:brown" if "wall" in o.name else "tab:red",
                                 alpha=0.6))
    points = list(zip(x, y))
    if len(points) > 1:
        segments = [[points[k], points[k + 1]] for k in range(len(points) - 1)]
        lines = LineCollection(segments, cmap="viridis", linewidths=2)
        lines.set_array(list(t[1:]))
        ax.add_collection(lines)
        fig.colorbar(lines, ax=ax, label="time [s]", shrink=0.8)
    if points:
        ax.plot(*points[0], "o", color="black", label="start")
        ax.plot(*points[-1], "x", color="black", markersize=9, label="end")
        if radius:
            ax.add_patch(Circle(points[-1], radius, fill=False, color="black", linestyle=":"))
    x0, x1, y0, y1 = world.extent()
    margin = 0.15
    ax.set_xlim(x0 - margin, x1 + margin)
    ax.set_ylim(y0 - margin, y1 + margin)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    with output(png_path) as f:  # a new file: never through a link left where the figure goes
        fig.savefig(f, format="png", dpi=90)
    plt.close(fig)
    return Path(png_path)
