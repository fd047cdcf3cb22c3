"""Reading a URDF (as ROS and robot vendors publish it) into checked, located data: links with their
inertials and visual and collision geometry, joints with origins, axes, limits, dynamics and mimics.

Every problem is a finding at its place (file:line:column of the element), all of them collected:
malformed XML, xacro left unexpanded, missing or malformed attributes, unknown joint types, unknown
links, two roots, cycles, a link with two parents, a number not finite or beyond any robot's (Bound:
a number merely beyond what robots have is a warning). The rules are urdfdom's (the ROS reference
parser): `<limit>` with `effort` and `velocity` is required on revolute and prismatic joints
(`lower` and `upper` default to 0), an axis defaults to (1, 0, 0), an `<inertial>` needs `<mass>`
and `<inertia>`. Elements that describe no kinematics or inertia (`<gazebo>`, `<transmission>`,
`<material>`, ...) are counted and left out.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from ..diagnostics import Diagnostics, Location

MAX_MASS = 1e6  # kg: a link heavier than a thousand tonnes is a typo or a unit slip, refused
MAX_MOMENT = 1e6  # kg m^2: an inertia entry beyond this is refused likewise
ROUNDOFF_MOMENT = 1e-12  # kg m^2: a negative moment this small is a CAD export's rounding of zero (iCub: -5.4e-20)
MAX_BYTES = 64 * 1024 * 1024  # a URDF larger than this is refused (the largest published ones are ~2 MB)
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")
UNSUPPORTED_TYPES = ("floating", "planar")  # valid URDF that a p-model joint cannot say (one degree of freedom)
SHAPES = ("box", "cylinder", "sphere", "mesh", "capsule")


@dataclass(frozen=True)
class Bound:
    """How large a finite number of a kind may be: beyond `warn` no robot has it (a warning at its element,
    the value kept), beyond `refuse` none could (an error, as for a mass beyond MAX_MASS): such a number is
    a slip, and the simulator's arithmetic on it (squares, products of transforms) means nothing."""

    warn: float
    refuse: float
    unit: str
    why: str


#: lengths: origin offsets, geometry sizes, prismatic limits (published URDFs stay within 2 m)
LENGTH = Bound(1e3, 1e6, " m", "a unit slip?")
#: rpy angles (published URDFs stay within 3/2 pi)
ANGLE = Bound(2 * math.pi, 1e6, " rad", "degrees written for radians?")
#: a mesh's scale factors (published URDFs use 1 and 0.001)
SCALE = Bound(1e3, 1e6, "", "a unit slip?")
#: a joint's effort and velocity limits and a revolute joint's positions (published: up to 5e4, and
#: +-1e16 as "unlimited"): only refused, far beyond
LIMIT = Bound(1e20, 1e20, "", "a unit slip?")
_XACRO = re.compile(r"\$\{|\$\(")


@dataclass
class Node:
    """An XML element with the place it starts at."""

    tag: str
    attrs: dict[str, str]
    loc: Location
    children: list["Node"] = field(default_factory=list)

    def all(self, tag: str) -> list["Node"]:
        return [c for c in self.children if c.tag == tag]

    def first(self, tag: str) -> "Node | None":
        return next((c for c in self.children if c.tag == tag), None)


@dataclass(frozen=True)
class Origin:
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass
class Geometry:
    kind: str  # box | cylinder | sphere | capsule | mesh
    size: dict[str, float]  # box: x, y, z; cylinder, capsule: radius, length; sphere: radius
    filename: str = ""  # a mesh's URI as written
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    loc: Location = Location("<urdf>", 0, 0)


@dataclass
class Shape:
    """A <visual> or <collision> of a link."""

    role: str  # visual | collision
    name: str  # its name attribute ("" if none)
    origin: Origin
    geometry: Geometry
    material: str = ""
    rgba: tuple[float, float, float, float] | None = None
    loc: Location = Location("<urdf>", 0, 0)


@dataclass
class Inertial:
    origin: Origin
    mass: float
    inertia: dict[str, float]  # ixx ixy ixz iyy iyz izz, about the centre of mass in the origin's frame
    loc: Location = Location("<urdf>", 0, 0)


@dataclass
class Link:
    name: str
    inertial: Inertial | None
    visuals: list[Shape]
    collisions: list[Shape]
    loc: Location


@dataclass
class Mimic:
    joint: str
    multiplier: float = 1.0
    offset: float = 0.0
    loc: Location = Location("<urdf>", 0, 0)


