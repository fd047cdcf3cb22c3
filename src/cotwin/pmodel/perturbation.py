"""Documented, seedable perturbations of the embedded platform: how a stand-in "physical" robot differs
from its digital twin. Payload, friction and damping are applied to the generated MuJoCo model
(here), latency and noise around the endpoint (cotwin.mapping.perturbed); never to the RoboSim models.

- `payload` (kg): a point mass at the tool frame (the project's tool, its cell geometry's [tool] link and point;
  for a p-model alone `cotwin.pmodel.ik.find_tool`'s default), welded to the tool's link as its own MJCF body with no gravity compensation: the servos feel its weight and inertia,
  as a real arm carrying an unannounced load does. The arm's own compensation is unchanged. On a
  free base (a mobile robot) the load sits at the base link's centre of mass.
- `friction` (N m for revolute, N for prismatic joints): Coulomb friction, MuJoCo's `frictionloss` of
  the joint's degree of freedom. A number applies to every actuated joint; a table names joints.
- `damping` (factor): scales the joint's viscous damping (the p-model's `Dynamics { damping }`); a
  number for every actuated joint or a table by joint.
- `latency_ms` (ms): every servo goal takes effect this long after it was commanded (rounded to whole
  physics steps), as a cell whose controller lags its commands.
- `noise` (standard deviation, in the quantity's unit): Gaussian noise on measurements, by sensor
  quantity (`position`, `velocity`, `effort`, `range`: a ray sensor's ranges, m); a number applies to
  all of them. Position and velocity
  noise also applies to the joint positions and velocities the endpoint reports (the encoders). One
  sample is drawn per quantity and reading after every advance, so repeated reads within a step agree.
- `seed`: the noise generator's seed (numpy's PCG64); the same seed gives the same noise.

A `Perturbation()` with no field set is nominal: the endpoint then behaves exactly as SimulatedEndpoint.
In a project file the same keys form the `[plant]` table; a perturbation file holds them at its top level.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

from ..config import Key, Schema, TomlFile, did_you_mean, is_number, raise_problems
from ..diagnostics import CotwinError, Finding, Location, Severity
from .ik import Tool, find_tool
from .mjcf import TIMESTEP, to_mjcf
from .simulator import PlatformSimulator
from .tree import KinematicTree
from .xmltext import nums, sub, to_text

QUANTITIES = ("position", "velocity", "effort", "range")
MAX_LATENCY_MS = 10_000.0
MAX_PAYLOAD = 1000.0  # kg: beyond any robot's load (a typo, not a perturbation)
MAX_FRICTION = 10_000.0  # N m (or N)
MAX_DAMPING = 1000.0  # times the p-model's damping
MAX_NOISE = 1000.0  # standard deviation, in the quantity's unit
PAYLOAD_BODY = "cotwin_payload"
PAYLOAD_RADIUS = 0.03  # m: the payload's inertia is that of a solid sphere of this radius


def _is_value(v) -> bool:
    return is_number(v) and v >= 0


def _per_name(what: str, high: float, names: tuple[str, ...] = ()):
    """A check for `key = number` or `key = { name = number }` (non-negative, finite, at most `high`)."""

    def check(value) -> str | None:
        if _is_value(value):
            return None if value <= high else f"must be at most {high:g}, got {value!r}"
        if not isinstance(value, dict):
            return f"must be a number >= 0 or a table of {what} -> number >= 0, got {value!r}"
        for name, v in value.items():
            if names and name not in names:
                return f"unknown {what} '{name}'{did_you_mean(name, names)} (known: {', '.join(names)})"
            if not _is_value(v) or v > high:
                return f"{what} '{name}' must be a number in [0, {high:g}], got {v!r}"
        return None

    return check


SCHEMA = Schema({
    "seed": Key("int", 0, check=lambda v: None if 0 <= v < 2 ** 63 else "must be in [0, 2^63)"),
    "payload": Key("nonnegative", 0.0, check=lambda v: None if v <= MAX_PAYLOAD else
                   f"must be at most {MAX_PAYLOAD:g} kg"),
    "friction": Key("any", {}, check=_per_name("joint", MAX_FRICTION)),
    "damping": Key("any", {}, check=_per_name("joint", MAX_DAMPING)),
    "latency_ms": Key("nonnegative", 0.0, check=lambda v: None if v <= MAX_LATENCY_MS else
                      f"must be at most {MAX_LATENCY_MS:g} ms"),
    "noise": Key("any", {}, check=_per_name("sensor quantity", MAX_NOISE, QUANTITIES)),
})


@dataclass(frozen=True)
class Perturbation:
    """How the plant differs from the nominal model (see the module doc for units and meaning)."""

    seed: int = 0
    payload: float = 0.0
    friction: dict[str, float] | float = field(default_factory=dict)
    damping: dict[str, float] | float = field(default_factory=dict)
    latency_ms: float = 0.0
    noise: dict[str, float] | float = field(default_factory=dict)

    @classmethod
    def from_table(cls, data: dict) -> "Perturbation":
        """From a table already checked by SCHEMA (the defaults filled in)."""
        return cls(**{k: data[k] for k in SCHEMA.keys})

    @property
    def nominal(self) -> bool:
        scales = self.damping.values() if isinstance(self.damping, dict) else [self.damping]
        return not (self.payload or self.latency_ms or _nonzero(self.friction) or _nonzero(self.noise)
                    or any(v != 1.0 for v in scales))

    def with_options(self, **options) -> "Perturbation":
        """A copy with the options that are not None replaced (command-line flags over the file)."""
        return replace(self, **{k: v for k, v in options.items() if v is not None})

    def noise_std(self, quantity: str) -> float:
        if isinstance(self.noise, dict):
            return float(self.noise.get(quantity, 0.0))
        return float(self.noise)

    def per_joint(self, name: str, joints: list[str]) -> dict[str, float]:
        """`friction` or `damping` by joint: a number applies to every joint in `joints`."""
        value = getattr(self, name)
        if isinstance(value, dict):
            return {j: float(v) for j, v in value.items()}
        return {j: float(value) for j in joints}

    def problems(self, tree: KinematicTree) -> list[tuple[tuple, str]]:
        """(key path, message) for every joint named that the p-model does not have."""
        joints = [j.name for j in tree.actuated]
        out = []
        for key in ("friction", "damping"):
            value = getattr(self, key)
            for name in value if isinstance(value, dict) else ():
                if name not in joints:
                    out.append(((key, name), f"{key}: p-model {tree.name} has no actuated joint '{name}'"
                                             f"{did_you_mean(name, joints)} (joints: {', '.join(joints)})"))
        return out

    def as_dict(self) -> dict:
        return {"seed": self.seed, "payload": self.payload, "friction": self.friction, "damping": self.damping,
                "latency_ms": self.latency_ms, "noise": self.noise}


def _nonzero(value) -> bool:
    return any(value.values()) if isinstance(value, dict) else bool(value)


def read_table(file: TomlFile, at: tuple = (), problems: list[Finding] | None = None) -> Perturbation | None:
    """The perturbation written in `file` at table `at` (() for a perturbation file), or None if absent."""
    data = file.data
    for key in at:
        data = data.get(key) if isinstance(data, dict) else None
    if data is None:
        return None
    own = problems is None
    problems = [] if own else problems
    if not isinstance(data, dict):
        problems.append(Finding(file.location(at), Severity.ERROR, f"[{'.'.join(at)}] must be a table"))
        checked = None
    else:
        checked = SCHEMA.read(data, file, at, problems)
    if own:
        raise_problems(problems)
    return Perturbation.from_table(checked) if checked is not None else None


def read_perturbation(path: str | Path) -> Perturbation:
    """A perturbation file: the `[plant]` keys at its top level (at least one: an empty file is a mistake)."""
    file = TomlFile(path, "perturbation file")
    if not file.data:
        raise file.error(f"the perturbation file sets none of {', '.join(SCHEMA.keys)}: it would perturb nothing "
                         "(leave it out for the nominal plant)")
    return read_table(file) or Perturbation()


def joint_problems(perturbation: Perturbation, tree: KinematicTree,
                   locate: Callable[[tuple], Location] | None = None) -> list[Finding]:
    """An error for each joint named that the p-model does not have, at `locate(key path)` when the
    perturbation was read from a file (a project's [plant]: cotwin.twin.project checks it with the
    project's other problems)."""
    where = locate or (lambda key: Location("<perturbation>", 0, 0))
    return [Finding(where(key), Severity.ERROR, message) for key, message in perturbation.problems(tree)]


def check_joints(perturbation: Perturbation, tree: KinematicTree, file: TomlFile | None = None,
                 at: tuple = ()) -> None:
    """Unknown joints are errors, located in `file` when the perturbation came from one."""
    found = joint_problems(perturbation, tree, None if file is None else (lambda key: file.location(at + key)))
    if found:
        raise CotwinError(found)


# ---- application -------------------------------------------------------------------------------------

def with_payload(xml: str, tree: KinematicTree, kg: float, base: str = "fixed", tool: Tool | None = None) -> str:
    """The MJCF with a point mass of `kg` welded at the tool frame (no gravity compensation), or at the
    base link's centre of mass for a free base. `tool`: the project's (TwinModels.tool: its [tool] link and point),
    the one its IK moves; None: find_tool's default, for a p-model without a project."""
    if kg <= 0:
        return xml
    if base == "free":
        link, at = tree.root.name, tree.root.com[:3, 3]
    else:
        tool = tool if tool is not None else find_tool(tree)
        link, at = tool.link, tool.offset[:3, 3]
    root = ET.fromstring(xml)
    body = next((b for b in root.iter("body") if b.get("name") == link), None)
    if body is None:
        raise CotwinError(f"no body '{link}' for the payload in the generated MJCF")
    holder = sub(body, "body", name=PAYLOAD_BODY, pos=nums(at), gravcomp="0")
    inertia = 0.4 * kg * PAYLOAD_RADIUS ** 2
    sub(holder, "inertial", pos="0 0 0", mass=nums([kg]), diaginertia=nums([inertia] * 3))
    return to_text(root)


def perturbed_simulator(tree: KinematicTree, scene, perturbation: Perturbation,
                        timestep: float = TIMESTEP, base: str = "fixed", tool: Tool | None = None) -> PlatformSimulator:
    """The MuJoCo platform with the perturbation's payload (at `tool`, see with_payload), friction and damping in
    its model."""
    check_joints(perturbation, tree)
    xml = with_payload(to_mjcf(tree, scene, timestep, visual=False, base=base), tree, perturbation.payload, base,
                       tool)
    sim = PlatformSimulator(tree, scene, timestep, mjcf=xml, base=base)
    joints = [j.name for j in tree.actuated]
    for name, value in perturbation.per_joint("friction", joints).items():
        sim.model.dof_frictionloss[sim.model.joint(name).dofadr[0]] = value
    for name, scale in perturbation.per_joint("damping", joints).items():
        sim.model.dof_damping[sim.model.joint(name).dofadr[0]] *= scale
    return sim


def cell_joint_problems(perturbation: Perturbation, robots: list,
                        location: Callable[[str], Location] = lambda key: Location("<[plant]>", 0, 0)) -> list[Finding]:
    """A cell's [plant] friction and damping tables: each key a joint name (on every robot that has it) or
    ROBOT.joint (on that robot alone); a key naming no actuated joint of the cell's robots is an error at
    `location(key)` (the project's place of the table; by default none: the message names [plant]), with the
    nearest name."""
    names = {r.name: [j.name for j in r.tree.actuated] for r in robots}
    known = sorted({j for joints in names.values() for j in joints} |
                   {f"{robot}.{j}" for robot, joints in names.items() for j in joints})
    out = []
    for key in ("friction", "damping"):
        value = getattr(perturbation, key)
        for name in value if isinstance(value, dict) else ():
            if name not in known:
                out.append(Finding(location(key), Severity.ERROR, f"[plant] {key}: {name!r} is no actuated joint of the "
                                   f"cell's robots (a joint name, on every robot that has it, or ROBOT.joint)"
                                   f"{did_you_mean(name, known)}"))
    return out


def perturbed_world(robots: list, scene, perturbation: Perturbation, timestep: float = TIMESTEP,
                    tools: dict[str, Tool] | None = None):
    """A world of several robots (cotwin.pmodel.shared.SharedWorld) with the perturbation's payload at each
    robot's tool (`tools`, by robot name: each robot's project's; see with_payload) and its friction and damping on each robot's joints (a table by joint: the joints of that
    name, on the robots that have them; a name no robot has is an error). Latency and noise are an
    endpoint's (cotwin.mapping.perturbed), not the world's."""
    from .shared import SharedWorld

    problems = cell_joint_problems(perturbation, robots)
    if problems:
        raise CotwinError(problems)
    tools = tools or {}
    placed = [replace(r, mjcf=with_payload(to_mjcf(r.tree, None, timestep, visual=False), r.tree,
                                           perturbation.payload, tool=tools.get(r.name))) for r in robots]
    world = SharedWorld(placed, scene, timestep)
    for r in robots:
        joints = [j.name for j in r.tree.actuated]
        prefix = world.prefix(r.name)
        for key in ("friction", "damping"):
            value = getattr(perturbation, key)
            amounts = {j: float(value) for j in joints} if not isinstance(value, dict) else \
                {**{n: float(v) for n, v in value.items() if n in joints},  # a joint of that name on every robot
                 **{n.split(".", 1)[1]: float(v) for n, v in value.items()  # ROBOT.joint: on that robot alone
                    if n.startswith(r.name + ".") and n.split(".", 1)[1] in joints}}
            for name, amount in amounts.items():
                dof = world.model.joint(prefix + name).dofadr[0]
                if key == "friction":
                    world.model.dof_frictionloss[dof] = amount
                else:
                    world.model.dof_damping[dof] *= amount
    return world
