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
        return _points(path, "vertex", [words[i + 1:i + 4] for i, w in enumerate(words) if w == "vertex"])
    if suffix == ".obj":
        return _points(path, "v", [line.split()[1:4] for line in data.decode("utf-8", errors="replace").splitlines()
                                   if line.startswith("v ")])
    raise ValueError(f"cannot read meshes of type '{suffix}' (readable: {', '.join(READABLE)})")


def _points(path: str, keyword: str, rows: list[list[str]]) -> np.ndarray:
    """The vertices of a text mesh, each row three numbers; ValueError naming the file and the first row that
    is not (a truncated ASCII STL was an IndexError, a crash; a row of two an error in numpy's words)."""
    if all(len(row) == 3 for row in rows):
        try:
            return np.array(rows, dtype=float).reshape(-1, 3)
        except ValueError:
            pass
    bad = next(k for k, row in enumerate(rows) if not _three_numbers(row))
    raise ValueError(f"mesh '{path}': its {keyword} #{bad + 1} is not three numbers ({' '.join(rows[bad])[:40]!r})")


def _three_numbers(row: list[str]) -> bool:
    try:
        return len([float(v) for v in row]) == 3
    except ValueError:
        return False


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
