"""Cell geometry (plate pose, tool point, tool orientation) and the deterministic full-pose IK."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.mapping.runtime import FunctionRegistry
from cotwin.pmodel import ik
from cotwin.pmodel.cell import CellGeometry
from cotwin.pmodel.mjcf import to_mjcf
from cotwin_cells.flexcell import Brick, FlexCell
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree, rpy_matrix, transform
from cotwin.robosim.check import load_checked
from cotwin.robosim.pmodel_elements import Mapping

# a cell like the recorded UR5e's: the plate tilted by 45 degrees about x, turned half a turn about z
TILTED = CellGeometry(plate_xyz=(0.05, -0.1, 0.02), plate_rpy=(np.pi / 4, 0.0, np.pi), tool="flange")


@pytest.fixture(scope="module")
def project():
    from conftest import EXAMPLES

    return load_checked([EXAMPLES / "ur5e"])


@pytest.fixture(scope="module")
def tree(project):
    return build_tree(project)


@pytest.fixture(scope="module")
def cell(project):
    return FlexCell.from_mapping(project.elements(Mapping)[0])


def _q(result, joints):
    return np.array([result.q[j] for j in joints])


def test_the_same_target_from_20_random_start_poses_gives_the_same_joint_solution(tree, cell):
    solver = ik.Solver(tree, ik.find_tool(tree, "flange"))
    target = TILTED.target_pose(cell.hole(8, 10, 1))
    rng = np.random.default_rng(7)
    lower, upper = solver.chain.lower, solver.chain.upper
    solutions = []
    for _ in range(20):
        start = dict(zip(solver.joints, lower + (upper - lower) * rng.random(len(lower))))
        start[solver.joints[0]] = rng.uniform(-np.pi, np.pi)
        result = solver.solve(target, current=start)
        assert result.ok(1e-9, 1e-9)
        q = _q(result, solver.joints)
        # the base is on the turn nearest where it was; nothing else depends on the start
        assert abs(q[0] - start[solver.joints[0]]) <= np.pi + 1e-9
        solutions.append(q)
    first = solutions[0]
    for q in solutions[1:]:
        assert np.array_equal(q[1:], first[1:])
        assert np.isclose((q[0] - first[0]) % (2 * np.pi), 0.0) or np.isclose((q[0] - first[0]) % (2 * np.pi), 2 * np.pi)
    # within half a turn of the solution's base angle, every start gives the very same joints
    same = {tuple(solver.solve(target, current={solver.joints[0]: first[0] + d}).q.values()) for d in (-3.0, 0.0, 2.5)}
    assert len(same) == 1


def test_ik_constrains_the_full_tool_orientation_including_the_last_wrist(tree):
    tool = ik.find_tool(tree, "flange")
    solver = ik.Solver(tree, tool)
    for yaw in (0.0, 0.7, -1.2):
        target = transform((0.45, 0.2, 0.1), (np.pi, 0.0, yaw))
        result = solver.solve(target)
        reached = ik.tool_pose(tree, tool, result.q)
        assert np.allclose(reached[:3, 3], target[:3, 3], atol=1e-9)
        assert np.allclose(reached[:3, :3], target[:3, :3], atol=1e-9)
    # turning the target about the approach axis turns only the tool: the last wrist follows
    a = _q(solver.solve(transform((0.45, 0.2, 0.1), (np.pi, 0.0, 0.0))), solver.joints)
    b = _q(solver.solve(transform((0.45, 0.2, 0.1), (np.pi, 0.0, 0.5))), solver.joints)
    assert np.allclose(a[:5], b[:5], atol=1e-9) and abs(abs(b[5] - a[5]) - 0.5) < 1e-9


def test_the_reference_posture_chooses_the_branch(tree):
    tool = ik.find_tool(tree)
    target = transform((0.4, -0.3, 0.15), (np.pi, 0.0, 0.0))
    up = ik.Solver(tree, tool).solve(target)
    elbow = tree.joints[2].name
    flipped = dict(up.q)
    flipped[elbow] = -up.q[elbow]
    down = ik.Solver(tree, tool, reference=flipped).solve(target)
    assert down.ok(1e-9, 1e-9) and up.ok(1e-9, 1e-9)
    assert np.sign(down.q[elbow]) == -np.sign(up.q[elbow])
    assert np.allclose(ik.tool_pose(tree, tool, down.q), target, atol=1e-9)


def test_tool_points_flange_fingertips_and_an_explicit_offset(tree):
    flange, tips = ik.find_tool(tree, "flange"), ik.find_tool(tree, "fingertips")
    assert flange.link == tips.link
    assert np.allclose(flange.offset[:3, :3], tips.offset[:3, :3])
    reach = tips.offset[:3, 3] @ tips.offset[:3, 2]
    assert reach > 0.1  # the fingertips are well beyond the flange, along the approach axis
    explicit = ik.find_tool(tree, (0.0, 0.0, 0.05))
    q = {j: 0.3 for j in ik.arm_joints(tree, flange)}
    F, E = ik.tool_pose(tree, flange, q), ik.tool_pose(tree, explicit, q)
    assert np.allclose(E[:3, 3], F[:3, 3] + 0.05 * F[:3, 2])
    # the registry puts the chosen tool point on the plate's hole, in the plate's frame
    geometry = CellGeometry(plate_xyz=(0.1, 0.0, 0.05), plate_rpy=(0.2, 0.0, 0.3), tool=(0.0, 0.0, 0.05))
    registry = FunctionRegistry(_Kinematic(tree), geometry)
    point = (0.5, 0.2, 0.07)
    reached = ik.tool_pose(tree, explicit, dict(zip(registry.arm, registry.inverse_kinematics(*point))))
    assert np.allclose(reached, geometry.target_pose(point), atol=1e-9)


def test_solver_joint_offsets_displace_the_chain_beyond_a_joint(tree):
    tool = ik.find_tool(tree, "flange")
    plain = ik.Chain(tree, tool)
    moved = ik.Chain(tree, tool, {"elbow_joint": (0.0, -0.02, 0.01)})
    assert np.allclose(moved.pose(np.zeros(6))[:3, 3] - plain.pose(np.zeros(6))[:3, 3], [0.0, -0.02, 0.01])
    q = np.array([0.3, 0.4, 1.2, -0.5, -1.5, 0.2])
    delta = moved.pose(q)[:3, 3] - plain.pose(q)[:3, 3]
    # beyond the elbow the offset turns with the shoulder (base about z, shoulder about y)
    R = plain.pose(np.array([0.3, 0.4, 0, 0, 0, 0]))[:3, :3] @ np.linalg.inv(plain.pose(np.zeros(6))[:3, :3])
    assert np.allclose(delta, R @ np.array([0.0, -0.02, 0.01]), atol=1e-12)
    solved = ik.Solver(tree, tool, offsets={"elbow_joint": (0.0, -0.02, 0.01)}).solve(moved.pose(q))
    assert np.allclose(moved.pose(_q(solved, moved.joints)), moved.pose(q), atol=1e-9)
    with pytest.raises(ValueError, match="not on the arm"):
        ik.Chain(tree, tool, {"left_finger_joint": (0.0, 0.0, 0.0)})


def test_scene_places_plate_holes_bricks_and_gravity_with_the_geometry(cell):
    tilted = FlexCell(cell.hole_dist, cell.x_max, cell.y_max, cell.xmax, cell.ymax, cell.z_table,
                      bricks=[Brick("brick1", (8, 10))], geometry=TILTED)
    model = mujoco.MjModel.from_xml_string(to_mjcf(build_tree(load_checked([_examples()])), tilted))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert np.allclose(data.geom("hole_8_10").xpos, TILTED.to_robot(np.array(cell.hole(8, 10)) * [1, 1, 0] + [0, 0, 0.0005]),
                       atol=1e-9)
    assert np.allclose(model.opt.gravity, TILTED.plate_pose()[:3, :3] @ [0, 0, -9.81])
    brick = data.body("brick1").xpos
    assert np.allclose(brick, TILTED.to_robot(np.array(cell.hole(8, 10)) * [1, 1, 0] + [0, 0, 0.03 + 1e-4]))
    # the default is the plate right under the robot: nothing moves
    assert cell.hole_in_robot(0, 23, 1) == pytest.approx(cell.hole(0, 23, 1))
    assert cell.gravity == pytest.approx((0.0, 0.0, -9.81))


def test_geometry_round_trips_through_toml(tmp_path):
    geometry = CellGeometry(plate_xyz=(0.1, -0.2, 0.3), plate_rpy=(0.7, 0.0, 3.1), tool=(0.0, 0.001, 0.032),
                            tool_rpy=(np.pi, 0.0, 0.1), reference=(0.0, 0.5, 1.5, -0.4, -1.57, 0.0),
                            reference_name="tool down, elbow up", joint_offsets={"elbow_joint": (0.0, -0.008, 0.0)})
    path = geometry.write(tmp_path / "cell.toml")
    again = CellGeometry.read(path)
    assert again == geometry
    assert CellGeometry.read(CellGeometry(tool="flange").write(tmp_path / "f.toml")).tool == "flange"


@pytest.mark.parametrize("text, where, message", [
    ("[plate]\nxyz = [0, 0,\n", "cell.toml:3:1:", "bad TOML"),
    ("[plate]\nxyz = [0, 0]\n", "cell.toml:2:1:", "[plate] xyz: must be a list of 3 finite numbers"),
    ("[plate]\nrpy = [0, 0, 0]\n\n[tool]\npoint = \"elbow\"\n", "cell.toml:5:1:", "flange, fingertips or [x, y, z]"),
    ("[tool]\nrpy = [0, \"x\", 0]\n", "cell.toml:2:1:", "[tool] rpy: must be a list of 3 finite numbers"),
    ("[plate]\nxzy = [0, 0, 0]\n", "cell.toml:2:1:", "unknown key 'xzy' in [plate]"),
    ("[ik]\njoint_offsets = { elbow_joint = [0, 1] }\n", "cell.toml:2:19:", "elbow_joint: must be a list of 3"),
    ("[motion]\nprofile = \"movej\"\n", "cell.toml:1:1:", "unknown key 'motion' in the file"),
])
def test_bad_geometry_files_are_reported_at_their_place(tmp_path, text, where, message):
    path = tmp_path / "cell.toml"
    path.write_text(text)
    with pytest.raises(CotwinError) as err:
        CellGeometry.read(path)
    assert where in str(err.value) and message in str(err.value)


def test_geometry_naming_joints_the_arm_lacks_is_reported_at_its_line(tmp_path, tree):
    path = tmp_path / "cell.toml"
    path.write_text("[plate]\nxyz = [0, 0, 0]\n[ik]\nreference = [0, 0, 0]\njoint_offsets = { knee = [0, 0, 0] }\n")
    geometry = CellGeometry.read(path)
    with pytest.raises(CotwinError) as err:
        FunctionRegistry(_Kinematic(tree), geometry)
    assert "cell.toml:4:1" in str(err.value) and "3 values" in str(err.value)
    assert "cell.toml:5:1" in str(err.value) and "'knee' is not an arm joint" in str(err.value)


def test_the_simulated_endpoint_gives_the_registry_the_scenes_geometry(tree, cell):
    tilted = FlexCell(cell.hole_dist, cell.x_max, cell.y_max, cell.xmax, cell.ymax, cell.z_table, geometry=TILTED)
    registry = FunctionRegistry(SimulatedEndpoint(PlatformSimulator(tree, tilted)))
    assert registry.geometry is TILTED
    q = dict(zip(registry.arm, registry.inverse_kinematics(*cell.hole(3, 20, 2))))
    assert np.allclose(ik.tool_pose(tree, registry.tool, q)[:3, 3], TILTED.to_robot(cell.hole(3, 20, 2)), atol=1e-9)
    assert np.allclose(ik.tool_pose(tree, registry.tool, q)[:3, :3], TILTED.plate_pose()[:3, :3] @ rpy_matrix(np.pi, 0, 0),
                       atol=1e-9)


class _Kinematic:
    """Just enough of an endpoint for the registry: a tree and joint positions."""

    def __init__(self, tree):
        self.tree = tree

    def joint_positions(self):
        return {}


def _examples():
    from conftest import EXAMPLES

    return EXAMPLES / "ur5e"


def test_a_joint_started_at_its_limit_does_not_stall_the_solver(tmp_path):
    """A new user's arm with a lift (a prismatic joint, 0 to 0.25 m) whose reference is its lower limit: a target
    the arm reaches with the lift 3 mm up was 'unreachable' (12 mm off, lift 0), every start stalled as Newton's step
    pushed the lift below its limit, was clipped back and never lowered the error. A joint at its limit pushed
    beyond it is left out of that step."""
    from cotwin.pmodel.urdf_import import import_urdf

    def link(name, z):
        return (f"<link name='{name}'><inertial><origin xyz='0 0 {z}'/><mass value='1'/><inertia ixx='0.01' ixy='0' "
                f"ixz='0' iyy='0.01' iyz='0' izz='0.01'/></inertial></link>")

    def joint(name, kind, parent, child, xyz, axis, limits="lower='-2.5' upper='2.5'"):
        return (f"<joint name='{name}' type='{kind}'><parent link='{parent}'/><child link='{child}'/>"
                f"<origin xyz='{xyz}'/><axis xyz='{axis}'/><limit {limits} effort='50' velocity='1'/></joint>")

    urdf = tmp_path / "lift.urdf"
    urdf.write_text("<robot name='lift'>" + "".join(link(n, 0.05) for n in ("p", "t", "c", "u", "f", "a", "b"))
                    + "<link name='tip'/>"
                    + joint("swivel", "revolute", "p", "t", "0 0 0.1", "0 0 1")
                    + joint("lift", "prismatic", "t", "c", "0 0 0.2", "0 0 1", "lower='0' upper='0.25'")
                    + joint("shoulder", "revolute", "c", "u", "0 0 0.3", "0 1 0")
                    + joint("elbow", "revolute", "u", "f", "0.3 0 0", "0 1 0")
                    + joint("pitch", "revolute", "f", "a", "0.25 0 0", "0 1 0")
                    + joint("roll", "revolute", "a", "b", "0.05 0 0", "1 0 0", "lower='-3.2' upper='3.2'")
                    + "<joint name='mount' type='fixed'><parent link='b'/><child link='tip'/><origin xyz='0.08 0 0'/>"
                    + "</joint></robot>")
    tree = build_tree(load_checked([import_urdf(urdf, tmp_path / "out").file]))
    found = ik.Solver(tree, ik.find_tool(tree)).branch(CellGeometry().target_pose((0.4, 0.0, 0.5)))
    assert found.position_error < 1e-9 and found.angle_error < 1e-9, found
    assert 0.0 < found.q["lift"] < 0.25
