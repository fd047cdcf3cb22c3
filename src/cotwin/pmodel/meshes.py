"""Mesh files named by p-models: where they are and their bounding boxes (STL binary or ASCII, OBJ).

A mesh cotwin cannot read is no error: the kinematic tree uses a placeholder (docs/pmodel-notation.md).
"""

from __future__ import annotations

import struct
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..diagnostics import CotwinError
from ..files import read_bytes

READABLE = (".stl", ".obj")  # bounding boxes read here; also the formats MuJoCo loads as mesh assets


@lru_cache(maxsize=64)
def _vertices(path: str, mtime: float) -> np.ndarray:
    try:
        data = read_bytes(path, "mesh")  # capped: a mesh of gigabytes is unreadable, not a MemoryError
    except CotwinError as err:
        raise ValueError(err.findings[0].message) from None
    suffix = Path(path).suffix.lower()
    if suffix == ".stl":
        if len(data) >= 84:
            (count,) = struct.unpack_from("<I", data, 80)
            if 84 + 50 * count == len(data):  # binary (its header may still start with "solid")
                rows = np.frombuffer(data, dtype=np.uint8, offset=84).reshape(count, 50)
                return rows[:, 12:48].copy().view("<f4").reshape(-1, 3).astype(float)
        words = data.decode("ascii", errors="replace").split()
        return np.array([[float(words[i + 1]), float(words[i + 2]), float(words[i + 3])]
                         for i, w in enumerate(words) if w == "vertex"], dtype=float).reshape(-1, 3)
    if suffix == ".obj":
        rows = [line.split()[1:4] for line in data.decode("utf-8", errors="replace").splitlines() if line.startswith("v ")]
        return np.array(rows, dtype=float).reshape(-1, 3)
    raise ValueError(f"cannot read meshes of type '{suffix}' (readable: {', '.join(READABLE)})")


def bounding_box(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(min corner, max corner) of a mesh file's vertices, in the file's units; ValueError if unreadable."""
    try:
        vertices = _vertices(str(path), path.stat().st_mtime)
    except (OSError, struct.error) as err:
        raise ValueError(f"cannot read mesh '{path}': {err}") from None
    except ValueError as err:
        raise ValueError(str(err)) from None
    if len(vertices) == 0 or not np.all(np.isfinite(vertices)):
        raise ValueError(f"mesh '{path}' has no usable vertices")
    return vertices.min(axis=0), vertices.max(axis=0)
