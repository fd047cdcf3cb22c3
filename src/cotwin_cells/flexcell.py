"""The Flex-cell scene of the UR5e case study: a plate with a grid of holes, and bricks on it.

The grid comes from the mapping's constants (the paper's `mapping.pm` and ours use the same names,
read case-insensitively): HOLE_DIST, x_max, y_max, XMAX, YMAX and Z_table_level (or Z_TABLE). A hole
(X, Y) is at x = x_max - (Y + 1) HOLE_DIST, y = y_max - X HOLE_DIST in the plate's (grid) frame, exactly
as the mapping computes movediscrete targets; the plate's top is that frame's z = 0 (or the geometry's
`surface`, when the targets were found to lie elsewhere than just above the plate). The cell's
geometry (cotwin.pmodel.cell) places the grid frame in the robot's frame (the identity by default:
the plate right under the robot base); the plate is level, so gravity points along its -z.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace

import numpy as np

from cotwin.diagnostics import CotwinError
from cotwin.pmodel.cell import CellGeometry
from cotwin.pmodel.mjcf import WORLD_CONAFFINITY, WORLD_CONTYPE
from cotwin.pmodel.scenes import SceneBase, SceneKind, SceneRequest
from cotwin.pmodel.xmltext import num, nums, quat, sub
from cotwin.robosim.consteval import const_env, evaluate
from cotwin.robosim.pmodel_elements import Mapping

_NAMES = {"hole_dist": ("hole_dist",), "x_max": ("x_max",), "y_max": ("y_max",), "xmax": ("xmax",),
          "ymax": ("ymax",), "z_table": ("z_table_level", "z_table")}


def has_grid(mapping: Mapping) -> bool:
    """Does the mapping define the Flex-cell grid's constants (so that the cell can be built from it)?"""
    names = {v.name.lower() for v in mapping.variables if v.is_const and v.init is not None}
    return all(any(n in names for n in options) for options in _NAMES.values())


@dataclass(frozen=True)
class Brick:
    name: str
    hole: tuple[int, int]  # (X, Y) grid hole it stands on
    size: tuple[float, float, float] = (0.045, 0.045, 0.06)  # fits the 2FG7's 35-73 mm stroke
    mass: float = 0.1


