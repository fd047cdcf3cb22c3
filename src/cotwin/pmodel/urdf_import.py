"""A RoboSim p-model (and its meshes) from a URDF: `import_urdf(urdf, out)`, `cotwin import-urdf`.

What a URDF says becomes (docs/urdf-import.md):
- each link a `local link` whose pose is the URDF link frame in the model frame at zero joint values
  (the root link's frame is the model frame); its `<inertial>` its inertial information (mass, inertia
  matrix, the origin as the inertial's pose); each `<collision>` a `local body` with the shape (RoboSim
  bodies are physical: the simulator collides them); each `<visual>` an `annotation Visual` of the
  link (shape, mesh, scale, origin, material), kept as data;
- each joint a `jref` of physmod::joints' Revolute, Continuous, Prismatic or Fixed in its parent link,
  its origin as the joint's pose, an SDF-style annotation with its axis, limits and dynamics (damping,
  `_friction`), an `annotation Mimic` for a mimic joint, and for a moving joint a ServoMotor
  (`J_motor.dangle`: a position command) and Position, Velocity and Torque (Force, prismatic) sensors,
  so that a mapping can command and read it (`robot::parent::J::J_position.output_position`);
- meshes (`package://`, `file://` or relative) copied into OUT/meshes and named relative to the model.

Names are kept; a name RoboSim cannot say is mangled (characters outside [A-Za-z0-9_] become `_`, a
leading digit gets `_` before it, a clash `_2`...) and a keyword is escaped (`^link`): the renamings
are returned (and printed). Output is deterministic: the same URDF and meshes give byte-identical
files, from any working directory.
"""

from __future__ import annotations

import os
import posixpath
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np

from ..diagnostics import CotwinError, Diagnostics, Finding, Severity
from ..files import check_outputs, read_bytes, write_bytes, write_text
from .tree import matrix_rpy, transform
from .urdf_read import Geometry, Joint, Link, Origin, Robot, Shape, read_urdf

MESH_FOLDER = "meshes"
_ID = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_PACKAGE_DEPTH = 4  # how deep a package path is searched for a package.xml naming the package


@lru_cache(maxsize=None)
def keywords() -> frozenset[str]:
    """The words of the p-model grammar that cannot be plain names (they are written `^word`)."""
    from ..robosim.parser import lark_parser

    return frozenset(t.pattern.value for t in lark_parser("pm").terminals
                     if t.pattern.type == "str" and _ID.fullmatch(t.pattern.value))


#: names RoboSim allows but cotwin's simulator cannot take, by kind: MuJoCo's world body is `world`
RESERVED = {"link": {"world": "world_link"}}


@dataclass(frozen=True)
class Renaming:
    kind: str  # robot | link | joint | mesh (its path under meshes/)
    urdf: str
    pmodel: str
    why: str


class Names:
    """RoboSim names for URDF names, unique per kind of element (links, joints, bodies, devices)."""

    def __init__(self):
        self.used: dict[str, set[str]] = {}
        self.renamed: list[Renaming] = []
        self.of: dict[tuple[str, str], str] = {}

    def add(self, kind: str, name: str, record: bool = True) -> str:
        base = re.sub(r"[^A-Za-z0-9_]", "_", name) or "_"
        if base[0].isdigit():
            base = "_" + base
        why = "not a RoboSim name" if base != name else ""
        if base in RESERVED.get(kind, {}):
            base, why = RESERVED[kind][base], "MuJoCo reserves the name"
        used = self.used.setdefault("device" if kind in ("aref", "sref") else kind, set())
        chosen, k = base, 2
        while chosen in used:
            chosen = f"{base}_{k}"
            k += 1
        used.add(chosen)
        if record:
            self.of[(kind, name)] = chosen
            if chosen != name:
                self.renamed.append(Renaming(kind, name, chosen, why or "taken by another name"))
        return chosen

    def __call__(self, kind: str, name: str) -> str:
        return self.of[(kind, name)]