@dataclass
class Joint:
    name: str
    type: str  # revolute | continuous | prismatic | fixed
    parent: str
    child: str
    origin: Origin
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    limit: dict[str, float] = field(default_factory=dict)  # lower upper effort velocity (those given)
    damping: float | None = None
    friction: float | None = None
    mimic: Mimic | None = None
    loc: Location = Location("<urdf>", 0, 0)

    @property
    def moving(self) -> bool:
        return self.type != "fixed"


@dataclass
class Robot:
    """A checked URDF: one root, a tree (each link but the root the child of exactly one joint)."""

    name: str
    path: Path
    links: list[Link]
    joints: list[Joint]
    ignored: Counter  # elements read past, by tag
    loc: Location

    @property
    def root(self) -> Link:
        children = {j.child for j in self.joints}
        return next(l for l in self.links if l.name not in children)

    def link(self, name: str) -> Link:
        return next(l for l in self.links if l.name == name)

    def tree_order(self) -> tuple[list[Link], list[Joint]]:
        """Links depth first from the root (each joint's children in the file's order), and the joint
        leading to each link after the root."""
        below: dict[str, list[Joint]] = {}
        for j in self.joints:
            below.setdefault(j.parent, []).append(j)
        links, joints = [], []
        stack = [(self.root.name, None)]
        while stack:
            name, joint = stack.pop()
            links.append(self.link(name))
            if joint is not None:
                joints.append(joint)
            stack.extend((j.child, j) for j in reversed(below.get(name, [])))
        return links, joints


# ---- XML with places ----

def parse_xml(text: bytes, path: str, diag: Diagnostics) -> Node | None:
    """The element tree of an XML document with each element's place; None (and an error) if malformed."""
    parser = expat.ParserCreate()
    root: list[Node] = []
    stack: list[Node] = []

    def start(tag, attrs):
        node = Node(tag, dict(attrs), Location(path, parser.CurrentLineNumber, parser.CurrentColumnNumber + 1))
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as err:
        diag.error(Location(path, err.lineno, err.offset + 1), f"malformed XML: {expat.ErrorString(err.code)}")
        return None
    return root[0] if root else None


# ---- values ----

class _Reader:
    def __init__(self, diag: Diagnostics):
        self.diag = diag

    def attr(self, node: Node, name: str, what: str) -> str | None:
        value = node.attrs.get(name)
        if value is None:
            self.diag.error(node.loc, f"{what}: <{node.tag}> has no '{name}' attribute")
        return value

    def name(self, node: Node, what: str) -> str | None:
        """An element's name attribute: one that is empty (`name=""`, or only spaces) names nothing, and is
        refused as a missing one is (an empty link name became `_`, an empty robot name the file's)."""
        value = self.attr(node, "name", what)
        if value is not None and not value.strip():
            self.diag.error(node.loc, f"{what}: <{node.tag}> has an empty 'name'")
            return None
        return value

    def numbers(self, node: Node, name: str, count: int, what: str, default=None):
        text = node.attrs.get(name)
        if text is None:
            if default is None:
                self.diag.error(node.loc, f"{what}: <{node.tag}> has no '{name}' attribute")
            return default
        try:
            values = tuple(float(v) for v in text.split())
        except ValueError:
            values = ()
        if len(values) != count or not all(math.isfinite(v) for v in values):
            self.diag.error(node.loc, f"{what}: {node.tag} {name}=\"{text[:60]}\" must be {count} finite "
                            f"number{'s' if count > 1 else ''}")
            return default
        return values

    def number(self, node: Node, name: str, what: str, default: float | None = None) -> float | None:
        values = self.numbers(node, name, 1, what, None if default is None else (default,))
        return None if values is None else values[0]

    def origin(self, owner: Node, what: str) -> Origin:
        node = owner.first("origin")
        if node is None:
            return Origin()
        xyz = self.numbers(node, "xyz", 3, what, (0.0, 0.0, 0.0))
        rpy = self.numbers(node, "rpy", 3, what, (0.0, 0.0, 0.0))
        self.plausible(node, "xyz", xyz, LENGTH, what)
        self.plausible(node, "rpy", rpy, ANGLE, what)
        return Origin(xyz, rpy)

    def plausible(self, node: Node, name: str, values, bound: Bound, what: str) -> None:
        """A finite attribute's numbers against what a robot has: the largest magnitude beyond the bound's
        `warn` a warning at the element, beyond its `refuse` an error (both naming the attribute)."""
        if not values:
            return
        worst = max(abs(v) for v in values)
        shown = f"{what}: {node.tag} {name}=\"{node.attrs.get(name, '')[:60]}\": {worst:g}{bound.unit}"
        if worst > bound.refuse:
            self.diag.error(node.loc, f"{shown}, beyond any robot's ({bound.refuse:g}{bound.unit}; {bound.why})")
        elif worst > bound.warn:
            self.diag.warning(node.loc, f"{shown}, more than a robot has ({bound.warn:g}{bound.unit}; {bound.why}): "
                              "kept as written")


