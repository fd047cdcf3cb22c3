"""`cotwin check` of p-models in RoboTool's notation: time per model (target: under a second), with
Lark's bare LALR parse of the same text as the peer. Models: the TurtleBot3 (issue 14), our per-construct
models (tests/models/pmodel) and RoboTool's physmod library and T3 test models (../shared/refs/robotool-physmod,
or COTWIN_PHYSMOD_REFS), where they are."""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.robosim.check import check_paths  # noqa: E402
from cotwin.robosim.parser import lark_parser  # noqa: E402
from cotwin.robosim.project import library_packages  # noqa: E402
from figures import figure, goal  # noqa: E402


def _models() -> list[Path]:
    models = sorted((ROOT / "tests" / "models" / "pmodel").glob("*.pm"))
    turtlebot = ROOT.parent / "shared" / "robosim" / "mobile" / "Turtlebot3_Burger.pm"
    if turtlebot.is_file():
        models.append(turtlebot)
    refs = Path(os.environ.get("COTWIN_PHYSMOD_REFS") or ROOT.parent / "shared" / "refs" / "robotool-physmod")
    if refs.is_dir():
        models += sorted(refs.rglob("*.pm"))
    return models


def main() -> None:
    library_packages()  # built once per process, as in a `cotwin check` of several folders
    lark_parser("pm")
    checks, parses = [], []
    for path in _models():
        text = path.read_text(encoding="utf-8", errors="replace")
        t0 = time.perf_counter()
        check_paths([path])
        checks.append((time.perf_counter() - t0, path))
        t0 = time.perf_counter()
        try:
            lark_parser("pm").parse(text)
        except Exception:  # a model RoboTool's generator wrote malformed: only the check is timed
            continue
        parses.append(time.perf_counter() - t0)
    times = [t for t, _ in checks]
    worst, worst_path = max(checks)
    figure("cotwin check of a p-model file, median", statistics.median(times) * 1000, "ms",
           peer="Lark's bare parse, median", peer_value=statistics.median(parses) * 1000, files=len(checks),
           slowest_ms=worst * 1000)
    print(f"cotwin check of {len(checks)} p-model files, one at a time: "
          f"median {statistics.median(times) * 1000:.1f} ms, "
          f"slowest {worst * 1000:.1f} ms ({worst_path.name}); "
          f"{goal('slowest p-model check', worst * 1000, 1000, at_most=True, unit=' ms')} (under 1000 ms per model)")
    print(f"Lark's bare parse of the same files: median {statistics.median(parses) * 1000:.2f} ms; "
          f"check/parse ratio {statistics.median(times) / statistics.median(parses):.1f}x (median)")


if __name__ == "__main__":
    main()
