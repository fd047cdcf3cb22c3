"""Robot profiles: how a robot controller's joint angles and base frame relate to the p-model's, as a
small TOML file a project names (`[robot] profile`), so the generic core holds no robot's conventions.

A profile file holds
    joint_offsets = [..]   # rad, one per arm joint: controller angle = p-model angle + offset
    base = [[..], ..]      # 4x4 rigid transform: the controller's base frame in the model frame
    name = ".."            # optional, for messages
    [lidar]                # optional: the robot's scanner, for LiDAR annotations that leave values out
    samples = 360          #   beams a turn; min_angle, max_angle (rad), range_min, range_max (m),
    ...                    #   update_rate (scans a second); [sonar] likewise (cotwin.pmodel.kinds.RaySpec)
Without a profile the identity convention holds (controller joints = model joints, base = model frame), and
ray sensors take cotwin.pmodel.kinds.RAY_DEFAULTS where their annotations say nothing.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import TomlFile
from ..diagnostics import CotwinError, Finding, Location, Severity

log = logging.getLogger("cotwin.twin")
IDENTITY_BASE = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0))
KEYS = ("name", "joint_offsets", "base", "lidar", "sonar")
RAY_KEYS = ("samples", "min_angle", "max_angle", "range_min", "range_max", "update_rate")
RIGID_TOLERANCE = 1e-6  # |R^T R - I| and |det R - 1| of a base's rotation


@dataclass(frozen=True)
class Convention:
    """How the controller's joint angles and base frame relate to the p-model's (default: the identity;
    offsets shorter than a joint vector count as zero for the rest)."""

    offsets: tuple[float, ...] = ()  # q_controller = q + offsets
    base: tuple[tuple[float, ...], ...] = IDENTITY_BASE  # controller base frame in the model frame
    name: str = "identity"

    def _offsets(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        out[: min(n, len(self.offsets))] = self.offsets[:n]
        return out

    def to_model(self, q_controller) -> np.ndarray:
        q = np.asarray(q_controller, float)
        return q - self._offsets(q.shape[-1])

    def to_controller(self, q) -> np.ndarray:
        q = np.asarray(q, float)
        return q + self._offsets(q.shape[-1])

    def pose_to_model(self, T_controller: np.ndarray) -> np.ndarray:
        return np.asarray(self.base) @ T_controller


IDENTITY = Convention()


def read_profile(path: str | Path, joints: int | None = None) -> Convention:
    """The convention of a profile file; every problem is an error at its key, all together (an unknown
    key, offsets not one per arm joint when `joints` is given, a non-finite number, a base that is not a
    4x4 rigid transform)."""
    file = TomlFile(path, "robot profile")
    problems: list[Finding] = []

    def bad(key: str, message: str) -> None:
        problems.append(Finding(file.location((key,)), Severity.ERROR, f"{key}: {message}"))

    for key in file.data:
        if key not in KEYS:
            bad(key, f"unknown key of a robot profile (it takes {', '.join(KEYS)})")
    name = file.data.get("name", Path(path).name)
    if not isinstance(name, str):
        bad("name", f"must be a string, got {name!r}")
    offsets = file.data.get("joint_offsets")
    if offsets is None:
        bad("joint_offsets", "missing: one offset (rad) per arm joint, controller angle = model angle + offset")
        offsets = []
    elif not isinstance(offsets, list) or not all(_finite(v) for v in offsets):
        bad("joint_offsets", f"must be a list of finite numbers (rad), got {str(offsets)[:80]}")
        offsets = []
    elif joints is not None and len(offsets) != joints:
        bad("joint_offsets", f"{len(offsets)} offsets for an arm of {joints} joints")
    base = file.data.get("base", [list(row) for row in IDENTITY_BASE])
    problem = _base_problem(base)
    if problem is not None:
        bad("base", problem)
    if problems:
        raise CotwinError(problems)
    return Convention(tuple(float(v) for v in offsets), tuple(tuple(float(v) for v in row) for row in base),
                      str(name))


def profile_rays(profile: str | Path | None) -> dict:
    """The ray sensors' defaults a profile gives ({"lidar": RaySpec, "sonar": RaySpec}, each from its table,
    the values it leaves out from cotwin.pmodel.kinds.RAY_DEFAULTS); {} without a profile. Every problem is
    an error at its key: an unknown key, a number that is not finite or out of range."""
    from dataclasses import replace

    from ..pmodel.kinds import RAY_DEFAULTS

    if profile is None:
        return {}
    file = TomlFile(profile, "robot profile")
    problems: list[Finding] = []
    out = {}
    for kind, default in RAY_DEFAULTS.items():
        table = file.data.get(kind)
        if table is None:
            continue
        if not isinstance(table, dict):
            problems.append(Finding(file.location((kind,)), Severity.ERROR, f"[{kind}] must be a table of "
                                    f"{', '.join(RAY_KEYS)}"))
            continue
        values = {}
        for key, value in table.items():
            where = file.location((kind, key))
            if key not in RAY_KEYS:
                problems.append(Finding(where, Severity.ERROR, f"[{kind}] {key}: unknown key (it takes "
                                        f"{', '.join(RAY_KEYS)})"))
            elif not _finite(value) or (key == "samples" and (value != int(value) or value < 1)) or \
                    (key in ("range_max", "update_rate") and value <= 0) or (key == "range_min" and value < 0):
                problems.append(Finding(where, Severity.ERROR, f"[{kind}] {key}: must be a finite number"
                                        f"{' (a whole number >= 1)' if key == 'samples' else ''}"
                                        f"{' > 0' if key in ('range_max', 'update_rate') else ''}"
                                        f"{' >= 0' if key == 'range_min' else ''}, got {str(value)[:40]}"))
            else:
                values[key] = int(value) if key == "samples" else float(value)
        spec = replace(default, **values)
        if spec.range_min >= spec.range_max:
            problems.append(Finding(file.location((kind,)), Severity.ERROR,
                                    f"[{kind}] range_min {spec.range_min:g} m is not below range_max {spec.range_max:g} m"))
        out[kind] = spec
    if problems:
        raise CotwinError(problems)
    return out


def robot_convention(profile: str | Path | None, joints: int | None = None,
                     where: Location | None = None) -> Convention:
    """The convention of a project's profile, or the identity with a warning that none was named, at
    `where` (the project file's [robot] table, or its start, where the profile would be named)."""
    if profile is None:
        log.warning("%sno robot profile named ([robot] profile): the controller's joints and base frame are "
                    "taken as the p-model's (identity)", f"{where}: " if where is not None else "")
        return IDENTITY
    return read_profile(profile, joints)


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _base_problem(base) -> str | None:
    """Why `base` is not a 4x4 rigid transform (rows of finite numbers), or None."""
    if not (isinstance(base, list) and len(base) == 4 and all(isinstance(r, list) and len(r) == 4 for r in base)):
        return "must be a 4x4 matrix: four rows of four numbers"
    if not all(_finite(v) for row in base for v in row):
        return "must hold finite numbers only"
    T = np.array(base, float)
    R = T[:3, :3]
    if not np.allclose(T[3], (0.0, 0.0, 0.0, 1.0)):
        return f"the last row must be [0, 0, 0, 1], got {T[3].tolist()}"
    if not np.allclose(R.T @ R, np.eye(3), atol=RIGID_TOLERANCE) or abs(np.linalg.det(R) - 1.0) > RIGID_TOLERANCE:
        return "is not a rigid transform: its rotation part must be orthonormal with determinant 1"
    return None