def read_urdf(path: str | Path, diag: Diagnostics) -> Robot | None:
    """The robot a URDF file describes, every problem reported to diag; None if it cannot be read at all
    (a robot is returned beside errors, so that its meshes can be looked for too: only one that comes
    without errors is a tree)."""
    path = Path(path)
    shown = str(path)
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            diag.error(Location(shown, 0, 0), f"the file has {size} bytes, more than a URDF may ({MAX_BYTES})")
            return None
        if not path.is_file():  # a FIFO (or a device) was read from, waiting forever
            diag.error(Location(shown, 0, 0), "cannot read the URDF: not a regular file")
            return None
        data = path.read_bytes()
    except OSError as err:
        diag.error(Location(shown, 0, 0), f"cannot read the URDF: {err.strerror or err}")
        return None
    root = parse_xml(data, shown, diag)
    if root is None:
        if not diag.has_errors:
            diag.error(Location(shown, 1, 1), "an empty file: a URDF is a <robot> element")
        return None
    if _xacro_left(root, path, diag):
        return None
    if root.tag != "robot":
        diag.error(root.loc, f"the document is a <{root.tag}>, not a URDF <robot>")
        return None
    return _robot(root, path, diag)


def _xacro_left(root: Node, path: Path, diag: Diagnostics) -> bool:
    """Report xacro macros and ${...} / $(...) substitutions left in the file."""
    found = False
    hint = f"expand it first (`xacro {path.name} > {path.name.removesuffix('.xacro').removesuffix('.urdf')}.urdf`)"
    stack = [root]
    while stack:
        node = stack.pop()
        if node.tag.startswith("xacro:"):
            diag.error(node.loc, f"<{node.tag}>: xacro left unexpanded: {hint}")
            found = True
            continue
        for key, value in node.attrs.items():
            if _XACRO.search(value):
                diag.error(node.loc, f"<{node.tag} {key}=\"{value[:60]}\">: xacro substitution left unexpanded: {hint}")
                found = True
        stack.extend(reversed(node.children))
    return found


def _robot(root: Node, path: Path, diag: Diagnostics) -> Robot | None:
    read = _Reader(diag)
    name = read.name(root, "the robot") or path.stem
    ignored: Counter = Counter()
    readers = {"link": _link, "joint": _joint}
    declared: dict[str, dict] = {"link": {}, "joint": {}}  # kind -> name -> element, in the file's order
    for node in root.children:
        if node.tag not in readers:
            ignored[node.tag] += 1
            continue
        element = readers[node.tag](node, read, ignored)
        if element is None:
            continue
        first = declared[node.tag].get(element.name)
        if first is not None:
            diag.error(node.loc, f"{node.tag} '{element.name}' is declared twice (first at line {first.loc.line})")
            continue
        declared[node.tag][element.name] = element
    seen_links, seen_joints = declared["link"], declared["joint"]
    links, joints = list(seen_links.values()), list(seen_joints.values())
    robot = Robot(name, path, links, joints, ignored, root.loc)
    if not links:
        if not root.all("link"):  # else each <link> has said why it was not read
            diag.error(root.loc, f"robot '{name}' has no <link>")
        return None
    _check_structure(robot, seen_links, seen_joints, diag)
    return robot


def _link(node: Node, read: _Reader, ignored: Counter) -> Link | None:
    name = read.name(node, "a link")
    if name is None:
        return None
    what = f"link '{name}'"
    inertial = None
    visuals, collisions = [], []
    for child in node.children:
        if child.tag == "inertial":
            if inertial is not None:
                read.diag.error(child.loc, f"{what} has two <inertial> elements")
                continue
            inertial = _inertial(child, read, what)
        elif child.tag in ("visual", "collision"):
            shape = _shape(child, read, what)
            if shape is not None:
                (visuals if child.tag == "visual" else collisions).append(shape)
        else:
            ignored[f"link/{child.tag}"] += 1
    return Link(name, inertial, visuals, collisions, node.loc)


