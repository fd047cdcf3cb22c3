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
    [tool]
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

from ..diagnostics import CotwinError, Finding, Location, Severity
from ..tomlfile import TomlDocument, dumps
from .tree import matrix_rpy, rpy_matrix, transform

TOOL_POINTS = ("flange", "fingertips")
DOWN = (math.pi, 0.0, 0.0)  # tool approach axis along the plate's -z, tool x along the plate's x


@dataclass
class CellGeometry:
    plate_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    plate_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tool: str | tuple[float, float, float] = "fingertips"
    tool_rpy: tuple[float, float, float] = DOWN
    reference: tuple[float, ...] | None = None  # None: zero posture with the base facing the target
    reference_name: str = ""
    joint_offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    where: dict[str, Location] = field(default_factory=dict, compare=False, repr=False)  # keys as read

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
        tables = {"plate": {"xyz": list(self.plate_xyz), "rpy": list(self.plate_rpy)},
                  "tool": {"point": self.tool if isinstance(self.tool, str) else list(self.tool),
                           "rpy": list(self.tool_rpy)}}
        if ik:
            tables["ik"] = ik
        return tables

    @classmethod
    def from_document(cls, doc: TomlDocument) -> "CellGeometry":
        """The geometry tables of a TOML document (absent tables keep their defaults); problems are
        recorded in doc's diagnostics with their places."""
        geometry = cls()
        plate = doc.table("plate", {"xyz", "rpy"})
        geometry.plate_xyz = doc.vector("plate", plate, "xyz", 3, geometry.plate_xyz)
        geometry.plate_rpy = doc.vector("plate", plate, "rpy", 3, geometry.plate_rpy)
        tool = doc.table("tool", {"point", "rpy"})
        point = tool.get("point", geometry.tool)
        if isinstance(point, str):
            if point not in TOOL_POINTS:
                doc.error("tool", "point", f"[tool] point must be one of {', '.join(TOOL_POINTS)} or [x, y, z], "
                          f"got {point!r}")
            else:
                geometry.tool = point
        else:
            geometry.tool = doc.vector("tool", tool, "point", 3, geometry.tool)
        geometry.tool_rpy = doc.vector("tool", tool, "rpy", 3, geometry.tool_rpy)
        ik = doc.table("ik", {"reference", "reference_name", "joint_offsets"})
        if "reference" in ik:
            ref = ik["reference"]
            if not (isinstance(ref, list) and ref and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                          and math.isfinite(v) for v in ref)):
                doc.error("ik", "reference", f"[ik] reference must be a list of joint angles (rad), got {ref!r}")
            else:
                geometry.reference = tuple(float(v) for v in ref)
        name = ik.get("reference_name", "")
        if not isinstance(name, str):
            doc.error("ik", "reference_name", "[ik] reference_name must be a string")
        else:
            geometry.reference_name = name
        offsets = ik.get("joint_offsets", {})
        if not isinstance(offsets, dict):
            doc.error("ik", "joint_offsets", "[ik] joint_offsets must be a table of joint = [dx, dy, dz]")
        else:
            for joint, value in offsets.items():
                if not (isinstance(value, list) and len(value) == 3 and all(
                        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
                    doc.error("ik", "joint_offsets", f"[ik] joint_offsets.{joint} must be [dx, dy, dz] in m, got {value!r}")
                else:
                    geometry.joint_offsets[joint] = tuple(float(v) for v in value)
        geometry.where = {"reference": doc.where("ik", "reference"), "joint_offsets": doc.where("ik", "joint_offsets")}
        return geometry

    @classmethod
    def read(cls, path: str | Path) -> "CellGeometry":
        doc = TomlDocument(path)
        geometry = cls.from_document(doc)
        doc.finish()
        return geometry

    def write(self, path: str | Path, header: str = "cotwin cell geometry") -> Path:
        path = Path(path)
        path.write_text(dumps(self.tables(), header))
        return path
