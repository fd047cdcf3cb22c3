"""The paper's second case study at length: the TurtleBot3's random walk, 30 s at a step of 0.2 s, over 20
seeds of its d-model in two worlds (examples/turtlebot/arena.toml, rooms.toml), on RoboTool's published
models (when ../shared has them) and on cotwin's own. Prints, per models and world: collisions (contacts
with an obstacle), the share of the free floor visited, the closest approach, the path length, and the
wall time of a walk beside the 30 s it simulates (the real-time factor, the peer)."""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.pmodel.world import load_world  # noqa: E402
from cotwin.twin.assembly.run import load  # noqa: E402
from cotwin.twin.analysis.walks import walks  # noqa: E402
from figures import figure  # noqa: E402

EXAMPLE = ROOT / "examples" / "turtlebot"
SEEDS = range(20)
WORLDS = ("arena", "rooms")


def main() -> None:
    projects = {"own models": EXAMPLE / "cotwin.toml"}
    if (ROOT.parent / "shared" / "robosim" / "mobile" / "OA_mapping.pm").is_file():
        projects = {"published models": EXAMPLE / "published.toml", **projects}
    else:
        print("the published models are not in ../shared/robosim/mobile: only cotwin's own are walked")
    total = 0
    with tempfile.TemporaryDirectory(prefix="cotwin-walks-") as tmp:
        for label, project in projects.items():
            system = load(project)
            for name in WORLDS:
                twin = system.in_world(load_world(EXAMPLE / f"{name}.toml"))
                started = time.perf_counter()
                done = walks(twin, SEEDS, Path(tmp) / f"{project.stem}-{name}")
                elapsed = time.perf_counter() - started
                collisions = sum(w.collisions for w in done)
                total += collisions
                visited = np.array([w.visited for w in done])
                figure(f"{label}, {name}: collisions over {len(done)} walks", collisions, "",
                       wall_s_median=float(np.median([w.wall_seconds for w in done])), simulated_s=twin.spec.end)
                wall = np.array([w.wall_seconds for w in done])
                print(f"{label}, {name}: {len(done)} walks of {twin.spec.end:g} s at {twin.spec.step:g} s; "
                      f"{collisions} collision(s) ({sum(bool(w.collisions) for w in done)} walk(s) with any)")
                print(f"  floor visited: mean {visited.mean():.1%}, min {visited.min():.1%}, max {visited.max():.1%}; "
                      f"closest approach {min(w.closest for w in done) * 100:.1f} cm; path "
                      f"{np.mean([w.length for w in done]):.2f} m on average")
                print(f"  wall time per walk: median {np.median(wall):.2f} s for {twin.spec.end:g} s simulated "
                      f"(real-time factor {twin.spec.end / np.median(wall):.0f}); {elapsed:.1f} s in all")
                for w in done:
                    if w.collisions:
                        print(f"  seed {w.seed}: touched {', '.join(sorted({o for _, _, o in w.touches}))} "
                              f"first at t = {w.touches[0][0]:.2f} s")
    print(f"collisions over every walk: {total}")


if __name__ == "__main__":
    main()
