"""The paper's UR5e experiment end to end on our models: d-model FMU (C) + mapping + MuJoCo + scenario."""

from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from cotwin.diagnostics import CotwinError
from cotwin.pipeline import Twin, load_twin_project
from cotwin.pmodel import ik

TOOL_TOLERANCE = 0.002  # m: the tool ends within 2 mm of the commanded hole


@pytest.fixture(scope="module")
def twin():
    from conftest import EXAMPLES

    return Twin(load_twin_project(EXAMPLES / "ur5e" / "cotwin.toml"))


@pytest.fixture(scope="module")
def built(twin, tmp_path_factory):
    out = tmp_path_factory.mktemp("build")
    twin.build(out)
    return out


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("step", [0.5, 0.25, 0.1])
@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_paper_experiment(twin, built, tmp_path, step, algorithm):
    import shutil

    shutil.copy(built / "dmodel.fmu", tmp_path / "dmodel.fmu")
    result = twin.run(tmp_path, step=step, algorithm=algorithm, plot=False)
    assert result.rows == int(round(20 / step)) + 1
    rows = _rows(tmp_path / "outputs.csv")
    executed = [(t, a) for t, op, a in twin.last_mapping.executed if op == "movediscrete"]
    tool = ik.find_tool(twin.tree)
    arm = ik.arm_joints(twin.tree, tool)
    idle = twin.program.leaf_names(twin.program.machines[0]).index("Idle")
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
        tip = ik.tool_pose(twin.tree, tool, q)[:3, 3]
        assert np.linalg.norm(tip - np.array(twin.scene.hole(*target))) < TOOL_TOLERANCE
        assert int(row["{dmodel}.dmodel.state"]) == idle


def test_pick_and_place_moves_a_brick(tmp_path):
    from conftest import EXAMPLES

    twin = Twin(load_twin_project(EXAMPLES / "ur5e" / "pick_place_project.toml"))
    twin.run(tmp_path, plot=True)
    sim = twin.last_mapping.mapping.endpoint.sim
    brick = sim.body_pose("brick1")[:3, 3]
    source, target = np.array(twin.scene.hole(8, 10)), np.array(twin.scene.hole(2, 14))
    assert np.hypot(*(brick[:2] - target[:2])) < 0.005
    assert np.hypot(*(brick[:2] - source[:2])) > 0.3
    assert brick[2] == pytest.approx(0.03, abs=0.005)  # standing on the plate
    ops = [op for _, op, _ in twin.last_mapping.executed]
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
        load_twin_project(bad)
    text = str(err.value)
    assert "unknown key 'algoritm' in [cosim]" in text and "step must be a positive number" in text
    assert "needs 'pmodel'" in text and f"{bad}:1:1: error" in text
    bad.write_text("[models\n")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(bad), "-o", str(tmp_path / "o")],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "bad TOML" in proc.stderr and "Traceback" not in proc.stderr


def test_bad_scenarios_are_reported_with_their_place(twin, tmp_path):
    from cotwin.cosim.scenario import read_plan, read_toml

    plan = tmp_path / "plan.csv"
    plan.write_text("timestep,moveDiscreteCommand,MovementArgs_target_X\n1000,true,abc\n")
    with pytest.raises(CotwinError, match=r"plan.csv:2:1: error: column 'MovementArgs_target_X': 'abc' is not a valid integer"):
        read_plan(plan, twin.program)
    plan.write_text("timestep,jump\n0,true\n")
    with pytest.raises(CotwinError, match="unknown d-model input"):
        read_plan(plan, twin.program)
    scenario = tmp_path / "s.toml"
    scenario.write_text('[[command]]\ntime = 1.0\nevent = "moveDiscreteCommand"\nargs = { target_X = 1.5 }\n')
    with pytest.raises(CotwinError, match="argument target_X must be an integer"):
        read_toml(scenario, twin.program)


def test_out_of_range_command_is_not_feasible(twin, tmp_path):
    from cotwin.cosim.scenario import Command

    import shutil

    original = twin.commands
    twin.commands = [Command(0.5, (("moveDiscreteCommand", True), ("MovementArgs_target_X", 40),
                                   ("MovementArgs_target_Y", 3), ("MovementArgs_target_Z", 0)), "test")]
    try:
        result = twin.run(tmp_path, end=3.0, algorithm="gauss-seidel", plot=False)
    finally:
        twin.commands = original
    rows = _rows(result.csv_path)
    assert any(r["{mapping}.mapping.nonfeasibleMoveDiscreteCommand"] == "true" for r in rows)
    assert all(abs(float(r["{mapping}.mapping.q0"])) < 1e-6 for r in rows)  # the arm did not move
    idle = twin.program.leaf_names(twin.program.machines[0]).index("Idle")
    assert int(rows[-1]["{dmodel}.dmodel.state"]) == idle
    shutil.rmtree(tmp_path, ignore_errors=True)


def test_unwritable_output_is_a_readable_error(tmp_path):
    from conftest import EXAMPLES

    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(EXAMPLES / "ur5e" / "cotwin.toml"), "-o",
                           str(blocker / "out")], capture_output=True, text=True)
    assert proc.returncode == 1 and proc.stderr.startswith("error: ") and "Traceback" not in proc.stderr
