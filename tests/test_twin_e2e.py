"""The paper's UR5e experiment end to end on our models: d-model FMU (C) + mapping + MuJoCo + scenario."""

from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from cotwin.diagnostics import CotwinError
from cotwin.twin.assembly.build import build
from cotwin.twin.project import load_project
from cotwin.twin.assembly.run import load, run_twin
from cotwin.pmodel import ik

TOOL_TOLERANCE = 0.002  # m: the tool ends within 2 mm of the commanded hole


@pytest.fixture(scope="module")
def twin():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


@pytest.fixture(scope="module")
def built(twin, tmp_path_factory):
    out = tmp_path_factory.mktemp("build")
    build(twin, out)
    return out


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("step", [0.5, 0.25, 0.1])
@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_paper_experiment(twin, built, tmp_path, step, algorithm):
    import shutil

    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(built / name, tmp_path / name)
    ran = run_twin(twin, tmp_path, step=step, algorithm=algorithm, plot=False)
    assert ran.result.rows == int(round(20 / step)) + 1
    rows = _rows(tmp_path / "outputs.csv")
    executed = [(t, a) for t, op, a in ran.mapping.executed if op == "movediscrete"]
    tree, scene, program = twin.models.tree, twin.models.scene, twin.models.program
    tool = ik.find_tool(tree)
    arm = ik.arm_joints(tree, tool)
    idle = program.leaf_names(program.machines[0]).index("Idle")
    delay = 2 if algorithm == "jacobi" else 0  # steps between the command's step and the robot's
    assert [c.time for c in twin.commands] == [1.0, 5.5, 8.0, 15.0]
    for command, following in zip(twin.commands, twin.commands[1:] + [None]):
        args = dict(command.values)
        target = (args["MovementArgs_target_X"], args["MovementArgs_target_Y"], args["MovementArgs_target_Z"])
        # the robot gets the command three steps after it is issued under Jacobi (it acts in the
        # step starting 2h later), in the very step under Gauss-Seidel
        start = next(t for t, a in executed if (a["target_X"], a["target_Y"], a["target_Z"]) == target)
        assert start == pytest.approx(command.time + delay * step)
        # before the next command reaches the d-model: arm at the hole, d-model back in Idle
        until = (following.time if following else 20.0) + (step if algorithm == "jacobi" and following else 0.0)
        row = [r for r in rows if float(r["time"]) <= until + 1e-9][-1]
        q = {j: float(row[f"{{mapping}}.mapping.q{i}"]) for i, j in enumerate(arm)}
        tip = ik.tool_pose(tree, tool, q)[:3, 3]
        assert np.linalg.norm(tip - np.array(scene.hole(*target))) < TOOL_TOLERANCE
        assert int(row["{dmodel}.dmodel.state"]) == idle


def test_pick_and_place_moves_a_brick(tmp_path):
    from conftest import EXAMPLES

    twin = load(EXAMPLES / "ur5e" / "pick_place_project.toml")
    ran = run_twin(twin, tmp_path, plot=True)
    sim = ran.mapping.mapping.endpoint.sim
    brick = sim.body_pose("brick1")[:3, 3]
    source, target = np.array(twin.models.scene.hole(8, 10)), np.array(twin.models.scene.hole(2, 14))
    assert np.hypot(*(brick[:2] - target[:2])) < 0.005
    assert np.hypot(*(brick[:2] - source[:2])) > 0.3
    assert brick[2] == pytest.approx(0.03, abs=0.005)  # standing on the plate
    ops = [op for _, op, _ in ran.mapping.executed]
    assert ops.count("pick") == 1 and ops.count("place") == 2
    assert (tmp_path / "figure.png").stat().st_size > 10_000


