"""The endpoint protocol: what a mapping asks of a platform (a simulator, a plant over OPC UA, a robot
behind the broker or RTDE, a replayed log), and the optional abilities some platforms have, declared
once with their defaults so that nothing probes an endpoint with getattr. A light module (no MuJoCo):
the robot-facing clients import it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..diagnostics import CotwinError

if TYPE_CHECKING:
    from ..pmodel.cell import CellGeometry
    from ..pmodel.simulator import PlatformSimulator
    from ..pmodel.tree import KinematicTree


class Endpoint:
    """What a mapping asks of a platform. The methods up to `joint` every endpoint has; the abilities
    after them are optional, declared here with what an endpoint without them does (no probing with
    getattr): an endpoint subclasses this and overrides those it has.

    - `close`: release sessions and threads (nothing to release by default);
    - `place(positions)`: put the robot at rest at these joint positions (a live twin starts its DT where
      the PT is); `placeable` says whether it can (a real robot cannot);
    - `snapshot`/`restore`: the platform's state as plain data (what-if forks, rollbacks); `saves_state`
      says whether it has them;
    - `actuator_names`: the actuator paths it takes (None: it does not say);
    - `geometry`: the cell's geometry when the platform knows it (the embedded simulator's scene);
    - `sim`: the MuJoCo simulator, when the platform runs one in this process (contacts, forks);
    - `ends()`: when the platform's data ends, if it does (a replayed log holds its last sample after);
    - `perturbation`: the perturbation a perturbed plant applies;
    - `robot_contacts()`: the other robots its robot touched in the step just made (a mapping's
      `robot_contact()`); `senses_contacts` says whether it can tell (a remote robot cannot).
    """

    tree: KinematicTree
    geometry: CellGeometry | None = None
    sim: PlatformSimulator | None = None
    perturbation = None  # cotwin.pmodel.perturbation.Perturbation
    placeable = False
    saves_state = False
    senses_contacts = False

    def start(self) -> None:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    def read_sensors(self) -> dict[str, float]:
        raise NotImplementedError

    def command(self, goals: dict[str, float]) -> None:
        raise NotImplementedError

    def advance(self, dt: float) -> None:
        raise NotImplementedError

    def joint_positions(self) -> dict[str, float]:
        raise NotImplementedError

    def joint_velocities(self) -> dict[str, float]:
        raise NotImplementedError

    def joint(self, name: str) -> str:
        raise NotImplementedError

    # ---- optional abilities ----
    def close(self) -> None:
        """Release the platform's sessions and threads (none by default)."""

    def place(self, positions: dict[str, float]) -> None:
        """Put the robot at rest at `positions` (only where `placeable`)."""
        raise CotwinError(f"the platform ({type(self).__name__}) cannot be placed")

    def ends(self) -> tuple[float, str] | None:
        """(the co-simulation time at which the platform's data ends, what ends there), or None: it does not end."""
        return None

    def actuator_names(self) -> list[str] | None:
        """The actuator paths this platform takes; None: it does not say."""
        return None

    def robot_contacts(self) -> set[str]:
        return set()

    def snapshot(self) -> dict:
        raise CotwinError(f"the platform ({type(self).__name__}) cannot save its state")

    def restore(self, snapshot: dict) -> None:
        raise CotwinError(f"the platform ({type(self).__name__}) cannot continue from a saved state")


def joint_readings(tree: "KinematicTree", positions: dict[str, float],
                   velocities: dict[str, float]) -> dict[str, float]:
    """The sensor readings of a robot that reports only its joints (a UR over RTDE, a replayed log of one): each
    joint sensor's port, named as the simulator names it (cotwin.pmodel.tree.reading_path), reads its joint's
    position or velocity, an effort 0 (a UR reports currents, not torques); so a mapping's or [monitor]'s path
    of a joint's sensor reads on the PT as on the DT."""
    from ..pmodel.tree import reading_path

    by_quantity = {"position": positions, "velocity": velocities}
    return {reading_path(tree.name, s): float(by_quantity.get(s.quantity, {}).get(s.joint, 0.0))
            for s in tree.sensors if s.joint is not None}


class NamedActuators:
    """For an endpoint whose actuators answer to every name the simulator's do (cotwin.pmodel.tree.actuator_names:
    joint, servo, command path): `joint` and `actuator_names` from one table, and the joints driven by position."""

    def _name_actuators(self, tree, who: str) -> None:
        from ..pmodel.tree import actuator_names, servo_mode

        actuators = actuator_names(tree)
        self._path_to_joint = {name: j.name for name, j in actuators.items()}
        self._positioned = {j.name for j in actuators.values() if servo_mode(j) == "position"}
        self._who = who  # how an unknown actuator's error names the platform

    def joint(self, name: str) -> str:
        if name not in self._path_to_joint:
            raise CotwinError(f"{self._who} has no actuator '{name}'")
        return self._path_to_joint[name]

    def actuator_names(self) -> list[str]:
        return list(self._path_to_joint)
