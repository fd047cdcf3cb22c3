"""A mapping commands an actuator by one name on every platform: the simulator (the DT), a replayed log and a live UR
over RTDE (a PT) take the names cotwin.pmodel.tree.actuator_names gives, whose path ends in the actuator's own
command port (cotwin.pmodel.tree.command_path): `...::spin_motor.speed` for a SpeedControlMotor. The replay and the
RTDE endpoint built the path by hand with `.dangle`, a ServoMotor's port: a speed- or effort-driven actuator the
simulator took by its path was unknown on the PT (and its `.dangle` name, unknown on the DT, was taken there). A UR
over RTDE takes joint positions only: it refuses a speed or an effort actuator by name, at its p-model joint.

The robot is the test's: a URDF imported by cotwin (every joint gets a ServoMotor), then edited as a user would,
its wheel driven by a SpeedControlMotor and its press by a TorqueControlMotor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.replay import ReplayEndpoint, Recording
from cotwin.mapping.urrtde import RTDEEndpoint
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree, command_path
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.robosim.check import load_checked

# joint, type, parent, child, origin, axis: a lift (position servo), a wheel (speed), a press (effort)
JOINTS = [("lift", "revolute", "base", "arm", "0 0 0.1", "0 0 1"),
          ("spin", "continuous", "arm", "wheel", "0.2 0 0", "0 1 0"),
          ("press", "revolute", "arm", "finger", "0 0 0.1", "1 0 0")]
POSITION = "bot::base::lift::lift_motor.dangle"
SPEED = "bot::arm::spin::spin_motor.speed"
EFFORT = "bot::arm::press::press_motor.TorqueIn"


def _urdf() -> str:
    text = ['<?xml version="1.0"?>', '<robot name="bot">']
    for name in ("base", "arm", "wheel", "finger"):
        text.append(f'<link name="{name}"><inertial><mass value="0.5"/>'
                    '<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>'
                    '<collision><geometry><sphere radius="0.02"/></geometry></collision></link>')
    for name, kind, parent, child, xyz, axis in JOINTS:
        limit = '<limit effort="30" velocity="3"/>' if kind == "continuous" else \
            '<limit lower="-2" upper="2" effort="30" velocity="3"/>'
        text.append(f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                    f'<origin xyz="{xyz}"/><axis xyz="{axis}"/>{limit}</joint>')
    text.append("</robot>")
    return "\n".join(text)


def _tree(folder: Path):
    """The robot's kinematic tree, and the p-model file it was read from."""
    (folder / "bot.urdf").write_text(_urdf())
    import_urdf(folder / "bot.urdf", folder, check=False)
    pmodel = folder / "bot.pm"
    text = pmodel.read_text()
    for old, new in (("aref spin_motor = ServoMotor { relation spin.tau == spin_motor.T }",
                      "aref spin_motor = SpeedControlMotor { relation spin.tau == spin_motor.T }"),
                     ("aref press_motor = ServoMotor { relation press.tau == press_motor.T }",
                      "aref press_motor = TorqueControlMotor { relation press.tau == press_motor.TorqueOut }")):
        assert old in text
        text = text.replace(old, new)
    pmodel.write_text(text)
    return build_tree(load_checked([pmodel])), pmodel


def test_the_simulator_names_each_actuator_by_its_own_command_port(tmp_path):
    tree, _ = _tree(tmp_path)
    modes = {j.name: j.servos[0].mode for j in tree.actuated}
    assert modes == {"lift": "position", "spin": "velocity", "press": "effort"}
    names = PlatformSimulator(tree).actuators()
    assert {POSITION, SPEED, EFFORT} <= set(names)
    assert names[SPEED] == "spin" and names[EFFORT] == "press"
    assert {command_path(tree.name, j, s) for j in tree.actuated for s in j.servos} == {POSITION, SPEED, EFFORT}
    assert not any(n.endswith(("spin_motor.dangle", "press_motor.dangle")) for n in names)


def test_a_replayed_log_takes_every_actuator_name_the_simulator_takes(tmp_path):
    tree, _ = _tree(tmp_path)
    simulated = PlatformSimulator(tree).actuators()
    t = np.array([0.0, 1.0])
    replay = ReplayEndpoint(tree, Recording(t, np.zeros((2, 1)), np.zeros((2, 1)), ["lift"], "log"), offset=0.0)
    assert set(replay.actuator_names()) == set(simulated)
    assert {name: replay.joint(name) for name in simulated} == simulated
    # a speed or an effort is taken, and moves no joint the log does not record (where would it be?)
    replay.command({SPEED: 2.0, EFFORT: 1.5})
    assert replay.joint_positions()["spin"] == replay.joint_positions()["press"] == 0.0
    replay.command({"press_motor": 0.0, "spin": 0.5})
    assert replay.goals[-1][1] == {"press_motor": 0.0, "spin": 0.5}


