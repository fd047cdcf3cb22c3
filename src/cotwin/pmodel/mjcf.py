"""p-model -> MJCF (MuJoCo XML): nested bodies in p-model link frames, a position servo per actuated
joint, a MuJoCo sensor per p-model sensor, and optionally a scene around the robot (cotwin.pmodel.scenes).

Documented defaults, used where the p-model gives no value:
- every joint gets an armature (reflected rotor inertia of its gearbox) of 0.1 kg m^2 or 0.1 kg;
- servo gains: `Kp`/`Kd` instantiated on the joint's actuator (aref), else kp = min(5000 N m/rad or
  2000 N/m, I (0.15 / dt)^2) and kv = 2 sqrt(kp I), critical damping, where I is the inertia moved by
  the joint at zero plus its armature; any kp is capped at I (0.5 / dt)^2, beyond which the explicit
  stiffness of a 1 ms step would make the simulation unstable;
- the arm's own weight is compensated (`gravcomp`), as a UR controller does, so servos hold targets
  without steady-state sag; payloads (a scene's loose objects) are not compensated;
- the robot does not collide with itself; it collides with the scene (its fixtures and loose objects);
- joint position limits become the joint range and the servo's control range; effort limits become
  the servo's force range; velocity limits are the trajectory generator's job (cotwin.mapping);
- an unstable simulation stops (MuJoCo's automatic reset is disabled: it would silently put the
  robot back at its initial state and carry on);
- an actuator taking a speed (kinds.servo_command) drives its joint by a velocity servo of gain
  kv = (I + armature) / 5 ms (a motor controller's fast speed loop: a slower one stalls a wheel
  against the scrub of its tyre when it turns slowly), one taking an effort by a motor; such joints get an
  armature of 0.001;
- the base is fixed to the world unless `base="free"` (a mobile robot): then it gets a free joint and
  no weight compensation (a body's gravcomp pushes through every joint above it, the free joint's too: it would lift
  the robot by its arm's weight; a twin project says so, cotwin.twin.assembly.system.free_base_arm_warning); a root link beside the base (a free body of the p-model, no joint leading to
  it) gets a free joint and falls;
- a massless link (mass 0: a URDF link without `<inertial>`, a tool or sensor frame) is a body of no mass and
  no inertia: MuJoCo accepts one where a joint moves a body of mass fixed to it; one a moving joint carries alone
  (`KinematicTree.moved_alone`, warned of by the tree builder) gets MOVING_FRAME_MASS (a gram) with the inertia of
  its geometry here only (`inertials`): the tree and the URDF/SDF exports keep it massless, as its source says;
- a mesh file cotwin can read becomes a mesh asset; one it cannot is a placeholder sphere that never
  collides (or the project's stand-in shapes);
- joints closing a kinematic loop become equality constraints (weld for fixed, connect otherwise);
- a body quantity of a sensor (yaw rate, forward speed, acceleration) is read by a site-based MuJoCo
  sensor at the sensor's pose; a ray sensor (LiDAR, sonar) gets a site at its pose, from which the
  simulator casts its beams (cotwin.pmodel.simulator), seeing the world (geom group 0) but not the
  robot (its geoms are in group 1); other sensors MuJoCo has no counterpart for are not written;
- a geom whose p-model body (or a project's stand-in) gives a sliding friction coefficient governs the
  friction of its contacts (MuJoCo's `priority` 2, above a world's floor; torsion and rolling scaled
  alike): a frictionless skid (a caster ball) stays frictionless on any floor;
- a scene may place the robot (`scene.robot_pose(tree)`, a world's start pose for a free base).

`visual=False` gives the model the simulator steps: what only shows (geoms that collide with nothing,
such as the plate's hole markers and mesh placeholders) is discarded by MuJoCo's compiler, so that it
costs no time per step.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from ..diagnostics import CotwinError, Finding, Severity
from ..robosim.check_pmodel import MOVING_FRAME_MASS
from .inertia import default_inertia
from .scenes import EARTH
from .tree import Geom, KinematicTree, TJoint, inverse, reading_path, servo_mode, servo_name
from .xmltext import num, nums, quat, sub, to_text

DEFAULT_KP = {"revolute": 5000.0, "prismatic": 2000.0}
ARMATURE = {"revolute": 0.1, "prismatic": 0.1}
DRIVEN_ARMATURE = 0.001  # kg m^2 or kg: joints driven by speed or effort (wheels), not by a geared servo
VELOCITY_TIME = 0.005  # s: time constant of a velocity servo
BODY_SENSORS = ("gyro", "velocimeter", "accelerometer")
TIMESTEP = 0.001  # s: the physics step
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1  # robot geoms touch the world and its loose objects, not each other
ROBOT_GROUP = "1"  # robot geoms' group: ray sensors see group 0 (the world) only
OWN_FRICTION = "2"  # priority of a geom whose p-model gives its friction: above a scene's floor (1)
WORLD_CONTYPE, WORLD_CONAFFINITY = 1, 3


POSE_PORTS = ("x", "y", "z", "yaw")  # a free base's pose readings (m, m, m, rad)


def pose_paths(tree: KinematicTree) -> list[str]:
    """The names a free base's pose is read by: `pmodel::link.x` .. `.yaw` (two-part paths, which no
    p-model sensor has), the root link's frame in the world."""
    return [f"{tree.name}::{tree.root.source}.{p}" for p in POSE_PORTS]