def ident(name: str) -> str:
    """A name as RoboSim text: a keyword escaped with ^."""
    return f"^{name}" if name in keywords() else name


# ---- numbers and poses as text ----

def num(value: float) -> str:
    """The shortest text that reads back as the same double (so that nothing is lost on the way)."""
    text = repr(float(value))
    return "0.0" if text == "-0.0" else text


def vector(values) -> str:
    return "(|" + ", ".join(num(v) for v in values) + "|)"


def pose_line(xyz, rpy, indent: str) -> list[str]:
    (x, y, z), (roll, pitch, yaw) = xyz, rpy
    return [f"{indent}pose {{ x = {num(x)} y = {num(y)} z = {num(z)} roll = {num(roll)} pitch = {num(pitch)} "
            f"yaw = {num(yaw)} }}"]


def pose_block(T: np.ndarray, indent: str) -> list[str]:
    """A transform as a pose (none for the identity)."""
    return [] if np.array_equal(T, np.eye(4)) else pose_line(T[:3, 3], matrix_rpy(T[:3, :3]), indent)


def origin_block(origin: Origin, indent: str) -> list[str]:
    """A URDF origin as a pose, with its own numbers (no round trip through a matrix)."""
    return [] if origin == Origin() else pose_line(origin.xyz, origin.rpy, indent)


def origin_matrix(origin: Origin) -> np.ndarray:
    return transform(origin.xyz, origin.rpy)


# ---- meshes: where they are, where they go ----

class Packages:
    """Where `package://NAME/...` is: a folder of the package path (`--package-path`, then
    ROS_PACKAGE_PATH) that is the package (named NAME, or holding a package.xml naming it), holds it
    (NAME/ below it), or holds it up to a few levels down (a package.xml naming it); else a folder
    above the URDF that is the package."""

    def __init__(self, roots: list[Path], urdf: Path):
        self.roots = roots
        self.urdf = urdf
        self.found: dict[str, Path | None] = {}

    @staticmethod
    def declared_name(folder: Path) -> str | None:
        manifest = folder / "package.xml"
        try:
            if manifest.is_file() and manifest.stat().st_size < 1_000_000:
                match = re.search(r"<name>\s*([^<]+?)\s*</name>", manifest.read_text(errors="replace"))
                return match.group(1) if match else None
        except OSError:
            return None
        return None

    def _is(self, folder: Path, name: str) -> bool:
        return folder.is_dir() and (folder.name == name or self.declared_name(folder) == name)

    def find(self, name: str) -> Path | None:
        if name not in self.found:
            self.found[name] = self._search(name)
        return self.found[name]

    def _search(self, name: str) -> Path | None:
        for root in self.roots:
            if self._is(root, name):
                return root
            if (root / name).is_dir():
                return root / name
            below = self._crawl(root, name)
            if below is not None:
                return below
        for folder in self.urdf.resolve().parents:
            if self._is(folder, name):
                return folder
        return None

    def _crawl(self, root: Path, name: str) -> Path | None:
        level = [root]
        for _ in range(_PACKAGE_DEPTH):
            following = []
            for folder in level:
                try:
                    entries = sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
                except OSError:
                    continue
                for entry in entries:
                    if self.declared_name(entry) == name:
                        return entry
                following.extend(entries)
            level = following
        return None

    def describe(self) -> str:
        roots = ", ".join(str(r) for r in self.roots) or "none given"
        return f"searched the package path ({roots}) and the folders above {self.urdf.name}"


@dataclass
class Mesh:
    """A mesh file of the URDF: where it is and what the p-model calls its copy."""

    source: Path
    written: str  # relative to the p-model's folder, with '/'


