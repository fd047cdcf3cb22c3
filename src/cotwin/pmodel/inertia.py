"""Default inertia for links whose p-model gives a mass but no (usable) inertia matrix, or one no body of
that geometry can have.

Documented choice: the link's collision geometry is taken as a solid of uniform density carrying the
link's whole mass (split between shapes by volume), and its inertia is computed about the centre of
mass (the inertial pose, else the link origin). A link without geometry is a solid sphere of 5 cm.
"""

from __future__ import annotations

import numpy as np

FALLBACK_RADIUS = 0.05


def solid_inertia(kind: str, size: dict[str, float], mass: float) -> np.ndarray:
    """Inertia of a solid about its centre, in its own frame (cylinders and capsules along z)."""
    if kind == "box":
        l, w, h = size["length"], size["width"], size["height"]
        return mass / 12.0 * np.diag([w * w + h * h, l * l + h * h, l * l + w * w])
    if kind in ("cylinder", "capsule"):
        r = size["radius"]
        L = size["length"] + (2 * r if kind == "capsule" else 0.0)
        side = mass * (3 * r * r + L * L) / 12.0
        return np.diag([side, side, mass * r * r / 2.0])
    r = size.get("radius", FALLBACK_RADIUS)
    return np.eye(3) * 0.4 * mass * r * r


def valid_inertia(I: np.ndarray, tolerance: float = 1e-9) -> bool:
    """A physical inertia: symmetric positive definite, principal moments obeying the triangle inequality."""
    if not np.all(np.isfinite(I)) or np.abs(I - I.T).max() > tolerance * max(1.0, np.abs(I).max()):
        return False
    moments = np.linalg.eigvalsh((I + I.T) / 2)
    if moments.min() <= 0:
        return False
    a, b, c = sorted(moments)
    return a + b >= c * (1 - 1e-6)


def _solid(g) -> tuple[str, dict, np.ndarray]:
    """The solid a geometry stands for: a mesh by its bounding box, centred where the box is."""
    if g.kind != "mesh":
        return g.kind, g.size, g.pose
    T = g.pose.copy()
    T[:3, 3] = g.pose[:3, 3] + g.pose[:3, :3] @ np.asarray(g.center)
    return "box", g.size, T


def default_inertia(mass: float, geoms, com: np.ndarray) -> np.ndarray:
    """3x3 inertia about the centre of mass `com` (a 4x4 pose in the link frame), in the COM frame."""
    volumes = [g.volume() for g in geoms]
    total = sum(volumes)
    if not geoms or total <= 0:
        return solid_inertia("sphere", {"radius": FALLBACK_RADIUS}, mass)
    I = np.zeros((3, 3))
    for g, v in zip(geoms, volumes):
        m = mass * v / total
        kind, size, pose = _solid(g)
        R = pose[:3, :3]
        d = pose[:3, 3] - com[:3, 3]
        I += R @ solid_inertia(kind, size, m) @ R.T + m * (d @ d * np.eye(3) - np.outer(d, d))
    Rc = com[:3, :3]
    I = Rc.T @ I @ Rc
    return (I + I.T) / 2.0


def reach(geoms, com: np.ndarray) -> float | None:
    """The largest distance from the centre of mass `com` (a pose) to the geometry (its shapes' bounding
    solids), or None when the geometry is not known (none, or a placeholder for an unread mesh)."""
    if not geoms or any(g.placeholder for g in geoms):
        return None
    c = com[:3, 3]
    far = 0.0
    for g in geoms:
        kind, size, pose = _solid(g)
        if kind == "sphere":
            far = max(far, float(np.linalg.norm(pose[:3, 3] - c)) + size["radius"])
            continue
        if kind == "box":
            half = np.array([size["length"], size["width"], size["height"]]) / 2
        else:  # cylinder, capsule (along z)
            r = size["radius"]
            half = np.array([r, r, size["length"] / 2 + (r if kind == "capsule" else 0.0)])
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
        points = corners @ pose[:3, :3].T + pose[:3, 3]
        far = max(far, float(np.linalg.norm(points - c, axis=1).max()))
    return far


def beyond_reach(I: np.ndarray, mass: float, distance: float) -> bool:
    """Is a principal moment larger than any body of this mass within `distance` of its centre of mass
    can have (m d^2: all the mass as far out as the geometry goes)?"""
    return float(np.linalg.eigvalsh((I + I.T) / 2).max()) > mass * distance * distance * (1 + 1e-6)