def reading_paths(tree: KinematicTree, free_base: bool = False) -> set[str]:
    """Every path the simulated platform of this p-model reads (cotwin.pmodel.simulator's read_sensors: what a
    [monitor] reading names, read by the DT of every project): each sensor port's `reading_path` (a sensor declared
    in a joint with that joint in its path, as every platform names it), and a free base's pose (`pose_paths`)."""
    out = set(pose_paths(tree)) if free_base else set()
    for s in tree.sensors:
        out.add(reading_path(tree.name, s))
    return out


def armature(joint: TJoint) -> float:
    return ARMATURE[joint.kind] if servo_mode(joint) == "position" else DRIVEN_ARMATURE


def _pose_attrs(T: np.ndarray) -> dict:
    attrs = {}
    if np.linalg.norm(T[:3, 3]) > 0:
        attrs["pos"] = nums(T[:3, 3])
    q = quat(T[:3, :3])
    if abs(q[0] - 1.0) > 1e-15:
        attrs["quat"] = nums(q)
    return attrs


def _geom(parent: ET.Element, g: Geom, **extra) -> None:
    if g.kind == "mesh":
        sub(parent, "geom", name=g.name, type="mesh", mesh=_mesh_name(g), **_pose_attrs(g.pose), **extra)
        return
    if g.kind == "box":
        size = [g.size["length"] / 2, g.size["width"] / 2, g.size["height"] / 2]
    elif g.kind in ("cylinder", "capsule"):
        size = [g.size["radius"], g.size["length"] / 2]
    else:
        size = [g.size["radius"]]
    sub(parent, "geom", name=g.name, type=g.kind, size=nums(size), **_pose_attrs(g.pose), **extra)


def _mesh_name(g: Geom) -> str:
    return f"{g.name}_mesh"


def _friction(g: Geom) -> dict:
    sliding = g.surface.get("friction", {}).get("translational", {}).get("coefficient1")
    if isinstance(sliding, (int, float)) and not isinstance(sliding, bool):  # its own friction governs its
        return {"friction": nums([sliding, 0.02 * sliding, 0.001 * sliding]), "priority": OWN_FRICTION}  # contacts
    return {}


def inertials(tree: KinematicTree) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """Each link's mass, centre of mass and inertia as MuJoCo's model has them: the tree's, except a massless link a
    moving joint carries alone, which gets MOVING_FRAME_MASS and its geometry's inertia (MuJoCo refuses a moving body
    without mass)."""
    out = {l.name: (l.mass, l.com, l.inertia) for l in tree.links}
    for link, _ in tree.moved_alone():
        out[link.name] = (MOVING_FRAME_MASS, np.eye(4), default_inertia(MOVING_FRAME_MASS, link.geoms, np.eye(4)))
    return out


def joint_inertia(tree: KinematicTree, joint: TJoint) -> float:
    """Inertia of everything beyond a joint about its axis (or mass along it), at zero: for servo damping."""
    beyond = {joint.child}
    for j in tree.joints:
        if j.parent in beyond:
            beyond.add(j.child)
    axis = joint.pose[:3, :3] @ joint.axis
    origin = joint.pose[:3, 3]
    total = 0.0
    simulated = inertials(tree)
    for link in tree.links:
        if link.name not in beyond:
            continue
        mass, com_local, inertia = simulated[link.name]
        com = link.pose @ com_local
        if joint.kind == "prismatic":
            total += mass
            continue
        R = com[:3, :3]
        I = R @ inertia @ R.T
        r = com[:3, 3] - origin
        r_perp = r - axis * (r @ axis)
        total += axis @ I @ axis + mass * (r_perp @ r_perp)
    return max(total, 1e-6)