class MeshCopies:
    """Each mesh file once, at a deterministic place under meshes/: `meshes/PACKAGE/PATH` for a package
    URI, the path below the URDF's folder for a file there, else `meshes/NAME` (a clash gets `_2`)."""

    def __init__(self, robot: Robot, packages: Packages, diag: Diagnostics):
        self.robot = robot
        self.packages = packages
        self.diag = diag
        self.by_source: dict[Path, Mesh] = {}
        self.by_uri: dict[str, Mesh | None] = {}
        self.taken: set[str] = set()
        self.renamed: list[Renaming] = []  # paths spelled otherwise than the URDF's (characters, clashes)

    def resolve(self, geometry: Geometry) -> Mesh | None:
        """The mesh a geometry names (once per URI as written), or None with an error at the geometry."""
        if geometry.filename not in self.by_uri:
            self.by_uri[geometry.filename] = self._resolve(geometry)
        return self.by_uri[geometry.filename]

    def _resolve(self, geometry: Geometry) -> Mesh | None:
        uri = geometry.filename
        parsed = urlparse(uri)
        where = geometry.loc
        if parsed.scheme == "package":
            package = parsed.netloc
            if not package:  # package:///NAME/...: an extra slash (talos_data's URDFs have it)
                package, _, rest = unquote(parsed.path).lstrip("/").partition("/")
                if not package:  # `package://` alone was looked for as the first package folder
                    self.diag.error(where, f"mesh '{uri}': names no package (package://PACKAGE/PATH)")
                    return None
                parsed = parsed._replace(netloc=package, path="/" + rest)
                self.diag.warning(where, f"mesh '{uri}': read as package://{package}/{rest} (one slash too many)")
            root = self.packages.find(package)
            if root is None:
                self.diag.error(where, f"mesh '{uri}': no package '{package}' found ({self.packages.describe()}; "
                                "give its folder or the folder holding it with --package-path)")
                return None
            inside = unquote(parsed.path).lstrip("/")
            source = root / inside
            wanted = posixpath.join(package, posixpath.normpath(inside))
        elif parsed.scheme == "file":
            source = Path(unquote(parsed.path))
            if parsed.netloc and parsed.netloc != "localhost":  # file://relative/path, as some exporters write
                source = Path(parsed.netloc + unquote(parsed.path))
            if not source.is_absolute():
                source = self.robot.path.parent / source
            wanted = self._below_urdf(source)
        elif not parsed.scheme or (len(parsed.scheme) == 1 and os.name == "nt"):  # a name (C:\\... on Windows)
            source = Path(uri)
            if not source.is_absolute():
                source = self.robot.path.parent / source
            wanted = self._below_urdf(source)
        else:
            self.diag.error(where, f"mesh '{uri}': cotwin reads package://, file:// and file names, not "
                            f"{parsed.scheme}:// (download the file and name it)")
            return None
        if not source.is_file():
            self.diag.error(where, f"mesh '{uri}': {_not_a_file(source)} ({source})")
            return None
        key = source.resolve()
        if key not in self.by_source:
            self.by_source[key] = Mesh(source, self._place(wanted))
        return self.by_source[key]

    def _below_urdf(self, source: Path) -> str:
        try:
            return source.resolve().relative_to(self.robot.path.resolve().parent).as_posix()
        except ValueError:
            return source.name

    def _place(self, wanted: str) -> str:
        raw = [p for p in wanted.split("/") if p not in ("", ".", "..")]
        parts = [re.sub(r"[^A-Za-z0-9._-]", "_", p) for p in raw]
        path = "/".join([MESH_FOLDER, *parts]) if parts else f"{MESH_FOLDER}/mesh"
        as_written = "/".join([MESH_FOLDER, *raw])
        stem, dot, suffix = path.rpartition(".")
        if not dot or "/" in suffix:
            stem, suffix = path, ""
        chosen, k = path, 2
        while chosen in self.taken:
            chosen = f"{stem}_{k}.{suffix}" if suffix else f"{stem}_{k}"
            k += 1
        self.taken.add(chosen)
        if chosen != as_written:
            self.renamed.append(Renaming("mesh", as_written, chosen, "taken by another mesh" if chosen != path
                                         else "characters a portable file name avoids"))
        return chosen

    def conflicts(self, folder: Path) -> list[Path]:
        """The files in folder a copy would replace that hold other bytes than the mesh copied there
        (a link is not one: copy_to replaces the link, never what it points at)."""
        found = []
        for mesh in sorted(self.by_source.values(), key=lambda m: m.written):
            target = folder / mesh.written
            if target.is_file() and not target.is_symlink() and not (
                    os.path.samefile(target, mesh.source) or _same_bytes(target, mesh.source)):
                found.append(target)
        return found

    def copy_to(self, folder: Path) -> list[Path]:
        """Copy every mesh into folder (a file already there with the same bytes is left alone; a link, or a
        hard link, there is replaced by a new file, not written through: files.write_bytes)."""
        written = []
        for mesh in sorted(self.by_source.values(), key=lambda m: m.written):
            target = folder / mesh.written
            if not (target.exists() and not target.is_symlink()
                    and (os.path.samefile(target, mesh.source) or _same_bytes(target, mesh.source))):
                write_bytes(target, read_bytes(mesh.source, "mesh"), [mesh.source])
            written.append(target)
        return written


