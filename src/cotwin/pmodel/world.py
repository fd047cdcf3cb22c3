"""A world for a mobile robot to walk in: a floor, an arena's walls and obstacles (walls, boxes, cylinders),
and where the robot starts. A scene (cotwin.pmodel.scenes), read from a world file or a
project's `[world]` table, so the same models run in different worlds:

    name = "two rooms"
    [arena]                          # a rectangular arena centred on the origin, walled all round
    size = [4.0, 3.0]                # inner length (x) and width (y), m
    wall_thickness = 0.05            # m (default 0.05)
    wall_height = 0.3                # m (default 0.3)
    [start]                          # the robot's base on the floor: position (m) and heading (degrees)
    x = -1.5
    y = 0.0
    yaw = 0.0
    [[wall]]                         # a wall from one point to another (m), on the floor
    from = [0.0, -1.5]
    to = [0.0, 0.5]
    thickness = 0.05                 # m (default 0.05); height (default 0.3)
    [[box]]
    center = [1.0, 0.8]              # m
    size = [0.4, 0.3, 0.3]           # length, width, height (m)
    yaw = 30.0                       # degrees (default 0)
    [[cylinder]]
    center = [-0.5, -0.8]
    radius = 0.15                    # m; height (default 0.3)

Every problem is reported at its key's line and column, all together (cotwin.config). Obstacles are
static geoms of the world (geom group 0: what ray sensors see; the floor is in group 2, so that a
LiDAR tilting as its robot brakes does not take the floor for an obstacle; its friction, sliding 1,
torsional 0.001, rolling 0.0001, governs its contacts with geoms that set none), named `wall_<i>`, `box_<i>`,
`cylinder_<i>` (or `box_<name>`); touching one is a collision (`obstacles`). A free-based robot is put
at the start pose with its lowest point on the floor (`robot_pose`); the start must leave room for it.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import Key, Schema, TomlFile, is_number, raise_problems, shown
from ..diagnostics import CotwinError, Finding, Location, Severity
from .mjcf import WORLD_CONAFFINITY, WORLD_CONTYPE
from .scenes import SceneBase
from .tree import KinematicTree, transform
from .xmltext import nums, sub

DEFAULT_HEIGHT = 0.3  # m: walls and obstacles
DEFAULT_THICKNESS = 0.05  # m: walls
FLOOR_CLEARANCE = 0.0005  # m: a free base is put this far above the floor and settles
FLOOR_GROUP = "2"  # the floor is no obstacle: a planar LiDAR's beams (which see group 0) pass over it
MAX_EXTENT = 1000.0  # m: no coordinate or size of a world beyond this (a robot's world, not a planet's)
MAX_OBSTACLES = 10_000  # walls, boxes and cylinders of one world
FLOOR_FRICTION = "1 0.001 0.0001"  # a hard, smooth floor: sliding 1, little torsion (tyres turn in place) and rolling


def _numbers(count: int, positive: bool = False):
    def check(value) -> str | None:
        if len(value) != count or not all(is_number(v) for v in value):
            return f"must be a list of {count} numbers, got {shown(value)}"
        if positive and not all(v > 0 for v in value):
            return f"must be {count} positive numbers, got {value!r}"
        if not all(abs(v) <= MAX_EXTENT for v in value):
            return f"must be within {MAX_EXTENT:g} m, got {value!r}"
        return None
    return check


def _length(value) -> str | None:
    return None if value <= MAX_EXTENT else f"must be at most {MAX_EXTENT:g} m, got {value!r}"


def _degrees(value) -> str | None:
    return None if abs(value) <= 360 else f"must be within 360 degrees, got {value!r}"


def _coordinate(value) -> str | None:
    return None if abs(value) <= MAX_EXTENT else f"must be within {MAX_EXTENT:g} m of the origin, got {value!r}"


ARENA = Schema({"size": Key("list", required=True, check=_numbers(2, positive=True)),
                "wall_thickness": Key("positive", DEFAULT_THICKNESS, check=_length),
                "wall_height": Key("positive", DEFAULT_HEIGHT, check=_length)})
START = Schema({"x": Key("number", 0.0, check=_coordinate), "y": Key("number", 0.0, check=_coordinate),
                "yaw": Key("number", 0.0, check=_degrees)})
WALL = Schema({"name": Key("str"), "from": Key("list", required=True, check=_numbers(2)),
               "to": Key("list", required=True, check=_numbers(2)),
               "thickness": Key("positive", DEFAULT_THICKNESS, check=_length),
               "height": Key("positive", DEFAULT_HEIGHT, check=_length)})
BOX = Schema({"name": Key("str"), "center": Key("list", required=True, check=_numbers(2)),
              "size": Key("list", required=True, check=_numbers(3, positive=True)),
              "yaw": Key("number", 0.0, check=_degrees)})
CYLINDER = Schema({"name": Key("str"), "center": Key("list", required=True, check=_numbers(2)),
                   "radius": Key("positive", required=True, check=_length),
                   "height": Key("positive", DEFAULT_HEIGHT, check=_length)})
SCHEMA = Schema({"name": Key("str", ""), "arena": Key("table", table=ARENA), "start": Key("table", {}, table=START),
                 "wall": Key("list", []), "box": Key("list", []), "cylinder": Key("list", [])})
_ITEMS = {"wall": WALL, "box": BOX, "cylinder": CYLINDER}


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle on the floor: a box (walls are boxes too) or a cylinder, in the world frame."""

    name: str
    kind: str  # box | cylinder
    x: float
    y: float
    size: tuple[float, ...]  # box: length, width, height; cylinder: radius, height
    yaw: float = 0.0  # rad

    @property
    def height(self) -> float:
        return self.size[-1]

    def outline(self) -> np.ndarray:
        """Its footprint's corners (a box) in the world's x-y plane, counter-clockwise."""
        half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * np.array(self.size[:2]) / 2
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return half @ np.array([[c, s], [-s, c]]) + (self.x, self.y)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance from points (n x 2) to the footprint (0 inside)."""
        d = np.asarray(points, float) - (self.x, self.y)
        if self.kind == "cylinder":
            return np.maximum(np.linalg.norm(d, axis=1) - self.size[0], 0.0)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        local = d @ np.array([[c, -s], [s, c]])
        outside = np.maximum(np.abs(local) - np.array(self.size[:2]) / 2, 0.0)
        return np.linalg.norm(outside, axis=1)


@dataclass
class World(SceneBase):
    """A floor, obstacles and a start pose (see the module doc)."""

    name: str = ""
    obstacles: list[Obstacle] = field(default_factory=list)
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x, y (m), yaw (rad)
    bounds: tuple[float, float, float, float] | None = None  # the arena's inside: x0, x1, y0, y1
    source: Location | None = None  # where the start was written (for errors about it)
    table: dict | None = None  # the table it was read from (a copy of a project carries it)

    walkable = True  # a floor a mobile robot walks on

    # ---- the scene interface ----
    @property
    def obstacle_names(self) -> list[str]:
        return [o.name for o in self.obstacles]

    def add_to(self, worldbody: ET.Element) -> None:
        x0, x1, y0, y1 = self.extent()
        half = max(x1 - x0, y1 - y0) / 2 + 1.0
        sub(worldbody, "geom", name="floor", type="plane", size=nums([half, half, 0.1]),
            pos=nums([(x0 + x1) / 2, (y0 + y1) / 2, 0.0]), rgba="0.35 0.35 0.37 1", group=FLOOR_GROUP,
            friction=FLOOR_FRICTION, priority="1", contype=str(WORLD_CONTYPE), conaffinity=str(WORLD_CONAFFINITY))
        for o in self.obstacles:
            attrs = {"pos": nums([o.x, o.y, o.height / 2]), "contype": str(WORLD_CONTYPE),
                     "conaffinity": str(WORLD_CONAFFINITY)}
            if o.yaw:
                attrs["euler"] = nums([0.0, 0.0, o.yaw])
            if o.kind == "box":
                sub(worldbody, "geom", name=o.name, type="box", size=nums([o.size[0] / 2, o.size[1] / 2, o.height / 2]),
                    rgba="0.75 0.55 0.3 1" if o.name.startswith("wall") else "0.8 0.3 0.2 1", **attrs)
            else:
                sub(worldbody, "geom", name=o.name, type="cylinder", size=nums([o.size[0], o.height / 2]),
                    rgba="0.25 0.45 0.8 1", **attrs)

    def robot_pose(self, tree: KinematicTree) -> np.ndarray:
        """Where the robot's model frame goes: at the start pose, its lowest point on the floor."""
        x, y, yaw = self.start
        reach = footprint_radius(tree)
        near = [(o.name, float(o.distance(np.array([[x, y]]))[0])) for o in self.obstacles]
        touching = [f"{n} ({d:.3f} m away)" for n, d in near if d < reach]
        if touching:
            where = self.source or Location("<world>", 1, 1)
            raise CotwinError([Finding(where, Severity.ERROR, f"the robot ({tree.name}, {reach:.3f} m from its base to "
                                       f"its farthest point) would start touching {', '.join(touching)}")])
        return transform((x, y, FLOOR_CLEARANCE - lowest_point(tree)), (0.0, 0.0, yaw))

    # ---- geometry for analysis ----
    def extent(self) -> tuple[float, float, float, float]:
        """x0, x1, y0, y1 of the arena's inside, else of everything in the world (and the start)."""
        if self.bounds is not None:
            return self.bounds
        xs, ys = [self.start[0]], [self.start[1]]
        for o in self.obstacles:
            r = max(o.size[:2]) if o.kind == "box" else o.size[0]
            xs += [o.x - r, o.x + r]
            ys += [o.y - r, o.y + r]
        return min(xs) - 0.5, max(xs) + 0.5, min(ys) - 0.5, max(ys) + 0.5

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance from points (n x 2) to the nearest obstacle."""
        points = np.asarray(points, float).reshape(-1, 2)
        if not self.obstacles:
            return np.full(len(points), np.inf)
        return np.min([o.distance(points) for o in self.obstacles], axis=0)

    def coverage(self, path: np.ndarray, radius: float, cell: float = 0.05) -> float:
        """The share of the free floor (cells of `cell` m inside the arena, not under an obstacle) that a
        disc of `radius` m swept along `path` (n x 2 points, joined by straight lines) came over."""
        x0, x1, y0, y1 = self.extent()
        xs = np.arange(x0 + cell / 2, x1, cell)
        ys = np.arange(y0 + cell / 2, y1, cell)
        centres = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
        free = self.clearance(centres) > 0
        path = np.asarray(path, float).reshape(-1, 2)
        dense = [path[:1]]
        for a, b in zip(path[:-1], path[1:]):
            n = max(1, int(np.ceil(np.linalg.norm(b - a) / (cell / 2))))
            dense.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
        samples = np.concatenate(dense)
        visited = np.zeros(len(centres), bool)
        for chunk in np.array_split(samples, max(1, len(samples) // 256)):
            d = np.linalg.norm(centres[:, None, :] - chunk[None, :, :], axis=2)
            visited |= (d <= radius).any(axis=1)
        return float((visited & free).sum() / max(free.sum(), 1))


def lowest_point(tree: KinematicTree) -> float:
    """The lowest z (model frame, joints as the simulator starts them) of the robot's colliding geometry."""
    low = math.inf
    for name, T in tree.geom_poses(tree.start_posture).items():
        g = next(g for l in tree.links for g in l.geoms if g.name == name)
        if g.placeholder:
            continue
        low = min(low, float(_corners(g, T)[:, 2].min()))
    return 0.0 if low == math.inf else low


