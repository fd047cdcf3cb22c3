"""Inverse kinematics on a p-model's kinematic tree: the tool frame reaches a target pose as far as the
arm's joints can, deterministically, for any serial arm.

The task follows the number of joints from the base to the tool (`task_for`):
- 6 or more ("pose"): the full pose, position and orientation (6 constraints; 7 and more: a redundant arm);
- 5 ("axis"): the position and the approach axis (the tool frame's z), the roll about it left free, as
  the arm gives it (5 constraints: a 5-axis arm such as the SO-ARM100 points its tool but cannot also
  choose its roll);
- 4 or fewer ("position"): the position first; then, holding it, the orientation as near the target's as
  the joints allow (least squares on the rotation error, moving only along postures that keep the
  position: a SCARA or palletiser turns its tool about the vertical, nothing more).
`IKResult.angle_error` is the error in what the task holds (the orientation, the approach axis, nothing:
0 for "position"), so `IKResult.ok` judges a target by the same task the solver reached it for.

The tool: a link named by the caller (`find_tool(tree, point, link=...)`, a cell geometry's `[tool] link`),
else the link below a moving joint that carries two or more prismatic joints (the gripper body; a mobile base's
two prismatic suspensions are none), else the hand on the way to the
leaf link with the most moving joints on its path from the base (the last such in the tree's order): the first
link there that branches into two or more unbranched fingers, moving ones shorter than the arm (a hand's) or
fixed bodies of two links or more (a gripper of fixed fingers; `hand_link`), else that leaf. A gripper or hand
that carries a declared grasp frame (`declared_frame`: a bodiless link fixed to it, named as a tool point, such as
TIAGo's hand_grasping_frame or a Franka hand's TCP) gives way to that frame: the URDF's author says there
where the hand grasps. Its tool point is
the flange (the tool link's origin), the fingertips (a gripper's: between the fingers, where their
geometry ends along the approach axis; the flange for a link without fingers, a declared frame's origin too) or an
explicit offset (x, y, z) in the tool link's frame; the tool frame has the tool link's orientation turned so that
its z axis is the approach axis (from the flange towards the fingers, a hand's too; a declared frame's own axis
nearest the hand's; the link's own z without).

Determinism: the same target gives the same joints whatever the arm's current posture. The solver
starts damped Newton iterations from a fixed set of seeds (the reference posture, the reference
turned towards the target, and fixed pseudo-random postures), keeps the converged solution nearest
the reference posture (the branch: shoulder, elbow and wrist configuration; the last joint, a
6-axis arm's tool roll, only breaks ties), puts every joint on the
turn (q + 2 pi k, within limits) nearest the reference, and only the base joint and the joints without
limits (URDF continuous: unbounded here, not one turn) on the turn nearest their current angle, so that the
arm never unwinds a full turn to reach a target (a base whose limits allow one turn only is never moved: the
same joints, bit for bit, from any start).

Redundant arms (more joints than the 6 a pose fixes): each converged solution is moved along its
self-motion (the Jacobian's null space), the pose held and joint limits respected, to the posture
nearest the reference there (weighted as above); the nearest of those is the answer.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from pathlib import Path

import numpy as np

from ..diagnostics import CotwinError
from .grippers import gripper_links
from .tree import KinematicTree, axis_angle, inverse

TWO_PI = 2.0 * np.pi
DOWN = np.diag([1.0, -1.0, -1.0])  # tool z along -z, tool x along x


@dataclass(frozen=True)
class Tool:
    link: str
    offset: np.ndarray  # tool frame in the link frame (z = approach)
    fingers: tuple[str, ...]  # prismatic finger joints
    hand: str = ""  # the gripper or hand a declared grasp frame (the tool link) is fixed to; "": none


def _rotation_onto_z(z: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the link's z axis onto z (identity when they agree)."""
    z = z / np.linalg.norm(z)
    e = np.array([0.0, 0.0, 1.0])
    c = float(e @ z)
    if c > 1 - 1e-12:
        return np.eye(3)
    if c < -1 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    axis = np.cross(e, z)
    return axis_angle(axis, float(np.arccos(np.clip(c, -1.0, 1.0))))[:3, :3]


def _corners(g) -> list[np.ndarray]:
    """Corners of a geometry's bounding box in its own frame."""
    if g.kind == "box":
        half = np.array([g.size["length"], g.size["width"], g.size["height"]]) / 2
    elif g.kind in ("cylinder", "capsule"):
        r = g.size["radius"]
        half = np.array([r, r, g.size["length"] / 2 + (r if g.kind == "capsule" else 0.0)])
    else:
        half = np.full(3, g.size.get("radius", 0.0))
    return [half * np.array([sx, sy, sz]) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]