@dataclass
class FlexCell(SceneBase):
    hole_dist: float = 0.05
    x_max: float = 1.128
    y_max: float = 0.711
    xmax: int = 15
    ymax: int = 23
    z_table: float = 0.02
    thickness: float = 0.02
    bricks: list[Brick] = field(default_factory=list)
    geometry: CellGeometry = field(default_factory=CellGeometry)

    @classmethod
    def from_mapping(cls, mapping: Mapping, bricks: list[Brick] | None = None,
                     geometry: CellGeometry | None = None) -> "FlexCell":
        consts = {v.name.lower(): v for v in mapping.variables if v.is_const and v.init is not None}
        env = const_env([v for v in mapping.variables if v.is_const])
        values = {}
        for key, names in _NAMES.items():
            decl = next((consts[n] for n in names if n in consts), None)
            if decl is None:
                raise CotwinError(f"mapping {mapping.name} has no constant {' or '.join(n.upper() for n in names)} "
                                  "for the Flex-cell grid")
            values[key] = evaluate(decl.init, env)
        return cls(values["hole_dist"], values["x_max"], values["y_max"], int(values["xmax"]), int(values["ymax"]),
                   values["z_table"], bricks=list(bricks or []), geometry=geometry or CellGeometry())

    def hole(self, X: int, Y: int, Z: int = 0) -> tuple[float, float, float]:
        """The point the mapping's movediscrete aims at for grid target (X, Y, Z)."""
        return (self.x_max - (Y + 1) * self.hole_dist, self.y_max - X * self.hole_dist, self.z_table + Z * self.hole_dist)

    def hole_in_robot(self, X: int, Y: int, Z: int = 0):
        """The same point in the robot's model frame (where the tool point goes)."""
        return tuple(float(v) for v in self.geometry.to_robot(self.hole(X, Y, Z)))

    @property
    def gravity(self) -> tuple[float, float, float]:
        """Gravity in the robot's frame: along the level plate's -z."""
        return tuple(float(v) + 0.0 for v in self.geometry.plate_pose()[:3, :3] @ (0.0, 0.0, -9.81))

    @property
    def name(self) -> str:
        return "Flex-cell"

    def with_geometry(self, geometry: CellGeometry | None, payloads: bool = True) -> "FlexCell":
        """The cell placed at `geometry` (None: where it is), its bricks kept only with `payloads`."""
        return replace(self, geometry=geometry or self.geometry, bricks=list(self.bricks) if payloads else [])

    def drawing(self) -> dict:
        """The plate and its holes, in the grid frame, as the page draws them."""
        x0, x1, y0, y1 = self.extent()
        holes = [self.hole(X, Y)[:2] for X in range(self.xmax + 1) for Y in range(self.ymax + 1)]
        return {"plate": {"x0": x0, "x1": x1, "y0": y0, "y1": y1, "thickness": self.thickness},
                "hole_radius": 0.006, "holes": [[round(x, 6), round(y, 6)] for x, y in holes]}

    def in_grid(self, X: int, Y: int) -> bool:
        return 0 <= X <= self.xmax and 0 <= Y <= self.ymax

    def extent(self) -> tuple[float, float, float, float]:
        xs = [self.hole(0, Y)[0] for Y in (0, self.ymax)]
        ys = [self.hole(X, 0)[1] for X in (0, self.xmax)]
        margin = self.hole_dist / 2
        return min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin

    def add_to(self, worldbody: ET.Element) -> None:
        x0, x1, y0, y1 = self.extent()
        P = self.geometry.plate_pose()
        orientation = quat(P[:3, :3])

        def place(point) -> dict:
            attrs = {"pos": nums(P[:3, :3] @ np.asarray(point, float) + P[:3, 3])}
            if abs(orientation[0] - 1.0) > 1e-15:
                attrs["quat"] = nums(orientation)
            return attrs

        top = self.geometry.surface
        sub(worldbody, "geom", name="floor", type="plane", size="3 3 0.1", rgba="0.3 0.3 0.3 1",
            contype=str(WORLD_CONTYPE), conaffinity=str(WORLD_CONAFFINITY), **place((0.0, 0.0, top - 0.8)))
        cell = sub(worldbody, "body", name="cell", **place((0.0, 0.0, top)))
        plate = sub(cell, "body", name="plate", pos=nums([(x0 + x1) / 2, (y0 + y1) / 2, -self.thickness / 2]))
        sub(plate, "geom", name="plate", type="box", size=nums([(x1 - x0) / 2, (y1 - y0) / 2, self.thickness / 2]),
            rgba="0.75 0.75 0.78 1", contype=str(WORLD_CONTYPE), conaffinity=str(WORLD_CONAFFINITY))
        for X in range(self.xmax + 1):
            for Y in range(self.ymax + 1):
                x, y, _ = self.hole(X, Y)
                sub(cell, "geom", name=f"hole_{X}_{Y}", type="cylinder", size="0.006 0.0005",  # a marker:
                    pos=nums([x, y, 0.0005]), rgba="0.2 0.2 0.2 1", contype="0", conaffinity="0")  # visual only
        for brick in self.bricks:
            if not self.in_grid(*brick.hole):
                raise CotwinError(f"brick {brick.name} stands on hole {brick.hole}, outside the grid")
            x, y, _ = self.hole(*brick.hole)
            body = sub(worldbody, "body", name=brick.name, **place((x, y, top + brick.size[2] / 2 + 1e-4)))
            sub(body, "freejoint", name=f"{brick.name}_free")
            sub(body, "geom", name=brick.name, type="box", size=nums([v / 2 for v in brick.size]), mass=num(brick.mass),
                rgba="0.8 0.3 0.2 1", friction="1.2 0.02 0.001", contype=str(WORLD_CONTYPE),
                conaffinity=str(WORLD_CONAFFINITY))


def _pairs(value) -> str | None:
    if not isinstance(value, list) or not all(
            isinstance(b, list) and len(b) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in b)
            for b in value):
        return "must be a list of [X, Y] hole pairs"
    twice = sorted({tuple(b) for b in value if value.count(b) > 1})
    if twice:
        return f"two bricks cannot stand on one hole: {', '.join(str(list(b)) for b in twice)}"
    return None


def build(request: SceneRequest) -> FlexCell:
    """The cell from the mapping's grid constants, bricks on the `[scene] bricks` holes, at the calibrated
    geometry (if any)."""
    holes = request.options.get("bricks", [])
    problem = _pairs(holes)
    if problem:
        raise request.error("bricks", problem)
    cell = FlexCell.from_mapping(request.mapping, [Brick(f"brick{i + 1}", tuple(b)) for i, b in enumerate(holes)],
                                 request.geometry)
    off = [list(b) for b in holes if not cell.in_grid(*b)]
    if off:
        raise request.error("bricks", f"{', '.join(map(str, off))} is no hole of the plate "
                                      f"(X in 0..{cell.xmax}, Y in 0..{cell.ymax})")
    return cell


KIND = SceneKind("flexcell", "the Flex-cell: a plate with a grid of holes (the mapping's constants), bricks on it",
                 build, options=("bricks",), fits=has_grid)