def _inertial(node: Node, read: _Reader, what: str) -> Inertial | None:
    mass_node, inertia_node = node.first("mass"), node.first("inertia")
    if mass_node is None or inertia_node is None:
        read.diag.error(node.loc, f"{what}: <inertial> needs <mass> and <inertia>")
        return None
    mass = read.number(mass_node, "value", f"mass of {what}")
    inertia = {}
    for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
        value = read.number(inertia_node, key, f"inertia of {what}")
        if value is not None:
            inertia[key] = value
    if mass is None or len(inertia) < 6:
        return None
    if not _physical(mass, mass_node, inertia, inertia_node, read, what):
        return None
    return Inertial(read.origin(node, f"inertial of {what}"), mass, inertia, node.loc)


def _physical(mass: float, mass_node: Node, inertia: dict[str, float], inertia_node: Node, read: _Reader,
              what: str) -> bool:
    """Whether a link's mass and inertia are ones a body can have; each problem an error at its element,
    mass and inertia both checked so that one run reports them together. Refused: a negative mass, a
    mass or inertia entry beyond any robot's (a unit slip), a negative moment about an axis (ixx, iyy or
    izz) beyond ROUNDOFF_MOMENT. An inertia merely not positive definite or against the triangle inequality is not refused:
    published URDFs carry many (zero inertias of sensor frames, rounding of CAD exports), and cotwin's
    tree builder replaces them by the geometry's with a warning the import shows (docs/urdf-import.md)."""
    ok = True
    if mass < 0:
        read.diag.error(mass_node.loc, f"{what}: a negative mass ({mass:g} kg)")
        ok = False
    elif mass > MAX_MASS:
        read.diag.error(mass_node.loc, f"{what}: a mass of {mass:g} kg, more than a link may have ({MAX_MASS:g} kg; "
                        "a unit slip?)")
        ok = False
    beyond = [k for k, v in inertia.items() if abs(v) > MAX_MOMENT]
    negative = [k for k in ("ixx", "iyy", "izz") if inertia[k] < -ROUNDOFF_MOMENT]
    if beyond:
        read.diag.error(inertia_node.loc, f"{what}: inertia {', '.join(f'{k}={inertia[k]:g}' for k in beyond)} kg m^2, "
                        f"more than a link may have ({MAX_MOMENT:g} kg m^2; a unit slip?)")
        ok = False
    elif negative:
        read.diag.error(inertia_node.loc, f"{what}: a negative moment of inertia "
                        f"({', '.join(f'{k}={inertia[k]:g}' for k in negative)} kg m^2): no body has one")
        ok = False
    return ok


def _shape(node: Node, read: _Reader, what: str) -> Shape | None:
    role = node.tag
    geometry_node = node.first("geometry")
    if geometry_node is None:
        read.diag.error(node.loc, f"{what}: <{role}> has no <geometry>")
        return None
    shapes = [c for c in geometry_node.children]
    if len(shapes) != 1:
        read.diag.error(geometry_node.loc, f"{what}: <geometry> must hold exactly one shape "
                        f"({', '.join(SHAPES)}), it holds {len(shapes)}")
        return None
    geometry = _geometry(shapes[0], read, f"{role} of {what}")
    if geometry is None:
        return None
    material, rgba = "", None
    mat = node.first("material")
    if mat is not None:
        material = mat.attrs.get("name", "")
        color = mat.first("color")
        if color is not None:
            rgba = read.numbers(color, "rgba", 4, f"material of {what}", None)
    return Shape(role, node.attrs.get("name", ""), read.origin(node, f"{role} of {what}"), geometry, material, rgba,
                 node.loc)


