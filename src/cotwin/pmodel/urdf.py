"""p-model -> URDF. URDF has no separate link frames: a child link's frame is its joint's frame, so
geometry and inertia are re-expressed there; the root link's frame is the model frame. URDF cannot
close kinematic loops: a loop's closing joints are left out, a comment names them."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from .tree import Geom, KinematicTree, inverse, matrix_rpy
from .xmltext import file_uri, num, nums, sub, to_text


def _origin(parent: ET.Element, T: np.ndarray) -> None:
    sub(parent, "origin", xyz=nums(T[:3, 3]), rpy=nums(matrix_rpy(T[:3, :3])))


def _geometry(parent: ET.Element, g: Geom) -> None:
    geometry = sub(parent, "geometry")
    if g.kind == "box":
        sub(geometry, "box", size=nums([g.size["length"], g.size["width"], g.size["height"]]))
    elif g.kind in ("cylinder", "capsule"):
        sub(geometry, "cylinder", radius=num(g.size["radius"]), length=num(g.size["length"]))
    elif g.kind == "mesh":
        sub(geometry, "mesh", filename=file_uri(g.mesh), scale=nums(g.scale))
    else:
        sub(geometry, "sphere", radius=num(g.size["radius"]))


def urdf_frames(tree: KinematicTree) -> dict[str, np.ndarray]:
    """The model-frame pose of each URDF link frame (the joint frame; the identity for the root)."""
    frames = {tree.root.name: np.eye(4)}
    for root in tree.roots[1:]:  # free bodies: floating joints from the base, at their poses
        frames[root.name] = root.pose
    for j in tree.joints:
        frames[j.child] = j.pose
    return frames


def to_urdf(tree: KinematicTree) -> str:
    frames = urdf_frames(tree)
    robot = ET.Element("robot", {"name": tree.name})
    for link in tree.links:
        el = sub(robot, "link", name=link.name)
        local = inverse(frames[link.name]) @ link.pose  # p-model link frame in the URDF link frame
        if link.mass > 0:  # a massless frame has no <inertial>, as URDF says one
            inertial = sub(el, "inertial")
            com = local @ link.com
            _origin(inertial, com)
            sub(inertial, "mass", value=num(link.mass))
            I = link.inertia
            sub(inertial, "inertia", ixx=num(I[0, 0]), ixy=num(I[0, 1]), ixz=num(I[0, 2]), iyy=num(I[1, 1]),
                iyz=num(I[1, 2]), izz=num(I[2, 2]))
        for g in link.geoms:
            for tag in ("visual",) if g.placeholder else ("visual", "collision"):
                part = sub(el, tag, name=f"{g.name}_{tag}")
                _origin(part, local @ g.pose)
                _geometry(part, g)
    for j in tree.joints:
        unlimited = j.kind == "revolute" and j.lower is None and j.upper is None  # URDF's revolute defaults to [0, 0]
        el = sub(robot, "joint", name=j.name, type="continuous" if unlimited else j.kind)
        _origin(el, inverse(frames[j.parent]) @ j.pose)
        sub(el, "parent", link=j.parent)
        sub(el, "child", link=j.child)
        if j.kind != "fixed":
            sub(el, "axis", xyz=nums(j.axis))
            limits = {k: num(getattr(j, k)) for k in ("lower", "upper", "effort", "velocity") if getattr(j, k) is not None}
            if limits or not unlimited:  # a continuous joint needs none: effort and velocity 0 would say it cannot move
                limits.setdefault("effort", "0")
                limits.setdefault("velocity", "0")
                sub(el, "limit", **limits)
            sub(el, "dynamics", damping=num(j.damping))
    for root in tree.roots[1:]:  # URDF has one root: a free body of the p-model floats from the base
        el = sub(robot, "joint", name=f"{root.name}_free", type="floating")
        _origin(el, root.pose)
        sub(el, "parent", link=tree.root.name)
        sub(el, "child", link=root.name)
    for j in tree.loops:
        robot.append(ET.Comment(f" joint {j.name} ({j.kind}, {j.parent} -> {j.child}) closes a kinematic loop: "
                                "URDF cannot say it "))
    return to_text(robot)