def footprint_radius(tree: KinematicTree) -> float:
    """The largest horizontal distance from the base's origin to the robot's colliding geometry."""
    base = tree.root.pose
    far = 0.0
    for name, T in tree.geom_poses(tree.start_posture).items():
        g = next(g for l in tree.links for g in l.geoms if g.name == name)
        if g.placeholder:
            continue
        points = _corners(g, T) - base[:3, 3]
        far = max(far, float(np.linalg.norm(points[:, :2], axis=1).max()))
    return far


def _corners(g, T: np.ndarray) -> np.ndarray:
    """Corners of a geometry's bounding solid in the model frame (a sphere: of its bounding cube)."""
    if g.kind == "mesh":
        half = np.array([g.size["length"], g.size["width"], g.size["height"]]) / 2
        centre = np.asarray(g.center)
    elif g.kind == "box":
        half, centre = np.array([g.size["length"], g.size["width"], g.size["height"]]) / 2, np.zeros(3)
    elif g.kind in ("cylinder", "capsule"):
        r = g.size["radius"]
        half = np.array([r, r, g.size["length"] / 2 + (r if g.kind == "capsule" else 0.0)])
        centre = np.zeros(3)
    else:
        half, centre = np.full(3, g.size["radius"]), np.zeros(3)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    local = signs * half + centre
    if g.kind == "sphere":  # the sphere's lowest point, not its cube's corner, matters for resting
        local = np.vstack([local, centre - (0, 0, g.size["radius"])])
    return local @ T[:3, :3].T + T[:3, 3]


