"""Where the work cell is with respect to the robot, and which point of the tool goes where.

A grid target is a point (x, y, z) the mapping computes in the plate's own frame (the grid frame).
`CellGeometry` places that frame in the robot's model frame (6 DoF: the real cell's robot base may be
turned and tilted with respect to the plate), says which point of the tool reaches a target (the
flange, the fingertips or an explicit offset in the tool link's frame) and with which orientation
(the tool frame in the plate frame: by default the approach axis points down into the plate). It also
carries what makes the inverse kinematics deterministic and faithful to the physical twin's solver:
the reference posture whose branch is kept, and corrections of the solver's joint origins (a PT's
IK may run on other link lengths than the arm's). Read and written as TOML:

    [plate]                     # the grid frame in the robot's model frame
    xyz = [0.0, 0.0, 0.0]       # m
    rpy = [0.0, 0.0, 0.0]       # rad, fixed-axis roll-pitch-yaw (as SDF poses)
    surface = 0.0               # m: height of the plate's top in the grid frame
    [tool]
    link = "tool0"              # the tool link (default: the gripper's, else the end of the arm's chain)
    point = "fingertips"        # "flange", "fingertips" or [x, y, z] (m, tool link frame)
    rpy = [3.14159265, 0, 0]    # the tool frame at a target, in the plate frame
    [ik]
    reference_name = "tool down, elbow up"
    reference = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]   # arm joints in kinematic order (rad)
    joint_offsets = { elbow_joint = [0.0, -0.008, 0.0] }  # m, model frame at zero
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import Key, Schema, TomlFile, dumps, is_number, raise_problems, shown
from ..diagnostics import CotwinError, Finding, Location, Severity
from ..files import write_text
from .tree import matrix_rpy, rpy_matrix, transform

TOOL_POINTS = ("flange", "fingertips")
DOWN = (math.pi, 0.0, 0.0)  # tool approach axis along the plate's -z, tool x along the plate's x


@dataclass
class CellGeometry:
    plate_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    plate_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    surface: float = 0.0  # the plate's top along the grid frame's z (targets are above it)
    tool: str | tuple[float, float, float] = "fingertips"
    tool_rpy: tuple[float, float, float] = DOWN
    reference: tuple[float, ...] | None = None  # None: zero posture with the base facing the target
    reference_name: str = ""
    joint_offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    where: dict[str, Location] = field(default_factory=dict, compare=False, repr=False)  # keys as read
    tool_link: str = ""  # the tool link; "": cotwin.pmodel.ik.find_tool's default (the gripper's, the chain's end)

    # ---- frames ----
    def plate_pose(self) -> np.ndarray:
        """The grid frame in the robot's model frame."""
        return transform(self.plate_xyz, self.plate_rpy)

    def to_robot(self, point) -> np.ndarray:
        """A point of the grid frame in the robot's model frame."""
        return (self.plate_pose() @ np.append(np.asarray(point, float), 1.0))[:3]

    def target_pose(self, point) -> np.ndarray:
        """The pose the tool frame must reach for grid point `point`, in the robot's model frame."""
        T = self.plate_pose()
        T[:3, 3] = self.to_robot(point)
        T[:3, :3] = T[:3, :3] @ rpy_matrix(*self.tool_rpy)
        return T

    def with_plate(self, T: np.ndarray) -> "CellGeometry":
        """A copy with the plate at pose T (4x4)."""
        copy = CellGeometry(**{k: getattr(self, k) for k in self.__dataclass_fields__ if k != "where"})
        copy.plate_xyz = tuple(float(v) for v in T[:3, 3])
        copy.plate_rpy = tuple(float(v) for v in matrix_rpy(T[:3, :3]))
        return copy

    def find_tool(self, tree):
        """The tool this geometry names on a tree (cotwin.pmodel.ik.find_tool): its link and point; an
        unknown link is an error at the `[tool] link` that names it."""
        from . import ik

        try:
            return ik.find_tool(tree, self.tool, self.tool_link or None)
        except CotwinError as err:
            where = self.where.get("tool_link")
            if where is None:
                raise
            raise CotwinError([Finding(where, Severity.ERROR, f.message) for f in err.findings]) from None

    # ---- checks against a kinematic chain ----
    def check_joints(self, arm: list[str]) -> None:
        """The reference posture and the offsets name the arm's joints (located in the file read)."""
        problems = []
        if self.reference is not None and len(self.reference) != len(arm):
            problems.append(("reference", f"the reference posture has {len(self.reference)} values, the arm "
                             f"has {len(arm)} joints ({', '.join(arm)})"))
        for name in self.joint_offsets:
            if name not in arm:
                problems.append(("joint_offsets", f"joint_offsets: '{name}' is not an arm joint ({', '.join(arm)})"))
        if problems:
            raise CotwinError([Finding(self.where.get(key, Location("<geometry>", 0, 0)), Severity.ERROR, message)
                               for key, message in problems])

    # ---- TOML ----
    def tables(self) -> dict[str, dict]:
        ik: dict = {}
        if self.reference_name:
            ik["reference_name"] = self.reference_name
        if self.reference is not None:
            ik["reference"] = [float(v) for v in self.reference]
        if self.joint_offsets:
            ik["joint_offsets"] = {k: [float(x) for x in v] for k, v in self.joint_offsets.items()}
        tool = {"link": self.tool_link} if self.tool_link else {}
        tables = {"plate": {"xyz": list(self.plate_xyz), "rpy": list(self.plate_rpy), "surface": self.surface},
                  "tool": {**tool, "point": self.tool if isinstance(self.tool, str) else list(self.tool),
                           "rpy": list(self.tool_rpy)}}
        if ik:
            tables["ik"] = ik
        return tables

    @classmethod
    def from_values(cls, values: dict, file: TomlFile) -> "CellGeometry":
        """The geometry from a file's tables as read by a Schema holding GEOMETRY's keys."""
        plate, tool, ik = values["plate"], values["tool"], values["ik"]
        point = tool["point"]
        return cls(tuple(plate["xyz"]), tuple(plate["rpy"]), float(plate["surface"]),
                   point if isinstance(point, str) else tuple(float(v) for v in point), tuple(tool["rpy"]),
                   tuple(float(v) for v in ik["reference"]) if ik["reference"] is not None else None,
                   ik["reference_name"], {k: tuple(float(x) for x in v) for k, v in (ik["joint_offsets"] or {}).items()},
                   {"reference": file.location(("ik", "reference")),
                    "joint_offsets": file.location(("ik", "joint_offsets")),
                    "tool_link": file.location(("tool", "link"))}, tool_link=tool["link"])

    @classmethod
    def read(cls, path: str | Path) -> "CellGeometry":
        """A geometry file: [plate], [tool] and [ik] (all optional)."""
        file = TomlFile(path, "geometry file")
        problems: list[Finding] = []
        values = Schema(GEOMETRY).read(file.data, file, (), problems)
        raise_problems(problems)
        return cls.from_values(values, file)

    def write(self, path: str | Path, header: str = "cotwin cell geometry") -> Path:
        return write_text(path, dumps(self.tables(), header))


