"""RTDE logs: reading with located errors, the UR-to-p-model convention, motion onsets."""

from __future__ import annotations

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.motion import JointMove
from cotwin.mapping.profile import read_profile
from cotwin.mapping.rtde import read_arm_log, read_rtde, write_rtde
from cotwin.pmodel import ik
from cotwin.pmodel.tree import build_tree
from cotwin.robosim.check import load_checked

RUN1 = "ur5e/rtde_run1.csv"


@pytest.fixture(scope="module")
def tree():
    from conftest import EXAMPLES

    return build_tree(load_checked([EXAMPLES / "ur5e"]))


def _run1():
    from conftest import ROOT

    path = ROOT.parent / "shared" / "data" / RUN1
    if not path.is_file():
        pytest.skip(f"the recorded UR5e run is not at {path} (only in the project workspace)")
    return path


def _synthetic(tree, path, onsets, goals, start, rate=10.0, end=None):
    """A 10 Hz log of movej moves (set-point = measurement) starting at the given times."""
    profile = JointMove(a=1.4, v=1.05)
    names = [j.name for j in tree.actuated][:6]
    segments, q = [], np.array(start, float)
    for onset, goal in zip(onsets, goals):
        segment = profile.plan(tree, dict(zip(names, q)), dict(zip(names, goal)), onset)
        segments.append(segment)
        q = np.array(goal, float)
    t = np.arange(0.0, end or segments[-1].end + 2.0, 1.0 / rate)

    def at(x):
        active = [s for s in segments if s.t0 <= x] or [None]
        s = active[-1]
        return np.array(start, float) if s is None else np.array([s.at(x)[n] for n in names])

    qs = np.array([at(x) for x in t])
    qd = np.array([(at(x + 1e-4) - at(x - 1e-4)) / 2e-4 for x in t])
    return write_rtde(path, 1000.0 + t, qs, qd, qs, qd)


def test_motion_onsets_and_settling_are_found_between_samples(tree, tmp_path):
    onsets = [1.234, 6.05, 9.5]
    goals = [[0.5, 0.3, 1.2, -0.4, -1.5, 0.1], [-0.5, 0.4, 1.0, -0.5, -1.4, 0.3], [-0.45, 0.4, 1.0, -0.5, -1.4, 0.3]]
    log = read_arm_log(_synthetic(tree, tmp_path / "s.csv", onsets, goals, [0.0, 0.2, 1.3, -0.3, -1.6, 0.0]))
    motions = log.motions()
    assert len(motions) == 3
    for m, onset, goal in zip(motions, onsets, goals):
        assert m.onset == pytest.approx(onset, abs=1e-3)  # both first samples on the acceleration ramp
        assert np.allclose(m.end_q, goal, atol=1e-9)
        assert m.settled >= onset + JointMove().duration(np.abs(np.array(goal) - m.start_q).max()) - 1e-9
        assert m.settled - (onset + JointMove().duration(np.abs(np.array(goal) - m.start_q).max())) <= 0.1 + 1e-9


def test_angles_and_poses_are_converted_to_the_p_models_convention(tree, tmp_path):
    from conftest import EXAMPLES

    ur = read_profile(EXAMPLES / "ur5e" / "ur.profile.toml", 6)  # the UR controller's conventions
    q = np.array([[0.1, 0.2, 0.3, 0.4, 0.5, 0.6], [0.1, 0.2, 0.3, 0.4, 0.5, 0.7]])
    tool = ik.find_tool(tree, "flange")
    poses = [ik.tool_pose(tree, tool, dict(zip(ik.arm_joints(tree, tool), row))) for row in q]
    path = write_rtde(tmp_path / "c.csv", [0.0, 0.1], q, tcp=poses, convention=ur)
    header = path.read_text().split("\n")[0].split()
    first = dict(zip(header, map(float, path.read_text().split("\n")[1].split())))
    assert first["actual_q_1"] == pytest.approx(0.2 - np.pi / 2) and first["actual_q_3"] == pytest.approx(0.4 - np.pi / 2)
    assert first["actual_TCP_pose_0"] == pytest.approx(-poses[0][0, 3])  # the UR base is turned by pi
    log = read_arm_log(path, ur)
    assert np.allclose(log.q, q) and np.allclose(log.tcp, poses)
    assert np.allclose(log.qd[0], [0, 0, 0, 0, 0, 1.0])  # differentiated when the log has no speeds