def test_a_ur_over_rtde_takes_position_actuators_by_the_simulators_names_and_refuses_speeds_and_efforts(
        tmp_path, ur_rtde):
    tree, pmodel = _tree(tmp_path)
    simulated = PlatformSimulator(tree).actuators()
    live = RTDEEndpoint(tree, "10.0.0.7", arm=["lift", "spin", "press"])
    positioned = {name for name, joint in simulated.items() if joint == "lift"}
    assert set(live.actuator_names()) == positioned
    assert all(live.joint(name) == "lift" for name in positioned)
    live.command({POSITION: 0.5})
    assert live.control.moves == [[0.5, 0.0, 0.0]]
    for name, what, joint in ((SPEED, "speed", "spin"), (EFFORT, "effort", "press"), ("spin_motor", "speed", "spin")):
        with pytest.raises(CotwinError) as err:
            live.joint(name)
        message = str(err.value)
        assert message.startswith(f"{pmodel}:")  # at the p-model joint the actuator drives
        assert f"a UR robot over RTDE cannot take {what} commands: actuator '{name}' sets joint {joint}'s {what}" \
            in message
    with pytest.raises(CotwinError, match="cannot take effort commands"):
        live.command({EFFORT: 1.0})
    with pytest.raises(CotwinError, match="the robot has no actuator 'bot::arm::spin::spin_motor.dangle'"):
        live.joint("bot::arm::spin::spin_motor.dangle")


def test_the_perturbed_robot_and_the_opcua_plant_take_the_simulators_names_and_drive_a_speed(tmp_path):
    """The perturbed stand-in robot and the OPC UA plant serving it (its Describe's Actuators; not started here)
    take the simulator's names: a speed commanded by its path turns the wheel, after the latency."""
    from cotwin.mapping.perturbed import PerturbedEndpoint
    from cotwin.pmodel.perturbation import Perturbation
    from cotwin.twin.services.plant import Plant

    tree, _ = _tree(tmp_path)
    simulated = PlatformSimulator(tree).actuators()
    robot = PerturbedEndpoint.build(tree, None, Perturbation(latency_ms=10.0))
    assert {name: robot.joint(name) for name in robot.actuator_names()} == simulated
    assert Plant(robot, "opc.tcp://127.0.0.1:0").actuators == simulated
    robot.start()
    robot.command({SPEED: 2.0})
    robot.advance(0.2)
    assert robot.joint_velocities()["spin"] == pytest.approx(2.0, abs=0.2)


def test_a_ur_over_rtde_warns_that_the_grippers_goals_move_the_dt_alone(tmp_path):
    """The UR5e's fingers are position-driven joints past its arm: RTDE's moveJ does not carry them, and `cotwin twin`
    and `cotwin check` say so at [pt] endpoint (EndpointKind.advice); a kind without advice says nothing."""
    import shutil

    from conftest import EXAMPLES, cotwin_in_process

    from cotwin.twin.assembly.endpoints import endpoint_advice
    from cotwin.twin.assembly.run import load

    project = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", project)
    text = (project / "cotwin.toml").read_text()
    (project / "cotwin.toml").write_text(text + '\n[pt]\nendpoint = "rtde"\nurl = "10.0.0.7"\n')
    system = load(project / "cotwin.toml")
    fingers = [j.name for j in system.models.tree.actuated if j.name not in system.models.arm]
    assert fingers, "the example's p-model has a gripper"
    (advice,) = endpoint_advice(system, "pt")
    line = text.count("\n") + 3  # endpoint = "rtde"
    assert (advice.location.line, advice.severity.name) == (line, "WARNING")
    assert all(f in advice.message for f in fingers) and "move the DT alone" in advice.message
    checked = cotwin_in_process("check", project / "cotwin.toml", cwd=tmp_path)  # `cotwin check` says it too, once
    assert checked.returncode == 0, checked.stderr
    assert checked.stderr.count("move the DT alone") == 1 and f"cotwin.toml:{line}:" in checked.stderr
    (project / "cotwin.toml").write_text(text + '\n[pt]\nendpoint = "opcua"\nurl = "opc.tcp://127.0.0.1:4840"\n')
    assert endpoint_advice(load(project / "cotwin.toml"), "pt") == []
