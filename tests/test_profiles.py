"""Robot profiles (cotwin.mapping.profile): a project names a TOML file holding a controller's joint
offsets and base frame; the core's default is the identity, with a warning that no profile was named."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.profile import IDENTITY, read_profile, robot_convention
from cotwin.mapping.rtde import read_arm_log, write_rtde

# a made-up controller: every joint's zero a different fraction of a turn away, its base a quarter turn
# about z and 0.5 m up from the model frame
OFFSETS = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6]
BASE = [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.5], [0.0, 0.0, 0.0, 1.0]]
PROFILE = f'name = "made-up arm"\njoint_offsets = {OFFSETS}\nbase = {BASE}\n'


def _log(tmp_path, q_controller, tcp_controller=None):
    """An RTDE log written as the controller would: its own angles (and TCP poses) in the columns."""
    q = np.asarray(q_controller, float)
    return write_rtde(tmp_path / "log.csv", [0.0, 0.1], q, tcp=tcp_controller)


def test_a_profile_read_and_applied_gives_the_model_angles_and_frame(tmp_path):
    path = tmp_path / "arm.profile.toml"
    path.write_text(PROFILE)
    profile = read_profile(path, 6)
    controller = np.array([[1.0, 1.0, 1.0, 1.0, 1.0, 1.0], [0.0, 0.5, -0.5, 0.0, 2.0, -2.0]])
    tcp = np.array([np.eye(4), np.eye(4)])
    tcp[:, :3, 3] = (0.3, 0.0, 0.0)  # a TCP 0.3 m along the controller's x
    log = read_arm_log(_log(tmp_path, controller, tcp), profile)
    assert np.allclose(log.q, controller - OFFSETS, atol=1e-12)  # model angle = controller angle - offset
    assert np.allclose(log.tcp[0][:3, 3], (0.0, 0.3, 0.5), atol=1e-12)  # the controller's x is the model's y, 0.5 up
    assert np.allclose(profile.to_controller(log.q), controller, atol=1e-12)  # and back
    assert profile.name == "made-up arm"


def test_the_ur5e_example_carries_the_ur_convention():
    from conftest import EXAMPLES

    ur = read_profile(EXAMPLES / "ur5e" / "ur.profile.toml", 6)
    assert ur.to_model([0.0] * 6) == pytest.approx([0, math.pi / 2, 0, math.pi / 2, 0, 0], abs=0)
    assert np.allclose(np.asarray(ur.base)[:3, :3], np.diag([-1.0, -1.0, 1.0]))


@pytest.mark.parametrize("text, key, message", [
    (PROFILE + "offsets = [0.0]\n", "offsets", "unknown key of a robot profile"),
    ("joint_offsets = [0.0, 0.1]\n", "joint_offsets", "2 offsets for an arm of 6 joints"),
    ("joint_offsets = [0.0, 0.1, nan, 0.0, 0.0, 0.0]\n", "joint_offsets", "list of finite numbers"),
    ("joint_offsets = [0.0, 0.1, 0.2, 0.0, 0.0, 0.0]\nbase = [[1.0, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0], "
     "[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]\n", "base", "not a rigid transform"),
    ("joint_offsets = [0.0, 0.1, 0.2, 0.0, 0.0, 0.0]\nbase = [[-1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], "
     "[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]\n", "base", "determinant 1"),  # a mirror is not rigid
    ("joint_offsets = [0.0, 0.1, 0.2, 0.0, 0.0, 0.0]\nbase = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\n", "base", "4x4"),
    ("joint_offsets = [0.0, 0.1, 0.2, 0.0, 0.0, 0.0]\nbase = [[1.0, 0.0, 0.0, inf], [0.0, 1.0, 0.0, 0.0], "
     "[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]\n", "base", "finite numbers"),
])
def test_a_bad_profile_is_an_error_at_its_key(tmp_path, text, key, message):
    path = tmp_path / "bad.profile.toml"
    path.write_text(text)
    line = next(n for n, row in enumerate(text.splitlines(), 1) if row.startswith(f"{key} ="))
    with pytest.raises(CotwinError) as err:
        read_profile(path, 6)
    [finding] = err.value.findings
    assert message in finding.message and finding.message.startswith(key)
    assert (finding.location.path, finding.location.line) == (str(path), line)


def test_no_profile_means_the_identity_and_a_warning(tmp_path, caplog):
    controller = np.array([[1.0, 1.0, 1.0, 1.0, 1.0, 1.0], [0.0, 0.5, -0.5, 0.0, 2.0, -2.0]])
    with caplog.at_level(logging.WARNING, logger="cotwin.twin"):
        convention = robot_convention(None, 6)
    assert convention is IDENTITY
    assert [r.message for r in caplog.records if "no robot profile" in r.message], caplog.text
    log = read_arm_log(_log(tmp_path, controller), convention)
    assert np.array_equal(log.q, controller)


@pytest.fixture
def replay_project(tmp_path):
    """The UR5e replay example copied elsewhere, replaying a log of our own (written as a made-up
    controller reports), with the [robot] table as the test writes it."""
    import shutil

    from conftest import EXAMPLES

    folder = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", folder)
    controller = np.array([[0.1, -1.2, 1.3, -1.6, -1.5, 0.2], [0.1, -1.2, 1.3, -1.6, -1.5, 0.25]])
    write_rtde(folder / "made-up.csv", [0.0, 0.1], controller, qd=np.zeros_like(controller))
    (folder / "arm.profile.toml").write_text(PROFILE)
    text = (folder / "replay.toml").read_text()
    text = text.replace('log = "../../../shared/data/ur5e/rtde_run1.csv"', 'log = "made-up.csv"')
    start = text.index("[robot]")
    text = text[:start] + text[text.index("[cosim]"):]

    def project(robot: str):
        (folder / "replay.toml").write_text(text.replace("[cosim]", robot + "[cosim]"))
        return folder / "replay.toml"

    return project, controller


def test_the_replay_pt_reads_the_log_through_the_projects_profile(replay_project, caplog):
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import pt_endpoint

    project, controller = replay_project
    with caplog.at_level(logging.WARNING, logger="cotwin.twin"):
        replayed = pt_endpoint(load(project('[robot]\nprofile = "arm.profile.toml"\n\n')))
    assert np.allclose(replayed.recording.q, controller - OFFSETS, atol=1e-12)
    assert not [r for r in caplog.records if "no robot profile" in r.message]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="cotwin.twin"):
        replayed = pt_endpoint(load(project("")))
    assert np.array_equal(replayed.recording.q, controller)  # no profile: the identity
    assert len([r for r in caplog.records if "no robot profile" in r.message]) == 1  # said once


def test_the_no_profile_warning_names_the_project_file_and_its_robot_table(replay_project, caplog):
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import pt_endpoint

    project, _ = replay_project
    for robot in ("", "[robot]\n\n"):
        path = project(robot)
        line = next((n for n, row in enumerate(path.read_text().splitlines(), 1) if row == "[robot]"), 1)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="cotwin.twin"):
            pt_endpoint(load(path))
        [said] = [r.getMessage() for r in caplog.records if "no robot profile" in r.getMessage()]
        assert said.startswith(f"{path}:{line}:1: no robot profile named ([robot] profile)"), said


def test_a_project_naming_a_missing_or_mismatched_profile_is_refused_at_its_key(replay_project, tmp_path):
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import pt_endpoint

    project, _ = replay_project
    with pytest.raises(CotwinError, match=r"replay.toml:\d+:1: error: \[robot\] profile: no file .*nowhere.toml"):
        load(project('[robot]\nprofile = "nowhere.toml"\n\n'))
    short = tmp_path / "ur5e" / "short.profile.toml"
    short.write_text("joint_offsets = [0.0, 0.1, 0.2]\n")
    with pytest.raises(CotwinError, match=r"short.profile.toml:1:1: error: joint_offsets: 3 offsets for an arm of 6"):
        pt_endpoint(load(project('[robot]\nprofile = "short.profile.toml"\n\n')))
