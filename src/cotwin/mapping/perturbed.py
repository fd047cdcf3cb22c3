"""The perturbed endpoint: the embedded simulator as a stand-in physical robot, seen through the
actuator latency and measurement noise of a `Perturbation` (cotwin.pmodel.perturbation documents
every perturbation; payload, friction and damping are already in the simulator's model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..diagnostics import CotwinError
from ..pmodel.perturbation import QUANTITIES, Perturbation, perturbed_simulator
from ..pmodel.tree import KinematicTree, reading_path
from .endpoint import SimulatedEndpoint
from .platform import Endpoint


NOISE_OF = {"closest_range": "range", "range": "range"}  # sensor quantity -> the noise it gets, where they differ


@dataclass
class _Pending:
    due: float
    goals: dict[str, float]


class PerturbedEndpoint(Endpoint):
    """A SimulatedEndpoint seen through the perturbation's actuator latency and measurement noise."""

    senses_contacts = True  # its simulator's contacts, as the inner endpoint's

    def __init__(self, inner: SimulatedEndpoint, perturbation: Perturbation):
        self.inner = inner
        self.perturbation = perturbation
        self.tree = inner.tree
        self.sim = inner.sim
        steps = round(perturbation.latency_ms / 1000.0 / self.sim.timestep)
        self.latency = steps * self.sim.timestep
        self._pending: list[_Pending] = []
        self._rng = np.random.default_rng(perturbation.seed)
        self._quantity = {reading_path(self.tree.name, s):
                          NOISE_OF.get(s.quantity, s.quantity) for s in self.tree.sensors}
        self._std = {q: perturbation.noise_std(q) for q in QUANTITIES}
        self._noisy = any(self._std.values())
        self._sample()

    @classmethod
    def build(cls, tree: KinematicTree, scene, perturbation: Perturbation, base: str = "fixed",
              tool=None) -> "PerturbedEndpoint":
        """The perturbed simulator of `tree`, its payload at `tool` (the project's, cotwin.pmodel.perturbation.
        with_payload)."""
        return cls(SimulatedEndpoint(perturbed_simulator(tree, scene, perturbation, base=base, tool=tool)), perturbation)

    # ---- noise ----
    def _sample(self) -> None:
        """Measure once: true values plus one noise draw each, in a fixed order (sensors, then joints)."""
        sensors = self.inner.read_sensors()
        q, qd = self.inner.joint_positions(), self.inner.joint_velocities()
        if self._noisy:
            sensors = {n: v + self._draw(self._quantity.get(n, "")) for n, v in sorted(sensors.items())}
            q = {n: v + self._draw("position") for n, v in q.items()}
            qd = {n: v + self._draw("velocity") for n, v in qd.items()}
        self._sensors, self._q, self._qd = sensors, q, qd

    def _draw(self, quantity: str) -> float:
        std = self._std.get(quantity, 0.0)
        return float(self._rng.normal(0.0, std)) if std > 0 else 0.0

    def reset(self) -> None:
        """Back to the initial state at time 0, nothing pending, the noise generator re-seeded."""
        self._pending.clear()
        self._rng = np.random.default_rng(self.perturbation.seed)
        self.sim.reset()
        self.inner.start()
        self._sample()

    # ---- the endpoint interface ----
    def start(self) -> None:
        self._pending.clear()
        self.inner.start()

    def stop(self) -> None:
        self._pending.clear()
        self.inner.stop()

    def actuator_names(self) -> list[str]:
        return self.inner.actuator_names()

    def joint(self, name: str) -> str:
        return self.inner.joint(name)

    def command(self, goals: dict[str, float]) -> None:
        """Goals are checked now and applied `latency` seconds later (at once without latency)."""
        for name, value in goals.items():
            self.inner.joint(name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise CotwinError(f"actuator '{name}': goal {value!r} is not a finite number")
        if self.latency <= 0:
            self.inner.command(goals)
        else:
            self._pending.append(_Pending(self.sim.time + self.latency, dict(goals)))

    def advance(self, dt: float) -> None:
        end = self.sim.time + dt
        half_step = self.sim.timestep / 2
        while self._pending and self._pending[0].due <= end + half_step:
            due = self._pending.pop(0)
            if due.due - self.sim.time > half_step:
                self.inner.advance(due.due - self.sim.time)
            self.inner.command(due.goals)
        if end - self.sim.time > half_step:
            self.inner.advance(end - self.sim.time)
        self._sample()

    # ---- on a world of several robots (cotwin.mapping.endpoint.advance_shared steps it) ----
    def next_due(self) -> float | None:
        return self._pending[0].due if self._pending else None

    def apply_due(self) -> None:
        """Apply the goals due by now (within half a physics step)."""
        now, half_step = self.sim.time, self.sim.timestep / 2
        while self._pending and self._pending[0].due <= now + half_step:
            self.inner.command(self._pending.pop(0).goals)

    def set_point(self, steps: int) -> bool:
        return self.inner.set_point(steps)

    def robot_contacts(self) -> set[str]:
        return self.inner.robot_contacts()

    def read_sensors(self) -> dict[str, float]:
        return dict(self._sensors)

    def joint_positions(self) -> dict[str, float]:
        return dict(self._q)

    def joint_velocities(self) -> dict[str, float]:
        return dict(self._qd)

    def goals(self) -> dict[str, float]:
        """The goals in force (joint -> value: a position, or the speed or effort commanded), pending ones
        not included."""
        return self.inner.goals()

    @property
    def time(self) -> float:
        return self.sim.time