def _geometry(node: Node, read: _Reader, what: str) -> Geometry | None:
    kind = node.tag
    if kind == "box":
        size = read.numbers(node, "size", 3, what)
        values = None if size is None else dict(zip(("x", "y", "z"), size))
    elif kind in ("cylinder", "capsule"):
        radius, length = read.number(node, "radius", what), read.number(node, "length", what)
        values = None if radius is None or length is None else {"radius": radius, "length": length}
    elif kind == "sphere":
        radius = read.number(node, "radius", what)
        values = None if radius is None else {"radius": radius}
    elif kind == "mesh":
        filename = read.attr(node, "filename", what)
        scale = read.numbers(node, "scale", 3, what, (1.0, 1.0, 1.0))
        if filename is None or scale is None:
            return None
        if not filename.strip():
            read.diag.error(node.loc, f"{what}: an empty mesh filename")
            return None
        read.plausible(node, "scale", scale, SCALE, what)
        return Geometry("mesh", {}, filename.strip(), scale, node.loc)
    else:
        read.diag.error(node.loc, f"{what}: unknown geometry <{kind}> ({', '.join(SHAPES)})")
        return None
    if values is None:
        return None
    negative = [k for k, v in values.items() if v < 0]
    if negative:
        read.diag.error(node.loc, f"{what}: a negative {kind} size ({', '.join(negative)})")
        return None
    for key in ("size",) if kind == "box" else values:
        read.plausible(node, key, values.values() if key == "size" else (values[key],), LENGTH, what)
    return Geometry(kind, values, loc=node.loc)


def _joint(node: Node, read: _Reader, ignored: Counter) -> Joint | None:
    name = read.name(node, "a joint")
    kind = read.attr(node, "type", f"joint '{name}'" if name else "a joint")
    if name is None or kind is None:
        return None
    what = f"joint '{name}'"
    if kind in UNSUPPORTED_TYPES:
        read.diag.error(node.loc, f"{what}: a {kind} joint has several degrees of freedom, which a p-model joint "
                        "cannot say (cotwin imports revolute, continuous, prismatic and fixed joints)")
        return None
    if kind not in JOINT_TYPES:
        read.diag.error(node.loc, f"{what}: unknown joint type '{kind}' (URDF's are "
                        f"{', '.join(JOINT_TYPES + UNSUPPORTED_TYPES)})")
        return None
    ends = {}
    for end in ("parent", "child"):
        el = node.first(end)
        if el is None:
            read.diag.error(node.loc, f"{what} has no <{end}>")
        else:
            ends[end] = read.attr(el, "link", what)
    if ends.get("parent") is None or ends.get("child") is None:
        return None
    joint = Joint(name, kind, ends["parent"], ends["child"], read.origin(node, what), loc=node.loc)
    known = {"origin", "parent", "child", "axis", "limit", "dynamics", "mimic"}
    for child in node.children:
        if child.tag not in known:
            ignored[f"joint/{child.tag}"] += 1
    if kind == "fixed":
        return joint
    axis_node = node.first("axis")
    if axis_node is not None:
        axis = read.numbers(axis_node, "xyz", 3, f"axis of {what}", (1.0, 0.0, 0.0))
        if axis is not None and math.hypot(*axis) < 1e-12:
            read.diag.error(axis_node.loc, f"{what}: a zero axis")
        elif axis is not None and not math.isfinite(sum(v * v for v in axis)):  # normalised, it would be zero
            read.diag.error(axis_node.loc, f"{what}: axis xyz=\"{axis_node.attrs['xyz'][:60]}\" is too long to "
                            "normalise (its squared length overflows): write a unit vector")
        elif axis is not None:
            joint.axis = axis
    limit = node.first("limit")
    if limit is not None:
        for key in ("lower", "upper", "effort", "velocity"):
            if key in limit.attrs:
                value = read.number(limit, key, f"limit of {what}")
                if value is not None:
                    joint.limit[key] = value
        if kind != "continuous":
            joint.limit.setdefault("lower", 0.0)
            joint.limit.setdefault("upper", 0.0)
            missing = [k for k in ("effort", "velocity") if k not in limit.attrs]
            if missing:
                read.diag.error(limit.loc, f"{what}: <limit> has no {' and no '.join(missing)} (URDF requires both)")
        else:  # a continuous joint has no position limits (urdfdom ignores them)
            joint.limit.pop("lower", None)
            joint.limit.pop("upper", None)
        if joint.limit.get("lower", 0.0) > joint.limit.get("upper", 0.0):
            read.diag.error(limit.loc, f"{what}: lower limit {joint.limit['lower']:g} above upper limit "
                            f"{joint.limit['upper']:g}")
        for key in ("effort", "velocity"):
            if joint.limit.get(key, 0.0) < 0:
                read.diag.error(limit.loc, f"{what}: a negative {key} limit")
        for key, value in joint.limit.items():  # a prismatic joint's positions are lengths
            bound = LENGTH if kind == "prismatic" and key in ("lower", "upper") else LIMIT
            read.plausible(limit, key, (value,), bound, f"limit of {what}")
    elif kind in ("revolute", "prismatic"):
        read.diag.error(node.loc, f"{what}: a {kind} joint needs <limit> (lower, upper, effort, velocity)")
    dynamics = node.first("dynamics")
    if dynamics is not None:
        if "damping" in dynamics.attrs:
            joint.damping = read.number(dynamics, "damping", f"dynamics of {what}")
        if "friction" in dynamics.attrs:
            joint.friction = read.number(dynamics, "friction", f"dynamics of {what}")
        for key in ("damping", "friction"):
            value = getattr(joint, key)
            if value is not None and value < 0:
                read.diag.error(dynamics.loc, f"{what}: a negative {key}")
    mimic = node.first("mimic")
    if mimic is not None:
        leader = read.attr(mimic, "joint", f"mimic of {what}")
        if leader is not None:
            joint.mimic = Mimic(leader, read.number(mimic, "multiplier", f"mimic of {what}", 1.0),
                                read.number(mimic, "offset", f"mimic of {what}", 0.0), mimic.loc)
    return joint


