"""IK for arms of fewer than 6 joints, on a third-party arm: the SO-ARM100 (example-robot-data's URDF, 5 joints
to its gripper link and a revolute jaw) reaches its own poses' position and approach axis, the roll left free,
with the same joints from any start; 4 joints (to its wrist link) reach the position, the orientation as near as
they allow; `IKResult.ok` and the mapping's `reachable` judge by the same task; a 6-joint arm is unchanged."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.mapping.runtime import FunctionRegistry
from cotwin.pmodel import ik
from cotwin.pmodel.cell import CellGeometry
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree, matrix_rpy, transform
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.robosim.check import load_checked
from test_urdf_import import PUBLISHED, robot_data

SO_ARM = "robots/so_arm_description/urdf/so100.urdf"
GRIPPER_TIP = (0.0, -0.1, 0.0)  # 10 cm out along the gripper link's -y, its roll axis: between the jaws' tips


@pytest.fixture(scope="module")
def so_arm(tmp_path_factory):
    urdf = robot_data() / SO_ARM
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no SO-ARM100 at {urdf} (an older release)")
    result = import_urdf(urdf, tmp_path_factory.mktemp("so_arm"), check=False)
    return build_tree(load_checked([result.file]))


def _solver(tree, link: str, point=GRIPPER_TIP) -> ik.Solver:
    return ik.Solver(tree, ik.find_tool(tree, point, link))


def _own_poses(solver: ik.Solver, count: int, seed: int) -> list[np.ndarray]:
    """Tool poses of postures drawn within the joints' limits: targets the arm reaches by construction."""
    rng = np.random.default_rng(seed)
    lower, upper = solver.chain.lower, solver.chain.upper
    return [solver.chain.pose(lower + (upper - lower) * rng.random(len(lower))) for _ in range(count)]


def _angle(a, b) -> float:
    """Between two unit vectors (atan2: arccos loses small angles)."""
    return float(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b)))


def test_the_so_arm_reaches_its_own_poses_position_and_approach_axis(so_arm):
    solver = _solver(so_arm, "gripper")
    assert solver.joints == ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll"]
    assert solver.task == "axis"
    for target in _own_poses(solver, 12, seed=1):
        result = solver.branch(target)
        assert result.ok(), (target[:3, 3], result)
        q = np.array([result.q[j] for j in solver.joints])
        assert np.all(q >= solver.chain.lower - 1e-12) and np.all(q <= solver.chain.upper + 1e-12)
        reached = solver.chain.pose(q)
        assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-3
        assert _angle(reached[:3, 2], target[:3, 2]) < 1e-2
        assert result.angle_error == pytest.approx(_angle(reached[:3, 2], target[:3, 2]), abs=1e-9)


def test_the_so_arm_gives_the_same_joints_from_any_start(so_arm):
    solver = _solver(so_arm, "gripper")
    [target] = _own_poses(solver, 1, seed=7)
    rng = np.random.default_rng(17)
    lower, upper = solver.chain.lower, solver.chain.upper
    first = None
    for _ in range(10):
        start = dict(zip(solver.joints, lower + (upper - lower) * rng.random(len(lower))))
        result = solver.solve(target, current=start)
        q = np.array([result.q[j] for j in solver.joints])
        first = q if first is None else first
        assert result.ok() and np.array_equal(q, first)  # bit for bit


def test_a_roll_the_arm_cannot_make_does_not_make_a_target_unreachable(so_arm):
    """The same position and approach axis with the roll turned: a full pose the 5 joints cannot reach, the
    task they can (a pose judgement said 'infeasible' here)."""
    solver = _solver(so_arm, "gripper")
    [target] = _own_poses(solver, 1, seed=3)
    rolled = target @ transform((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))  # one radian about the tool's z
    result = solver.branch(rolled)
    assert result.ok() and result.position_error < 1e-7
    reached = solver.chain.pose(np.array([result.q[j] for j in solver.joints]))
    assert np.linalg.norm(ik.rotation_error(rolled[:3, :3], reached[:3, :3])) > 0.1  # the roll is the arm's


