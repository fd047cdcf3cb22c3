"""Inverse kinematics on a p-model's kinematic tree: a tool point reaches a position with the tool's
approach axis along a given direction (down, for the Flex-cell). Damped least squares, numeric
Jacobian, joint limits respected, several seeds.

The tool: the link that carries two or more prismatic joints (the gripper body); the approach axis
points from the gripper body's origin to the centre between the fingers, and the tool point is the
fingertip: between the fingers, where their geometry ends along the approach axis (their link
origins when they have no geometry). A grid target's height is where the fingertips go. Without a gripper, the last link's origin and z axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tree import KinematicTree, inverse


@dataclass(frozen=True)
class Tool:
    link: str
    offset: np.ndarray  # tool frame in the link frame (z = approach)
    fingers: tuple[str, ...]  # prismatic finger joints


def _frame_with_z(z: np.ndarray, origin: np.ndarray) -> np.ndarray:
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = origin
    return T


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


def find_tool(tree: KinematicTree) -> Tool:
    for link in reversed(tree.links):
        fingers = [j for j in tree.joints if j.parent == link.name and j.kind == "prismatic"]
        if len(fingers) >= 2:
            centres, corners = [], []
            for j in fingers:
                child = tree.link(j.child)
                local = inverse(link.pose) @ child.pose
                points = [local @ g.pose[:, 3] for g in child.geoms] or [local[:, 3]]
                centres.append(np.mean(points, axis=0)[:3])
                for g in child.geoms:
                    corners.extend((local @ g.pose @ np.append(c, 1.0))[:3] for c in _corners(g))
            mid = np.mean(centres, axis=0)
            approach = mid / np.linalg.norm(mid) if np.linalg.norm(mid) > 1e-9 else np.array([0.0, 0.0, 1.0])
            reach = max((c @ approach for c in corners), default=mid @ approach)
            tip = mid + (reach - mid @ approach) * approach
            return Tool(link.name, _frame_with_z(approach, tip), tuple(j.name for j in fingers))
    last = tree.links[-1]
    return Tool(last.name, np.eye(4), ())


def arm_joints(tree: KinematicTree, tool: Tool) -> list[str]:
    """The actuated joints on the path from the base to the tool link."""
    path, link = [], tool.link
    while link != tree.root.name:
        joint = next(j for j in tree.joints if j.child == link)
        if joint.kind != "fixed":
            path.append(joint.name)
        link = joint.parent
    return list(reversed(path))


def tool_pose(tree: KinematicTree, tool: Tool, q: dict[str, float]) -> np.ndarray:
    return tree.forward(q)[tool.link] @ tool.offset


@dataclass
class IKResult:
    q: dict[str, float]
    position_error: float  # m
    angle_error: float  # rad between the approach axis and the requested direction
    iterations: int

    def ok(self, position_tol: float = 1e-3, angle_tol: float = 1e-2) -> bool:
        return self.position_error <= position_tol and self.angle_error <= angle_tol


def solve(tree: KinematicTree, target: np.ndarray, approach=(0.0, 0.0, -1.0), seed: dict | None = None,
          tool: Tool | None = None, max_iterations: int = 300) -> IKResult:
    tool = tool or find_tool(tree)
    joints = arm_joints(tree, tool)
    limits = {j.name: (j.lower if j.lower is not None else -np.pi, j.upper if j.upper is not None else np.pi)
              for j in tree.joints}
    approach = np.asarray(approach, float) / np.linalg.norm(approach)
    target = np.asarray(target, float)
    seeds = [dict(seed or {})]
    # standard postures: elbow up, tool down, facing the target
    yaw = float(np.arctan2(target[1], target[0]))
    for base in (yaw, yaw + np.pi / 2, yaw - np.pi / 2, yaw + np.pi):
        for elbow in (1.0, -1.0):
            seeds.append({joints[0]: base, **{n: v * elbow for n, v in zip(joints[1:], (0.5, 1.5, 0.5, 0.0, 0.0))}})
    best: IKResult | None = None
    for start in seeds:
        result = _solve_from(tree, tool, joints, limits, target, approach, start, max_iterations)
        if best is None or (result.position_error + 0.1 * result.angle_error) < (best.position_error + 0.1 * best.angle_error):
            best = result
        if best.ok(1e-4, 1e-3):
            break
    return best


def _residual(tree, tool, q, target, approach):
    T = tool_pose(tree, tool, q)
    return np.concatenate([target - T[:3, 3], 0.3 * np.cross(T[:3, 2], approach)]), T


def _solve_from(tree, tool, joints, limits, target, approach, start, max_iterations) -> IKResult:
    q = {n: float(np.clip(start.get(n, 0.0), *limits[n])) for n in joints}
    damping = 1e-3
    best_norm, since_best = np.inf, 0
    for it in range(max_iterations):
        r, T = _residual(tree, tool, q, target, approach)
        norm = float(np.linalg.norm(r))
        if np.linalg.norm(r[:3]) < 1e-7 and np.linalg.norm(r[3:]) < 1e-7:
            break
        if norm < best_norm * (1 - 1e-4):
            best_norm, since_best = norm, 0
        else:
            since_best += 1
            if since_best >= 15:  # stalled: out of reach from this seed
                break
        J = np.zeros((6, len(joints)))
        eps = 1e-6
        for k, n in enumerate(joints):
            dq = dict(q)
            dq[n] += eps
            J[:, k] = -(_residual(tree, tool, dq, target, approach)[0] - r) / eps
        step = J.T @ np.linalg.solve(J @ J.T + damping ** 2 * np.eye(6), r)
        step *= min(1.0, 0.5 / max(np.abs(step).max(), 1e-12))
        for k, n in enumerate(joints):
            q[n] = float(np.clip(q[n] + step[k], *limits[n]))
    r, T = _residual(tree, tool, q, target, approach)
    angle = float(np.arccos(np.clip(T[:3, 2] @ approach, -1.0, 1.0)))
    return IKResult(q, float(np.linalg.norm(r[:3])), angle, it + 1)
