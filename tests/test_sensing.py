"""Sensors computed in a stretch's last physics step only (cotwin.pmodel.sensing): the same states and readings,
bit for bit, as MuJoCo computing them in every step; every step computes them where that cannot be done."""

from __future__ import annotations

import ctypes

import mujoco
import numpy as np
import pytest

from cotwin.mapping import native
from cotwin.pmodel.sensing import SENSOR, flags_address
from cotwin.pmodel.simulator import STATE, PlatformSimulator
from cotwin.twin.assembly.run import load


@pytest.fixture(scope="module")
def twin():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


def after(sim: PlatformSimulator) -> list[bytes]:
    d = sim.data
    state = np.empty(mujoco.mj_stateSize(sim.model, STATE))
    mujoco.mj_getState(sim.model, sim.data, state, STATE)
    return [state.tobytes(), d.sensordata.tobytes(), d.xpos.tobytes(), d.qacc.tobytes(), d.actuator_force.tobytes()]


def test_a_move_in_the_control_loop_reads_what_every_step_computing_sensors_reads(twin):
    """The endpoint's control loop (cotwin.mapping.native) along a move: sensors off but in each call's last step."""
    from cotwin.twin.assembly.run import simulated_endpoint

    if native.advance_function() is None:
        pytest.skip("the control loop cannot be built here (no C compiler)")
    runs = []
    for skip in (True, False):
        endpoint = simulated_endpoint(twin)
        sim = endpoint.sim
        if skip:
            assert sim.sensor_flags() is not None, "MuJoCo's headers are installed with the mujoco wheel"
        else:
            sim._sensor_flags = None  # every step computes the sensors
        joints = sim.joint_names[:6]
        endpoint.command({j: 0.4 for j in joints})  # a move of about a second, then held
        readings = []
        for _ in range(12):
            endpoint.advance(0.05)
            readings.append(after(sim))
        assert sim.model.opt.disableflags & SENSOR == 0  # put back after each call
        runs.append(readings)
    assert runs[0] == runs[1]


def test_no_sensor_skipping_where_sensors_may_keep_state_or_are_off_already():
    xml = """<mujoco><worldbody><body><joint name="j"/><geom size=".1" mass="1"/></body></worldbody>
             <sensor><jointpos joint="j"/><user dim="1" needstage="pos"/></sensor></mujoco>"""
    assert flags_address(mujoco.MjModel.from_xml_string(xml)) is None  # a user sensor: a callback computes it
    plain = xml.replace('<user dim="1" needstage="pos"/>', "")
    model = mujoco.MjModel.from_xml_string(plain)
    address = flags_address(model)
    assert address is not None and ctypes.c_int.from_address(address).value == model.opt.disableflags
    model.opt.disableflags |= SENSOR  # the user's choice: left alone
    assert flags_address(model) is None


def test_the_simulators_own_steps_read_what_every_step_computing_sensors_reads(twin):
    """PlatformSimulator.step (the FMU path's held steps, calibration's runs): sensors in each call's last step."""
    sims = [PlatformSimulator(twin.models.tree, twin.models.scene) for _ in range(2)]
    sims[1]._sensor_flags = None  # every step computes the sensors
    assert sims[0].sensor_flags() is not None
    for sim in sims:
        sim.data.ctrl[:6] = [0.4, -1.2, 1.1, -1.3, -1.4, 0.2]
    for n in (1, 2, 37, 100):
        for sim in sims:
            sim.step(n)
        assert after(sims[0]) == after(sims[1])
    assert sims[0].model.opt.disableflags & SENSOR == 0


def test_sensors_the_user_turns_off_after_the_lookup_stay_off_in_every_loop(twin):
    """The flags' address is looked up once; sensors the user turns off on the model afterwards stay off in the
    simulator's own steps and in the endpoint's control loop (C), and the readings are those of MuJoCo stepping
    with them off: not computed again in a stretch's last step."""
    from cotwin.twin.assembly.run import simulated_endpoint

    reference = PlatformSimulator(twin.models.tree, twin.models.scene)
    endpoint = simulated_endpoint(twin)
    sim = endpoint.sim
    assert sim.sensor_flags() is not None  # looked up while the sensors are on
    for s in (sim, reference):
        s.data.ctrl[:6] = [0.4, -1.2, 1.1, -1.3, -1.4, 0.2]
        mujoco.mj_step(s.model, s.data, 5)
        s.model.opt.disableflags |= SENSOR  # the user's choice, made now
    sim.step(37)
    mujoco.mj_step(reference.model, reference.data, 37)
    assert sim.model.opt.disableflags & SENSOR, "the simulator's steps turned the user's sensors back on"
    assert after(sim) == after(reference)
    if native.advance_function() is None:
        return  # no C compiler: the control loop is Python's, the steps above
    endpoint.command({j: 0.2 for j in sim.joint_names[:6]})  # a move: its set-points in the C control loop
    endpoint.advance(0.05)
    assert sim.model.opt.disableflags & SENSOR, "the control loop turned the user's sensors back on"