def servo_gains(tree: KinematicTree, joint: TJoint, timestep: float = TIMESTEP) -> tuple[float, float]:
    servo = joint.servos[0] if joint.servos else None
    inertia = joint_inertia(tree, joint) + armature(joint)
    kp = servo.kp if servo and servo.kp else min(DEFAULT_KP[joint.kind], inertia * (0.15 / timestep) ** 2)
    kp = min(kp, inertia * (0.5 / timestep) ** 2)
    kd = servo.kd if servo and servo.kd else 2.0 * np.sqrt(kp * inertia)
    return float(kp), float(kd)


def velocity_gain(tree: KinematicTree, joint: TJoint) -> float:
    servo = joint.servos[0] if joint.servos else None
    if servo is not None and servo.kd:
        return float(servo.kd)
    return float((joint_inertia(tree, joint) + armature(joint)) / VELOCITY_TIME)


def to_mjcf(tree: KinematicTree, scene=None, timestep: float = TIMESTEP, visual: bool = True,
            base: str = "fixed") -> str:
    """MJCF of the robot, alone or inside a scene (cotwin.pmodel.scenes.Scene); without the
    purely visual elements when `visual` is false (see the module doc); `base` is fixed (to the world)
    or free."""
    if base not in ("fixed", "free"):
        raise ValueError(f"base must be fixed or free, not {base!r}")
    root = ET.Element("mujoco", {"model": tree.name})
    sub(root, "compiler", angle="radian", autolimits="true", **({} if visual else {"discardvisual": "true"}))
    gravity = scene.gravity if scene is not None else EARTH  # a scene may tilt the world (a level plate)
    option = sub(root, "option", timestep=num(timestep), gravity=nums(gravity), integrator="implicitfast",
                 cone="elliptic", impratio="10")
    sub(option, "flag", autoreset="disable")
    visual = sub(root, "visual")
    sub(visual, "global", offwidth="1280", offheight="960")
    default = sub(root, "default")
    sub(default, "geom", condim="4", friction="1 0.02 0.001", solref="0.004 1")
    meshes = [g for link in tree.links for g in link.geoms if g.kind == "mesh"]
    if meshes:
        asset = sub(root, "asset")
        for g in meshes:
            sub(asset, "mesh", name=_mesh_name(g), file=g.mesh, scale=nums(g.scale), inertia="shell")
    worldbody = sub(root, "worldbody")
    sub(worldbody, "light", name="sun", pos="0.5 0.3 3", dir="0 0 -1", directional="true")
    if scene is not None:
        scene.add_to(worldbody)
    bodies = {}
    parents = {j.child: j for j in tree.joints}
    placement = scene.robot_pose(tree) if scene is not None else None
    simulated = inertials(tree)
    for link in tree.links:
        if link.name not in parents:  # the base, or a free body (a root link beside it)
            parent_el, local = worldbody, (placement @ link.pose if placement is not None else link.pose)
        else:
            joint = parents[link.name]
            parent_el = bodies[joint.parent]
            local = inverse(tree.link(joint.parent).pose) @ link.pose
        weight = {"gravcomp": "1"} if base == "fixed" and link.name in bodies_of_base(tree) else {}
        body = sub(parent_el, "body", name=link.name, **weight, **_pose_attrs(local))
        bodies[link.name] = body
        if link.name not in parents and (link is not tree.root or base == "free"):
            sub(body, "freejoint", name=f"{link.name}_free")
        mass, com, inertia = simulated[link.name]
        if mass > 0:
            R = com[:3, :3]  # MJCF takes a full inertia in the body's axes only (no quat beside it)
            I = R @ inertia @ R.T
            sub(body, "inertial", mass=num(mass),
                fullinertia=nums([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]), pos=nums(com[:3, 3]))
        else:  # a massless frame (its geoms must not give it a mass); MuJoCo refuses a zero fullinertia
            sub(body, "inertial", mass="0", pos="0 0 0", diaginertia="0 0 0")
        if link.name in parents:
            joint = parents[link.name]
            if joint.kind != "fixed":
                in_child = inverse(link.pose) @ joint.pose
                attrs = {"name": joint.name, "type": "hinge" if joint.kind == "revolute" else "slide",
                         "pos": nums(in_child[:3, 3]), "axis": nums(in_child[:3, :3] @ joint.axis),
                         "damping": num(joint.damping), "armature": num(armature(joint))}
                if joint.lower is not None and joint.upper is not None:
                    attrs["range"] = f"{num(joint.lower)} {num(joint.upper)}"
                sub(body, "joint", **attrs)
        for g in link.geoms:
            if g.placeholder:
                _geom(body, g, contype="0", conaffinity="0", group=ROBOT_GROUP, rgba="0.6 0.65 0.7 0.4")
            else:
                _geom(body, g, contype=str(ROBOT_CONTYPE), conaffinity=str(ROBOT_CONAFFINITY), group=ROBOT_GROUP,
                      rgba="0.6 0.65 0.7 1", **_friction(g))
        for s_ in _body_sensors(tree, link.name):
            sub(body, "site", name=_site_name(tree, s_), **_pose_attrs(s_.pose))
    if tree.loops:
        equality = sub(root, "equality")
        for j in tree.loops:
            if j.kind == "fixed":
                sub(equality, "weld", name=j.name, body1=j.parent, body2=j.child)
            else:
                anchor = inverse(tree.link(j.parent).pose) @ j.pose
                sub(equality, "connect", name=j.name, body1=j.parent, body2=j.child, anchor=nums(anchor[:3, 3]))
    actuator = sub(root, "actuator")
    for j in tree.actuated:
        mode = servo_mode(j)
        attrs = {"name": servo_name(j), "joint": j.name}
        if mode == "velocity":
            attrs["kv"] = num(velocity_gain(tree, j))
        elif mode == "position":
            kp, kd = servo_gains(tree, j, timestep)
            attrs.update(kp=num(kp), kv=num(kd))
            if j.lower is not None and j.upper is not None:
                attrs["ctrlrange"] = f"{num(j.lower)} {num(j.upper)}"
        if j.effort:
            attrs["forcerange"] = f"{num(-j.effort)} {num(j.effort)}"
        sub(actuator, {"position": "position", "velocity": "velocity", "effort": "motor"}[mode], **attrs)
    sensor = sub(root, "sensor")
    kinds = {"position": "jointpos", "velocity": "jointvel", "effort": "jointactuatorfrc"}
    for s_ in tree.sensors:
        name = reading_path(tree.name, s_)  # the MJCF sensor is named by the reading it gives
        if s_.quantity in BODY_SENSORS:
            sub(sensor, s_.quantity, name=name, site=_site_name(tree, s_))
        elif s_.joint is not None and s_.quantity in kinds:
            sub(sensor, kinds[s_.quantity], name=name, joint=s_.joint)
    return to_text(root)