def find_tool(tree: KinematicTree, point="fingertips", link: str | None = None) -> Tool:
    """The tool of the tree with its tool frame at `point`: "fingertips", "flange" or (x, y, z) in the
    tool link's frame; `link` names the tool link (default: the gripper's, else the end of the longest
    chain, see the module's docstring)."""
    if link is not None:
        names = [l.name for l in tree.links]
        if link not in names:
            raise CotwinError(f"tool link '{link}' is not a link of p-model {tree.name} (links: {', '.join(names)})")
        candidates = [tree.link(link)]
    else:
        candidates = list(reversed(tree.links))
    named = {c.name for c in candidates} if link is not None else set()
    grippers = set(gripper_links(tree))  # below a moving joint: a mobile base's two suspensions are no gripper
    for link in candidates:
        fingers = [j for j in tree.joints if j.parent == link.name and j.kind == "prismatic"]
        if len(fingers) >= 2 and (link.name in named or link.name in grippers):
            branches = [[tree.link(j.child)] for j in fingers]
            tool = Tool(link.name, _hand_frame(tree, link, branches, point), tuple(j.name for j in fingers))
            return tool if link.name in named else _at_declared_frame(tree, tool, point)
    end = candidates[0].name if len(candidates) == 1 else _chain_end(tree)
    hand = None if len(candidates) == 1 else hand_link(tree, end)
    if hand is not None:
        branches = [[tree.link(name) for name in _chain(tree, j.child)] for j in tree.joints if j.parent == hand]
        return _at_declared_frame(tree, Tool(hand, _hand_frame(tree, tree.link(hand), branches, point), ()), point)
    return Tool(end, _tool_frame(np.array([0.0, 0.0, 1.0]), np.zeros(3), point), ())


TOOL_WORDS = frozenset({"grasp", "grasping", "tcp", "tool", "ee", "eef", "effector", "endeffector", "gripper"})
FRAME_WORDS = frozenset({"frame", "link", "point"})  # a name's last words that say nothing of what it is


