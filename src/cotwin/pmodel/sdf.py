"""p-model -> SDF 1.6 (the paper's format, for Gazebo or CoppeliaSim). SDF puts a joint's pose in its
child link's frame and its axis in the joint frame."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from .tree import Geom, KinematicTree, inverse
from .xmltext import num, pose_text, sub, to_text


def _geometry(parent: ET.Element, g: Geom) -> None:
    geometry = sub(parent, "geometry")
    if g.kind == "box":
        box = sub(geometry, "box")
        sub(box, "size", f"{num(g.size['length'])} {num(g.size['width'])} {num(g.size['height'])}")
    elif g.kind in ("cylinder", "capsule"):
        shape = sub(geometry, g.kind)
        sub(shape, "radius", num(g.size["radius"]))
        sub(shape, "length", num(g.size["length"]))
    else:
        sphere = sub(geometry, "sphere")
        sub(sphere, "radius", num(g.size["radius"]))


def to_sdf(tree: KinematicTree) -> str:
    root = ET.Element("sdf", {"version": "1.6"})
    model = sub(root, "model", name=tree.name)
    for link in tree.links:
        el = sub(model, "link", name=link.name)
        sub(el, "pose", pose_text(link.pose))
        inertial = sub(el, "inertial")
        sub(inertial, "pose", pose_text(link.com))
        sub(inertial, "mass", num(link.mass))
        inertia = sub(inertial, "inertia")
        I = link.inertia
        for key, (r, c) in (("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)), ("iyz", (1, 2)), ("izz", (2, 2))):
            sub(inertia, key, num(I[r, c]))
        for g in link.geoms:
            for tag in ("collision", "visual"):
                part = sub(el, tag, name=f"{g.name}_{tag}")
                sub(part, "pose", pose_text(g.pose))
                _geometry(part, g)
    for j in tree.joints:
        el = sub(model, "joint", name=j.name, type=j.kind)
        sub(el, "parent", j.parent)
        sub(el, "child", j.child)
        sub(el, "pose", pose_text(inverse(tree.link(j.child).pose) @ j.pose))
        if j.kind != "fixed":
            axis = sub(el, "axis")
            sub(axis, "xyz", " ".join(num(v) for v in j.axis))
            limit = sub(axis, "limit")
            for key in ("lower", "upper", "effort", "velocity"):
                value = getattr(j, key)
                if value is not None:
                    sub(limit, key, num(value))
            dynamics = sub(axis, "dynamics")
            sub(dynamics, "damping", num(j.damping))
    return to_text(root)