def bodies_of_base(tree: KinematicTree) -> set[str]:
    """The base and the links joints lead to from it (free bodies and theirs are not the robot's arm)."""
    reached = {tree.root.name}
    for j in tree.joints:  # parents before children
        if j.parent in reached:
            reached.add(j.child)
    return reached


_ELEMENT = re.compile(r"Element name '([^']*)'")


def load(xml: str, tree: KinematicTree):
    """The MuJoCo model of an MJCF text made from `tree`; MuJoCo's refusal is a CotwinError located at the
    p-model element (link, joint, shape) its message names, not only at the generated MJCF."""
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as err:
        text = " ".join(str(err).replace("Error: ", "").split())
        named = _ELEMENT.search(str(err))
        loc = tree.located(named.group(1)) if named else None
        if loc is not None and loc.line > 0:
            raise CotwinError([Finding(loc, Severity.ERROR, f"MuJoCo rejected the model made of this element "
                                                            f"({named.group(1)}): {text}")]) from None
        raise CotwinError(f"MuJoCo rejected the generated model: {text}") from None


def _body_sensors(tree: KinematicTree, link: str) -> list:
    """The sensors of a link that need a site (one site per placed sensor, first port wins)."""
    seen, out = set(), []
    for s_ in tree.sensors:
        if s_.body == link and (s_.quantity in BODY_SENSORS or s_.ray is not None) and (s_.via, s_.name) not in seen:
            seen.add((s_.via, s_.name))
            out.append(s_)
    return out


def site_name(tree: KinematicTree, s_) -> str:
    """The MJCF site a body or ray sensor is mounted at: `pmodel::link::sref` (or `pmodel::link::joint::sref`)."""
    return _site_name(tree, s_)


def _site_name(tree: KinematicTree, s_) -> str:
    return f"{tree.name}::{s_.link}::{s_.via + '::' if s_.via else ''}{s_.name}"