def test_the_recorded_ur5e_run_reads_with_four_moves_and_a_consistent_convention(tree):
    from conftest import EXAMPLES

    ur = read_profile(EXAMPLES / "ur5e" / "ur.profile.toml", 6)  # the UR controller's conventions
    log = read_arm_log(_run1(), ur)
    assert len(log.t) == 241 and log.t[-1] == pytest.approx(24.0)
    motions = log.motions()
    assert len(motions) == 4
    assert [round(m.onset) for m in motions] == [2, 9, 12, 20]
    # the controller's own forward kinematics (its TCP pose, in the log) against the p-model's flange at the
    # measured joints: the cell's tool is 32 mm long along the flange's z axis, so the TCP seen from the
    # p-model's flange is (0, 0, 0.032) in every posture; 5 mm is what the p-model's nominal link lengths
    # leave against the robot's factory-calibrated ones (a joint convention off by 0.05 rad moves it more)
    tool = ik.find_tool(tree, "flange")
    arm = ik.arm_joints(tree, tool)
    for row in range(0, 241, 10):
        flange = ik.tool_pose(tree, tool, dict(zip(arm, log.q[row])))
        tcp = log.tcp[row]
        seen = (np.linalg.inv(flange) @ tcp)[:3, 3]
        assert np.linalg.norm(seen - [0.0, 0.0, 0.032]) < 0.005, (row, seen)
        assert np.degrees(np.arccos(np.clip((np.trace(flange[:3, :3].T @ tcp[:3, :3]) - 1) / 2, -1, 1))) < 1.0
    assert ur.to_controller(log.q)[0] == pytest.approx(
        [log.raw.column(f"actual_q_{i}")[0] for i in range(6)])


HEADER = "timestamp " + " ".join(f"actual_q_{i}" for i in range(6))


@pytest.mark.parametrize("text, where, message", [
    (HEADER + "\n0.0 0 0 0 0 0 0\n0.1 0 0 zero 0 0 0\n", "x.csv:3:9:", "column 'actual_q_2': 'zero' is not a finite number"),
    (HEADER + "\n0.0 0 0 0 0 0 0\n0.1 0 0 0 0 0 nan\n", "x.csv:3:15:", "'nan' is not a finite number"),
    ("timestamp actual_q_0 actual_q_1\n0 0 0\n0.1 0 0\n", "x.csv:1:1:", "the log has no column(s) actual_q_2"),
    ("timestamp,actual_q_0,actual_q_1\n", "x.csv:1:1:", "is the file space-separated?"),
    (HEADER + "\n0.0 0 0 0 0 0 0\n0.1 0 0 0 0 0\n", "x.csv:3:14:", "6 values for 7 columns"),
    (HEADER + "\n0.0 0 0 0 0 0 0\n0.0 0 0 0 0 0 0\n", "x.csv:3:1:", "timestamps must increase: 0.0 after 0.0"),
    (HEADER + " actual_q_0\n", "x.csv:1:", "column 'actual_q_0' appears twice"),
    ("\n\n", "x.csv:1:1:", "the log is empty"),
    (HEADER + "\n0.0 0 0 0 0 0 0\n", "x.csv:", "the log has 1 sample(s)"),
])
def test_bad_logs_are_reported_at_their_place(tmp_path, text, where, message):
    path = tmp_path / "x.csv"
    path.write_text(text)
    with pytest.raises(CotwinError) as err:
        read_arm_log(path)
    assert where in str(err.value) and message in str(err.value)


def test_a_five_megabyte_field_is_reported_not_parsed(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text(HEADER + "\n0.0 0 0 0 0 0 0\n0.1 0 0 " + "1" * 5_000_000 + " 0 0 0\n")
    with pytest.raises(CotwinError) as err:
        read_arm_log(path)
    assert "x.csv:3:9: error: column 'actual_q_2': a field of 5000000 characters is not a number" in str(err.value)
    assert len(str(err.value)) < 500


def test_a_live_log_needs_speeds_an_arm_log_does_not(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text(HEADER + "\n0.0 0 0 0 0 0 0\n0.1 0 0 0 0 0 0.1\n")
    with pytest.raises(CotwinError, match=r"x.csv:1:1: error: the log has no column\(s\) actual_qd_0"):
        read_rtde(path)
    assert read_arm_log(path).qd[:, 5] == pytest.approx([1.0, 1.0])


def test_undecodable_bytes_are_reported(tmp_path):
    path = tmp_path / "x.csv"
    path.write_bytes(HEADER.encode() + b"\n0.0 0 0 \xff\xfe 0 0 0\n")
    with pytest.raises(CotwinError, match=r"x.csv:2:\d+: error: the log is not UTF-8"):
        read_arm_log(path)


def test_a_vector_field_with_some_of_its_columns_is_refused_not_read_as_absent(tmp_path):
    """A log holding target_q_0..2, 4, 5 but not target_q_3 was read as a log without set-points: calibrate
    fitted the motion profile to the measured joints instead, without a word. Missing actual_q_3 is said once."""
    targets = " ".join(f"target_q_{i}" for i in (0, 1, 2, 4, 5))
    path = tmp_path / "x.csv"
    path.write_text(f"{HEADER} {targets}\n" + "".join(f"{t / 10} 0 0 0 0 0 0 0 0 0 0 0\n" for t in range(3)))
    with pytest.raises(CotwinError) as err:
        read_arm_log(path)
    assert str(err.value) == (f"{path}:1:{len(HEADER) + 2}: error: the field target_q lacks column(s) target_q_3: a "
                              "vector read by cotwin has all of target_q_0..target_q_5, or none")
    path.write_text(HEADER.replace(" actual_q_3", "") + "\n0 0 0 0 0 0\n0.1 0 0 0 0 0\n")
    with pytest.raises(CotwinError) as err:
        read_arm_log(path)
    assert str(err.value).count("actual_q_3") == 1