def _numbers(length: int | None):
    def check(value) -> str | None:
        if not all(is_number(v) for v in value) \
                or (length is not None and len(value) != length) or not value:
            return f"must be a list of {length or 'some'} finite numbers, got {shown(value)}"
        return None
    return check


def _tool_point(value) -> str | None:
    if isinstance(value, str):
        return None if value in TOOL_POINTS else f"must be one of {', '.join(TOOL_POINTS)} or [x, y, z], got {value!r}"
    if isinstance(value, list):
        return _numbers(3)(value)
    return f"must be one of {', '.join(TOOL_POINTS)} or [x, y, z], got {value!r}"


GEOMETRY = {
    "plate": Key("table", {}, table=Schema({"xyz": Key("list", [0.0, 0.0, 0.0], check=_numbers(3)),
                                            "rpy": Key("list", [0.0, 0.0, 0.0], check=_numbers(3)),
                                            "surface": Key("number", 0.0)})),
    "tool": Key("table", {}, table=Schema({"link": Key("str", ""), "point": Key("any", "fingertips", check=_tool_point),
                                           "rpy": Key("list", list(DOWN), check=_numbers(3))})),
    "ik": Key("table", {}, table=Schema({"reference": Key("list", check=_numbers(None)), "reference_name": Key("str", ""),
                                         "joint_offsets": Key("table", {}, table=Schema(
                                             open=True, values=Key("list", check=_numbers(3))))})),
}
