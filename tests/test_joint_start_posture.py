"""A joint whose limits exclude 0 starts at the limit nearest 0 (TJoint.start): the simulator must put its
link there, not only report that angle. The Go1's calves (limits [-2.818, -0.888] in example-robot-data's
URDF) used to read -0.888 while their links hung straight (MuJoCo's reference configuration moved instead
of the joint): every calf angle was off by 0.888 rad, and a free base stood on the floor by the bent-knee
posture started with its feet 7 cm in the ground and was thrown 2 m up."""

from __future__ import annotations

import numpy as np
import pytest

from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.robosim.check import load_checked
from test_urdf_import import robot_data


@pytest.fixture(scope="module")
def go1(tmp_path_factory):
    urdf = robot_data() / "robots/go1_description/urdf/go1.urdf"
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    result = import_urdf(urdf, tmp_path_factory.mktemp("go1"), check=False)
    return build_tree(load_checked([result.file]))


def test_a_joint_started_at_a_limit_has_its_link_where_its_angle_says(go1):
    start = go1.start_posture
    assert start["FR_calf_joint"] == pytest.approx(-0.888)  # the case this test is about
    sim = PlatformSimulator(go1)
    assert sim.joint_positions()["FR_calf_joint"] == pytest.approx(-0.888)
    links = go1.forward(start)
    for foot in ("FR_foot", "FL_foot", "RR_foot", "RL_foot"):
        expected = links[foot][:3, 3] - links["trunk"][:3, 3]
        found = sim.data.xpos[sim.model.body(foot).id] - sim.data.xpos[sim.model.body("trunk").id]
        assert np.allclose(found, expected, atol=1e-6), (foot, found, expected)


def test_a_free_base_stood_on_the_floor_at_its_start_posture_stays_on_it(go1):
    from cotwin.pmodel.world import World

    sim = PlatformSimulator(go1, World(name="floor"), base="free")
    heights = []
    for _ in range(50):  # 0.5 s, the servos holding the start posture
        sim.step(10)
        heights.append(float(sim.data.xpos[sim.model.body("trunk").id][2]))
    assert max(heights) < 0.5  # it stood at 0.38 m; thrown up, it passed 2 m
