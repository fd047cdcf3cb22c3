"""The TurtleBot walk verified with its documented domain (docs/verification.md) within GOAL seconds,
beside its peer in the same run: as many interpreter cycles run straight from one state (no snapshot,
restore or choice), i.e. what the search costs beyond interpreting its cycles. Exits 1 on a missed goal."""

from __future__ import annotations

import random
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.dmodel.interpreter import Interpreter  # noqa: E402
from cotwin.dmodel.program import build_program  # noqa: E402
from cotwin.dmodel.verify import verify  # noqa: E402
from cotwin.robosim.check import load_checked  # noqa: E402

GOAL = 60.0  # s, wall clock: issue 19's "the TurtleBot walk verified within 60 s"
DOMAIN = {"closest_distance": [0.3, 0.5, 1.5], "closest_angle": [-45, 0, 45, 120]}


def main() -> int:
    program = build_program(load_checked([ROOT / "examples" / "turtlebot" / "random_walk.rst"]))
    wall, cpu = time.perf_counter(), time.process_time()
    report = verify(program, DOMAIN)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    interp = Interpreter(program)
    rng = random.Random(1)
    peer = time.perf_counter()
    for _ in range(report.cycles):
        interp.step({"closestDistance": rng.choice(DOMAIN["closest_distance"]),
                     "closestAngle": rng.choice(DOMAIN["closest_angle"])})
    peer = time.perf_counter() - peer
    print(f"verify random_walk.rst, documented domain: {report.states} states, {report.cycles} cycles, "
          f"complete={report.complete}, in {wall:.1f} s wall ({cpu:.1f} s CPU; goal {GOAL:g} s)")
    print(f"  peer, {report.cycles} interpreter cycles straight: {peer:.1f} s (search/straight = {wall / peer:.2f})")
    ok = report.complete and wall <= GOAL
    if not ok:
        print(f"  MISSED: {'incomplete' if not report.complete else f'{wall:.1f} s > {GOAL:g} s'}", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
