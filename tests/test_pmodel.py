"""p-model export (SDF, URDF, MJCF agree) and the MuJoCo platform simulator."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.pmodel import ik
from cotwin.pmodel.mjcf import to_mjcf
from cotwin_cells.flexcell import Brick, FlexCell
from cotwin.pmodel.sdf import to_sdf
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree, inverse, rpy_matrix, transform
from cotwin.pmodel.urdf import to_urdf, urdf_frames
from cotwin.robosim.check import load_checked
from cotwin.robosim.pmodel_elements import Mapping

TOL = 1e-9


def _tree(path):
    return build_tree(load_checked([path]))


@pytest.fixture(scope="module")
def example_tree():
    from conftest import EXAMPLES

    return _tree(EXAMPLES / "ur5e")


def _published(name):
    from conftest import SHARED

    path = SHARED / name
    if not path.is_dir():
        pytest.skip(f"the paper's published models are not at {SHARED}")
    return path


def test_sdf_of_the_published_ur5e_has_the_models_structure():
    tree = _tree(_published("ur5e"))
    root = ET.fromstring(to_sdf(tree))
    assert root.tag == "sdf" and root.get("version") == "1.6"
    model = root.find("model")
    links = model.findall("link")
    joints = model.findall("joint")
    assert len(links) == 10
    kinds = [j.get("type") for j in joints]
    assert (kinds.count("revolute"), kinds.count("prismatic"), kinds.count("fixed")) == (6, 2, 1)
    by_name = {l.get("name"): l for l in links}
    # masses, poses, axes and limits as written in the model
    assert float(by_name["upper_arm_link"].find("inertial/mass").text) == pytest.approx(8.058)
    assert [float(v) for v in by_name["upper_arm_link"].find("pose").text.split()][:3] == pytest.approx([0, 0.13585, 0.089159])
    # the gripper part's links keep RoboTool's names (its SDF of the paper's model: 8-link_2fg7_base,
    # 9-rightFingerLink, 10-leftFingerLink, without the running number)
    assert {"link_2fg7_base", "leftFingerLink", "rightFingerLink"} <= set(by_name)
    assert not any(name.startswith("Gripper") for name in by_name)
    assert float(by_name["link_2fg7_base"].find("inertial/mass").text) == pytest.approx(1.2646523179240972)
    pan = next(j for j in joints if j.get("name") == "shoulder_pan_joint")
    assert (pan.find("parent").text, pan.find("child").text) == ("base_link", "shoulder_link")
    assert [float(v) for v in pan.find("axis/xyz").text.split()] == pytest.approx([0, 0, 1])
    limit = pan.find("axis/limit")
    assert float(limit.find("lower").text) == pytest.approx(-2 * 3.1415)
    assert float(limit.find("velocity").text) == pytest.approx(3.1415 / 2)
    assert float(pan.find("axis/dynamics/damping").text) == 10
    fixed = next(j for j in joints if j.get("type") == "fixed")
    assert (fixed.find("parent").text, fixed.find("child").text) == ("wrist_3_link", "link_2fg7_base")
    # joint pose in the child frame: at the shoulder link, 0.0988 above the base's origin
    pan_world = tree.link("shoulder_link").pose @ transform(*_pose(pan.find("pose").text))
    assert pan_world[:3, 3] == pytest.approx([0, 0, 0.0988])


def _pose(text):
    v = [float(x) for x in text.split()]
    return v[:3], v[3:]


def test_ur3e_exports_in_every_format(tmp_path):
    path = _published("ur3e")
    for fmt in ("sdf", "urdf", "mjcf"):
        out = tmp_path / f"ur3e.{fmt}"
        proc = subprocess.run([sys.executable, "-m", "cotwin", "export-pmodel", str(path), "--format", fmt, "-o", str(out)],
                              capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
        ET.fromstring(out.read_text())
        assert "7 links, 6 revolute" in proc.stdout
    mujoco.MjModel.from_xml_path(str(tmp_path / "ur3e.mjcf"))


def test_exports_are_deterministic(example_tree):
    from conftest import EXAMPLES

    again = _tree(EXAMPLES / "ur5e")
    for writer in (to_sdf, to_urdf, to_mjcf):
        assert writer(example_tree) == writer(again)


def _sdf_world_geoms(text: str, q: dict) -> dict:
    """Forward kinematics read back from the SDF text alone (an independent reading of its conventions)."""
    model = ET.fromstring(text).find("model")
    link_pose = {l.get("name"): transform(*_pose(l.find("pose").text)) for l in model.findall("link")}
    geoms = {l.get("name"): [(c.get("name").removesuffix("_collision"), transform(*_pose(c.find("pose").text)))
                             for c in l.findall("collision")] for l in model.findall("link")}
    world = {}
    joints = model.findall("joint")
    children = {j.find("child").text for j in joints}
    root = next(n for n in link_pose if n not in children)
    world[root] = link_pose[root]
    pending = list(joints)
    while pending:
        j = pending.pop(0)
        parent, child = j.find("parent").text, j.find("child").text
        if parent not in world:
            pending.append(j)
            continue
        J0 = link_pose[child] @ transform(*_pose(j.find("pose").text))  # joint frame in the model frame
        motion = np.eye(4)
        if j.get("type") != "fixed":
            axis = np.array([float(v) for v in j.find("axis/xyz").text.split()])
            value = q.get(j.get("name"), 0.0)
            if j.get("type") == "revolute":
                from cotwin.pmodel.tree import axis_angle

                motion = axis_angle(axis, value)
            else:
                motion[:3, 3] = axis * value
        world[child] = world[parent] @ inverse(link_pose[parent]) @ J0 @ motion @ inverse(J0) @ link_pose[child]
    return {name: world[l] @ T for l, items in geoms.items() for name, T in items}


@pytest.mark.parametrize("which", ["example", "ur5e", "ur3e"])
def test_sdf_urdf_mjcf_have_the_same_forward_kinematics(which, example_tree):
    tree = example_tree if which == "example" else _tree(_published(which))
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = {j.name: float(rng.uniform(-2, 2) if j.kind == "revolute" else rng.uniform(0, 0.02)) for j in tree.actuated}
        ours = tree.geom_poses(q)
        links = tree.forward(q)
        # SDF, read back independently
        sdf = _sdf_world_geoms(to_sdf(tree), q)
        assert set(sdf) == set(ours)
        for name, T in ours.items():
            assert np.abs(sdf[name] - T).max() < TOL, name
        # MJCF, through MuJoCo's own kinematics: body frames, and geoms from the compiled local poses
        m = mujoco.MjModel.from_xml_string(to_mjcf(tree))
        d = mujoco.MjData(m)
        for name, value in q.items():
            d.qpos[m.joint(name).qposadr[0]] = value
        mujoco.mj_kinematics(m, d)
        for link in tree.links:
            b = m.body(link.name).id
            assert np.abs(d.xpos[b] - links[link.name][:3, 3]).max() < TOL
            assert np.abs(d.xmat[b].reshape(3, 3) - links[link.name][:3, :3]).max() < TOL
        for name, T in ours.items():
            g = m.geom(name)
            R = np.zeros(9)
            mujoco.mju_quat2Mat(R, g.quat)
            local = np.eye(4)
            local[:3, :3], local[:3, 3] = R.reshape(3, 3), g.pos
            body = np.eye(4)
            body[:3, :3], body[:3, 3] = d.xmat[g.bodyid[0]].reshape(3, 3), d.xpos[g.bodyid[0]]
            assert np.abs(body @ local - T).max() < TOL, name
        # URDF, through MuJoCo's URDF importer (static bodies kept): its link frames are joint frames
        urdf = to_urdf(tree).replace("\n  <link", '\n  <mujoco><compiler fusestatic="false" discardvisual="false"/></mujoco>\n  <link', 1)
        mu = mujoco.MjModel.from_xml_string(urdf)
        du = mujoco.MjData(mu)
        for name, value in q.items():
            du.qpos[mu.joint(name).qposadr[0]] = value
        mujoco.mj_kinematics(mu, du)
        frames = urdf_frames(tree)
        for link in tree.links[1:]:
            expected = links[link.name] @ inverse(link.pose) @ frames[link.name]
            b = mu.body(link.name).id
            assert np.abs(du.xpos[b] - expected[:3, 3]).max() < TOL
            assert np.abs(du.xmat[b].reshape(3, 3) - expected[:3, :3]).max() < TOL


def test_rpy_round_trip():
    from cotwin.pmodel.tree import matrix_rpy

    for rpy in [(0.3, -1.2, 2.5), (3.1415, 1.57075, 3.1415), (0, 0, 0)]:
        assert np.abs(rpy_matrix(*matrix_rpy(rpy_matrix(*rpy))) - rpy_matrix(*rpy)).max() < 1e-12


@pytest.fixture()
def sim(example_tree):
    return PlatformSimulator(example_tree)


def test_each_joint_reaches_its_servo_target(sim, example_tree):
    # stated: every arm joint within 1e-3 rad and every finger within 1e-4 m of its target after 1.0 s
    targets = {j.name: (0.6 if i % 2 else -0.4) if j.kind == "revolute" else 0.012
               for i, j in enumerate(example_tree.actuated)}
    sim.write_actuators(targets)
    sim.advance(1.0)
    q = sim.joint_positions()
    for name, target in targets.items():
        tol = 1e-3 if "finger" not in name else 1e-4
        assert abs(q[name] - target) < tol, (name, q[name], target)


def test_velocity_sensors_read_zero_at_rest(sim):
    sim.write_actuators({"shoulder_lift_joint": 0.5, "elbow_joint": -0.8})
    sim.advance(2.0)
    readings = sim.read_sensors()
    velocities = {k: v for k, v in readings.items() if k.endswith(".output_vel")}
    assert len(velocities) == 8
    assert max(abs(v) for v in velocities.values()) < 1e-6
    positions = {k: v for k, v in readings.items() if k.endswith(".output_position")}
    assert positions["ur5e::shoulder_link::PS2.output_position"] == pytest.approx(0.5, abs=1e-3)


def test_actuator_names_from_the_pmodel_and_errors(sim):
    sim.write_actuators({"ur5e::base_link::shoulder_pan_joint::M1.dangle": 0.3, "M3": -0.2})
    sim.advance(1.0)
    q = sim.joint_positions()
    assert q["shoulder_pan_joint"] == pytest.approx(0.3, abs=1e-3) and q["elbow_joint"] == pytest.approx(-0.2, abs=1e-3)
    with pytest.raises(CotwinError, match="unknown actuator 'elbow'"):
        sim.write_actuators({"elbow": 1.0})
    with pytest.raises(CotwinError, match="not a finite number"):
        sim.write_actuators({"elbow_joint": float("nan")})
    sim.write_actuators({"left_finger_joint": 0.5})  # beyond the 19 mm stroke: clipped
    sim.advance(1.0)
    assert sim.joint_positions()["left_finger_joint"] == pytest.approx(0.019, abs=1e-4)


def test_snapshot_and_restore_give_identical_futures(sim):
    sim.write_actuators({"shoulder_pan_joint": 1.0})
    sim.advance(0.3)
    snap = sim.get_state()
    sim.advance(0.5)
    first = sim.joint_positions()
    sim.set_state(snap)
    sim.advance(0.5)
    assert sim.joint_positions() == first


def test_brick_is_picked_and_placed_by_a_scripted_sequence(example_tree):
    from conftest import EXAMPLES

    project = load_checked([EXAMPLES / "ur5e"])
    cell = FlexCell.from_mapping(project.elements(Mapping)[0], [Brick("brick1", (8, 10))])
    sim = PlatformSimulator(example_tree, cell)
    tool = ik.find_tool(example_tree)
    half = cell.bricks[0].size[2] / 2

    def move(point, fingers, seconds=1.5):
        start = sim.joint_positions()
        solution = ik.solve(example_tree, np.asarray(point), current=start)
        assert solution.ok()
        goal = {**solution.q, **{f: fingers for f in tool.fingers}}
        steps = int(seconds / 0.01)
        for k in range(1, steps + 1):
            a = k / steps
            s = a * a * (3 - 2 * a)
            sim.write_actuators({j: start[j] + s * (goal[j] - start[j]) for j in goal})
            sim.advance(0.01)
        sim.advance(0.3)

    source, target = np.array(cell.hole(8, 10)), np.array(cell.hole(2, 14))
    move(source + [0, 0, 0.15], 0.019, 2.0)
    move(source + [0, 0, half], 0.019)
    move(source + [0, 0, half], 0.0, 0.5)  # close
    move(source + [0, 0, 0.2], 0.0)
    lifted = sim.body_pose("brick1")[:3, 3]
    assert lifted[2] > 0.15  # a closed gripper lifts the brick
    move(target + [0, 0, 0.2], 0.0)
    move(target + [0, 0, half + 0.003], 0.0)
    move(target + [0, 0, half + 0.003], 0.019, 0.5)  # open
    move(target + [0, 0, 0.2], 0.019)
    placed = sim.body_pose("brick1")[:3, 3]
    assert np.hypot(*(placed[:2] - target[:2])) < 0.005  # within 5 mm of the target hole
    assert placed[2] == pytest.approx(half, abs=0.005)  # an open gripper let it go: it rests on the plate


def test_flexcell_grid_matches_the_published_mapping_constants():
    from cotwin.robosim.check import load_checked as load

    project = load([_published("ur5e")])
    cell = FlexCell.from_mapping(project.elements(Mapping)[0])
    assert (cell.xmax, cell.ymax, cell.hole_dist) == (15, 23, 0.05)
    assert cell.hole(0, 23, 1) == pytest.approx((-0.072, 0.711, 0.07))
    model = mujoco.MjModel.from_xml_string(to_mjcf(_tree(_published("ur5e")), cell))
    assert sum(model.geom(i).name.startswith("hole_") for i in range(model.ngeom)) == 16 * 24


def test_unreachable_target_is_reported_by_ik(example_tree):
    result = ik.solve(example_tree, np.array([1.5, 0.0, 0.2]))
    assert not result.ok() and result.position_error > 0.3