def _not_a_file(source: Path) -> str:
    """Why a mesh's path is not read: missing, a folder, or a FIFO or device (which would be read forever)."""
    if source.is_dir():
        return "a folder, not a mesh file"
    return "not a regular file (a FIFO, a device?)" if source.exists() else "no such file"


def _same_bytes(a: Path, b: Path) -> bool:
    return a.stat().st_size == b.stat().st_size and a.read_bytes() == b.read_bytes()


# ---- the p-model text ----

JOINT_DEVICES = {"revolute": "Revolute", "continuous": "Continuous", "prismatic": "Prismatic", "fixed": "Fixed"}
#: the sensors of a moving joint: quantity -> (physmod::sensors device, its output port); effort by joint kind
SENSORS = {"position": ("PositionSensor", "output_position"), "velocity": ("VelocitySensor", "output_vel")}
EFFORT_SENSORS = {"prismatic": ("ForceSensor", "output_force"), "revolute": ("TorqueSensor", "output_torque"),
                  "continuous": ("TorqueSensor", "output_torque")}


@dataclass
class Device:
    """What a mapping uses of a moving joint: the actuator's command and the sensors' readings, as paths."""

    joint: str
    kind: str
    command: str
    readings: dict[str, str]


@dataclass
class ImportResult:
    pmodel: str
    file: Path
    meshes: list[Path]
    renamings: list[Renaming]
    devices: list[Device]
    links: int
    joints: dict[str, int]
    ignored: dict[str, int]
    findings: list[Finding] = field(default_factory=list)  # warnings: the URDF's and the p-model's readings


