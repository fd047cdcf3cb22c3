"""One physical world holding several robots: a cell whose arms share one MuJoCo model and step together.

Each robot's MJCF is made from its own p-model (`to_mjcf`, alone) and attached into one world (MuJoCo's
model editing, `MjSpec.attach`, as dm_control's mjcf attach does) at its base pose, every name scoped by
the robot's name (`NAME/`), so that two robots' links, joints, servos and sensors never clash. The
scene (cotwin.pmodel.scenes) is the world's, built around no robot in particular: its frame is the
world's.

Robots collide with the scene and with each other, never with themselves: robot k's geoms get a
collision bit of their own in `contype` and every other robot's in `conaffinity` (MuJoCo collides two
geoms when the contype of one meets the conaffinity of the other). Contacts between two robots' geoms
are checked every CONTACT_PERIOD while stepping and kept, by robot, until the next `advance`, so that a
mapping asks "did this robot touch another one in the step just made" (`robot_contacts`).

A robot's view of the world is a PlatformSimulator bound to it (`view`): its joints, servos and sensors
by the p-model's own names; only the world steps (`step`), once for every robot.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np

from ..diagnostics import CotwinError
from .mjcf import ROBOT_CONAFFINITY, ROBOT_CONTYPE, TIMESTEP, to_mjcf
from .scenes import EARTH
from .tree import KinematicTree
from .xmltext import num, nums, quat, sub, to_text

CONTACT_PERIOD = 0.005  # s between checks for contacts between robots
FIRST_ROBOT_BIT = 2  # contype bits 0 and 1 are the world's and the robots' (cotwin.pmodel.mjcf)
MAX_ROBOTS = 28  # robots' own bits in MuJoCo's 32-bit contype


@dataclass(frozen=True)
class PlacedRobot:
    """A robot of the world: its name (the scope of its MJCF names), its p-model and its base pose in the
    world (4x4), fixed to it."""

    name: str
    tree: KinematicTree
    pose: np.ndarray
    mjcf: str | None = None  # an MJCF text derived from to_mjcf(tree, None, visual=False) to attach instead (a payload)


def world_mjcf(scene, timestep: float = TIMESTEP) -> str:
    """The world without robots: the physics options of `to_mjcf`, a light and the scene."""
    root = ET.Element("mujoco", {"model": "cell"})
    sub(root, "compiler", angle="radian", autolimits="true", discardvisual="true")
    gravity = scene.gravity if scene is not None else EARTH
    option = sub(root, "option", timestep=num(timestep), gravity=nums(gravity), integrator="implicitfast",
                 cone="elliptic", impratio="10")
    sub(option, "flag", autoreset="disable")
    default = sub(root, "default")
    sub(default, "geom", condim="4", friction="1 0.02 0.001", solref="0.004 1")
    worldbody = sub(root, "worldbody")
    sub(worldbody, "light", name="sun", pos="0.5 0.3 3", dir="0 0 -1", directional="true")
    if scene is not None:
        scene.add_to(worldbody)
    return to_text(root)


class SharedWorld:
    """The MuJoCo model and data of a cell's robots and scene (see the module doc)."""

    def __init__(self, robots: list[PlacedRobot], scene=None, timestep: float = TIMESTEP):
        names = [r.name for r in robots]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise CotwinError(f"two robots of one world are called {', '.join(twice)}: each needs a name of its own")
        if not 1 <= len(robots) <= MAX_ROBOTS:
            raise CotwinError(f"a world holds 1 to {MAX_ROBOTS} robots, not {len(robots)}")
        self.robots = list(robots)
        self.scene = scene
        self.timestep = timestep
        spec = mujoco.MjSpec.from_string(world_mjcf(scene, timestep))
        bits = [1 << (FIRST_ROBOT_BIT + k) for k in range(len(robots))]
        everyone = sum(bits)
        for k, robot in enumerate(robots):
            child = mujoco.MjSpec.from_string(robot.mjcf if robot.mjcf is not None else
                                              to_mjcf(robot.tree, None, timestep, visual=False))
            for geom in child.geoms:
                if geom.contype == ROBOT_CONTYPE and geom.conaffinity == ROBOT_CONAFFINITY:
                    geom.contype = ROBOT_CONTYPE | bits[k]
                    geom.conaffinity = ROBOT_CONAFFINITY | (everyone & ~bits[k])
            frame = spec.worldbody.add_frame(pos=[float(v) for v in robot.pose[:3, 3]],
                                             quat=[float(v) for v in quat(robot.pose[:3, :3])])
            spec.attach(child, prefix=self.prefix(robot.name), frame=frame)
        try:
            self.model = spec.compile()
        except ValueError as err:
            raise CotwinError(f"MuJoCo rejected the cell of {', '.join(names)}: {err}") from None
        self.xml = spec.to_xml()
        self.data = mujoco.MjData(self.model)
        self._owner = np.full(self.model.ngeom, -1, dtype=int)  # geom -> robot index (-1: the world's)
        for k, robot in enumerate(robots):
            prefix = self.prefix(robot.name)
            for g in range(self.model.ngeom):
                body = self.model.body(int(self.model.geom_bodyid[g])).name
                if body.startswith(prefix):
                    self._owner[g] = k
        self._contact_steps = max(1, int(round(CONTACT_PERIOD / timestep)))
        self._steps = 0
        self.touched: dict[str, set[str]] = {r.name: set() for r in robots}  # in the last advance
        self.contacts: list[tuple[float, str, str]] = []  # (time, robot, robot) when a contact between two began
        self._touching: set[tuple[int, int]] = set()
        mujoco.mj_forward(self.model, self.data)

    @staticmethod
    def prefix(name: str) -> str:
        return f"{name}/"

    def view(self, name: str):
        """Robot `name`'s simulator: a PlatformSimulator of its p-model bound to this world."""
        from .simulator import PlatformSimulator

        robot = next((r for r in self.robots if r.name == name), None)
        if robot is None:
            raise CotwinError(f"no robot {name!r} in this world (robots: {', '.join(r.name for r in self.robots)})")
        return PlatformSimulator(robot.tree, self.scene, self.timestep, shared=self, prefix=self.prefix(name))

    @property
    def time(self) -> float:
        return float(self.data.time)

    def steps_for(self, dt: float) -> int:
        if not (math.isfinite(dt) and dt >= 0):
            raise CotwinError(f"cannot advance by {dt!r} s")
        return int(round(dt / self.timestep))

    def begin(self) -> None:
        """A new communication step: the robots' contacts of the previous one are forgotten."""
        for touched in self.touched.values():
            touched.clear()

    def step(self, steps: int) -> float:
        """Simulate `steps` physics steps for every robot at once, checking contacts between robots every
        CONTACT_PERIOD; returns the simulation time."""
        while steps > 0:
            n = min(steps, self._contact_steps - self._steps % self._contact_steps)
            mujoco.mj_step(self.model, self.data, n)
            self._steps += n
            steps -= n
            q = self.data.qpos
            if not math.isfinite(q.dot(q)):
                raise CotwinError(f"the physics became unstable at t = {self.data.time:.3f} s (non-finite state)")
            if self._steps % self._contact_steps == 0:
                self._contacts()
        return self.time

    def _contacts(self) -> None:
        now = set()
        contact, owner = self.data.contact, self._owner
        for k in range(self.data.ncon):
            a, b = owner[int(contact.geom1[k])], owner[int(contact.geom2[k])]
            if a >= 0 and b >= 0 and a != b:
                now.add((min(a, b), max(a, b)))
        for a, b in now:
            first, second = self.robots[a].name, self.robots[b].name
            self.touched[first].add(second)
            self.touched[second].add(first)
        for a, b in sorted(now - self._touching):
            self.contacts.append((self.time, self.robots[a].name, self.robots[b].name))
        self._touching = now

    def robot_contacts(self, name: str) -> set[str]:
        """The robots `name` touched during the last advance."""
        return set(self.touched[name])
