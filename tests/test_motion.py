"""Motion profiles: the default quintic and a UR controller's synchronised movej."""

from __future__ import annotations

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.config import Key, Schema, TomlFile, dumps, raise_problems
from cotwin.mapping.motion import MOTION, JointMove, Quintic, profile_from_values
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree
from cotwin.robosim.check import load_checked


@pytest.fixture(scope="module")
def tree():
    from conftest import EXAMPLES

    return build_tree(load_checked([EXAMPLES / "ur5e"]))


def _sampled(segment, joint, dt=1e-4):
    t = np.arange(segment.t0 - 0.1, segment.end + 0.1, dt)
    q = np.array([segment.at(x)[joint] for x in t])
    return t, q, np.gradient(q, dt), np.gradient(np.gradient(q, dt), dt)


def test_movej_has_a_trapezoidal_speed_for_the_leading_joint_and_all_joints_arrive_together(tree):
    profile = JointMove(a=1.4, v=1.05)
    start = {"shoulder_pan_joint": 0.0, "elbow_joint": 0.5, "wrist_1_joint": 1.0}
    goal = {"shoulder_pan_joint": -3.0, "elbow_joint": 1.5, "wrist_1_joint": 1.0}
    segment = profile.plan(tree, start, goal, t0=2.0)
    assert segment.t0 == 2.0
    assert segment.duration == pytest.approx(3.0 / 1.05 + 1.05 / 1.4)
    t, q, qd, qdd = _sampled(segment, "shoulder_pan_joint")
    assert np.abs(qd).max() == pytest.approx(1.05, rel=1e-3)  # cruise at v
    assert np.abs(qdd[np.abs(qdd) < 100]).max() == pytest.approx(1.4, rel=1e-2)  # ramps at a
    cruising = (t > 2.0 + 0.75 + 0.01) & (t < segment.end - 0.75 - 0.01)
    assert np.allclose(np.abs(qd[cruising]), 1.05, rtol=1e-6)
    # the others scaled: the same fraction of their way at every instant
    for x in np.linspace(1.9, segment.end + 0.1, 37):
        at = segment.at(x)
        s = (at["shoulder_pan_joint"] - 0.0) / -3.0
        assert (at["elbow_joint"] - 0.5) / 1.0 == pytest.approx(s, abs=1e-12)
        assert at["wrist_1_joint"] == 1.0
    assert segment.at(segment.end) == goal


def test_movej_is_triangular_when_v_cannot_be_reached(tree):
    profile = JointMove(a=1.4, v=1.05)
    segment = profile.plan(tree, {"shoulder_pan_joint": 0.0}, {"shoulder_pan_joint": 0.5}, t0=0.0)
    assert segment.duration == pytest.approx(2 * np.sqrt(0.5 / 1.4))
    _, _, qd, _ = _sampled(segment, "shoulder_pan_joint")
    assert qd.max() == pytest.approx(np.sqrt(1.4 * 0.5), rel=1e-3) and qd.max() < 1.05


def test_a_profile_delay_shifts_the_start_and_a_negative_one_leads(tree):
    start, goal = {"shoulder_pan_joint": 0.0}, {"shoulder_pan_joint": 1.0}
    late = JointMove(delay=0.25).plan(tree, start, goal, t0=1.0)
    early = JointMove(delay=-0.05).plan(tree, start, goal, t0=1.0)
    plain = JointMove().plan(tree, start, goal, t0=1.0)
    assert late.at(1.2)["shoulder_pan_joint"] == 0.0
    assert late.at(1.25 + 0.3)["shoulder_pan_joint"] == pytest.approx(plain.at(1.3)["shoulder_pan_joint"])
    assert early.at(1.0)["shoulder_pan_joint"] == pytest.approx(plain.at(1.05)["shoulder_pan_joint"])
    assert early.at(1.0)["shoulder_pan_joint"] > 0


def test_quintic_keeps_each_joint_within_its_velocity_limit(tree):
    limits = {j.name: j.velocity for j in tree.actuated}
    segment = Quintic().plan(tree, {"shoulder_pan_joint": 0.0, "wrist_3_joint": 0.0},
                             {"shoulder_pan_joint": 2.0, "wrist_3_joint": 0.3}, t0=0.0)
    _, _, qd, _ = _sampled(segment, "shoulder_pan_joint")
    assert np.abs(qd).max() == pytest.approx(limits["shoulder_pan_joint"], rel=1e-3)


def test_the_simulated_endpoint_follows_the_profile_it_is_given(tree):
    sim = PlatformSimulator(tree)
    endpoint = SimulatedEndpoint(sim, JointMove(a=1.4, v=1.05))
    endpoint.start()
    endpoint.command({"shoulder_pan_joint": 1.2})
    expected = JointMove(a=1.4, v=1.05).duration(1.2)
    endpoint.advance(expected / 2)
    assert sim.joint_positions()["shoulder_pan_joint"] == pytest.approx(0.6, abs=0.07)  # halfway, minus servo lag
    endpoint.advance(expected / 2 + 0.5)
    assert sim.joint_positions()["shoulder_pan_joint"] == pytest.approx(1.2, abs=1e-3)
    assert isinstance(SimulatedEndpoint(PlatformSimulator(tree)).profile, Quintic)  # the default


def _read_motion(path):
    file = TomlFile(path)
    problems = []
    values = Schema({"motion": Key("table", table=MOTION)}).read(file.data, file, (), problems)
    profile = profile_from_values(values["motion"], file, problems)
    raise_problems(problems)
    return profile


@pytest.mark.parametrize("text, message", [
    ("[motion]\nprofile = \"movel\"\n", "x.toml:2:1: error: [motion] profile must be one of 'quintic', 'movej'"),
    ("[motion]\nprofile = \"movej\"\na = -1\n", "x.toml:3:1: error: [motion] a must be a positive number"),
    ("[motion]\nprofile = \"movej\"\nv = \"fast\"\n", "x.toml:3:1: error: [motion] v must be a positive number"),
    ("[motion]\nprofile = \"quintic\"\na = 1.4\n", "x.toml:3:1: error: [motion] a applies to profile 'movej' only"),
    ("[motion]\nspeed = 1\n", "x.toml:2:1: error: unknown key 'speed' in [motion]"),
])
def test_bad_motion_tables_are_reported_at_their_place(tmp_path, text, message):
    path = tmp_path / "x.toml"
    path.write_text(text)
    with pytest.raises(CotwinError) as err:
        _read_motion(path)
    assert message in str(err.value)


def test_motion_tables_read_what_they_write(tmp_path):
    for profile in (JointMove(1.3, 0.9, -0.04), Quintic(0.1)):
        path = tmp_path / "m.toml"
        path.write_text(dumps({"motion": profile.tables()}))
        assert _read_motion(path) == profile


def test_a_movej_in_flight_is_saved_and_restored_with_the_endpoint(tree):
    first = SimulatedEndpoint(PlatformSimulator(tree), JointMove(a=1.4, v=1.05, delay=-0.05))
    first.start()
    first.command({"shoulder_pan_joint": 1.2, "elbow_joint": 0.4})
    first.advance(0.7)
    saved = first.snapshot()
    first.advance(1.0)
    second = SimulatedEndpoint(PlatformSimulator(tree), JointMove(a=1.4, v=1.05, delay=-0.05))
    second.restore(saved)
    second.advance(1.0)
    assert second.segment == first.segment and second.joint_positions() == first.joint_positions()