def _check_structure(robot: Robot, links: dict[str, Link], joints: dict[str, Joint], diag: Diagnostics) -> None:
    """Known links, one parent each, one root, no cycle; mimics name moving joints."""
    parent_of: dict[str, Joint] = {}
    for j in robot.joints:
        for end in (j.parent, j.child):
            if end not in links:
                diag.error(j.loc, f"joint '{j.name}' names link '{end}', which the robot does not declare")
        if j.parent == j.child:
            diag.error(j.loc, f"joint '{j.name}' connects link '{j.parent}' to itself")
            continue
        if j.child in parent_of:
            diag.error(j.loc, f"link '{j.child}' is the child of joints '{parent_of[j.child].name}' (line "
                       f"{parent_of[j.child].loc.line}) and '{j.name}': a URDF is a tree (one parent per link)")
            continue
        parent_of[j.child] = j
        if j.mimic is not None:
            leader = joints.get(j.mimic.joint)
            if leader is None:
                diag.error(j.mimic.loc, f"joint '{j.name}' mimics joint '{j.mimic.joint}', which the robot does not declare")
            elif not leader.moving:
                diag.error(j.mimic.loc, f"joint '{j.name}' mimics the fixed joint '{leader.name}'")
            elif leader.name == j.name:
                diag.error(j.mimic.loc, f"joint '{j.name}' mimics itself")
    _mimic_cycles(joints, diag)
    if diag.has_errors:
        return
    roots = [l for l in robot.links if l.name not in parent_of]
    if len(roots) > 1:
        names = ", ".join(f"'{l.name}' (line {l.loc.line})" for l in roots[:8]) + (", ..." if len(roots) > 8 else "")
        for link in roots:
            diag.error(link.loc, f"link '{link.name}' is a root (no joint leads to it) beside others: a URDF has one "
                       f"root; roots: {names}")
        return
    reached = set()
    if roots:
        below: dict[str, list[str]] = {}
        for j in robot.joints:
            below.setdefault(j.parent, []).append(j.child)
        stack = [roots[0].name]
        while stack:
            name = stack.pop()
            reached.add(name)
            stack.extend(below.get(name, []))
    for link in robot.links:
        if link.name in reached:
            continue
        cycle, name = [], link.name  # walk up the parents until a link comes again
        while name not in cycle:
            cycle.append(name)
            name = parent_of[name].parent
        loop = cycle[cycle.index(name):]
        if link.name == min(loop):  # report each cycle once, at its first link by name
            path = " -> ".join(f"{parent_of[n].parent} --{parent_of[n].name}--> {n}" for n in reversed(loop))
            diag.error(parent_of[link.name].loc, f"joints form a cycle: {path}")


def _mimic_cycles(joints: dict[str, Joint], diag: Diagnostics) -> None:
    """Mimics that lead back to their follower (j1 mimics j2, j2 mimics j1): no joint of the loop has a value
    of its own. Each loop once, at its first joint by name."""
    for joint in joints.values():
        chain, at = [], joint
        while at is not None and at.mimic is not None and at.name not in chain:
            chain.append(at.name)
            at = joints.get(at.mimic.joint)
        if at is None or at.name not in chain or at.name == at.mimic.joint:  # no loop, or one mimicking itself (said)
            continue
        loop = chain[chain.index(at.name):]
        if joint.name == min(loop):
            path = " -> ".join([*loop, loop[0]])
            diag.error(joint.mimic.loc, f"mimic joints form a cycle: {path} (each follows the next, none has a value)")