def _words(name: str) -> list[str]:
    """The words of a link's name, lower case: snake_case, CamelCase and digits split (tool0 -> tool)."""
    return [w.lower() for w in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+", name)]


def names_a_tool_point(name: str) -> bool:
    """Whether a link's name says it is a tool point: its last word (a trailing frame/link aside) is a tool word
    (hand_grasping_frame, a Franka hand's *_hand_tcp, l_gripper_tool_frame, j2s6s200_end_effector, left_gripper; not
    l_gripper_led_frame or an accelerometer's link fixed to the same hand)."""
    words = _words(name)
    while words and words[-1] in FRAME_WORDS:
        words.pop()
    return bool(words) and words[-1] in TOOL_WORDS


def declared_frame(tree: KinematicTree, hand: str) -> str | None:
    """The grasp or tool frame a URDF declares on a gripper or hand: a link fixed to it (through fixed joints only)
    without a body (a frame, not a finger) whose name says it is a tool point (`names_a_tool_point`); the nearest,
    then the first in the tree's order. None: the hand declares none, its own tool frame stands."""
    level, found = [hand], []
    while level and not found:
        below = [j.child for j in tree.joints if j.parent in level and j.kind == "fixed"]
        found = [c for c in below if not tree.link(c).geoms and names_a_tool_point(c)]
        level = below
    return found[0] if found else None


def _at_declared_frame(tree: KinematicTree, tool: Tool, point) -> Tool:
    """The tool moved to the grasp frame its hand declares (`declared_frame`), else unchanged. The frame's origin is
    the tool point (an explicit point is in its axes); its approach axis is the frame's own axis nearest the hand's
    (URDFs say a grasp frame's approach by x, PAL's and Kinova's, or by z, Franka's) and its roll about it the hand's
    tool frame's, so a target's orientation means what it meant on the hand."""
    frame = declared_frame(tree, tool.link)
    if frame is None:
        return tool
    in_hand = inverse(tree.link(tool.link).pose) @ tree.link(frame).pose
    hand = in_hand[:3, :3].T @ tool.offset[:3, :3]  # the hand's tool axes in the frame's
    k = int(np.argmax(np.abs(hand[:, 2])))
    z = np.zeros(3)
    z[k] = np.sign(hand[k, 2])
    x = hand[:, 0] - (hand[:, 0] @ z) * z  # never zero: z is within 55 degrees of the hand's approach, its x at 90
    x /= np.linalg.norm(x)
    T = _tool_frame(z, np.zeros(3), point)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    return Tool(frame, T, tool.fingers, tool.link)


def _hand_frame(tree: KinematicTree, link, branches: list[list], point) -> np.ndarray:
    """The tool frame of a link carrying fingers (each branch the links of one finger): approach from the link
    towards the fingers' middle, the tip where their geometry ends along it."""
    centres, corners = [], []
    for finger in branches:
        points = []
        for child in finger:
            local = inverse(link.pose) @ child.pose
            points.extend(local @ g.pose[:, 3] for g in child.geoms)
            for g in child.geoms:
                corners.extend((local @ g.pose @ np.append(c, 1.0))[:3] for c in _corners(g))
        centres.append(np.mean(points or [(inverse(link.pose) @ finger[0].pose)[:, 3]], axis=0)[:3])
    mid = np.mean(centres, axis=0)
    approach = mid / np.linalg.norm(mid) if np.linalg.norm(mid) > 1e-9 else np.array([0.0, 0.0, 1.0])
    reach = max((c @ approach for c in corners), default=mid @ approach)
    tip = mid + (reach - mid @ approach) * approach
    return _tool_frame(approach, tip, point)


def _chain_end(tree: KinematicTree) -> str:
    """The leaf link with the most moving joints on its path from the root (the last such in tree order)."""
    parents = {j.parent for j in tree.joints}
    moving = {tree.root.name: 0}
    for j in tree.joints:  # parents come before children
        moving[j.child] = moving[j.parent] + (j.kind != "fixed")
    leaves = [l.name for l in tree.links if l.name not in parents]
    most = max(moving[l] for l in leaves)
    return [l for l in leaves if moving[l] == most][-1]


def _chain(tree: KinematicTree, link: str) -> list[str] | None:
    """The links from `link` down while each has one child joint at most (a finger); None where it branches."""
    links = [link]
    while True:
        below = [j for j in tree.joints if j.parent == links[-1]]
        if len(below) > 1:
            return None
        if not below:
            return links
        links.append(below[0].child)


def hands(tree: KinematicTree) -> list[str]:
    """Every hand of the tree (`hand_link` on the way to each leaf), in the tree's order: a robot of two arms with
    hands has two, the IK's default tool is one of them."""
    parents = {j.parent for j in tree.joints}
    found = {hand_link(tree, l.name) for l in tree.links if l.name not in parents and l.name != tree.root.name}
    return [l.name for l in tree.links if l.name in found]


def hand_link(tree: KinematicTree, end: str) -> str | None:
    """The hand on the way to the leaf `end`: the first link below a moving joint that branches into two or more
    unbranched fingers, either moving ones (a hand's: each of fewer moving joints than the arm up to it, so a
    torso's arms are no fingers) or, with no moving joint below, bodies of two links or more (a gripper's fixed
    fingers and their tips; a flange's tool0 beside its ee_link are no fingers). None: no hand, the leaf is the
    tool.
    Without this, the tool was one fingertip (the Kinova's, its approach axis sideways) or a finger's joints
    were the arm's last (TIAGo's)."""
    arm = 0
    for joint in _path(tree, end):
        arm += joint.kind != "fixed"
        below = [j for j in tree.joints if j.parent == joint.child]
        if not arm or len(below) < 2:
            continue
        fingers = [_chain(tree, j.child) for j in below]
        if any(f is None for f in fingers):
            continue
        moving = [sum(j.kind != "fixed" for j in tree.joints if j.child in f) for f in fingers]
        if any(moving):
            if sum(1 for m in moving if m) >= 2 and max(moving) < arm:
                return joint.child
        elif sum(1 for f in fingers if len(f) >= 2 and any(tree.link(name).geoms for name in f)) >= 2:
            return joint.child
    return None


def _tool_frame(approach: np.ndarray, tip: np.ndarray, point) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rotation_onto_z(approach)
    if isinstance(point, str):
        if point not in ("fingertips", "flange"):
            raise ValueError(f"unknown tool point {point!r}")
        T[:3, 3] = tip if point == "fingertips" else 0.0
    else:
        T[:3, 3] = np.asarray(point, float)
    return T


ARM_JOINTS = 4  # fewer moving joints from the base to the default tool: no arm (a mobile base's wheels, a leg)
FULL_POSE_JOINTS = 6  # an arm with fewer cannot reach a full pose (3 for position, 3 for orientation)
AXIS_JOINTS = 5  # position and approach axis (3 + 2): the roll about the axis is what the joints make it


REACHES = {"pose": "the full tool pose", "axis": "the position and approach axis, the roll left free",
           "position": "the position, the orientation as near as they allow"}  # each task, in words (messages)


def task_for(joints: int) -> str:
    """What an arm of `joints` moving joints reaches (see the module's docstring): "pose", "axis" or
    "position"."""
    if joints >= FULL_POSE_JOINTS:
        return "pose"
    return "axis" if joints == AXIS_JOINTS else "position"


def arm_joints(tree: KinematicTree, tool: Tool) -> list[str]:
    """The actuated joints on the path from the base to the tool link."""
    return [j.name for j in _path(tree, tool.link) if j.kind != "fixed"]


def _path(tree: KinematicTree, link: str) -> list:
    path = []
    while link != tree.root.name:
        joint = next(j for j in tree.joints if j.child == link)
        path.append(joint)
        link = joint.parent
    return list(reversed(path))


def tool_pose(tree: KinematicTree, tool: Tool, q: dict[str, float]) -> np.ndarray:
    return tree.forward(q)[tool.link] @ tool.offset


class Chain:
    """The serial chain from the tree's root to the tool frame, for fast forward kinematics and
    Jacobians. `offsets` displace joint origins (m, model frame at zero) and everything beyond them:
    the kinematic corrections of a solver whose link lengths differ from the p-model's."""

    def __init__(self, tree: KinematicTree, tool: Tool, offsets: dict[str, tuple] | None = None):
        offsets = dict(offsets or {})
        self.joints: list[str] = []
        self.kinds: list[str] = []
        self.axes: list[np.ndarray] = []
        self.limits: list[tuple[float, float]] = []
        self.before: list[np.ndarray] = []  # parent link frame -> joint frame (at zero)
        self.after: list[np.ndarray] = []  # joint frame -> child link frame
        self.base = tree.root.pose.copy()
        pending = np.eye(4)  # fixed joints folded into the next moving joint
        for joint in _path(tree, tool.link):
            parent, child = tree.link(joint.parent).pose, tree.link(joint.child).pose
            before = inverse(parent) @ joint.pose
            before[:3, 3] += parent[:3, :3].T @ np.asarray(offsets.pop(joint.name, (0.0, 0.0, 0.0)), float)
            after = inverse(joint.pose) @ child
            if joint.kind == "fixed":
                pending = pending @ before @ after
                continue
            self.joints.append(joint.name)
            self.kinds.append(joint.kind)
            self.axes.append(np.asarray(joint.axis, float))
            # a joint without limits (URDF continuous) is unbounded: bounded to one turn, a wrist crossing pi
            # unwound a full turn (the Kinova Jaco2's, 10 s at its 0.63 rad/s) for a target a degree away
            free = np.inf if joint.kind == "revolute" else np.pi
            lower = joint.lower if joint.lower is not None else -free
            upper = joint.upper if joint.upper is not None else free
            self.limits.append((float(lower), float(upper)))
            self.before.append(pending @ before)
            self.after.append(after)
            pending = np.eye(4)
        self.tail = pending @ tool.offset
        if offsets:
            raise ValueError(f"offsets for joints not on the arm: {', '.join(offsets)}")
        self._before = [(B[:3, :3].copy(), B[:3, 3].copy()) for B in self.before]
        self._after = [(A[:3, :3].copy(), A[:3, 3].copy()) for A in self.after]
        self._skew = []
        for a in self.axes:
            a = a / np.linalg.norm(a)
            K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
            self._skew.append((K, K @ K))
        self._eye = np.eye(3)
        self._revolute = np.array([k == "revolute" for k in self.kinds], dtype=bool)
        self.lower = np.array([lo for lo, _ in self.limits])
        self.upper = np.array([hi for _, hi in self.limits])

    def forward(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tool pose (4x4) and the 6 x n Jacobian (linear; angular) in the model frame."""
        R, p = self.base[:3, :3], self.base[:3, 3]
        n = len(self.kinds)
        origins, axes = np.empty((n, 3)), np.empty((n, 3))
        for k in range(n):
            Rb, pb = self._before[k]
            p = p + R @ pb
            R = R @ Rb
            origins[k] = p
            axes[k] = R @ self.axes[k]
            if self.kinds[k] == "revolute":
                K, K2 = self._skew[k]
                s, c = math.sin(q[k]), math.cos(q[k])
                R = R @ (self._eye + s * K + (1.0 - c) * K2)
            else:
                p = p + axes[k] * q[k]
            Ra, pa = self._after[k]
            p = p + R @ pa
            R = R @ Ra
        p = p + R @ self.tail[:3, 3]
        R = R @ self.tail[:3, :3]
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = p
        J = np.zeros((6, n))
        revolute = self._revolute
        J[:3, revolute] = _cross(axes[revolute], p - origins[revolute]).T
        J[3:, revolute] = axes[revolute].T
        J[:3, ~revolute] = axes[~revolute].T
        return T, J

    def pose(self, q) -> np.ndarray:
        return self.forward(np.asarray(q, float))[0]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product (np.cross costs more than the rest of the forward kinematics)."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors (np.cross costs a 5-axis arm's IK a third of its time)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _across(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit vector z to a right-handed frame (fixed by z alone)."""
    other = np.zeros(3)
    other[int(np.argmin(np.abs(z)))] = 1.0
    u = _cross3(z, other)
    u /= np.linalg.norm(u)
    return u, _cross3(z, u)


def _axis_error(z_target: np.ndarray, z: np.ndarray, across: np.ndarray) -> np.ndarray:
    """Rotation vector (model frame) of the smallest turn taking the axis z onto z_target (a half turn: about
    `across`, a unit vector across z)."""
    axis = _cross3(z, z_target)
    s, c = float(np.linalg.norm(axis)), float(z @ z_target)
    angle = float(np.arctan2(s, c))
    if s < 1e-12:
        return axis if c > 0 else across * angle
    return axis * (angle / s)


def rotation_error(R_target: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Rotation vector (model frame) turning R onto R_target."""
    E = R_target @ R.T
    angle = float(np.arccos(np.clip((np.trace(E) - 1.0) / 2.0, -1.0, 1.0)))
    v = np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
    if angle < 1e-9:
        return v / 2.0
    if np.pi - angle < 1e-6:  # near a half turn: the axis from the symmetric part
        w, V = np.linalg.eigh((E + E.T) / 2.0)
        axis = V[:, np.argmax(w)]
        if axis @ v < 0:
            axis = -axis
        return axis * angle
    return v * angle / (2.0 * np.sin(angle))


@dataclass
class IKResult:
    q: dict[str, float]
    position_error: float  # m
    angle_error: float  # rad off what the arm's task holds: the tool orientation (6 joints and more), the
    # approach axis (5), nothing (4 or fewer: 0.0); see the module's docstring
    iterations: int

    def ok(self, position_tol: float = 1e-3, angle_tol: float = 1e-2) -> bool:
        return self.position_error <= position_tol and self.angle_error <= angle_tol


class Solver:
    """Deterministic IK on a chain, the task chosen from its number of joints (see the module's docstring)."""

    SEEDS = 8  # fixed pseudo-random starts besides the reference-based ones
    MORE_SEEDS = 32  # further fixed starts of an arm of fewer than 6 joints (see __init__)
    TOLERANCE = 1e-10

    def __init__(self, tree: KinematicTree, tool: Tool | None = None, reference: dict[str, float] | None = None,
                 offsets: dict[str, tuple] | None = None, max_iterations: int = 100):
        self.tool = tool or find_tool(tree)
        self.chain = Chain(tree, self.tool, offsets)
        self.joints = self.chain.joints
        self.reference = None if reference is None else np.array([float(reference.get(j, 0.0)) for j in self.joints])
        self.max_iterations = max_iterations
        self.task = task_for(len(self.joints))
        rng = np.random.default_rng(20240531)
        lo, hi = np.maximum(self.chain.lower, -np.pi), np.minimum(self.chain.upper, np.pi)
        # the last joint (a 6-axis arm's tool roll) defines no branch: it only breaks ties
        self._weights = np.ones(len(self.joints))
        if len(self.joints) > 1:
            self._weights[-1] = 1e-2
        self._random = [lo + (hi - lo) * rng.random(len(self.joints)) for _ in range(self.SEEDS)]
        self._middle = (lo + hi) / 2.0  # every joint in the middle of its range (within a turn either way)
        # an arm of fewer than 6 joints: further starts, tried only when none of the first reaches the target
        # (the SO-ARM100's joint limits leave each start a small basin: the first starts missed 2 of 60 of its
        # own poses, these reach them)
        more = np.random.default_rng(20261128)
        self._more = [] if self.task == "pose" else [lo + (hi - lo) * more.random(len(self.joints))
                                                     for _ in range(self.MORE_SEEDS)]

    def fingerprint(self) -> str:
        """What the solver's answers depend on (the chain, the tool, the reference, the seeds, this
        module's code and the tree's transforms it uses), as a hash: solutions stored under it stay exact
        (cotwin.pmodel.ikcache)."""
        import hashlib
        import inspect

        h = hashlib.sha256(Path(__file__).read_bytes())
        for helper in (axis_angle, inverse):  # the tree's transforms this solver computes with
            h.update(inspect.getsource(helper).encode())
        c = self.chain
        for part in (c.joints, c.kinds, c.limits, self.max_iterations, self.SEEDS, self.TOLERANCE):
            h.update(repr(part).encode())
        for array in (c.base, c.tail, *c.axes, *c.before, *c.after, *self._random, *self._more, *( [self.reference] if self.reference is not None else [])):
            h.update(np.ascontiguousarray(array, dtype=float).tobytes())
        return h.hexdigest()

    def reference_for(self, target: np.ndarray) -> np.ndarray:
        """The reference posture; without one, the zero posture with the base facing the target."""
        if self.reference is not None:
            return self.reference.copy()
        ref = np.zeros(len(self.joints))
        if self.chain.kinds and self.chain.kinds[0] == "revolute":
            ref[0] = self._yaw(target)
        return ref

    def _yaw(self, target: np.ndarray) -> float:
        """Direction of the target seen from the base (about the base frame's z); an arm of fewer than 6
        joints: the base joint's angle facing the middle posture's tool towards it (`_facing`)."""
        if self.task != "pose":
            facing = self._facing(target, self._middle)
            if facing is not None:
                return facing
        p = inverse(self.chain.base) @ np.append(target[:3, 3], 1.0)
        return float(np.arctan2(p[1], p[0]))

    def _facing(self, target: np.ndarray, posture: np.ndarray) -> float | None:
        """The base joint's angle that turns the tool of `posture` towards the target, about the base joint's
        own axis (None: the tool or the target on that axis). The base frame's x (`_yaw`) is not where every
        arm faces: the SO-ARM100 faces its base frame's -y, and at zero it is folded back over its base, so its
        yaw seeds started it facing away. Of 60 of its own poses, the first starts missed 4 without these
        seeds, 2 with them (0 with the further starts, 1 of 60 without these)."""
        chain = self.chain
        B = chain.base @ chain.before[0]
        axis = B[:3, :3] @ (chain.axes[0] / np.linalg.norm(chain.axes[0]))
        across = np.eye(3) - np.outer(axis, axis)
        tool = across @ (chain.pose(posture)[:3, 3] - B[:3, 3])
        aim = across @ (target[:3, 3] - B[:3, 3])
        if min(np.linalg.norm(tool), np.linalg.norm(aim)) < 1e-6:
            return None
        return float(self._wrap(posture[0] + np.arctan2(np.cross(tool, aim) @ axis, tool @ aim)))

    def solve(self, target, current: dict[str, float] | None = None) -> IKResult:
        """Joints putting the tool frame at `target` (4x4 pose, or a point reached pointing down), the
        base on the turn nearest its `current` angle."""
        return self.near(self.branch(target), current)

    def near(self, result: IKResult, current: dict[str, float] | None) -> IKResult:
        """The same solution with the base joint, and every joint without limits (a continuous wrist), on the
        turn nearest its current angle: a continuous tool roll on the reference's nearest turn swung a full
        turn between neighbouring targets whose roll straddled the reference's opposite angle."""
        if current is None:
            return result
        q = dict(result.q)
        for k, joint in enumerate(self.joints):
            unlimited = np.isinf(self.chain.limits[k]).all()
            if self.chain.kinds[k] == "revolute" and (k == 0 or unlimited) and joint in current:
                q[joint] = self._nearest_turn(q[joint], float(current[joint]), k)
        return IKResult(q, result.position_error, result.angle_error, result.iterations)

    def branch(self, target) -> IKResult:
        """The solution on the reference's branch, every joint on the turn nearest the reference."""
        target = np.asarray(target, float)
        if target.shape == (3,):
            T = np.eye(4)
            T[:3, :3] = DOWN
            T[:3, 3] = target
            target = T
        ref = self.reference_for(target)
        candidates = [self._continuation(target, ref)]
        seeds = [ref]
        if self.chain.kinds and self.chain.kinds[0] == "revolute":
            yaw = self._yaw(target)
            for base in (yaw, yaw + np.pi):
                seed = ref.copy()
                seed[0] = base
                seeds.append(seed)
        if self.task != "pose" and self.chain.kinds[0] == "revolute":  # the middle of every joint's range, facing
            facing = self._facing(target, self._middle)  # the target and away from it (see _facing)
            for base in () if facing is None else (facing, facing + np.pi):
                seed = self._middle.copy()
                seed[0] = self._wrap(base)  # within a turn of 0, not clipped to a limit beyond it
                seeds.append(seed)
        seeds.extend(self._random)
        if self.task == "position":
            found = candidates + [self.newton(target, seed) for seed in seeds]
            if not any(f[1] < 1e-7 for f in found) and not self._beyond(target):  # none reached it: further starts
                found += [self.newton(target, seed) for seed in self._more]
            return self._position_branch(target, ref, found)
        start = self.newton if self.task == "pose" else self._staged
        best, best_distance, best_error = None, np.inf, None
        fallback = None
        moved: list[np.ndarray] = []  # a redundant arm's converged solutions already moved towards the reference
        for found in candidates + [None] * (len(seeds) + len(self._more)):
            if found is None and not seeds:  # a 5-axis arm's first starts all missed: the further starts
                if best is not None or self._beyond(target):
                    break
                seeds = list(self._more)
            q, pos, ang, iterations = found if found is not None else start(target, seeds.pop(0))
            if pos < 1e-7 and ang < 1e-7:
                q = self._wind(q, ref)
                if self.redundant:
                    if any(np.abs(q - m).max() < 1e-6 for m in moved):
                        continue
                    moved.append(q)
                    q, pos, ang = self._toward(target, q, ref)
                distance = self._distance(q, ref)
                if distance < best_distance - 1e-9:
                    best, best_distance, best_error = q, distance, (pos, ang, iterations)
            elif fallback is None or pos + 0.1 * ang < fallback[1] + 0.1 * fallback[2]:
                fallback = (q, pos, ang, iterations)
        if best is None:  # unreachable: the closest approach found
            q, pos, ang, iterations = fallback
        else:
            q, (pos, ang, iterations) = best, best_error
        return IKResult(dict(zip(self.joints, map(float, q))), float(pos), float(ang), iterations)

    def _beyond(self, target: np.ndarray) -> bool:
        """Is the target's position farther from the base joint than the arm reaches stretched out (the lengths
        between its joints, the tool's and its slides' travel added up)? Then no start reaches it: an arm of
        fewer than 6 joints skips its further starts (the SO-ARM100 took 5 s on a point 2 m away)."""
        c = self.chain
        reach = sum(float(np.linalg.norm(A[:3, 3])) for A in c.after) + float(np.linalg.norm(c.tail[:3, 3]))
        reach += sum(float(np.linalg.norm(B[:3, 3])) for B in c.before[1:])
        reach += sum(max(abs(lo), abs(hi)) for kind, (lo, hi) in zip(c.kinds, c.limits) if kind != "revolute")
        origin = (c.base @ c.before[0])[:3, 3]
        return float(np.linalg.norm(target[:3, 3] - origin)) > reach + 1e-3

    def _position_branch(self, target: np.ndarray, ref: np.ndarray, found: list) -> IKResult:
        """An arm of 4 joints or fewer: among the starts that reach the position, the postures turned (the
        position held) to the orientation nearest the target's; of those within 1e-6 rad of the nearest, the one
        nearest the reference. No start reaching it: the closest approach found."""
        reached = []
        for q, pos, _, iterations in found:
            if pos < 1e-7:
                q, pos, turned = self._orient(target, q)
                reached.append((self._wind(q, ref), pos, turned, iterations))
        if not reached:
            q, pos, _, iterations = min(found, key=lambda f: f[1])  # the first of equals: the order is fixed
            return IKResult(dict(zip(self.joints, map(float, q))), float(pos), 0.0, iterations)
        least = min(r[2] for r in reached)
        best, best_distance = None, np.inf
        for q, pos, turned, iterations in reached:
            distance = self._distance(q, ref)
            if turned <= least + 1e-6 and distance < best_distance - 1e-9:
                best, best_distance = (q, pos, iterations), distance
        q, pos, iterations = best
        return IKResult(dict(zip(self.joints, map(float, q))), float(pos), 0.0, iterations)

    def _orient(self, target: np.ndarray, q: np.ndarray, steps: int = 30):
        """A posture reaching the target's position turned, the position held, to lower its rotation error: a
        Gauss-Newton step on the rotation error within the position's null space, then Newton back onto the
        position, each step halved until it lowers the error. (q, position error, rotation error left) of the
        best found."""
        chain = self.chain
        T, J = chain.forward(q)
        pos = float(np.linalg.norm(target[:3, 3] - T[:3, 3]))
        error = rotation_error(target[:3, :3], T[:3, :3])
        angle = float(np.linalg.norm(error))
        eye = np.eye(len(q))
        for _ in range(steps):
            free = eye - np.linalg.pinv(J[:3]) @ J[:3]  # joint motions that keep the position (to first order)
            step = free @ np.linalg.pinv(J[3:] @ free, rcond=1e-8) @ error
            largest = np.abs(step).max() if len(step) else 0.0
            if largest < 1e-12:
                break
            if largest > 0.5:
                step *= 0.5 / largest
            for scale in (1.0, 0.5, 0.25, 0.125):
                trial, p, _, _ = self.newton(target, np.clip(q + scale * step, chain.lower, chain.upper), 20)
                T2, J2 = chain.forward(trial)
                e2 = rotation_error(target[:3, :3], T2[:3, :3])
                a2 = float(np.linalg.norm(e2))
                if p < 1e-9 and a2 < angle - 1e-13:
                    q, pos, J, error, angle = trial, p, J2, e2, a2
                    break
            else:
                break
        return q, pos, angle

    # ---- internals ----
    @staticmethod
    def _wrap(d: np.ndarray) -> np.ndarray:
        return (d + np.pi) % TWO_PI - np.pi

    @property
    def redundant(self) -> bool:
        """More joints than the six a full pose fixes: a solution can move along its self-motion."""
        return len(self.joints) > 6

    def _distance(self, q: np.ndarray, ref: np.ndarray) -> float:
        return float(np.sum(self._weights * self._wrap(q - ref) ** 2))

    def _toward(self, target: np.ndarray, q: np.ndarray, ref: np.ndarray, steps: int = 30):
        """A redundant arm's solution moved along its self-motion (the Jacobian's null space) towards the
        reference posture, the pose held (Newton after each step) and the limits kept: (q, position error,
        angle error) of the posture nearest the reference found, each step halved until it brings it nearer."""
        chain = self.chain
        T, J = chain.forward(q)
        pos = float(np.linalg.norm(target[:3, 3] - T[:3, 3]))
        ang = float(np.linalg.norm(rotation_error(target[:3, :3], T[:3, :3])))
        distance = self._distance(q, ref)
        eye = np.eye(len(q))
        for _ in range(steps):
            step = -(eye - np.linalg.pinv(J) @ J) @ (self._weights * self._wrap(q - ref))
            if np.abs(step).max() < 1e-10:
                break
            for scale in (1.0, 0.5, 0.25, 0.125):
                trial, p, a, _ = self.newton(target, np.clip(q + scale * step, chain.lower, chain.upper), 20)
                if p < 1e-9 and a < 1e-9 and self._distance(trial, ref) < distance - 1e-12:
                    q, pos, ang, distance = trial, p, a, self._distance(trial, ref)
                    J = chain.forward(q)[1]
                    break
            else:
                break
        return q, pos, ang

    def _nearest_turn(self, value: float, near: float, k: int) -> float:
        """value + 2 pi n (n whole, the value itself when n = 0: no rounding) within the joint's limits,
        nearest `near`."""
        if self.chain.kinds[k] != "revolute":
            return value
        turns = round((near - value) / TWO_PI)
        lo, hi = self.chain.limits[k]
        for n in (turns, turns + 1, turns - 1):  # the nearest turn, else the next one up or down
            candidate = value + n * TWO_PI if n else value
            if lo - 1e-9 <= candidate <= hi + 1e-9:
                return float(np.clip(candidate, lo, hi))
        return value

    def _wind(self, q: np.ndarray, ref: np.ndarray) -> np.ndarray:
        return np.array([self._nearest_turn(float(v), float(r), k) for k, (v, r) in enumerate(zip(q, ref))])

    def _continuation(self, target: np.ndarray, ref: np.ndarray, steps: int = 16):
        """Follow the tool from the reference posture's pose to the target along a straight line and a
        uniform rotation, a few Newton steps at each waypoint: the solution on the reference's branch."""
        q = np.clip(ref.astype(float), self.chain.lower, self.chain.upper)
        start = self.chain.forward(q)[0]
        turn = rotation_error(target[:3, :3], start[:3, :3])
        total = 0
        for k in range(1, steps + 1):
            s = k / steps
            waypoint = np.eye(4)
            waypoint[:3, :3] = axis_angle(turn, float(np.linalg.norm(turn)) * s)[:3, :3] @ start[:3, :3] \
                if np.linalg.norm(turn) > 1e-12 else start[:3, :3]
            waypoint[:3, 3] = start[:3, 3] + s * (target[:3, 3] - start[:3, 3])
            q, pos, ang, iterations = self.newton(waypoint, q, max_iterations=None if k == steps else 8)
            total += iterations
        return q, pos, ang, total

    def _staged(self, target: np.ndarray, seed: np.ndarray):
        """A 5-axis arm's start: Newton on the position alone, then on the position and the approach axis (from
        the same starts, the axis at once reached 33 of the SO-ARM100's 40 own poses, staged 37)."""
        q, _, _, first = self.newton(target, seed, task="position")
        q, pos, ang, iterations = self.newton(target, q)
        return q, pos, ang, first + iterations

    def newton(self, target: np.ndarray, seed: np.ndarray, max_iterations: int | None = None,
               task: str | None = None):
        """Damped Newton iterations from one start (no branch choice) on the solver's task (or `task`): (q,
        position error, angle error, iterations)."""
        chain = self.chain
        task = task or self.task
        residual = lambda target, T, J: self._residual(target, T, J, task)  # noqa: E731
        q = np.clip(seed.astype(float), chain.lower, chain.upper)
        damping = 1e-4
        T, J = chain.forward(q)
        e, J = residual(target, T, J)
        eye = np.eye(len(e))
        norm = float(np.linalg.norm(e))
        iterations = 0
        for iterations in range(1, (max_iterations or self.max_iterations) + 1):
            if norm < self.TOLERANCE:
                break
            step = J.T @ np.linalg.solve(J @ J.T + damping * eye, e)
            pinned = ((q <= chain.lower) & (step < 0)) | ((q >= chain.upper) & (step > 0))
            if pinned.any():  # a joint at its limit pushed beyond it: solve without it (else the clipped step
                # never lowers the error and the damping grows until the start is given up)
                free = J * ~pinned
                step = free.T @ np.linalg.solve(free @ free.T + damping * eye, e)
            largest = np.abs(step).max()
            if largest > 0.5:
                step *= 0.5 / largest
            trial = np.clip(q + step, chain.lower, chain.upper)
            T2, J2 = chain.forward(trial)
            e2, J2 = residual(target, T2, J2)
            norm2 = float(np.linalg.norm(e2))
            if norm2 < norm:
                q, T, J, e, norm = trial, T2, J2, e2, norm2
                damping = max(damping * 0.3, 1e-12)
            else:
                damping *= 10.0
                if damping > 1e4:
                    break
        return q, float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])), iterations

    @staticmethod
    def _residual(target: np.ndarray, T: np.ndarray, J: np.ndarray, task: str) -> tuple[np.ndarray, np.ndarray]:
        """The error `task` drives to zero (position first, then what the task holds of the orientation as a
        rotation vector: all of it, its two components turning the approach axis, none) and its Jacobian rows."""
        if task == "pose":
            return np.concatenate([target[:3, 3] - T[:3, 3], rotation_error(target[:3, :3], T[:3, :3])]), J
        if task == "position":
            return target[:3, 3] - T[:3, 3], J[:3]
        z = T[:3, 2]
        u, v = _across(z)
        turn = _axis_error(target[:3, 2], z, u)
        plane = np.stack([u, v])  # a turn about z itself moves no axis: only these two components count
        return np.concatenate([target[:3, 3] - T[:3, 3], plane @ turn]), np.vstack([J[:3], plane @ J[3:]])


def solve(tree: KinematicTree, target, tool: Tool | None = None, reference: dict[str, float] | None = None,
          current: dict[str, float] | None = None, offsets: dict[str, tuple] | None = None) -> IKResult:
    """One-off IK (see Solver): `target` is a 4x4 tool pose, or a point reached with the tool down."""
    return Solver(tree, tool, reference, offsets).solve(target, current)
