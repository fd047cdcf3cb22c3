"""A [monitor] reading of a joint's sensor reads on the physical twin as on the digital twin: every platform names a
sensor port's reading by one function (cotwin.pmodel.tree.reading_path), the simulator, a replayed RTDE log and a
live UR robot alike. The arm here is the test's URDF import (tests/test_tool_link_project.py), whose sensors are
declared inside their joints: their path has the joint (`arm::base::joint1::joint1_position.output_position`), which
the replay and the RTDE endpoint left out, so such a reading ran on the DT and stopped the PT's first step."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from cotwin.mapping.replay import ReplayEndpoint, Recording
from cotwin.mapping.rtde import write_rtde
from cotwin.mapping.urrtde import RTDEEndpoint
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.twin.assembly.run import load
from cotwin.twin.live.runtime import LiveTwin

from test_tool_link_project import REFERENCE, _project

POSITION = "arm::base::joint1::joint1_position.output_position"
SPEED = "arm::l1::joint2::joint2_velocity.output_vel"


def _log(path, duration: float = 3.0):
    """A recorded run of the arm: joint1 turning at 0.2 rad/s from the reference posture, joint2 at -0.1 rad/s."""
    t = np.arange(0.0, duration, 0.01)
    qd = np.zeros((len(t), 6))
    qd[:, 0], qd[:, 1] = 0.2, -0.1
    q = np.array(REFERENCE, float) + qd * t[:, None]
    write_rtde(path, t, q, qd)
    return t, q


def test_every_live_endpoint_names_a_joints_sensor_as_the_simulator_does(tmp_path, ur_rtde):
    system = load(_project(tmp_path, REFERENCE))
    tree = system.models.tree
    simulated = set(PlatformSimulator(tree).read_sensors())
    joint_sensors = simulated  # every sensor of this arm is one of a joint's three, declared in the joint
    assert POSITION in joint_sensors and len(joint_sensors) == 3 * 7
    arm = [f"joint{k}" for k in range(1, 7)]
    t = np.array([0.0, 1.0])
    replayed = ReplayEndpoint(tree, Recording(t, np.zeros((2, 6)), np.zeros((2, 6)), arm, "log"), offset=0.0)
    live = RTDEEndpoint(tree, "10.0.0.7", arm=arm)
    assert set(replayed.read_sensors()) == joint_sensors
    assert set(live.read_sensors()) == joint_sensors


def test_a_joint_sensors_monitor_reading_has_values_on_the_replayed_pt_and_the_simulated_dt(tmp_path):
    project = _project(tmp_path, REFERENCE)
    t, q = _log(tmp_path / "run.csv")
    project.write_text(project.read_text() + '[pt]\nendpoint = "replay"\nlog = "run.csv"\noffset = 0.0\n'
                       f'[monitor]\nreadings = {{ a = "{POSITION}", w = "{SPEED}" }}\n')
    out = tmp_path / "out"
    result = LiveTwin(load(project), out, end=1.0).run()
    assert result.pt.steps == result.dt.steps == 10
    sides = {side: list(csv.DictReader(open(out / side / "outputs.csv"))) for side in ("pt", "dt")}
    for side, rows in sides.items():
        assert len(rows) == 11, side
        assert all(r["{mapping}.mapping.a"] not in ("", None) for r in rows), side
    pt = sides["pt"]
    for row in pt:  # the PT reads the log: joint1's angle and joint2's speed at the row's time
        time = float(row["time"])
        assert float(row["{mapping}.mapping.a"]) == pytest.approx(np.interp(time, t, q[:, 0]), abs=1e-9)
        assert float(row["{mapping}.mapping.w"]) == pytest.approx(-0.1, abs=1e-9)
    # the DT starts where the PT is and holds (nothing commands it): it reads its own joint, near the log's first
    assert float(sides["dt"][0]["{mapping}.mapping.a"]) == pytest.approx(q[0, 0], abs=1e-3)