def test_build_writes_artefacts_and_a_maestro_multimodel(built, twin):
    import json

    mm = json.loads((built / "multimodel.json").read_text())
    assert mm["fmus"] == {"{dmodel}": "dmodel.fmu", "{mapping}": "mapping.fmu", "{controller}": "controller.fmu"}
    assert mm["connections"]["{controller}.controller.moveDiscreteCommand"] == ["{dmodel}.dmodel.moveDiscreteCommand"]
    assert mm["connections"]["{dmodel}.dmodel.movediscrete"] == ["{mapping}.mapping.movediscrete"]
    assert mm["connections"]["{mapping}.mapping.moveCompleted"] == ["{dmodel}.dmodel.moveCompleted"]
    assert mm["algorithm"] == {"type": "fixed-step", "size": 0.1} and mm["endTime"] == 20.0
    assert validate_fmu(str(built / "dmodel.fmu")) == []
    assert (built / "ur5e.sdf").is_file() and (built / "ur5e_scene.xml").is_file()


def test_bad_project_files_are_reported_with_the_file(tmp_path):
    bad = tmp_path / "cotwin.toml"
    bad.write_text('[models]\ndmodel = "nope.rst"\n[cosim]\nstep = -1\nalgoritm = "x"\n')
    with pytest.raises(CotwinError) as err:
        load_project(bad)
    text = str(err.value)
    assert "unknown key 'algoritm' in [cosim]" in text and "step must be a positive number" in text
    assert f"{bad}:1:1: error: [models] needs 'pmodel'" in text and f"{bad}:5:1: error: unknown key 'algoritm'" in text
    assert f"{bad}:4:1: error: [cosim] step must be a positive number" in text
    bad.write_text("[models\n")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(bad), "-o", str(tmp_path / "o")],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "bad TOML" in proc.stderr and "Traceback" not in proc.stderr


def test_bad_scenarios_are_reported_with_their_place(twin, tmp_path):
    from cotwin.twin.assembly.scenario import read_plan, read_toml

    plan = tmp_path / "plan.csv"
    plan.write_text("timestep,moveDiscreteCommand,MovementArgs_target_X\n1000,true,abc\n")
    with pytest.raises(CotwinError, match=r"plan.csv:2:11: error: column 'MovementArgs_target_X': 'abc' is not a valid integer"):
        read_plan(plan, twin.models.program)
    plan.write_text("timestep,jump\n0,true\n")
    with pytest.raises(CotwinError, match="unknown d-model input"):
        read_plan(plan, twin.models.program)
    scenario = tmp_path / "s.toml"
    scenario.write_text('[[command]]\ntime = 1.0\nevent = "moveDiscreteCommand"\nargs = { target_X = 1.5 }\n')
    with pytest.raises(CotwinError, match="argument target_X: 1.5 is not an integer"):
        read_toml(scenario, twin.models.program)


def test_out_of_range_command_is_not_feasible(twin, tmp_path):
    from cotwin.twin.assembly.scenario import Command, ScenarioUnit

    import shutil

    command = Command(0.5, (("moveDiscreteCommand", True), ("MovementArgs_target_X", 40),
                            ("MovementArgs_target_Y", 3), ("MovementArgs_target_Z", 0)), "test")
    source = ScenarioUnit("{controller}.controller", twin.models.program, [command])
    ran = run_twin(twin, tmp_path, end=3.0, algorithm="gauss-seidel", plot=False, source=source)
    rows = _rows(ran.csv)
    assert any(r["{mapping}.mapping.nonfeasibleMoveDiscreteCommand"] == "true" for r in rows)
    assert all(abs(float(r["{mapping}.mapping.q0"])) < 1e-6 for r in rows)  # the arm did not move
    idle = twin.models.program.leaf_names(twin.models.program.machines[0]).index("Idle")
    assert int(rows[-1]["{dmodel}.dmodel.state"]) == idle
    shutil.rmtree(tmp_path, ignore_errors=True)


def test_unwritable_output_is_a_readable_error(tmp_path):
    from conftest import EXAMPLES

    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(EXAMPLES / "ur5e" / "cotwin.toml"), "-o",
                           str(blocker / "out")], capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr  # refused at the option, before any work
    assert f"Invalid value for -o/--output: {blocker / 'out'}: would be made inside {blocker}, a file" in proc.stderr