# ---- reading ----

def read_world(file: TomlFile, at: tuple = ()) -> World:
    """The world written in `file` at table `at` (() for a world file)."""
    data = file.data
    for key in at:
        data = data.get(key) if isinstance(data, dict) else None
    problems: list[Finding] = []
    if not isinstance(data, dict):
        raise CotwinError([Finding(file.location(at), Severity.ERROR, f"[{'.'.join(at)}] must be a table")])
    checked = SCHEMA.read(data, file, at, problems)
    obstacles: list[Obstacle] = []
    bounds = None
    arena = checked.get("arena")
    if arena and arena.get("size") is not None:
        (length, width), t, h = arena["size"], arena["wall_thickness"], arena["wall_height"]
        bounds = (-length / 2, length / 2, -width / 2, width / 2)
        for i, (x, y, lx, ly) in enumerate(((0.0, width / 2 + t / 2, length + 2 * t, t),
                                            (0.0, -width / 2 - t / 2, length + 2 * t, t),
                                            (length / 2 + t / 2, 0.0, t, width), (-length / 2 - t / 2, 0.0, t, width))):
            obstacles.append(Obstacle(f"arena_wall_{i + 1}", "box", x, y, (lx, ly, h)))
    names: dict[str, tuple] = {}
    count = sum(len(checked.get(kind) or []) for kind in _ITEMS)
    if count > MAX_OBSTACLES:
        raise CotwinError([Finding(file.location(at + (next(k for k in _ITEMS if checked.get(k)),)), Severity.ERROR,
                                   f"the world has {count} walls, boxes and cylinders, more than {MAX_OBSTACLES}")])
    for kind, schema in _ITEMS.items():
        items = checked.get(kind) or []
        for i, item in enumerate(items):
            where = at + (kind, i)
            if not isinstance(item, dict):
                problems.append(Finding(file.location(where), Severity.ERROR, f"each [[{kind}]] must be a table"))
                continue
            values = schema.read(item, file, where, problems)
            if any(values.get(k) is None for k, spec in schema.keys.items() if spec.required):
                continue
            name = f"{kind}_{values.get('name') or i + 1}"
            if name in names:
                problems.append(Finding(file.location(where + ("name",)), Severity.ERROR,
                                        f"two obstacles are called '{name}'"))
                continue
            names[name] = where
            obstacles.append(_obstacle(kind, name, values))
    start = checked.get("start") or {}
    x, y = float(start.get("x", 0.0)), float(start.get("y", 0.0))
    if bounds is not None and not (bounds[0] < x < bounds[1] and bounds[2] < y < bounds[3]):
        problems.append(Finding(file.location(at + ("start",)), Severity.ERROR,
                                f"the start ({x:g}, {y:g}) is outside the arena"))
    if bounds is not None:
        for o in obstacles:
            inside = bounds[0] <= o.x <= bounds[1] and bounds[2] <= o.y <= bounds[3]
            if not o.name.startswith("arena_wall") and not inside:
                problems.append(Finding(file.location(names.get(o.name, at)), Severity.ERROR,
                                        f"{o.name} at ({o.x:g}, {o.y:g}) is outside the arena"))
    raise_problems(problems)
    return World(checked.get("name") or "", obstacles, (x, y, math.radians(float(start.get("yaw", 0.0)))), bounds,
                 file.location(at + ("start",)), data)


def _obstacle(kind: str, name: str, v: dict) -> Obstacle:
    if kind == "box":
        return Obstacle(name, "box", float(v["center"][0]), float(v["center"][1]), tuple(float(s) for s in v["size"]),
                        math.radians(float(v["yaw"])))
    if kind == "cylinder":
        return Obstacle(name, "cylinder", float(v["center"][0]), float(v["center"][1]),
                        (float(v["radius"]), float(v["height"])))
    (ax, ay), (bx, by) = v["from"], v["to"]
    length = math.hypot(bx - ax, by - ay)
    return Obstacle(name, "box", (ax + bx) / 2, (ay + by) / 2, (length + v["thickness"], v["thickness"], v["height"]),
                    math.atan2(by - ay, bx - ax))


def load_world(path: str | Path) -> World:
    """A world file (the keys of the module doc at its top level)."""
    return read_world(TomlFile(path, "world file"))


__all__ = ["Obstacle", "World", "footprint_radius", "load_world", "lowest_point", "read_world"]
