"""Default inertia for links whose p-model gives a mass but no (usable) inertia matrix.

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
