"""p-model -> SDF 1.6 (the paper's format, for Gazebo or CoppeliaSim), as RoboTool's SDF generator writes
it (docs/pmodel-notation.md, section 7). SDF puts a joint's pose in its child link's frame and its axis in
the joint frame.

Two namings: `style="cotwin"` (the default) names links and joints as the kinematic tree does, the
names every other cotwin artefact uses: RoboTool's names without its running number (`link_2fg7_base`
of a gripper part, `1-Tip` for value 1 of an indexed link); `style="robotool"` writes them as
RoboTool's generator does: one running number over links (a p-model's parts first, then its links,
those of indexed ones last), then joints and fixed connections (`1-Tip`, `3-Link1Joint`,
`4-fixedJoint`), another over bodies (`1--my_body`), each collision with RoboTool's default surface,
and each sensor's pose turned by a pitch of pi/2 as RoboTool turns it. Both write joint types from the
joint's definition (revolute, prismatic, continuous, gearbox, fixed), collision surfaces (bounce,
friction, laser retro) where the p-model gives them, and a <sensor> for each sensor whose annotation
names an SDF sensor type (ray, sonar, imu, logical_camera, contact, light, ...), a <light> for an
actuator annotated Light, their annotations' entries as SDF elements (an entry naming a body, link or
part of the model is written as that element's name); no sensor the model does not declare.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import replace

import numpy as np

from .kinematics import ElementRef, Geom, KinematicTree, PlacedDevice, TJoint, inverse, transform
from .xmltext import file_uri, num, pose_text, sub, to_text

#: RoboTool's SDF generator turns every sensor by this (a pitch of pi/2) after its p-model pose
ROBOTOOL_SENSOR_TURN = transform(rpy=(0.0, np.pi / 2, 0.0))

#: RoboTool's SDF defaults for a collision's surface (its generator writes them for every body)
ROBOTOOL_SURFACE = {"restitution": 0.0, "threshold": 100000.0, "mu": 1.0, "mu2": 1.0, "fdir1": (0.0, 0.0, 0.0),
                    "slip1": 0.0, "slip2": 0.0, "torsional": 1.0, "laser_retro": 0.0}
#: p-model friction entries -> SDF <ode> elements
FRICTION_KEYS = {"coefficient1": "mu", "coefficient2": "mu2", "direction": "fdir1", "slip1": "slip1",
                 "slip2": "slip2", "mu": "mu", "mu2": "mu2", "fdir1": "fdir1"}


def _geometry(parent: ET.Element, g: Geom) -> None:
    geometry = sub(parent, "geometry")
    if g.kind == "box":
        box = sub(geometry, "box")
        sub(box, "size", f"{num(g.size['length'])} {num(g.size['width'])} {num(g.size['height'])}")
    elif g.kind in ("cylinder", "capsule"):
        shape = sub(geometry, g.kind)
        sub(shape, "radius", num(g.size["radius"]))
        sub(shape, "length", num(g.size["length"]))
    elif g.kind == "mesh":
        mesh = sub(geometry, "mesh")
        sub(mesh, "uri", file_uri(g.mesh))
        sub(mesh, "scale", " ".join(num(v) for v in g.scale))
    else:
        sphere = sub(geometry, "sphere")
        sub(sphere, "radius", num(g.size["radius"]))


def _surface(parent: ET.Element, g: Geom, defaults: dict | None) -> None:
    """<surface> of a collision: the p-model's bounce and friction, over `defaults` (RoboTool's) if given."""
    given = g.surface
    if not given and defaults is None:
        return
    values = dict(defaults or {})
    values.update({k: given[k] for k in ("restitution", "threshold") if k in given})
    friction = given.get("friction", {})
    for key, value in friction.get("translational", {}).items():
        if key in FRICTION_KEYS and value is not None:
            values[FRICTION_KEYS[key]] = value
    torsional = friction.get("torsional", {})
    surface = sub(parent, "surface")
    if "restitution" in values or "threshold" in values:
        bounce = sub(surface, "bounce")
        for key, tag in (("restitution", "restitution_coefficient"), ("threshold", "threshold")):
            if key in values:
                sub(bounce, tag, num(values[key]))
    ode_keys = [k for k in ("mu", "mu2", "fdir1", "slip1", "slip2") if k in values]
    if ode_keys or torsional or "torsional" in values:
        fr = sub(surface, "friction")
        if ode_keys:
            ode = sub(fr, "ode")
            for key in ode_keys:
                value = values[key]
                sub(ode, key, " ".join(num(v) for v in value) if isinstance(value, tuple) else num(value))
        if torsional or "torsional" in values:
            tors = sub(fr, "torsional")
            sub(tors, "coefficient", num(torsional.get("coefficient", values.get("torsional", 1.0))))
            for key, value in torsional.items():
                if key != "coefficient" and value is not None:
                    sub(tors, key, _text(value))


def _text(value, names: "_Names | None" = None) -> str:
    if isinstance(value, ElementRef):
        return names.element(value) if names is not None else str(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return num(value) if isinstance(value, float) else str(value)
    if isinstance(value, tuple):
        return " ".join(_text(v, names) for v in value)
    return str(value)


def _entries(parent: ET.Element, record: dict, names: "_Names") -> None:
    """An evaluated annotation as SDF elements (`_key` written `key`: RoboTool escapes keywords so)."""
    for key, value in record["entries"]:
        tag = key.lstrip("_")
        if isinstance(value, dict):
            _entries(sub(parent, tag), value, names)
        elif value is not None:
            sub(parent, tag, _text(value, names))


def _device(parent: ET.Element, device: PlacedDevice, names: "_Names") -> None:
    """A sensor as RoboTool writes it (<sensor> of its annotation's type), or a light actuator (<light>)."""
    if device.kind == "actuator":
        el = sub(parent, "light", name=device.sdf_name or device.name)
    else:
        el = sub(parent, "sensor", name=device.sdf_name or device.name, type=device.sdf_type)
        turn = ROBOTOOL_SENSOR_TURN if names.style == "robotool" else np.eye(4)
        sub(el, "pose", pose_text(device.pose @ turn))
        sub(el, "visualize", "true")
    if device.annotation is not None:
        _entries(el, device.annotation, names)


class _Names:
    """Link, joint and body names of one SDF style."""

    def __init__(self, tree: KinematicTree, style: str):
        self.style = style
        self.links: dict[str, str] = {}
        self.joints: dict[str, str] = {}
        self.geoms: dict[str, str] = {}
        if style == "cotwin":
            self.links = {l.name: l.name for l in tree.links}
            self.joints = {j.name: j.name for j in (*tree.joints, *tree.loops)}
            self.geoms = {g.name: g.name for l in tree.links for g in l.geoms}
            return
        parts = self.ordered(tree)  # RoboTool: parts' links first, indexed links last
        for k, link in enumerate(parts, 1):
            self.links[link.name] = f"{k}-{link.source}"
        count = len(parts)
        for j in self.ordered_joints(tree):
            count += 1
            fixed = j.kind == "fixed" and not j.source
            self.joints[j.name] = f"{count}-{'fixedJoint' if fixed else (j.source or j.name)}"
        k = 0
        for link in parts:
            for g in link.geoms:
                k += 1
                self.geoms[g.name] = f"{k}--{g.body or g.name}"

    def ordered(self, tree: KinematicTree):
        if self.style != "robotool":
            return tree.links
        return sorted(tree.links, key=lambda l: (l.part is None, l.index is not None, l.seq))

    def ordered_joints(self, tree: KinematicTree) -> list[TJoint]:
        """RoboTool's order: parts' joints then their fixed connections, then the p-model's (the tree's else)."""
        joints = [*tree.joints, *tree.loops]
        if self.style != "robotool":
            return joints
        written = {l.name: l for l in tree.links}
        return sorted(joints, key=lambda j: (written[j.child if j.flipped else j.parent].part is None,
                                             j.kind == "fixed"))

    def element(self, ref: ElementRef) -> str:
        """The name of a body (its collision), link or part an annotation names."""
        if ref.kind == "body":
            return self.geoms.get(ref.target.name, ref.target.name)
        if ref.kind == "link":
            return self.links.get(ref.target.name, ref.target.name)
        return str(ref)


def to_sdf(tree: KinematicTree, style: str = "cotwin") -> str:
    """SDF text of the tree; style is "cotwin" (tree names) or "robotool" (RoboTool's generator's names)."""
    if style not in ("cotwin", "robotool"):
        raise ValueError(f"unknown SDF style '{style}' (cotwin or robotool)")
    names = _Names(tree, style)
    robotool = style == "robotool"
    root = ET.Element("sdf", {"version": "1.6"})
    model = sub(root, "model", name=tree.name)
    if robotool:
        sub(model, "self_collide", "true")
        sub(model, "pose", "0 0 0 0 0 0")
    devices = {}
    for d in tree.devices:
        devices.setdefault(d.link, []).append(d)
    for link in names.ordered(tree):
        el = sub(model, "link", name=names.links[link.name])
        sub(el, "pose", pose_text(link.pose))
        inertial = sub(el, "inertial")
        sub(inertial, "pose", pose_text(link.com))
        sub(inertial, "mass", num(link.mass))
        inertia = sub(inertial, "inertia")
        I = link.inertia if link.written_inertia is None else link.written_inertia  # the model's, as RoboTool
        for key, (r, c) in (("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)), ("iyz", (1, 2)), ("izz", (2, 2))):
            sub(inertia, key, num(I[r, c]))
        for g in link.geoms:
            tags = ("visual",) if g.placeholder else ("collision", "visual")
            for tag in tags:
                name = names.geoms[g.name] if robotool else f"{g.name}_{tag}"
                part = sub(el, tag, name=name)
                if "laser_retro" in g.surface or robotool:
                    sub(part, "laser_retro", num(g.surface.get("laser_retro", 0.0)))
                sub(part, "pose", pose_text(g.pose))
                _geometry(part, g)
                if tag == "collision":
                    _surface(part, g, ROBOTOOL_SURFACE if robotool else None)
        for device in devices.get(link.name, []):
            if device.sdf_type is not None:
                _device(el, device, names)
    for j in names.ordered_joints(tree):
        _joint(model, tree, j, names, robotool)
    return to_text(root)


#: joint annotation entries RoboTool writes as elements of the <joint> (a gearbox's)
JOINT_ENTRIES = ("gearbox_ratio", "gearbox_reference_body")


def _joint(model: ET.Element, tree: KinematicTree, j: TJoint, names: _Names, robotool: bool) -> None:
    el = sub(model, "joint", name=names.joints[j.name], type=j.sdf_kind or j.kind)
    if j.flipped:  # a fixed connection written the other way round (RoboTool's direction)
        j = replace(j, parent=j.child, child=j.parent, pose=tree.link(j.parent).pose)
    if not (robotool and j.kind == "fixed"):
        sub(el, "parent", names.links[j.parent])
        sub(el, "child", names.links[j.child])
        sub(el, "pose", pose_text(inverse(tree.link(j.child).pose) @ j.pose))
    else:
        sub(el, "parent", names.links[j.parent])
        sub(el, "child", names.links[j.child])
    for key, value in j.annotations.get("entries", []) if j.annotations else ():
        if key in JOINT_ENTRIES and value is not None:
            sub(el, key, _text(value, names))
    if j.kind == "fixed":
        if robotool:
            axis = sub(el, "axis")
            sub(axis, "xyz", "0 0 1")
        return
    axis = sub(el, "axis")
    sub(axis, "xyz", " ".join(num(v) for v in j.axis))
    limit = sub(axis, "limit")
    for key in ("lower", "upper", "effort", "velocity"):
        value = getattr(j, key)
        if value is not None and not (j.sdf_kind == "continuous" and key in ("lower", "upper")):
            sub(limit, key, num(value))
    dynamics = sub(axis, "dynamics")
    sub(dynamics, "damping", num(j.damping))
    if robotool:
        given = dict(_find(j.annotations, "axis", "dynamics"))
        for key in ("_friction", "spring_reference", "spring_stiffness"):
            if given.get(key) is not None:
                sub(dynamics, key.lstrip("_"), _text(given[key]))


def _find(record: dict, *path: str) -> list:
    """The entries of a nested evaluated annotation at `path` ([] if absent)."""
    entries = record.get("entries", []) if record else []
    for key in path:
        value = next((v for k, v in entries if k == key), None)
        if not isinstance(value, dict):
            return []
        entries = value["entries"]
    return entries