class Writer:
    """The p-model text of a checked robot (see the module docstring)."""

    def __init__(self, robot: Robot, meshes: MeshCopies, source_name: str):
        self.robot = robot
        self.meshes = meshes
        self.source_name = source_name
        self.names = Names()
        self.devices: list[Device] = []
        self.lines: list[str] = []
        self.links, self.joints = robot.tree_order()
        self.name = self.names.add("robot", robot.name)
        for link in self.links:
            self.names.add("link", link.name)
        for joint in self.joints:
            self.names.add("joint", joint.name)
        self.frames = {self.links[0].name: np.eye(4)}
        for joint in self.joints:
            self.frames[joint.child] = self.frames[joint.parent] @ origin_matrix(joint.origin)

    def text(self) -> str:
        out = self.lines
        out += [f"// RoboSim p-model of the robot '{self.robot.name}', imported by cotwin import-urdf from "
                f"{self.source_name}.",
                "// Link poses are the URDF link frames at zero joint values, in the model frame; joint poses are the",
                "// URDF joint origins, relative to the parent link. Collision shapes are bodies; visuals are kept as",
                "// `annotation Visual`. Each moving joint has a position servo and position, velocity, effort sensors.",
                "import physmod::joints::*", "import physmod::actuators::*", "import physmod::sensors::*", "",
                f"pmodel {ident(self.name)} {{"]
        below: dict[str, list[Joint]] = {}
        for joint in self.joints:
            below.setdefault(joint.parent, []).append(joint)
        for k, link in enumerate(self.links):
            if k:
                out.append("")
            self.link(link, below.get(link.name, []))
        out.append("}")
        return "\n".join(out) + "\n"

    def link(self, link: Link, joints: list[Joint]) -> None:
        out, name = self.lines, self.names("link", link.name)
        out.append(f"\tlocal link {ident(name)} {{")
        definition = []
        if link.inertial is not None:
            i = link.inertial
            matrix = " ".join(f"{k} = {num(i.inertia[k])}" for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
            definition += ["\t\t\tinertial information {", f"\t\t\t\tmass {num(i.mass)} kg",
                           f"\t\t\t\tinertia matrix {{ {matrix} }}", *origin_block(i.origin, "\t\t\t\t"), "\t\t\t}"]
        else:  # URDF's massless link (a tool or sensor frame): mass 0, not RoboTool's 1 kg and 1 kg m^2 for a
            # link without inertial information, which made a massless tool frame a flywheel on the wrist
            definition += ["\t\t\tinertial information {", "\t\t\t\tmass 0 kg", "\t\t\t}"]
        for shape in link.visuals:
            definition += self.visual(shape)
        if definition:
            out += ["\t\tdef {", *definition, "\t\t}"]
        for k, shape in enumerate(link.collisions):
            body = self.names.add("body", f"{name}_collision" + (f"_{k}" if len(link.collisions) > 1 else ""), False)
            out += [f"\t\tlocal body {ident(body)} {{", "\t\t\tdef {", f"\t\t\t\t{self.shape(shape.geometry)}", "\t\t\t}",
                    *origin_block(shape.origin, "\t\t\t"), "\t\t}"]
        for joint in joints:
            self.joint(joint, name)
        out += pose_block(self.frames[link.name], "\t\t")
        out.append("\t}")

    def shape(self, g: Geometry) -> str:
        if g.kind == "box":
            return f"box ( length = {num(g.size['x'])} , width = {num(g.size['y'])} , height = {num(g.size['z'])} )"
        if g.kind in ("cylinder", "capsule"):
            return f"{g.kind} ( radius = {num(g.size['radius'])} , length = {num(g.size['length'])} )"
        if g.kind == "sphere":
            return f"sphere ( radius = {num(g.size['radius'])} )"
        mesh = self.meshes.resolve(g)
        scale = num(g.scale[0]) if len(set(g.scale)) == 1 else vector(g.scale)
        return f"mesh {{ shape \"{mesh.written if mesh else g.filename}\" scaling {scale} }}"

    def visual(self, shape: Shape) -> list[str]:
        g = shape.geometry
        entries = [f"geometry = \"{g.kind}\""]
        if g.kind == "mesh":
            mesh = self.meshes.resolve(g)
            entries += [f"file = \"{mesh.written if mesh else ''}\"", f"scale = {vector(g.scale)}"]
        elif g.kind == "box":
            entries.append(f"size = {vector([g.size['x'], g.size['y'], g.size['z']])}")
        else:
            entries += [f"{k} = {num(v)}" for k, v in g.size.items()]
        if shape.origin != Origin():
            entries += [f"xyz = {vector(shape.origin.xyz)}", f"rpy = {vector(shape.origin.rpy)}"]
        if shape.name and '"' not in shape.name:
            entries.insert(0, f"name = \"{shape.name}\"")
        if shape.material and '"' not in shape.material:
            entries.append(f"material = \"{shape.material}\"")
        if shape.rgba is not None:
            entries.append(f"rgba = {vector(shape.rgba)}")
        return [f"\t\t\tannotation Visual {{ {' '.join(entries)} }}"]

    def joint(self, joint: Joint, parent: str) -> None:
        out, name = self.lines, self.names("joint", joint.name)
        device = JOINT_DEVICES[joint.type]
        out.append(f"\t\tjref {ident(name)} = {device} {{")
        if joint.moving:
            limit = " ".join(f"{k} = {num(joint.limit[k])}" for k in ("lower", "upper", "velocity", "effort")
                             if k in joint.limit)
            dynamics = " ".join(f"{k} = {num(v)}" for k, v in (("damping", joint.damping), ("_friction", joint.friction))
                                if v is not None)
            axis = [f"xyz = {vector(joint.axis)}"]
            if dynamics:
                axis.append(f"dynamics = Dynamics {{ {dynamics} }}")
            if limit:
                axis.append(f"limit = Limit {{ {limit} }}")
            out += [f"\t\t\tannotation {device} {{", "\t\t\t\taxis = Axis {", *(f"\t\t\t\t\t{a}" for a in axis),
                    "\t\t\t\t}", "\t\t\t}"]
            if joint.mimic is not None:
                m = joint.mimic
                out.append(f"\t\t\tannotation Mimic {{ leader = \"{self.names('joint', m.joint)}\" "
                           f"multiplier = {num(m.multiplier)} offset = {num(m.offset)} }}")
            self.drives(joint, name, parent)
        out.append(f"\t\t\tflexibly connected to {ident(self.names('link', joint.child))}")
        out += origin_block(joint.origin, "\t\t\t")
        out.append("\t\t}")

    def drives(self, joint: Joint, name: str, parent: str) -> None:
        """A position servo and the joint's sensors, declared in the joint (their paths name it)."""
        out = self.lines
        motor = self.names.add("aref", f"{name}_motor", False)
        out.append(f"\t\t\taref {ident(motor)} = ServoMotor {{ relation {ident(name)}.tau == {ident(motor)}.T }}")
        base = f"{self.name}::{parent}::{name}"
        readings = {}
        for quantity, (sensor, port) in {**SENSORS, "effort": EFFORT_SENSORS[joint.type]}.items():
            sref = self.names.add("sref", f"{name}_{quantity}", False)
            out.append(f"\t\t\tsref {ident(sref)} = {sensor}")
            readings[quantity] = f"{base}::{sref}.{port}"
        self.devices.append(Device(name, joint.type, f"{base}::{motor}.dangle", readings))


def package_roots(given: list[str | Path], environ: dict[str, str] | None = None) -> list[Path]:
    """The package path: the folders given, then ROS_PACKAGE_PATH's."""
    environ = os.environ if environ is None else environ
    roots = [Path(p) for p in given]
    roots += [Path(p) for p in environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    return roots


def import_urdf(urdf: str | Path, out: str | Path, package_path: list[str | Path] = (),
                environ: dict[str, str] | None = None, check: bool = True, force: bool = False) -> ImportResult:
    """Write OUT/<robot>.pm and OUT/meshes/... from a URDF; CotwinError with every problem found (nothing
    is written then). A p-model or mesh already in OUT with other bytes than the import's (a hand edit)
    is refused, each named, unless `force`: the same bytes are no conflict, so an import repeats freely. With `check`, the written p-model is read back as cotwin reads it (its warnings,
    such as an inertia replaced or a mesh shown as a placeholder, are in the result's findings)."""
    urdf, out = Path(urdf), Path(out)
    diag = Diagnostics()
    robot = read_urdf(urdf, diag)
    if robot is None:
        diag.raise_if_errors()
        raise CotwinError(f"{urdf}: nothing to import")
    meshes = MeshCopies(robot, Packages(package_roots(list(package_path), environ), urdf), diag)
    for link in robot.links:  # every mesh looked for, whatever else is wrong
        for shape in (*link.collisions, *link.visuals):
            if shape.geometry.kind == "mesh":
                meshes.resolve(shape.geometry)
    diag.raise_if_errors()
    writer = Writer(robot, meshes, urdf.name)
    text = writer.text()
    findings = [f for f in diag.findings if f.severity is Severity.WARNING] + _notes(robot)
    if out.exists() and not out.is_dir():
        raise CotwinError(f"{out}: not a folder (-o names the folder to write the p-model and its meshes into)")
    if len(f"{writer.name}.pm".encode()) > NAME_MAX:  # else "File name too long: " and the whole name, after mkdir
        raise CotwinError([Finding(robot.loc, Severity.ERROR, f"the robot's name ({len(writer.name)} characters, "
                                   f"{writer.name[:40]}...) is too long for the p-model's file name {{name}}.pm "
                                   f"(at most {NAME_MAX - 3} bytes): give the robot a shorter name")])
    out.mkdir(parents=True, exist_ok=True)
    file = out / f"{writer.name}.pm"
    check_outputs([file], [urdf])  # never over the URDF being imported
    if not force:
        _refuse_overwrites(file, text, meshes.conflicts(out))
    copies = meshes.copy_to(out)
    write_text(file, text)  # a new file renamed into place: never through a link left there
    kinds = {k: sum(j.type == k for j in robot.joints) for k in JOINT_DEVICES}
    result = ImportResult(writer.name, file, copies, writer.names.renamed + meshes.renamed, writer.devices,
                          len(robot.links), kinds,
                          dict(sorted(robot.ignored.items())), findings)
    if check:
        result.findings += read_back(file)
    return result


NAME_MAX = 255  # bytes of a file name (Linux, macOS, Windows)


def _refuse_overwrites(file: Path, text: str, meshes: list[Path]) -> None:
    """CotwinError naming every file the import would replace with other bytes (the p-model, meshes)."""
    changed = [file] if file.is_file() and not file.is_symlink() and file.read_bytes() != text.encode("utf-8") else []
    changed += meshes
    if changed:
        raise CotwinError([f"{path}: already there with other content than import-urdf writes (edited by hand?): "
                           "left as it is; --force replaces it" for path in changed])


def _notes(robot: Robot) -> list[Finding]:
    """Warnings about what the p-model keeps but cotwin's simulator does not use."""
    notes = Diagnostics()
    for j in robot.joints:
        if j.mimic is not None:
            notes.warning(j.mimic.loc, f"joint '{j.name}' mimics '{j.mimic.joint}': kept as `annotation Mimic`; cotwin's "
                          "simulator drives it by its own servo (a mapping commands both)")
        if j.type in ("revolute", "prismatic") and j.limit.get("lower") == j.limit.get("upper"):
            notes.warning(j.loc, f"joint '{j.name}': lower and upper limits are both {j.limit['lower']:g} (URDF's "
                          "default where <limit> gives neither): the joint cannot move")
        if j.friction:
            notes.warning(j.loc, f"joint '{j.name}': friction {j.friction:g} kept in the p-model's annotation; cotwin's "
                          "simulator applies damping only")
    return [f for f in notes.findings if f.severity is Severity.WARNING]


def read_back(file: Path) -> list[Finding]:
    """The written p-model read as cotwin reads it (checked, its kinematic tree built): its warnings;
    an error here is an importer bug, raised as it is."""
    from ..robosim.check import check_project
    from ..robosim.project import load_project
    from .tree import build_tree

    diag = Diagnostics()
    project = load_project([file], diag)
    check_project(project, diag)
    try:
        diag.raise_if_errors()
        tree = build_tree(project)
    except CotwinError as err:
        raise CotwinError([*err.findings, f"{file}: cotwin cannot read the p-model import-urdf wrote: a bug of the "
                           "importer (please report it with the URDF)"]) from None
    return [f for f in (*diag.findings, *tree.findings) if f.severity is Severity.WARNING]
