"""What a benchmark module reports: figures (each with the peer it is compared to) and goals (met or
missed), printed as text and kept for `run.py`, which writes them all to a JSON file beside the text.

A module calls `figure(...)` / `goal(...)` as it measures; when run by run.py (COTWIN_BENCH_JSON set)
its records are written to that file when the module ends, and run.py exits non-zero naming every
goal missed. `percentile` refuses to name a percentile the samples cannot support."""

from __future__ import annotations

import atexit
import json
import math
import os
import statistics

import numpy as np

_RECORDS: dict[str, list[dict]] = {"figures": [], "goals": []}


def figure(name: str, value: float | None, unit: str, peer: str | None = None, peer_value: float | None = None,
           **detail) -> float | None:
    """Record one figure (and the peer measured in the same run, where there is one); returns value."""
    entry = {"name": name, "value": _plain(value), "unit": unit}
    if peer is not None:
        entry.update(peer=peer, peer_value=_plain(peer_value))
        if value is not None and peer_value:
            entry["ratio"] = value / peer_value
    entry.update({k: _plain(v) for k, v in detail.items()})
    _RECORDS["figures"].append(entry)
    return value


def goal(name: str, value: float | None, target: float, at_most: bool = False, unit: str = "") -> str:
    """Judge value against target (at least, or at most); record it; return 'met' or 'MISSED ...' for the
    text. A value that could not be measured (None) misses its goal."""
    met = bool(value is not None and math.isfinite(value) and (value <= target if at_most else value >= target))
    _RECORDS["goals"].append({"name": name, "value": _plain(value), "target": _plain(target),
                              "comparison": "<=" if at_most else ">=", "unit": unit, "met": met})
    return "met" if met else f"MISSED: goal {'<=' if at_most else '>='} {target:g}{unit}"


def percentile(samples: list[float], p: float) -> float | None:
    """The p-th percentile (nearest rank), or None when fewer than 100 / (100 - p) samples are there
    (a p99 needs at least 100 samples to be more than the maximum)."""
    n = len(samples)
    if n == 0 or n < 100.0 / (100.0 - p) - 1e-9:
        return None
    ordered = sorted(samples)
    return ordered[min(n - 1, max(0, math.ceil(p / 100.0 * n) - 1))]


def spread(samples: list[float]) -> dict:
    """Median, p90, p99 (None where too few samples) and max of `samples`, with their count."""
    return {"n": len(samples), "median": statistics.median(samples) if samples else None,
            "p90": percentile(samples, 90), "p99": percentile(samples, 99), "max": max(samples) if samples else None}


def shown(value: float | None, fmt: str = ".1f") -> str:
    return "n/a (too few samples)" if value is None else format(value, fmt)


def _plain(value):
    """A JSON value: numpy's numbers and booleans as Python's, non-finite numbers as text."""
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    try:
        value = float(value)
    except (TypeError, ValueError):
        return str(value)
    return value if math.isfinite(value) else str(value)


@atexit.register
def _write() -> None:
    path = os.environ.get("COTWIN_BENCH_JSON")
    if path:
        text = json.dumps(_RECORDS, indent=1, default=str)
        with open(path + ".part", "w") as f:
            f.write(text)
        os.replace(path + ".part", path)