def test_four_joints_reach_the_position_and_the_orientation_they_allow(so_arm):
    solver = _solver(so_arm, "wrist", "flange")
    assert solver.joints == ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex"]
    assert solver.task == "position"
    for target in _own_poses(solver, 8, seed=2):
        result = solver.branch(target)
        assert result.ok() and result.angle_error == 0.0
        reached = solver.chain.pose(np.array([result.q[j] for j in solver.joints]))
        assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-6
        # the target's orientation is one the joints allow: reached with the position
        assert np.linalg.norm(ik.rotation_error(target[:3, :3], reached[:3, :3])) < 1e-6
    # an orientation no posture at that position has: the position still reached
    rolled = target @ transform((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    result = solver.branch(rolled)
    assert result.ok() and result.position_error < 1e-7


def test_a_target_out_of_reach_is_not_ok(so_arm):
    solver = _solver(so_arm, "gripper")
    result = solver.branch(transform((2.0, 0.0, 0.5), (np.pi, 0.0, 0.0)))
    assert not result.ok() and result.position_error > 1.0


def test_the_mapping_reaches_the_so_arm_and_says_once_what_it_holds(so_arm, caplog, monkeypatch, tmp_path):
    """The mapping's `reachable` and `inverse_kinematics` on the SO-ARM's gripper (a 5-joint arm was refused:
    'needs 6 or more'): a point it reaches pointing down is reachable, its joints reach it, a warning once."""
    monkeypatch.setenv("COTWIN_CACHE", str(tmp_path / "cache"))
    solver = _solver(so_arm, "gripper")
    posed = solver.chain.pose(np.array([0.3, 1.2, -1.4, -0.6, 0.4]))  # the tool as the arm holds it there
    geometry = CellGeometry(tool=GRIPPER_TIP, tool_link="gripper", tool_rpy=tuple(matrix_rpy(posed[:3, :3])))
    registry = FunctionRegistry(SimulatedEndpoint(PlatformSimulator(so_arm, None)), geometry)
    assert registry.arm == solver.joints
    point = posed[:3, 3]
    with caplog.at_level(logging.WARNING, logger="cotwin.ik"):
        assert registry.reachable(*point)
        q = registry.inverse_kinematics(*point)
        assert registry.reachable(*(point + [0.0, 0.0, 0.01]))
        assert not registry.reachable(1.5, 0.0, 0.0)
    told = [r.getMessage() for r in caplog.records if r.name == "cotwin.ik"]
    assert len(told) == 1 and "5 moving joints" in told[0] and "approach axis" in told[0], told
    reached = solver.chain.pose(np.array(q))
    assert np.linalg.norm(reached[:3, 3] - point) < 1e-6 and _angle(reached[:3, 2], posed[:3, 2]) < 1e-6


def test_a_six_joint_arm_still_reaches_the_full_pose(tmp_path):
    """The UR5: the full pose (orientation and all) from its fixed starts, none of the further starts of the
    smaller arms, its task 'pose'."""
    tree = build_tree(load_checked([import_urdf(robot_data() / PUBLISHED["ur5"], tmp_path, check=False).file]))
    solver = ik.Solver(tree, ik.find_tool(tree))
    assert len(solver.joints) == 6 and solver.task == "pose" and solver._more == []
    target = transform((0.4, 0.2, 0.3), (np.pi, 0.2, 0.5))
    result = solver.branch(target)
    assert result.ok(1e-9, 1e-9)
    reached = solver.chain.pose(np.array([result.q[j] for j in solver.joints]))
    assert np.abs(reached - target).max() < 1e-9
    rolled = target @ transform((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    assert solver.branch(rolled).ok(1e-9, 1e-9)  # 6 joints choose the roll too
