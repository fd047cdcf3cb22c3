"""Perturbations of the stand-in plant: each acts as documented, seeded, and is read strictly."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.mapping.perturbed import PerturbedEndpoint
from cotwin.pmodel.ik import find_tool
from cotwin.pmodel.perturbation import PAYLOAD_BODY, Perturbation, perturbed_simulator, read_perturbation
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.twin.services.plant import load_plant
from cotwin.twin.project import load_project
from cotwin.twin.assembly.run import load

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ur5e"


@pytest.fixture(scope="module")
def models():
    return load(EXAMPLE / "cotwin.toml").models


def _run(endpoint, steps: int = 30, dt: float = 0.01, goals=None) -> list[tuple]:
    """Command at step 2, then record (time, joints, sensors) after every step."""
    endpoint.start()
    out = []
    for k in range(steps):
        if k == 2:
            endpoint.command(goals or {"M2": -0.8, "M3": 1.0})
        endpoint.advance(dt)
        out.append((endpoint.time, endpoint.joint_positions(), endpoint.read_sensors()))
    return out


def _nominal(models):
    return SimulatedEndpoint(PlatformSimulator(models.tree, models.scene))


def _perturbed(models, **fields):
    return PerturbedEndpoint.build(models.tree, models.scene, Perturbation(**fields))


def test_no_perturbation_is_exactly_the_simulated_endpoint(models):
    assert Perturbation().nominal and Perturbation(damping=1.0).nominal and not Perturbation(seed=1, noise=0.1).nominal
    a, b = _run(_nominal(models)), _run(_perturbed(models))
    assert a == b


def test_payload_is_an_uncompensated_mass_at_the_tool(models):
    plain = perturbed_simulator(models.tree, None, Perturbation())
    loaded = perturbed_simulator(models.tree, None, Perturbation(payload=3.0))
    payload = loaded.model.body(PAYLOAD_BODY).id
    assert loaded.model.body_mass[payload] == 3.0 and loaded.model.body_gravcomp[payload] == 0
    assert loaded.model.body_subtreemass[0] == pytest.approx(plain.model.body_subtreemass[0] + 3.0)
    for sim in (plain, loaded):  # hold the arm out horizontally for a second
        sim.reset({"shoulder_lift_joint": -1.57})
        sim.write_actuators({"shoulder_lift_joint": -1.57})
        sim.advance(1.0)
    assert abs(plain.joint_positions()["shoulder_lift_joint"] + 1.57) < 1e-3
    assert abs(loaded.joint_positions()["shoulder_lift_joint"] + 1.57) > 5e-3  # held with a steady-state error
    tool = find_tool(models.tree).link
    assert plain.body_pose(tool)[2, 3] - loaded.body_pose(tool)[2, 3] > 3e-3  # downwards: the weight pulls the tool


def test_friction_and_damping_act_on_the_named_joints(models):
    sim = perturbed_simulator(models.tree, None, Perturbation(friction={"elbow_joint": 2.5}, damping=3.0))
    nominal = PlatformSimulator(models.tree)
    elbow = sim.model.joint("elbow_joint").dofadr[0]
    assert sim.model.dof_frictionloss[elbow] == 2.5
    assert sim.model.dof_frictionloss.sum() == 2.5  # only the elbow
    assert np.allclose(sim.model.dof_damping, 3.0 * nominal.model.dof_damping)
    # Coulomb friction f against a position servo of stiffness kp: while the joint moves steadily, it lags the
    # frictionless joint by f / kp (the servo's extra error that makes the torque f), whatever f is
    kp = nominal.model.actuator_gainprm[next(a for a in range(nominal.model.nu)
                                             if nominal.model.actuator_trnid[a, 0] == sim.model.joint("elbow_joint").id), 0]
    a = _run(_nominal(models), steps=120, goals={"M3": 1.0})
    for friction in (10.0, 40.0):
        b = _run(_perturbed(models, friction={"elbow_joint": friction}), steps=120, goals={"M3": 1.0})
        moving = range(25, 50)  # 0.23 to 0.48 s after the command: mid-move, past the start's transient
        lags = [b[k][1]["elbow_joint"] - a[k][1]["elbow_joint"] for k in moving]
        assert np.allclose(lags, -friction / kp, rtol=0.05), (friction, kp, lags)
    # viscous damping scaled by 20 on the elbow: it lags the nominal joint while moving
    c = _run(_perturbed(models, damping={"elbow_joint": 20.0}), steps=120, goals={"M3": 1.0})
    assert all(c[k][1]["elbow_joint"] - a[k][1]["elbow_joint"] < -0.01 for k in range(25, 50))


def test_latency_delays_every_goal_by_exactly_its_time(models):
    a = _run(_nominal(models), steps=40)
    b = _run(_perturbed(models, latency_ms=50), steps=40)
    for (_, qa, _), (_, qb, _) in zip(a, b[5:]):  # 5 steps of 10 ms later, the same motion
        for joint in qa:
            assert qb[joint] == pytest.approx(qa[joint], abs=1e-9)
    assert b[6][1]["elbow_joint"] == pytest.approx(b[0][1]["elbow_joint"], abs=1e-9)  # not moved yet


def test_noise_is_gaussian_by_quantity_seeded_and_stable_within_a_step(models):
    first = _run(_perturbed(models, noise={"position": 0.01}, seed=11))
    assert first == _run(_perturbed(models, noise={"position": 0.01}, seed=11))  # the same seed, the same noise
    assert first != _run(_perturbed(models, noise={"position": 0.01}, seed=12))
    noisy, truth = _perturbed(models, noise={"position": 0.01}, seed=11), _nominal(models)
    assert noisy.read_sensors() == noisy.read_sensors()  # one draw per step, not per read
    errors, velocity_errors = [], []
    noisy.start()
    for _ in range(200):
        noisy.advance(0.01)
        truth.advance(0.01)
        errors += [noisy.joint_positions()[j] - q for j, q in truth.joint_positions().items()]
        velocity_errors += [noisy.joint_velocities()[j] - v for j, v in truth.joint_velocities().items()]
    assert np.std(errors) == pytest.approx(0.01, rel=0.1) and abs(np.mean(errors)) < 2e-3
    assert max(abs(e) for e in velocity_errors) < 1e-9  # velocity noise was not asked for
    sensors = noisy.read_sensors()
    assert sensors["ur5e::base_link::VS1.output_vel"] == pytest.approx(truth.read_sensors()["ur5e::base_link::VS1.output_vel"], abs=1e-12)


def _project(tmp_path, plant: str) -> Path:
    """A copy of the example project whose [plant] table starts on line 5."""
    for f in ("arm.rst", "ur5e.pm", "mapping.pm"):
        shutil.copy(EXAMPLE / f, tmp_path / f)
    path = tmp_path / "cotwin.toml"
    path.write_text('[models]\ndmodel = "arm.rst"\npmodel = "ur5e.pm"\nmapping = "mapping.pm"\n' + plant)
    return path


def test_plant_table_is_read_strictly_with_locations(tmp_path):
    path = _project(tmp_path, '[plant]\nseed = 3\npayload = -1\nnoise = { torque = 0.1 }\nlatency = 5\n')
    with pytest.raises(CotwinError) as err:
        load_project(path)
    text = str(err.value)
    assert f"{path}:7:1: error: [plant] payload must be a number >= 0, got -1" in text
    assert f"{path}:8:1: error: [plant] noise: unknown sensor quantity 'torque'" in text
    assert f"{path}:9:1: error: unknown key 'latency' in [plant]" in text


@pytest.mark.parametrize("other, where, message", [
    ("[cosim]\nstpe = 0.1\n", "9:1", "unknown key 'stpe' in [cosim]"),  # the project's schema
    ("[monitor]\njoints = [\"wrist\"]\n", "9:1", "[monitor] joints: wrist is not an actuated joint"),  # its models
], ids=["schema", "models"])
def test_cotwin_plant_reports_an_unknown_plant_joint_with_the_projects_other_errors(tmp_path, other, where, message):
    """One run names every error: the [plant] joint the p-model lacks beside a schema error (found before
    the models are read) or an error against the models, not in a round of its own once those are fixed."""
    from conftest import cotwin_in_process

    path = _project(tmp_path, '[plant]\nfriction = { elbow = 1.0 }\n\n' + other)
    proc = cotwin_in_process("plant", path, "--opcua", "opc.tcp://127.0.0.1:0")
    errors = [line for line in proc.stderr.splitlines() if ": error: " in line]
    assert proc.returncode == 1 and len(errors) == 2, proc.stderr
    assert errors[0].startswith(f"{path}:6:14: error: friction: p-model ur5e has no actuated joint 'elbow'"), errors
    assert errors[1].startswith(f"{path}:{where}: error: ") and message in errors[1], errors
    assert "Traceback" not in proc.stderr


def test_plant_table_names_joints_the_pmodel_has_and_options_override_it(tmp_path):
    path = _project(tmp_path, '[plant]\nfriction = { elbow = 1.0 }\n')
    with pytest.raises(CotwinError, match=r"cotwin.toml:6:14: error: friction: p-model ur5e has no actuated joint "
                                          r"'elbow'; did you mean 'elbow_joint'\? \(joints: shoulder_pan_joint"):
        load_plant(path)
    path.write_text(path.read_text().replace("elbow", "elbow_joint") + "payload = 1.0\nseed = 5\n")
    spec = load_project(path)
    assert spec.plant == Perturbation(seed=5, payload=1.0, friction={"elbow_joint": 1.0})
    plant = load_plant(path, "opc.tcp://127.0.0.1:0", payload=2.5, noise=0.001)  # built, not started
    assert plant.endpoint.perturbation == Perturbation(seed=5, payload=2.5, friction={"elbow_joint": 1.0}, noise=0.001)
    assert plant.url == "opc.tcp://127.0.0.1:0"
    file = tmp_path / "heavy.toml"
    file.write_text("payload = 4.0\nlatency_ms = 20\n")
    assert read_perturbation(file) == Perturbation(payload=4.0, latency_ms=20)
    assert load_plant(path, perturbation_file=file).endpoint.perturbation == Perturbation(payload=4.0, latency_ms=20)
    file.write_text("payload = true\n")
    with pytest.raises(CotwinError, match=r"heavy.toml:1:1: error: 'payload' must be a number >= 0, got True"):
        read_perturbation(file)
