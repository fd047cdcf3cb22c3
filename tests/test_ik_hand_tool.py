"""The IK's default tool on robots whose arm ends in a hand or in fixed fingers, as a new user imports them from
example-robot-data. Found: the Kinova Jaco2's default tool was one fixed fingertip (`j2s6s200_link_finger_tip_2`):
the IK "reached" every target with the hand lying on its side, one fingertip at the target and the other 11 cm
away; TIAGo's was the tip of its little finger, so the finger's 7 joints were taken as the arm's last. The tool is
now the link carrying the fingers, its approach axis towards them; an arm ending in a flange and tool frames (the
UR5's tool0) and a humanoid's torso (its arms are no fingers) are not taken for a hand.
Found next: TIAGo's URDF declares where its hand grasps (hand_grasping_frame, fixed to the palm), the Kinova's its
end effector, the Panda's its TCP; the IK ignored them for the hand's own fingertip point (TIAGo's 7 cm beyond its
grasp point). A declared grasp frame on the hand is now the tool, the hand's approach kept."""

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
    assert (tool.link, tool.hand) == ("j2s6s200_end_effector", "j2s6s200_link_6")  # the frame declared on the hand
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
    hand = frames["j2s6s200_link_6"][:3, 3]
    assert np.allclose(frames["j2s6s200_end_effector"][:3, 3], target[:3, 3], atol=1e-6)  # its declared grasp point
    assert np.allclose(np.mean(tips, axis=0)[:2], target[:2, 3], atol=0.005)  # astride the target
    assert hand[2] > target[2, 3] + 0.1 and abs(hand[0] - target[0, 3]) < 0.01  # the hand above, pointing down


def test_tiagos_arm_ends_at_its_palm_not_a_finger(tmp_path_factory):
    tree = _tree(TIAGO, tmp_path_factory)
    tool = ik.find_tool(tree)
    assert (tool.link, tool.hand) == ("hand_grasping_frame", "hand_palm_link")
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
    assert ("inverse_kinematics: tool link j2s6s200_end_effector (the grasp frame the URDF declares on j2s6s200_link_6, "
            "the hand at the end of the longest chain of moving joints, "
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
    assert tool.hand == "hand_right_palm_link" and len(ik.arm_joints(tree, tool)) == 8


def test_the_import_names_the_other_hand_of_a_two_armed_robot(tmp_path):
    """TIAGo dual has a hand on each arm: the import said which the IK takes, not that there is another."""
    urdf = robot_data() / "robots/tiago_description/robots/tiago_dual.urdf"
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    run = CliRunner().invoke(main, ["import-urdf", str(urdf), "-o", str(tmp_path / "tiago_dual")])
    assert run.exit_code == 0, run.output
    assert ("inverse_kinematics: tool link hand_right_grasping_frame (the grasp frame the URDF declares on "
            "hand_right_palm_link, the hand ") in run.output
    assert "; it is one of 2 hands (also hand_left_palm_link): to drive another arm" in run.output


def test_a_grasp_frame_the_urdf_declares_on_the_hand_is_the_tool(tmp_path_factory):
    """TIAGo's hand_grasping_frame (fixed to the palm, 13 cm out) is where its URDF says the hand grasps: the IK puts
    that frame on the target, the hand's approach axis (its x, as PAL's frames say it) down."""
    tree = _tree(TIAGO, tmp_path_factory)
    tool = ik.find_tool(tree)
    assert (tool.link, tool.hand) == ("hand_grasping_frame", "hand_palm_link")
    assert np.allclose(tool.offset[:3, 3], 0.0) and np.allclose(tool.offset[:3, 2], (1.0, 0.0, 0.0))
    assert np.isclose(np.linalg.det(tool.offset[:3, :3]), 1.0)  # a frame, its roll the hand's (x near the palm's -z)
    target = np.eye(4)
    target[:3, :3] = ik.DOWN
    target[:3, 3] = (0.6, -0.2, 0.5)
    result = ik.solve(tree, target, tool=tool)
    assert result.ok()
    frames = tree.forward(result.q)
    assert np.allclose(frames["hand_grasping_frame"][:3, 3], target[:3, 3], atol=1e-6)
    assert frames["hand_palm_link"][2, 3] > target[2, 3] + 0.1  # the palm above its grasp point
    # the hand itself named: its own tool frame, as before
    assert ik.find_tool(tree, link="hand_palm_link").link == "hand_palm_link"


@pytest.mark.parametrize("name, said", [
    ("hand_grasping_frame", True), ("panda_hand_tcp", True), ("l_gripper_tool_frame", True), ("tool0", True),
    ("j2s6s200_end_effector", True), ("left_gripper", True), ("RightGraspFrame", True), ("ee_link", True),
    ("l_gripper_led_frame", False), ("l_gripper_motor_accelerometer_link", False), ("gripper_camera", False),
    ("toolbox", False), ("frame", False)])
def test_a_link_named_as_a_tool_point(name, said):
    assert ik.names_a_tool_point(name) is said


def test_the_pr2s_tool_frame_not_its_sensor_frames(tmp_path_factory):
    """The PR2's palm carries three bodiless frames: an LED's, an accelerometer's and its tool frame."""
    tree = _tree("robots/pr2_description/urdf/pr2.urdf", tmp_path_factory)
    assert ik.find_tool(tree).link == "l_gripper_tool_frame"


def test_the_import_says_the_tool_is_the_declared_grasp_frame(tmp_path, monkeypatch):
    """As a new user imports TIAGo, from another folder."""
    urdf = robot_data() / TIAGO
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    monkeypatch.chdir(tmp_path)
    run = CliRunner().invoke(main, ["import-urdf", str(urdf), "-o", "tiago"])
    assert run.exit_code == 0, run.output
    assert ("inverse_kinematics: tool link hand_grasping_frame (the grasp frame the URDF declares on hand_palm_link, "
            "the hand at the end of the longest chain of moving joints,") in run.output
