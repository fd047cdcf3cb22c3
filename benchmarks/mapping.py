"""Mapping runtime: microseconds to evaluate every input event of the example twin's mapping once
(equations and predicates over variables and sensor readings), compiled to closures (the runtime's
default) against the interpreting evaluator as the peer in the same run."""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.mapping.endpoint import SimulatedEndpoint  # noqa: E402
from cotwin.mapping.runtime import Mapping  # noqa: E402
from cotwin.twin.assembly.run import load  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from figures import figure  # noqa: E402


def per_round(mapping: Mapping, rounds: int) -> float:
    mapping.start_mapping()
    mapping.execute_operation("movediscrete", {"target_X": 1, "target_Y": 20, "target_Z": 2})
    mapping.step(0.1)
    events = sorted(mapping.events)
    for e in events:  # warm up (compiles the closures once)
        mapping.get_event(e)
    t0 = time.perf_counter()
    for _ in range(rounds):
        for e in events:
            mapping.get_event(e)
    return (time.perf_counter() - t0) / rounds


def main(rounds: int = 2000) -> None:
    twin = load(ROOT / "examples" / "ur5e" / "cotwin.toml").models
    times = {}
    for compiled in (True, False):
        mapping = Mapping(twin.project, SimulatedEndpoint(PlatformSimulator(twin.tree, twin.scene)), compiled=compiled)
        times[compiled] = per_round(mapping, rounds)
    events = len(mapping.events)
    figure("mapping: every input event once, compiled closures", times[True] * 1e6, "us",
           peer="interpreting evaluator", peer_value=times[False] * 1e6)
    print(f"mapping: all {events} input events once: compiled closures {times[True] * 1e6:.1f} us, "
          f"peer interpreting evaluator {times[False] * 1e6:.1f} us (compiled/interpreted = "
          f"{times[True] / times[False]:.2f})")


if __name__ == "__main__":
    main()
