"""Front-end speed: parse and check the published (or example) models; peer: Lark's bare parse.

Prints the cold parser-construction time, the warm parse+build time per file and the full check,
with the ratio of our typed-model build over Lark's bare LALR parse of the same text.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from figures import figure  # noqa: E402


def _best(fn, repeat: int = 20) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), statistics.median(times)


def main() -> None:
    shared = ROOT.parent / "shared" / "robosim"
    folders = [shared / "ur5e", shared / "ur3e"] if shared.is_dir() else [ROOT / "examples" / "ur5e"]
    files = sorted(p for f in folders for p in f.iterdir() if p.suffix in (".rst", ".pm"))

    t0 = time.perf_counter()
    from cotwin.robosim.parser import lark_parser, notation_of, parse_text
    from cotwin.robosim.check import check_paths

    lark_parser("rst"), lark_parser("pm")
    cold = time.perf_counter() - t0
    print(f"parser construction (import + both grammars, cache warm on 2nd run): {cold * 1000:.1f} ms")
    total_ours = total_lark = 0.0
    for path in files:
        text = path.read_text()
        notation = notation_of(path)
        ours, _ = _best(lambda: parse_text(text, str(path)))
        bare, _ = _best(lambda: lark_parser(notation).parse(text))
        total_ours += ours
        total_lark += bare
        print(f"  {path.name:22s} {len(text):6d} chars  parse+build {ours * 1000:6.2f} ms   lark parse {bare * 1000:6.2f} ms")
    figure("parse+build of all files", total_ours * 1000, "ms", peer="Lark's bare parse", peer_value=total_lark * 1000)
    print(f"all files: parse+build {total_ours * 1000:.1f} ms, lark bare parse {total_lark * 1000:.1f} ms, "
          f"ratio {total_ours / total_lark:.2f}x")
    full, median = _best(lambda: check_paths(folders), repeat=5)
    figure("cotwin check of the models, best", full * 1000, "ms", median_ms=median * 1000)
    print(f"cotwin check of {', '.join(f.name for f in folders)} (parse, resolve, type-check): "
          f"best {full * 1000:.1f} ms, median {median * 1000:.1f} ms")


if __name__ == "__main__":
    main()
