"""IK for any serial arm: the 7-joint Franka Panda (imported from example-robot-data's URDF) reaches a grid
of targets, with the same joints from any start posture, its redundancy resolved nearest the reference
posture within its joint limits; the tool point named by link and offset."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.runtime import FunctionRegistry
from cotwin.pmodel import ik
from cotwin.pmodel.cell import CellGeometry
from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.tree import build_tree, transform
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.robosim.check import load_checked
from test_urdf_import import PUBLISHED, robot_data

READY = (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785)  # the Panda's usual "ready" posture


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    folder = tmp_path_factory.mktemp("panda")
    result = import_urdf(robot_data() / PUBLISHED["panda"], folder, check=False)
    return build_tree(load_checked([result.file]))


@pytest.fixture(scope="module")
def solver(panda):
    tool = ik.find_tool(panda)
    return ik.Solver(panda, tool, dict(zip(ik.arm_joints(panda, tool), READY)))


def _q(result, joints) -> np.ndarray:
    return np.array([result.q[j] for j in joints])


def mujoco_tool_pose(tree, tool, q: dict[str, float]) -> np.ndarray:
    """The tool frame from MuJoCo's kinematics of the tree's MJCF (not cotwin's own forward kinematics)."""
    model = mujoco.MjModel.from_xml_string(to_mjcf(tree, None, visual=False))
    data = mujoco.MjData(model)
    for name, value in q.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_kinematics(model, data)
    T = np.eye(4)
    T[:3, :3] = data.body(tool.link).xmat.reshape(3, 3)
    T[:3, 3] = data.body(tool.link).xpos
    return T @ tool.offset


def test_the_panda_reaches_a_grid_of_targets_in_its_cell_within_its_limits(panda, solver):
    assert solver.joints == [f"panda_joint{k}" for k in range(1, 8)] and solver.redundant
    grid = [transform((x, y, z), (np.pi, 0.0, yaw)) for x in (0.35, 0.55) for y in (-0.2, 0.0, 0.2) for z in (0.15, 0.4)
            for yaw in (0.0,)]
    grid.append(transform((0.45, 0.1, 0.3), (np.pi, 0.3, 0.8)))  # tilted, turned
    for target in grid:
        result = solver.branch(target)
        assert result.ok(1e-9, 1e-9), target[:3, 3]
        q = _q(result, solver.joints)
        assert np.all(q >= solver.chain.lower - 1e-12) and np.all(q <= solver.chain.upper + 1e-12)
        assert np.abs(mujoco_tool_pose(panda, solver.tool, result.q) - target).max() < 1e-9


def test_the_same_joints_from_20_random_start_postures(solver):
    target = transform((0.5, -0.15, 0.25), (np.pi, 0.0, 0.4))
    rng = np.random.default_rng(17)
    lower, upper = solver.chain.lower, solver.chain.upper
    first = None
    for _ in range(20):
        start = dict(zip(solver.joints, lower + (upper - lower) * rng.random(len(lower))))
        q = _q(solver.solve(target, current=start), solver.joints)
        if first is None:
            first = q
        assert np.array_equal(q, first)  # bit for bit: nothing depends on where the arm was


def test_the_redundancy_is_resolved_nearest_the_reference_posture(panda, solver):
    target = transform((0.45, 0.2, 0.35), (np.pi, 0.0, 0.0))
    result = solver.branch(target)
    q = _q(result, solver.joints)
    ref = np.array(READY)
    # no motion that keeps the tool where it is brings the arm nearer the reference (the null-space
    # gradient vanishes, joints at a limit aside)
    _, J = solver.chain.forward(q)
    gradient = solver._weights * (q - ref)
    free = (q > solver.chain.lower + 1e-6) & (q < solver.chain.upper - 1e-6)
    N = np.eye(7) - np.linalg.pinv(J) @ J
    assert np.abs((N @ gradient)[free]).max() < 1e-6
    # another reference, another posture for the same pose: the elbow (joint 3 turns the arm's plane)
    other = ref.copy()
    other[2] = 1.2
    turned = ik.Solver(panda, solver.tool, dict(zip(solver.joints, other))).branch(target)
    assert turned.ok(1e-9, 1e-9)
    assert abs(turned.q["panda_joint3"] - result.q["panda_joint3"]) > 0.3
    assert np.allclose(solver.chain.pose(_q(turned, solver.joints)), target, atol=1e-9)


def test_the_tool_point_is_named_by_link_and_offset(panda, tmp_path):
    tcp = ik.find_tool(panda, "flange", link="panda_hand_tcp")
    assert tcp.link == "panda_hand_tcp" and np.array_equal(tcp.offset, np.eye(4)) and tcp.fingers == ()
    offset = ik.find_tool(panda, (0.0, 0.0, 0.02), link="panda_hand_tcp")
    q = {j: 0.1 for j in ik.arm_joints(panda, tcp)}
    assert np.allclose(ik.tool_pose(panda, offset, q)[:3, 3], (ik.tool_pose(panda, tcp, q) @ [0, 0, 0.02, 1.0])[:3])
    # by default the TCP the URDF declares on the gripper, its fingers kept; the gripper link named: its fingertips
    default, gripper = ik.find_tool(panda), ik.find_tool(panda, link="panda_hand")
    assert (default.link, default.hand, default.fingers) == ("panda_hand_tcp", "panda_hand", gripper.fingers)
    assert np.allclose(default.offset, np.eye(4), atol=1e-12) and gripper.offset[2, 3] > 0.1034
    with pytest.raises(CotwinError, match="tool link 'hand' is not a link of p-model panda"):
        ik.find_tool(panda, link="hand")
    # a cell geometry names it: [tool] link, read back, used by the mapping's inverse_kinematics
    path = CellGeometry(tool="flange", tool_link="panda_hand_tcp", reference=READY).write(tmp_path / "cell.toml")
    assert 'link = "panda_hand_tcp"' in path.read_text()
    geometry = CellGeometry.read(path)
    assert geometry.tool_link == "panda_hand_tcp"
    registry = FunctionRegistry(_Kinematic(panda), geometry)
    assert registry.tool.link == "panda_hand_tcp" and len(registry.arm) == 7
    point = (0.5, 0.1, 0.2)
    joints = dict(zip(registry.arm, registry.inverse_kinematics(*point)))
    assert np.allclose(ik.tool_pose(panda, registry.tool, joints), geometry.target_pose(point), atol=1e-9)
    path.write_text(path.read_text().replace("panda_hand_tcp", "tcp"))
    with pytest.raises(CotwinError) as err:
        FunctionRegistry(_Kinematic(panda), CellGeometry.read(path))
    assert "cell.toml:" in str(err.value) and "tool link 'tcp' is not a link" in str(err.value)


def test_the_default_tool_of_an_arm_without_gripper_ends_its_longest_chain(panda):
    # a UR-like tree: tool0 and ee_link both end the six-joint chain; base hangs off the root
    arm = ik.find_tool(panda, "flange", link=None)
    assert arm.hand == "panda_hand"  # the gripper (two prismatic fingers) wins; the tool its declared TCP
    from cotwin.pmodel.ik import _chain_end

    assert _chain_end(panda) in ("panda_leftfinger", "panda_rightfinger")  # 8 moving joints on their path


class _Kinematic:
    def __init__(self, tree):
        self.tree = tree

    def joint_positions(self):
        return {}


def test_the_ik_cache_is_keyed_on_what_determines_the_answer(panda, solver, tmp_path):
    from cotwin.pmodel.ikcache import SolutionCache

    tool = solver.tool
    same = ik.Solver(panda, tool, dict(zip(solver.joints, READY)))
    assert same.fingerprint() == solver.fingerprint()
    other_reference = ik.Solver(panda, tool, dict(zip(solver.joints, np.zeros(7))))
    other_tool = ik.Solver(panda, ik.find_tool(panda, link="panda_hand"), dict(zip(solver.joints, READY)))
    assert len({solver.fingerprint(), other_reference.fingerprint(), other_tool.fingerprint()}) == 3
    # a solution stored and read back is what solving gives
    target = transform((0.4, 0.0, 0.3), (np.pi, 0.0, 0.0))
    found = solver.branch(target)
    cache = SolutionCache(solver.fingerprint(), tmp_path)
    key = SolutionCache.key(target.ravel())
    cache.put(key, {"q": found.q, "position_error": found.position_error, "angle_error": found.angle_error,
                    "iterations": found.iterations})
    cache.save()
    assert ik.IKResult(**SolutionCache(same.fingerprint(), tmp_path).get(key)).q == solver.branch(target).q
    assert SolutionCache(other_tool.fingerprint(), tmp_path).get(key) is None
