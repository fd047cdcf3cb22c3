"""The live UR robot endpoint (cotwin.mapping.urrtde.RTDEEndpoint) against stand-ins for ur-rtde's two
client classes, which record what the endpoint asks of the robot and answer as a UR controller does (in
the controller's joint convention). No robot, URSim or RTDE server runs here: ur-rtde's control
interface uploads a URScript program through the controller's secondary and dashboard ports and drives
it through RTDE registers, more of a controller than a test can stand in for honestly. What is tested is
cotwin's side: the convention both ways, the movej it sends, the pacing, the sensors, the errors."""

from __future__ import annotations

import sys
import time
import types

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.profile import read_profile
from cotwin.mapping.urrtde import RTDEEndpoint
from cotwin.pmodel import ik

CONTROLLER_Q = [0.1, -1.2, 1.3, -1.6, -1.5, 0.2]  # what the controller reports (UR convention)
CONTROLLER_QD = [0.0, 0.01, -0.02, 0.0, 0.0, 0.03]


class Controller:
    """What ur-rtde's RTDEReceiveInterface and RTDEControlInterface would talk to: one robot's state."""

    def __init__(self):
        self.q, self.qd = list(CONTROLLER_Q), list(CONTROLLER_QD)
        self.calls: list[tuple] = []
        self.hosts: list[str] = []
        self.reachable = True


@pytest.fixture
def robot(monkeypatch):
    controller = Controller()

    class Receive:
        def __init__(self, host):
            if not controller.reachable:
                raise RuntimeError("Timeout connecting to UR dashboard server.")
            controller.hosts.append(host)

        def getActualQ(self):
            return list(controller.q)

        def getActualQd(self):
            return list(controller.qd)

    class Control:
        def __init__(self, host):
            controller.hosts.append(host)

        def moveJ(self, q, speed, acceleration, asynchronous):
            controller.calls.append(("moveJ", list(q), speed, acceleration, asynchronous))
            return True

        def stopJ(self, acceleration):
            controller.calls.append(("stopJ", acceleration))

    monkeypatch.setitem(sys.modules, "rtde_receive", types.SimpleNamespace(RTDEReceiveInterface=Receive))
    monkeypatch.setitem(sys.modules, "rtde_control", types.SimpleNamespace(RTDEControlInterface=Control))
    return controller


@pytest.fixture(scope="module")
def ur():
    """The UR controller's profile the UR5e example carries."""
    from conftest import EXAMPLES

    return read_profile(EXAMPLES / "ur5e" / "ur.profile.toml", 6)


@pytest.fixture(scope="module")
def tree():
    from conftest import EXAMPLES
    from cotwin.pmodel.tree import build_tree
    from cotwin.robosim.check import load_checked

    return build_tree(load_checked([EXAMPLES / "ur5e"]))


def test_joints_read_in_the_p_models_convention(robot, tree, ur):
    endpoint = RTDEEndpoint(tree, "rtde://10.0.0.7:30004", convention=ur)
    assert robot.hosts == ["10.0.0.7", "10.0.0.7"]  # the scheme and port are not the host
    arm = ik.arm_joints(tree, ik.find_tool(tree))
    q = endpoint.joint_positions()
    assert list(q) == arm
    # the documented convention (interop.md): q_model = q_ur + (0, pi/2, 0, pi/2, 0, 0)
    assert np.allclose([q[j] for j in arm], np.array(CONTROLLER_Q) + [0, np.pi / 2, 0, np.pi / 2, 0, 0], atol=0)
    assert np.allclose([q[j] for j in arm], ur.to_model(np.array(CONTROLLER_Q)))  # logs read alike
    assert [endpoint.joint_velocities()[j] for j in arm] == CONTROLLER_QD
    sensors = endpoint.read_sensors()
    assert sensors and all(np.isfinite(v) for v in sensors.values())


def test_a_command_is_one_asynchronous_movej_in_the_controllers_convention(robot, tree, ur):
    endpoint = RTDEEndpoint(tree, "10.0.0.7", speed=0.5, acceleration=0.8, convention=ur)
    arm = ik.arm_joints(tree, ik.find_tool(tree))
    current = endpoint.joint_positions()
    goal = {arm[1]: current[arm[1]] + 0.3}
    endpoint.command(goal)
    [(call, q, speed, acceleration, asynchronous)] = robot.calls
    assert (call, speed, acceleration, asynchronous) == ("moveJ", 0.5, 0.8, True)  # the twin keeps stepping
    expected = list(CONTROLLER_Q)
    expected[1] += 0.3  # only the joint commanded moves; the others hold where the robot is
    assert np.allclose(q, expected, atol=1e-12)
    endpoint.stop()
    assert robot.calls[-1] == ("stopJ", 0.8)


def test_bad_goals_and_names_are_refused_before_the_robot_moves(robot, tree):
    endpoint = RTDEEndpoint(tree, "10.0.0.7")
    arm = ik.arm_joints(tree, ik.find_tool(tree))
    with pytest.raises(CotwinError, match="is not a finite number"):
        endpoint.command({arm[0]: float("nan")})
    with pytest.raises(CotwinError, match="the robot has no actuator 'M99'"):
        endpoint.command({"M99": 0.1})
    assert robot.calls == []
    robot.q[2] = float("inf")
    with pytest.raises(CotwinError, match="non-finite joint value"):
        endpoint.joint_positions()


def test_advance_keeps_to_the_robots_wall_clock(robot, tree):
    endpoint = RTDEEndpoint(tree, "10.0.0.7")
    endpoint.start()
    started = time.monotonic()
    for _ in range(5):
        endpoint.advance(0.05)
    assert time.monotonic() - started >= 0.25 - 1e-3 and endpoint.time == pytest.approx(0.25)


def test_an_unreachable_robot_or_a_missing_client_is_a_clear_error(robot, tree, monkeypatch):
    robot.reachable = False
    with pytest.raises(CotwinError, match="cannot reach the robot's RTDE interface at 10.0.0.9"):
        RTDEEndpoint(tree, "10.0.0.9")
    monkeypatch.setitem(sys.modules, "rtde_receive", None)  # not installed
    with pytest.raises(CotwinError, match=r"pip install 'cotwin\[rtde\]'"):
        RTDEEndpoint(tree, "10.0.0.9")
