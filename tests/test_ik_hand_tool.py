"""The IK's default tool on robots whose arm ends in a hand or in fixed fingers, as a new user imports them from
example-robot-data. Found: the Kinova Jaco2's default tool was one fixed fingertip (`j2s6s200_link_finger_tip_2`):
the IK "reached" every target with the hand lying on its side, one fingertip at the target and the other 11 cm
away; TIAGo's was the tip of its little finger, so the finger's 7 joints were taken as the arm's last. The tool is
now the link carrying the fingers, its approach axis towards them; an arm ending in a flange and tool frames (the
UR5's tool0) and a humanoid's torso (its arms are no fingers) are not taken for a hand."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from cotwin.cli import main
from cotwin.pmodel import ik
from cotwin.pmodel.grippers import gripper_links
from cotwin.pmodel.tree import build_tree
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.robosim.check import load_checked
from test_urdf_import import robot_data

KINOVA = "robots/kinova_description/robots/kinova.urdf"
TIAGO = "robots/tiago_description/robots/tiago.urdf"
UR5 = "robots/ur_description/urdf/ur5_gripper.urdf"  # its tool0 a body beside ee_link
HUMANOID = "robots/simple_humanoid_description/urdf/simple_humanoid_classical.urdf"


def _tree(path: str, tmp_path_factory):
    urdf = robot_data() / path
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    result = import_urdf(urdf, tmp_path_factory.mktemp(urdf.stem), check=False)
    return build_tree(load_checked([result.file]))


@pytest.fixture(scope="module")
def kinova(tmp_path_factory):
    return _tree(KINOVA, tmp_path_factory)


def test_the_kinova_tool_is_its_hand_not_a_fingertip(kinova):
    tool = ik.find_tool(kinova)
    assert tool.link == "j2s6s200_link_6"
    assert ik.arm_joints(kinova, tool) == [f"j2s6s200_joint_{i}" for i in range(1, 7)]


def test_the_kinova_reaches_a_target_with_both_fingertips_astride_it_pointing_down(kinova):
    tool = ik.find_tool(kinova)
    target = np.eye(4)
    target[:3, :3] = ik.DOWN
    target[:3, 3] = (0.45, 0.1, 0.1)
    reference = dict(zip(ik.arm_joints(kinova, tool), [1.5707, 2.618, 1.5707, 3.1415, 2.618, 0.0]))
    result = ik.solve(kinova, target, tool=tool, reference=reference)
    assert result.ok()
    frames = kinova.forward(result.q)
    tips = [frames[f"j2s6s200_link_finger_tip_{i}"][:3, 3] for i in (1, 2)]
    hand = frames["j2s6s200_end_effector"][:3, 3]
    assert np.allclose(np.mean(tips, axis=0)[:2], target[:2, 3], atol=0.005)  # astride the target
    assert min(t[2] for t in tips) > target[2, 3] - 1e-6  # the fingers end at the target, not through it
    assert hand[2] > target[2, 3] and abs(hand[0] - target[0, 3]) < 0.01  # the hand above, pointing down


def test_tiagos_arm_ends_at_its_palm_not_a_finger(tmp_path_factory):
    tree = _tree(TIAGO, tmp_path_factory)
    tool = ik.find_tool(tree)
    assert tool.link == "hand_palm_link"
    assert ik.arm_joints(tree, tool) == ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]


@pytest.mark.parametrize("path, link", [(UR5, "tool0"), (HUMANOID, "l_wrist")])
def test_a_flange_or_a_torso_is_no_hand(path, link, tmp_path_factory):
    tree = _tree(path, tmp_path_factory)
    assert ik.find_tool(tree).link == link


def test_the_import_says_the_tool_is_the_hand_and_what_it_carries(tmp_path):
    urdf = robot_data() / KINOVA
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    run = CliRunner().invoke(main, ["import-urdf", str(urdf), "-o", str(tmp_path / "kinova")])
    assert run.exit_code == 0, run.output
    assert ("inverse_kinematics: tool link j2s6s200_link_6 (the hand at the end of the longest chain of moving joints, "
            "carrying j2s6s200_joint_end_effector, j2s6s200_joint_finger_1, j2s6s200_joint_finger_2), arm joints "
            "j2s6s200_joint_1,") in run.output


def test_continuous_wrist_joints_take_the_short_way_between_neighbouring_holes(kinova):
    """The Kinova's joints 4 and 6 are continuous. Bounded to one turn by the IK, joint 4 (near pi at these holes)
    unwound a full turn between two holes 25 cm apart, and joint 6, the tool roll, put on the turn nearest the
    reference, swung 5.9 rad: 14 s per move at 0.63 rad/s. Unbounded and on the turn nearest the current angle,
    no joint turns more than the move needs."""
    tool = ik.find_tool(kinova)
    arm = ik.arm_joints(kinova, tool)
    solver = ik.Solver(kinova, tool, dict(zip(arm, [1.5707, 2.618, 1.5707, 3.1415, 2.618, 0.0])))
    first = solver.solve(np.array([0.51, 0.2, 0.1]))
    second = solver.solve(np.array([0.35, 0.0, 0.06]), first.q)
    assert first.ok() and second.ok()
    turned = {j: abs(second.q[j] - first.q[j]) for j in arm}
    assert max(turned.values()) < 1.0, turned


def test_a_mobile_bases_two_suspensions_are_no_gripper(tmp_path_factory):
    """TIAGo dual's base_link carries its two prismatic wheel suspensions: it was taken for the gripper, the IK's
    tool the base and its arm empty. A gripper is below a moving joint."""
    tree = _tree("robots/tiago_description/robots/tiago_dual.urdf", tmp_path_factory)
    assert "base_link" not in gripper_links(tree)
    tool = ik.find_tool(tree)
    assert tool.link == "hand_right_palm_link" and len(ik.arm_joints(tree, tool)) == 8


def test_the_import_names_the_other_hand_of_a_two_armed_robot(tmp_path):
    """TIAGo dual has a hand on each arm: the import said which the IK takes, not that there is another."""
    urdf = robot_data() / "robots/tiago_description/robots/tiago_dual.urdf"
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    run = CliRunner().invoke(main, ["import-urdf", str(urdf), "-o", str(tmp_path / "tiago_dual")])
    assert run.exit_code == 0, run.output
    assert "inverse_kinematics: tool link hand_right_palm_link (the hand " in run.output
    assert "; it is one of 2 hands (also hand_left_palm_link): to drive another arm" in run.output
