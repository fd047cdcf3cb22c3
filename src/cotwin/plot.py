"""A figure like the paper's Fig. 16 from a Maestro-format outputs.csv: commands and their arguments,
the d-model's operation calls, and the joint angles over time."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_csv(path: str | Path) -> dict[str, list]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, data = rows[0], rows[1:]
    columns: dict[str, list] = {h: [] for h in header}
    for row in data:
        for h, v in zip(header, row):
            columns[h].append(1.0 if v == "true" else 0.0 if v == "false" else float(v) if v else float("nan"))
    return columns


def figure(csv_path: str | Path, png_path: str | Path, panels: list[tuple[str, list[str], str]],
           title: str = "") -> Path:
    """A figure like the paper's Fig. 16 from a Maestro-format outputs.csv: one panel per (label,
    columns, draw style); the twin chooses the columns from its models (see `twin_panels`)."""
    cols = read_csv(csv_path)
    t = cols["time"]
    panels = [(label, [c for c in names if c in cols], style) for label, names, style in panels]
    panels = [p for p in panels if p[1]] or [("(no variables)", [], "default")]
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 2.3 * len(panels) + 0.6), sharex=True, squeeze=False)
    for ax, (label, names, style) in zip(axes[:, 0], panels):
        for name in names:
            ax.plot(t, cols[name], drawstyle=style, label=name.split(".")[-1])
        ax.set_ylabel(label, fontsize=8)
        ax.grid(True, alpha=0.3)
        if names:
            ax.legend(fontsize=7, loc="upper right", ncol=3)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(png_path, dpi=90)
    plt.close(fig)
    return Path(png_path)


def twin_figure(pt_csv: str | Path, dt_csv: str | Path, alarms: list[dict], png_path: str | Path,
                variables: list[str], title: str = "") -> Path:
    """The live twin's figure: each monitored variable of the PT (solid) and the DT (dashed) over time,
    deviation alarms shaded from raised to cleared."""
    pt, dt = read_csv(pt_csv), read_csv(dt_csv)
    names = [v for v in variables if v in pt and v in dt]
    fig, axes = plt.subplots(max(len(names), 1), 1, figsize=(10, 1.7 * max(len(names), 1) + 1.2), sharex=True,
                             squeeze=False)
    end = pt["time"][-1] if pt["time"] else 0.0
    for ax, name in zip(axes[:, 0], names):
        short = name.split(".")[-1]
        ax.plot(pt["time"], pt[name], label="PT", color="tab:blue")
        ax.plot(dt["time"], dt[name], label="DT", color="tab:orange", linestyle="--")
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
        ax.set_ylabel(short, fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="upper right", ncol=2)
    axes[-1, 0].set_xlabel("time [s] (red: deviation alarm)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(png_path, dpi=90)
    plt.close(fig)
    return Path(png_path)
