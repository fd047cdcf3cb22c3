"""Walks of a mobile robot in a world: a twin project with a free base in a world (cotwin.pmodel.world),
run for one seed of its d-model's random source after another, and what each walk did: the contacts
with obstacles (the simulator's `touches`: every one is a collision), the share of the free floor its
footprint came over, how close its base came to an obstacle, how far it went and how long it took.

The robot's path is read from the monitored readings of its base's x and y ([monitor] readings), as
the run's top view draws it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...diagnostics import CotwinError
from ..assembly.run import path_columns, run_twin, simulated_endpoint
from ..assembly.system import DMODEL, TwinSystem


@dataclass
class Walk:
    seed: int
    world: str
    touches: list[tuple[float, str, str]]  # (time, robot geom, obstacle) when each contact began
    visited: float  # share of the free floor the footprint came over
    closest: float  # m: the least distance from the base's origin to an obstacle, less the robot's reach
    length: float  # m: the path's length
    turned: float  # rad: the total heading change
    wall_seconds: float
    path: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 2)))

    @property
    def collisions(self) -> int:
        return len(self.touches)


def walk(system: TwinSystem, out: str | Path, seed: int | None = None) -> Walk:
    """One walk of the twin's robot in its world (the d-model's seed set when given), written into `out`."""
    from ...pmodel.world import footprint_radius
    from ...plot import read_csv

    world = system.models.scene
    columns = path_columns(system)
    if world is None or not world.walkable or columns is None:
        raise CotwinError(f"{system.spec.path}: a walk needs a world ([platform] world) and the base's x and y "
                          "among the monitored readings ([monitor] readings)")
    if seed is not None:
        system = system.with_seed(seed)
    endpoint = simulated_endpoint(system)
    started = time.perf_counter()
    ran = run_twin(system, out, endpoint=endpoint, plot=False)
    wall = time.perf_counter() - started
    data = read_csv(ran.csv)
    path = np.column_stack([data[columns[0]], data[columns[1]]])
    reach = footprint_radius(system.models.tree)
    yaw = [name for name, p in system.spec.readings.items() if p.endswith(".yaw")]
    heading = np.unwrap(data[f"{columns[0].rsplit('.', 1)[0]}.{yaw[0]}"]) if yaw else np.zeros(len(path))
    return Walk(int(system.parameters.get(DMODEL.name, {}).get(system.seed_port, 0)), world.name,
                list(endpoint.sim.touches),
                world.coverage(path, reach), float(world.clearance(path).min() - reach),
                float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()), float(np.abs(np.diff(heading)).sum()),
                wall, path)


def walks(system: TwinSystem, seeds, out: str | Path) -> list[Walk]:
    """A walk per seed, one after another in `out` (the d-model FMU built once)."""
    return [walk(system, out, seed) for seed in seeds]


__all__ = ["Walk", "walk", "walks"]
