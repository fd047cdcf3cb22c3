"""examples/flexcell2: the UR5e and the Panda (imported from URDF) on one plate, one MuJoCo world, each with
its own instance of the same d-model FMU, its own mapping and its own plan columns; contacts between the
arms reported as collisions to both d-models; the generic core naming neither robot nor the cell."""

from __future__ import annotations

import csv
import json
import re
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cotwin.cosim.observers import Observer
from cotwin.diagnostics import CotwinError
from cotwin.twin.assembly.cell import CellSystem, read_cell_plan, run_cell
from cotwin.twin.project import load_project

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "examples" / "flexcell2"
ROBOTS = ("ur5e", "panda")


def cell_copy(folder: Path, project: str = "cotwin.toml", edit=lambda text: text) -> Path:
    """The cell example's files in `folder` (its meshes linked), `project` rewritten by `edit` with the UR5e's
    files named where they are: a user's copy of the cell, to change."""
    for name in ("ur5e_mapping.pm", "panda_mapping.pm", "panda.pm", "panda_cell.toml", "apart.csv"):
        shutil.copy(CELL / name, folder / name)
    (folder / "meshes").symlink_to(CELL / "meshes")
    text = (CELL / project).read_text().replace('"../ur5e/', f'"{ROOT}/examples/ur5e/')
    (folder / project).write_text(edit(text))
    return folder / project


class CollisionInputs(Observer):
    """What each d-model FMU instance holds on its `collision` input after every step (read from the FMU)."""

    def __init__(self):
        self.seen: dict[str, list[float]] = {r: [] for r in ROBOTS}

    def step_complete(self, execution) -> None:
        for robot in ROBOTS:
            if execution.system.units[f"{{dmodel}}.{robot}"].get(["collision"])["collision"]:
                self.seen[robot].append(execution.time)


def rows(csv_path: Path) -> list[dict]:
    with open(csv_path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def apart(tmp_path_factory):
    cell = CellSystem(load_project(CELL / "cotwin.toml"))
    return cell, run_cell(cell, tmp_path_factory.mktemp("apart"))


@pytest.fixture(scope="module")
def collide(tmp_path_factory):
    cell = CellSystem(load_project(CELL / "collide.toml"))
    watch = CollisionInputs()
    return cell, run_cell(cell, tmp_path_factory.mktemp("collide"), observers=[watch]), watch


def test_apart_completes_every_move_of_both_arms(apart):
    cell, ran = apart
    table = rows(ran.csv)
    for robot in ROBOTS:
        planned = len(next(r for r in cell.robots if r.name == robot).system.commands)
        assert planned == 4
        completed = sum(r[f"{{mapping}}.cell.{robot}.moveCompleted"] == "true" for r in table)
        infeasible = sum(r[f"{{mapping}}.cell.{robot}.nonfeasibleMoveDiscreteCommand"] == "true" for r in table)
        assert (completed, infeasible) == (planned, 0), robot
        assert not any(r[f"{{mapping}}.cell.{robot}.collision"] == "true" for r in table), robot
        outcome = ran.outcomes.robots[robot]
        assert (outcome.commands, outcome.completed, outcome.collisions) == (4, 4, [])
    assert ran.contacts == []


def test_both_arms_move_each_by_its_own_commands(apart):
    _, ran = apart
    table = rows(ran.csv)
    first, last = table[0], table[-1]
    for robot in ROBOTS:  # each arm's first joint turned away from where it started, differently
        assert abs(float(last[f"{{mapping}}.cell.{robot}.q0"]) - float(first[f"{{mapping}}.cell.{robot}.q0"])) > 0.05
    assert last["{mapping}.cell.ur5e.q0"] != last["{mapping}.cell.panda.q0"]


def test_driving_both_arms_to_one_hole_reports_the_collision_to_both_dmodels(collide):
    cell, ran, watch = collide
    assert ran.contacts and {ran.contacts[0][1], ran.contacts[0][2]} == set(ROBOTS)
    touched = ran.contacts[0][0]
    for robot in ROBOTS:
        assert watch.seen[robot], f"{robot}'s d-model never had its collision input set"
        assert watch.seen[robot][0] == pytest.approx(touched, abs=0.2)  # in the step the arms touched
        assert ran.outcomes.robots[robot].collisions
    # the Panda, still moving when the arms met, is stopped by it: its move never completes
    assert ran.outcomes.robots["panda"].completed == 0


def test_each_robot_has_its_own_instance_of_the_same_dmodel_fmu(apart):
    cell, ran = apart
    units = ran.system.units
    first, second = (units[f"{{dmodel}}.{r}"] for r in ROBOTS)
    assert first is not second and first.path == second.path  # one FMU file, two instances
    connected = {(c.source, c.output, c.target, c.input) for c in ran.system.connections}
    for robot in ROBOTS:
        assert ("{mapping}.cell", f"{robot}.collision", f"{{dmodel}}.{robot}", "collision") in connected
        assert (f"{{controller}}.{robot}", "moveDiscreteCommand", f"{{dmodel}}.{robot}", "moveDiscreteCommand") in connected


def test_two_robots_of_one_pmodel_share_a_world_without_name_clashes():
    from cotwin.pmodel.shared import PlacedRobot, SharedWorld
    from cotwin.pmodel.tree import transform
    from cotwin.robosim.check import load_checked
    from cotwin.pmodel.tree import build_tree

    tree = build_tree(load_checked([CELL / "panda.pm"]), None, {})
    world = SharedWorld([PlacedRobot("a", tree, transform((0, 0, 0), (0, 0, 0))),
                         PlacedRobot("b", tree, transform((2.0, 0, 0), (0, 0, 0)))])
    a, b = world.view("a"), world.view("b")
    a.write_actuators({"panda_joint1": 0.5})
    world.step(500)
    assert a.joint_positions()["panda_joint1"] > 0.3
    assert abs(b.joint_positions()["panda_joint1"]) < 1e-6
    assert np.allclose(b.body_pose("panda_link0")[:3, 3], (2.0, 0.0, 0.0))
    with pytest.raises(CotwinError, match="the world steps"):
        a.step(1)
    with pytest.raises(CotwinError, match="two robots of one world are called a"):
        SharedWorld([PlacedRobot("a", tree, np.eye(4)), PlacedRobot("a", tree, np.eye(4))])


def test_cell_project_errors_are_located(tmp_path):
    text = cell_copy(tmp_path).read_text()  # the user's copy, changed three ways below
    (tmp_path / "cotwin.toml").write_text(text.replace('name = "panda"', 'name = "ur5e"'))
    with pytest.raises(CotwinError) as err:
        load_project(tmp_path / "cotwin.toml")
    assert "two robots are called 'ur5e'" in str(err.value) and err.value.findings[0].location.line > 1
    (tmp_path / "cotwin.toml").write_text(text.replace('"panda.pm"', '"nowhere.pm"'))
    with pytest.raises(CotwinError, match=r"\[\[robots\]\] pmodel of panda: no file"):
        load_project(tmp_path / "cotwin.toml")
    (tmp_path / "cotwin.toml").write_text(text.replace('arm.rst"', 'arm.rst"\npmodel = "panda.pm"', 1))
    with pytest.raises(CotwinError) as err:
        load_project(tmp_path / "cotwin.toml")
    finding = err.value.findings[0]
    assert "[models] pmodel: a cell's robots name their own" in finding.message
    assert text.splitlines()[finding.location.line - 2].startswith("dmodel")  # at the key, the line after dmodel


def test_a_plan_column_of_an_unknown_robot_is_located(tmp_path):
    cell = CellSystem(load_project(CELL / "cotwin.toml"))
    plan = tmp_path / "plan.csv"
    plan.write_text("timestep,ur5e.moveDiscreteCommand,ur5e.MovementArgs_target_X,ur5e.MovementArgs_target_Y,"
                    "ur5e.MovementArgs_target_Z,kuka.moveDiscreteCommand\n1000,true,1,2,0,true\n")
    with pytest.raises(CotwinError) as err:
        read_cell_plan(plan, cell.program, list(ROBOTS))
    finding = err.value.findings[0]
    at = plan.read_text().index("kuka.") + 1  # the character column of the cell, not its index
    assert "kuka.moveDiscreteCommand" in finding.message and (finding.location.line, finding.location.column) == (1, at)


def test_a_plan_header_with_a_cell_quoted_over_two_lines_is_an_error_not_an_index_error(tmp_path):
    """A quoted header cell holding a line break makes more header cells than its first line shows: the columns
    after it are located at the line's start (an IndexError in both plan readers, found by the input fuzzer)."""
    from conftest import EXAMPLES

    from cotwin.twin.assembly.run import load
    from cotwin.twin.assembly.scenario import read_plan

    cell = CellSystem(load_project(CELL / "cotwin.toml"))
    plan = tmp_path / "plan.csv"
    plan.write_text('timestep,"x\ny",ur5e.moveDiscreteCommand,ur5e.moveDiscreteCommand\n1000,1,true,true\n')
    with pytest.raises(CotwinError, match="appears twice"):
        read_cell_plan(plan, cell.program, list(ROBOTS))
    plan.write_text('timestep,"x\ny",moveDiscreteCommand,moveDiscreteCommand\n1000,1,true,true\n')
    with pytest.raises(CotwinError) as err:
        read_plan(plan, load(EXAMPLES / "ur5e" / "cotwin.toml").models.program)
    assert any("appears twice" in f.message and f.location.line == 1 for f in err.value.findings), str(err.value)


def test_a_robot_given_some_of_its_cells_in_a_row_or_a_huge_cell_is_located(tmp_path):
    """A row gives a robot all its columns or none: one empty argument beside its event (it was sent as 0), or
    arguments with no event (the row was dropped without a word), is an error at the first empty cell; a cell
    beyond the plan's limit is an error at its line, not csv's crash."""
    cell = CellSystem(load_project(CELL / "cotwin.toml"))
    header = (CELL / "apart.csv").read_text().splitlines()[0]
    plan = tmp_path / "plan.csv"
    plan.write_text(f"{header}\n1000,true,12,,1,true,2,9,1\n2000,,12,20,1,,,,\n3000,true,1,2,{'x' * 200_000},,,,\n")
    with pytest.raises(CotwinError) as err:
        read_cell_plan(plan, cell.program, list(ROBOTS))
    found = [(f.location.line, f.location.column, f.message) for f in err.value.findings]
    assert len(found) == 3, found
    (l2, c2, m2), (l3, c3, m3), (l4, _, m4) = found
    assert (l2, c2) == (2, len("1000,true,12,") + 1) and "'ur5e.MovementArgs_target_Y' empty beside" in m2
    assert (l3, c3) == (3, len("2000,") + 1) and "'ur5e.moveDiscreteCommand' empty" in m3
    assert l4 == 4 and "longer than" in m4
    # per event: a row that moves the arm leaves its gripper event empty (not sent), and that is no error
    plan.write_text(f"{header},ur5e.openGripperCommand\n1000,true,12,20,1,true,2,9,1,\n2000,,,,,,,,,true\n")
    plans = read_cell_plan(plan, cell.program, list(ROBOTS))
    assert [dict(c.values) for c in plans["ur5e"]] == [
        {"moveDiscreteCommand": True, "MovementArgs_target_X": 12, "MovementArgs_target_Y": 20, "MovementArgs_target_Z": 1},
        {"openGripperCommand": True}]


def test_the_generic_core_names_neither_robot_nor_the_cell():
    """The issue's grep over src/cotwin, every file: no example's robot, cell or brick (the vendored
    three.js names the colour 'firebrick', a generic word)."""
    named = re.compile(r"ur5e|ur3e|panda|flexcell|flex-cell|turtlebot|brick", re.IGNORECASE)
    offenders = sorted({f"{p.relative_to(ROOT)}: {m.group(0)}" for p in (ROOT / "src" / "cotwin").rglob("*")
                        if p.is_file() and p.suffix not in (".pyc",)
                        for m in named.finditer(p.read_text(errors="replace"))
                        if not (p.name == "three.min.js" and m.group(0).lower() == "brick")})
    assert offenders == []


def test_the_cell_twin_runs_pt_and_dt_with_deviation_and_history_per_robot(tmp_path):
    import sqlite3

    from cotwin.twin.live.cell_live import run_cell_twin

    cell = CellSystem(load_project(CELL / "twin.toml"))
    result = run_cell_twin(cell, tmp_path)
    assert result.pt.steps == result.dt.steps == 160
    for side in ("pt", "dt"):
        for robot in ROBOTS:
            outcome = result.outcomes[side].robots[robot]
            assert (outcome.commands, outcome.completed, outcome.collisions) == (4, 4, []), (side, robot)
    assert set(result.deviation) == set(ROBOTS)
    for robot in ROBOTS:  # the perturbed plant (0.5 kg, 0.3 N m) moves measurably otherwise than the nominal DT
        variables = result.deviation[robot]["variables"]
        assert all(v.startswith(f"{robot}.q") for v in variables)
        assert max(v["max_deviation"] for v in variables.values()) > 1e-4
    db = sqlite3.connect(tmp_path / "history.sqlite")
    machines = {row[0] for row in db.execute("select distinct machine from states")}
    assert {m.split(".")[0] for m in machines} == set(ROBOTS)
    assert db.execute("select count(*) from samples").fetchone()[0] == 2 * 161  # the start, then every step
    commands = {row[0] for row in db.execute("select distinct port from commands")}
    assert {c.split(".")[0] for c in commands} == set(ROBOTS) and all("." in c for c in commands)
    assert (tmp_path / "pt" / "outputs.csv").is_file() and (tmp_path / "dt" / "outputs.csv").is_file()


def test_a_heavier_plant_raises_alarms_naming_the_robot(tmp_path):
    from cotwin.twin.live.cell_live import run_cell_twin

    from cotwin.twin.assembly.observing import TwinObserver

    class Told(TwinObserver):  # a cell twin tells its observers what a live twin tells its own
        def __init__(self):
            self.said = []

        def twin_started(self, twin):
            self.said.append("started")

        def twin_alarm(self, twin, event):
            self.said.append(event["twin"])

        def twin_ended(self, twin, status):
            self.said.append(status)

    told = Told()
    spec = load_project(CELL / "twin.toml").with_overrides(plant_payload=3.0, deviation_absolute=0.002, end=8.0)
    result = run_cell_twin(CellSystem(spec), tmp_path, observers=[told])
    assert result.alarms
    assert told.said == ["started", *[event["twin"] for event in result.alarms], "done"]
    for event in result.alarms:
        assert event["twin"] in ROBOTS and event["variable"].startswith(event["twin"] + ".")


def test_cotwin_run_and_twin_of_the_cell(tmp_path):
    from click.testing import CliRunner

    from cotwin.cli import main

    ran = CliRunner().invoke(main, ["run", str(CELL / "collide.toml"), "-o", str(tmp_path / "run")])
    assert ran.exit_code == 0, ran.output
    assert re.search(r"^ur5e: 1 command\(s\) applied, .* collision reported at t = ", ran.output, re.MULTILINE)
    assert re.search(r"^panda: 1 command\(s\) applied, 0 move\(s\) completed, collision reported", ran.output, re.MULTILINE)
    assert "contact: ur5e and panda at t = " in ran.output
    twin = CliRunner().invoke(main, ["twin", str(CELL / "collide.toml"), "-o", str(tmp_path / "twin")])
    assert twin.exit_code == 0, twin.output
    assert "PT and DT, 80 steps each" in twin.output and "PT: panda: 1 command(s) applied" in twin.output
    refused = CliRunner().invoke(main, ["twin", str(CELL / "collide.toml"), "-o", str(tmp_path / "t2"),
                                        "--pt-url", "opc.tcp://127.0.0.1:4999"])
    assert refused.exit_code != 0 and "--pt-url not done yet" in refused.output


def test_broker_commands_are_routed_per_robot(tmp_path, broker):
    """Each robot's publisher sends on its own routing key (TO_COSIM.ROBOT); each arm does its own move."""
    import threading
    import uuid

    from cotwin.twin.assembly.cell import routed
    from cotwin.twin.services.publisher import Publisher, idle_values
    from cotwin.twin.assembly.rabbitmq import port_types

    exchange = f"cotwin.test.cell.{uuid.uuid4().hex[:8]}"
    project = cell_copy(tmp_path, "collide.toml", lambda text: text.replace(
        'plan = "collide.csv"', f'rabbitmq = {{ exchange = "{exchange}" }}').replace("end = 8.0", "end = 5.0\nrealtime = true"))
    cell = CellSystem(load_project(project))
    assert [u.name for u in cell.units if u.role == "source"] == ["{rabbitmq}.ur5e", "{rabbitmq}.panda"]
    plans = read_cell_plan(CELL / "apart.csv", cell.program, list(ROBOTS))  # different holes for each arm
    publishers = []
    for robot in cell.robots:
        settings = routed(cell.spec.rabbitmq, robot.name)
        assert settings.to_cosim == f"data.to_cosim.{robot.name}"
        idle = idle_values(port_types(cell.program, robot.system.live_ports()))
        publishers.append(Publisher(settings, plans[robot.name][:1], idle, period=0.2, end=5.0))
    threads = [threading.Thread(target=p.run, daemon=True) for p in publishers]
    for thread in threads:
        thread.start()
    ran = run_cell(cell, tmp_path / "out")
    for thread in threads:
        thread.join(timeout=30)
    for robot in ROBOTS:
        outcome = ran.outcomes.robots[robot]
        assert (outcome.commands, outcome.completed, outcome.collisions) == (1, 1, []), robot
    table = rows(ran.csv)
    sent = {robot: [r for r in table if r[f"{{rabbitmq}}.{robot}.moveDiscreteCommand"] == "true"] for robot in ROBOTS}
    for robot in ROBOTS:  # each robot's source got its own robot's command, with its own arguments
        (row,) = sent[robot]
        expected = dict(plans[robot][0].values)
        assert int(row[f"{{rabbitmq}}.{robot}.MovementArgs_target_X"]) == expected["MovementArgs_target_X"]
        assert int(row[f"{{rabbitmq}}.{robot}.MovementArgs_target_Y"]) == expected["MovementArgs_target_Y"]


def test_commands_of_one_robot_refuse_a_cell_at_its_robots():
    from cotwin.twin.assembly.run import load

    with pytest.raises(CotwinError) as err:
        load(CELL / "cotwin.toml")
    finding = err.value.findings[0]
    assert "takes a twin of one robot" in finding.message and finding.location.line > 1
    assert isinstance(load(CELL / "cotwin.toml", cells=True), CellSystem)


def test_the_cell_plants_latency_and_noise_reach_each_robot(tmp_path):
    from cotwin.twin.live.cell_live import run_cell_twin

    spec = load_project(CELL / "twin.toml").with_overrides(plant_latency_ms=300.0, plant_noise={"position": 0.001},
                                                             plant_payload=0.0, plant_friction=0.0, end=6.0)
    run_cell_twin(CellSystem(spec), tmp_path)
    pt, dt = rows(tmp_path / "pt" / "outputs.csv"), rows(tmp_path / "dt" / "outputs.csv")
    for robot in ROBOTS:
        done = [next(float(r["time"]) for r in side if r[f"{{mapping}}.cell.{robot}.moveCompleted"] == "true")
                for side in (pt, dt)]
        assert done[0] >= done[1] + 0.2, robot  # its goals take effect 0.3 s later on the plant
        before = [float(r[f"{{mapping}}.cell.{robot}.q0"]) for r in pt if float(r["time"]) < 1.0]
        assert 0 < np.std(before) < 0.01, robot  # at rest, measured with noise


def test_a_cells_log_names_are_scoped_by_robot_and_unsupported_tables_are_located(tmp_path):
    spec = load_project(CELL / "cotwin.toml")
    cell = CellSystem(spec.with_overrides(cosim_log=["ur5e.q0", "panda.q6"]))
    assert cell.log["{mapping}.cell"] == ["ur5e.q0", "panda.q6"]
    with pytest.raises(CotwinError, match=r"\[cosim\] log: q0: a cell's variables are named ROBOT.variable"):
        CellSystem(spec.with_overrides(cosim_log=["q0"]))
    with pytest.raises(CotwinError, match=r"\[monitor\] readings: not for a cell"):
        CellSystem(spec.with_overrides(monitor_readings={"x": "panda::panda_link0.x"}))
    ran = run_cell(cell, tmp_path, end=1.0)
    assert ran.figure is not None and ran.figure.is_file()


def _get(url: str):
    import urllib.request

    with urllib.request.urlopen(url, timeout=10) as r:
        return r.status, r.read()


def test_the_page_shows_both_robots_their_variables_and_both_dmodels(tmp_path):
    import json

    from cotwin.twin.live.cell_live import run_cell_twin
    from cotwin.twin.services.dashboard import Dashboard

    cell = CellSystem(load_project(CELL / "collide.toml"))
    with Dashboard(cell, port=0, mode="run") as dash:
        model = json.loads(_get(dash.url + "api/model")[1])["model"]
        assert [r["label"] for r in model["robots"]] == list(ROBOTS)
        panda = model["robots"][1]
        assert panda["root_pose"][3] == pytest.approx(1.0) and panda["root_pose"][7] == pytest.approx(0.65)
        assert any(g["kind"] == "box" and g.get("mesh") for link in panda["links"] for g in link["geoms"])
        assert {j["variable"] for j in panda["joints"] if j["variable"]} == {f"panda.q{i}" for i in range(7)}
        assert [m["name"] for m in model["machines"]] == ["ur5e: stm_ref", "panda: stm_ref"]
        assert model["scene"]["plate"]
        ran = run_cell(cell, tmp_path / "run", end=3.0, observers=[dash.feed])
        status = json.loads(_get(dash.url + "api/status")[1])
        assert status["state"] == "done" and status["time"] == pytest.approx(3.0)
        rows, _, _ = dash.feed.samples.since(0)
        names = [v["name"] for v in model["variables"]]
        assert dash.feed.variables == names
        last = rows[-1][2]
        written = {k: float(v) for k, v in rows_of_csv(ran.csv)[-1].items() if k != "time"}
        for name in ("ur5e.q0", "panda.q5"):
            assert last[0][names.index(name)] == pytest.approx(written[f"{{mapping}}.cell.{name}"])
        assert len(last[1]) == 2  # both d-models' states
        assert {e["name"] for e in dash.feed.events if e["kind"] == "command"} == \
            {"ur5e.moveDiscreteCommand", "panda.moveDiscreteCommand"}
    with Dashboard(cell, port=0, mode="twin") as dash:
        result = run_cell_twin(cell, tmp_path / "twin", end=3.0, observers=[dash.feed])
        status = json.loads(_get(dash.url + "api/status")[1])
        assert status["sides"] == ["pt", "dt"] and status["time"] == pytest.approx(3.0)
        assert result.pt.steps == 30


def rows_of_csv(path: Path) -> list[dict]:
    return [{k: v for k, v in r.items() if v not in ("true", "false", "")} for r in rows(path)]


def test_a_cell_run_is_deterministic(tmp_path):
    cell = CellSystem(load_project(CELL / "collide.toml"))
    first = run_cell(cell, tmp_path / "a", end=3.0, plot=False)
    second = run_cell(cell, tmp_path / "b", end=3.0, plot=False)
    assert first.csv.read_text() == second.csv.read_text() and first.contacts == second.contacts


def test_the_cells_artefacts_run_in_the_multimodel_master_as_cotwin_run_does(tmp_path):
    """cotwin build writes one d-model FMU instantiated per robot in multimodel.json; cotwin simulate of it
    (the Python FMUs of the sources and the cell's mapping) writes the very rows cotwin run writes."""
    import json
    import subprocess
    import sys

    from cotwin.twin.assembly.build import build

    cell = CellSystem(load_project(CELL / "collide.toml"))
    written = build(cell, tmp_path / "build")
    model = json.loads(written["multimodel"].read_text())
    assert model["fmus"] == {"{controller}": "controller.fmu", "{dmodel}": "dmodel.fmu", "{mapping}": "mapping.fmu"}
    assert model["connections"]["{mapping}.cell.panda.collision"] == ["{dmodel}.panda.collision"]
    done = subprocess.run([sys.executable, "-m", "cotwin", "simulate", str(written["multimodel"]), "-o",
                           str(tmp_path / "simulated.csv")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and "corrupted" not in done.stderr, done.stderr
    ran = run_cell(cell, tmp_path / "run", plot=False)
    assert rows(tmp_path / "simulated.csv") == rows(ran.csv)


def test_a_robots_infeasible_command_is_said_in_its_outcome(tmp_path):
    """A robot whose command its mapping answers infeasible (a hole off its grid) says so, instead of only
    '0 move(s) completed' (found trying a cell of one's own: the UR3e given a hole out of its reach)."""
    plan = tmp_path / "plan.csv"
    header = (CELL / "collide.csv").read_text().splitlines()[0]
    plan.write_text(header + "\n1000,true,12,20,1,true,99,9,1\n")
    cell = CellSystem(load_project(CELL / "collide.toml").with_overrides(scenario_plan=str(plan)))
    lines = run_cell(cell, tmp_path / "out", end=4.0).outcomes.lines()
    assert lines[0].startswith("ur5e: 1 command(s) applied, 1 move(s) completed, no collision"), lines
    assert lines[1].startswith("panda: 1 command(s) applied, 0 move(s) completed, 1 infeasible,"), lines


def test_the_cell_twin_takes_broker_commands_routed_per_robot_into_both_sides(tmp_path, broker):
    """`cotwin twin --rabbitmq` of a cell: each robot's commands (TO_COSIM.ROBOT) reach its PT and its DT in the
    same step, once each (one bridge and stream per robot shared by both sides), and each arm does its own move
    on both sides; the history records each command under its robot's name."""
    import sqlite3
    import threading
    import uuid

    from cotwin.twin.assembly.cell import routed
    from cotwin.twin.assembly.rabbitmq import port_types
    from cotwin.twin.live.cell_live import run_cell_twin
    from cotwin.twin.services.publisher import Publisher, idle_values

    exchange = f"cotwin.test.celltwin.{uuid.uuid4().hex[:8]}"
    spec = load_project(cell_copy(tmp_path, "twin.toml")).with_overrides(
        scenario_plan=None, scenario_commands=None, scenario_rabbitmq_exchange=exchange, realtime=True, end=5.0)
    cell = CellSystem(spec)
    assert [u.name for u in cell.units if u.role == "source"] == ["{rabbitmq}.ur5e", "{rabbitmq}.panda"]
    plans = read_cell_plan(CELL / "apart.csv", cell.program, list(ROBOTS))
    publishers = [Publisher(routed(cell.spec.rabbitmq, r.name), plans[r.name][:1],
                            idle_values(port_types(cell.program, r.system.live_ports())), period=0.2, end=5.0)
                  for r in cell.robots]
    threads = [threading.Thread(target=p.run, daemon=True) for p in publishers]
    for thread in threads:
        thread.start()
    result = run_cell_twin(cell, tmp_path / "out")
    for thread in threads:
        thread.join(timeout=30)
    for side in ("pt", "dt"):
        for robot in ROBOTS:
            outcome = result.outcomes[side].robots[robot]
            assert (outcome.commands, outcome.completed, outcome.collisions) == (1, 1, []), (side, robot)
    for robot in ROBOTS:  # the same step on both sides
        fired = {side: [r["time"] for r in rows(tmp_path / "out" / side / "outputs.csv")
                        if r[f"{{rabbitmq}}.{robot}.moveDiscreteCommand"] == "true"] for side in ("pt", "dt")}
        assert len(fired["pt"]) == 1 and fired["pt"] == fired["dt"], (robot, fired)
    db = sqlite3.connect(tmp_path / "out" / "history.sqlite")
    recorded = {row[0] for row in db.execute("select port from commands where value = 'true'")}
    assert recorded == {f"{robot}.moveDiscreteCommand" for robot in ROBOTS}


def test_strict_fails_a_cell_run_whose_moves_did_not_all_complete(tmp_path):
    """`cotwin run --strict` of a cell: the apart plan (every move of both arms completes) exits 0; the
    colliding plan exits 3 naming each robot's moves not completed and the collision (it was ignored)."""
    from conftest import cotwin_in_process

    apart = cotwin_in_process("run", CELL / "cotwin.toml", "-o", tmp_path / "apart", "--strict")
    assert apart.returncode == 0, apart.stderr[-2000:]
    hit = cotwin_in_process("run", CELL / "collide.toml", "-o", tmp_path / "collide", "--strict")
    assert hit.returncode == 3, hit.stdout + hit.stderr[-2000:]
    assert "--strict: " in hit.stderr and "panda: collision reported at t = " in hit.stderr
    refused = cotwin_in_process("run", CELL / "cotwin.toml", "-o", tmp_path / "r", "--on-unit-failure",
                                "restart-from-state")
    assert refused.returncode == 2 and "cannot save its state yet" in refused.stderr


def test_an_interrupted_cell_twin_stops_after_the_step_and_keeps_its_results(tmp_path):
    """Ctrl-C in a cell twin's step loop ends it after the step, as a single robot's twin does: both sides'
    outputs.csv, deviation.json and a history run marked stopped (it printed only 'interrupted' and kept
    partial files). Signals: a process of its own."""
    import signal
    import sqlite3
    import subprocess
    import sys
    import time

    out = tmp_path / "twin"
    proc = subprocess.Popen([sys.executable, "-m", "cotwin", "twin", str(CELL / "twin.toml"), "-o", str(out),
                             "--realtime"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline, part = time.monotonic() + 120, out / "dt" / "outputs.csv.part"

        def rows() -> int:  # the DT's rows flushed: a header and the start row at its initialisation, then steps'
            try:
                return part.read_text().count("\n")
            except OSError:
                return 0

        while rows() < 4 and time.monotonic() < deadline and proc.poll() is None:  # in the paced loop
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr[-2000:]
    assert "stopping after this step" in stderr and "stopped early" in stdout
    for side in ("pt", "dt"):
        assert (out / side / "outputs.csv").is_file() and not (out / side / "outputs.partial.csv").exists()
    assert set(json.loads((out / "deviation.json").read_text())) == set(ROBOTS)
    (status,) = sqlite3.connect(out / "history.sqlite").execute("select status from runs").fetchone()
    assert status == "stopped"


def test_commands_after_the_end_are_warned_once_per_row_and_a_long_tail_summed_up():
    """A cell's row holds a command per robot: one warning per row, not one per robot; a plan of thousands of
    rows past the end gets its first ten and one line for the rest (it printed 298 000 lines)."""
    from cotwin.twin.assembly.scenario import AFTER_END_SHOWN, Command, after_end

    cell = CellSystem(load_project(CELL / "cotwin.toml"))
    late = after_end(cell.commands, 4.0)
    rows = {f.location.line for f in late}
    assert len(late) == len(rows) == 3  # the rows at 5, 9 and 12 s, both robots' commands in each
    many = [Command(10.0 + k, (("moveDiscreteCommand", True),), f"plan.csv:{k + 2}:1") for k in range(5000)]
    said = after_end(many, 5.0)
    assert len(said) == AFTER_END_SHOWN + 1 and f"and {5000 - AFTER_END_SHOWN} more" in said[-1].message


def test_a_cells_deviation_variables_are_robot_scoped_and_checked_where_written(tmp_path):
    """`[deviation] variables` of a cell name ROBOT.variable (as its log and its alarms do): unknown robots and
    variables are located at the key, together (a bare 'q0' was scoped twice into 'not observed:
    {mapping}.cell.ur5e.ur5e.q0' without a place); a variable of one robot is compared for that robot only."""
    from cotwin.twin.live.cell_live import run_cell_twin

    spec = load_project(CELL / "twin.toml")
    wrong = spec.with_overrides(deviation_variables=["ur5e.q0", "panda.q9", "q0", "kuka.q1"])
    with pytest.raises(CotwinError) as err:
        CellSystem(wrong)
    messages = [f.message for f in err.value.findings]
    assert len(messages) == 3 and all(f.location.line > 0 for f in err.value.findings), messages
    for name in ("'panda.q9'", "'q0'", "'kuka.q1'"):
        assert sum(name in m for m in messages) == 1, (name, messages)
    result = run_cell_twin(CellSystem(spec.with_overrides(deviation_variables=["panda.q6"], end=2.0)), tmp_path)
    assert list(result.deviation["panda"]["variables"]) == ["panda.q6"] and result.deviation["ur5e"]["variables"] == {}


def test_platform_keys_of_one_robot_are_refused_for_a_cell_at_their_place(tmp_path):
    """[platform] endpoint, base and calibration beside [[robots]] were ignored without a word (the run went
    ahead on MuJoCo): each is an error at its key."""
    project = cell_copy(tmp_path, edit=lambda text: text.replace(
        '[platform]\n', '[platform]\nendpoint = "broker"\nbase = "free"\ncalibration = "x.toml"\n'))
    (tmp_path / "x.toml").write_text("")
    text = project.read_text()
    with pytest.raises(CotwinError) as err:
        CellSystem(load_project(tmp_path / "cotwin.toml"))
    found = {f.message.split(":")[0]: f.location.line for f in err.value.findings}
    lines = text.splitlines()
    table = lines.index("[platform]")
    for key in ("endpoint", "base", "calibration"):
        assert found.get(f"[platform] {key}") == next(k + 1 for k, line in enumerate(lines)
                                                      if k > table and line.startswith(key)), found


def test_a_cells_plant_joints_are_located_and_may_name_one_robot(tmp_path):
    """[plant] friction of a cell: a joint name applies to every robot that has it, ROBOT.joint to that robot
    alone; an unknown name is an error at the table's key with the nearest name (it had no location)."""
    from cotwin.pmodel.perturbation import Perturbation

    spec = load_project(CELL / "twin.toml")
    with pytest.raises(CotwinError) as err:
        CellSystem(replace(spec, plant=Perturbation(friction={"bogus_joint": 2.0, "panda.panda_joint9": 1.0})))
    assert len(err.value.findings) == 2 and all(f.location.line > 1 for f in err.value.findings)
    said = " ".join(f.message for f in err.value.findings)
    assert "'bogus_joint'" in said and "'panda.panda_joint9' is no actuated joint" in said and "did you mean" in said
    cell = CellSystem(replace(spec, plant=Perturbation(friction={"panda.panda_joint1": 3.0})))
    world = cell.world(cell.spec.plant)
    loss = {name: world.model.dof_frictionloss[world.model.joint(world.prefix(name) + joint).dofadr[0]]
            for name, joint in (("panda", "panda_joint1"), ("ur5e", "shoulder_pan_joint"))}
    assert loss["panda"] == 3.0 and loss["ur5e"] != 3.0


def test_a_robots_model_errors_name_the_robot(tmp_path):
    """The Panda given the UR5e's mapping: its errors (unknown p-model 'ur5e', every path) say which robot and
    which pairing they come from (49 errors named no robot)."""
    cell_copy(tmp_path, edit=lambda text: text.replace('mapping = "panda_mapping.pm"', 'mapping = "ur5e_mapping.pm"'))
    with pytest.raises(CotwinError) as err:
        CellSystem(load_project(tmp_path / "cotwin.toml"))
    errors = [f for f in err.value.findings if f.severity.value == "error"]
    assert errors and all(f.message.startswith("robot panda (ur5e_mapping.pm on panda.pm): ") for f in errors)
    assert any("unknown p-model 'ur5e'" in f.message for f in errors)


def test_a_cell_run_cut_short_says_what_each_robots_plan_left_unapplied(tmp_path):
    """A robot's commands not applied before the end are said in its outcome (a single robot's run lists them;
    a cell's said only how many were applied), and --strict counts them."""
    ran = run_cell(CellSystem(load_project(CELL / "cotwin.toml")), tmp_path, end=6.0, plot=False)
    for robot in ROBOTS:
        assert "2 command(s) applied (2 of its plan's 4 not applied before the end)" in ran.outcomes.robots[robot].line()
    assert f"{ROBOTS[0]}: 2 of its plan's 4 command(s) not applied" in ran.outcomes.strict_failures()


def test_rows_out_of_time_order_or_sharing_a_time_are_warned_at_their_line():
    """Rows out of time order were sorted without a word, and rows sharing a time deferred without one: each
    such row is warned about at its line, a cell's robots each judged on their own commands."""
    from cotwin.twin.assembly.scenario import Command, plan_order

    move = (("moveDiscreteCommand", True),)
    said = plan_order([Command(5.0, move, "p.csv:2:1"), Command(1.0, move, "p.csv:3:1"), Command(6.0, move, "p.csv:4:1"),
                       Command(6.0, move, "p.csv:5:1")])
    assert [(f.location.line, "comes after one at 5 s" in f.message, "has the time of line 4" in f.message)
            for f in said] == [(3, True, False), (5, False, True)]
    cell = CellSystem(load_project(CELL / "cotwin.toml"))
    assert [f for r in cell.robots for f in plan_order(r.system.commands)] == []  # one row per time, both robots


def test_a_build_removes_what_an_earlier_build_wrote_there_and_this_one_does_not(tmp_path):
    """Building the cell where the single UR5e twin was built left ur5e_scene.xml (and a removed robot's files)
    beside the new multimodel: a build removes the files the last build wrote that it does not write, and
    nothing else (a file of the user's stays)."""
    from cotwin.twin.assembly.build import build
    from cotwin.twin.assembly.run import load

    out = tmp_path / "build"
    build(load(ROOT / "examples" / "ur5e" / "cotwin.toml"), out)
    assert (out / "ur5e_scene.xml").is_file()
    (out / "notes.txt").write_text("mine")
    build(CellSystem(load_project(CELL / "cotwin.toml")), out)
    assert not (out / "ur5e_scene.xml").exists() and (out / "cell_scene.xml").is_file()
    assert (out / "notes.txt").read_text() == "mine" and (out / "panda.urdf").is_file() and (out / "dmodel.fmu").is_file()


def test_a_cell_rolls_back_and_a_fork_reruns_bit_for_bit_through_a_collision(tmp_path):
    """A cell's state (each robot's mapping, the one world, its contacts so far, the d-model instances, the
    sources) saved in the colliding plan, run on, restored into the same execution and into a fresh one: both
    rerun every value bit for bit, the collision and the contacts included (a cell could not save its state)."""
    from cotwin.cosim.algorithm import algorithm
    from cotwin.cosim.execution import Execution
    from cotwin.twin.assembly.build import dmodel_fmu

    cell = CellSystem(load_project(CELL / "collide.toml"))
    fmu = dmodel_fmu(cell.robots[0].system, tmp_path)

    def execution():
        return Execution(cell.instantiate(fmu), algorithm("jacobi"), cell.spec.step)

    def run(ex, until):
        keys, rows = list(ex.values.keys()), []
        while ex.time < until - 1e-9:
            ex.step()
            rows.append((repr(ex.time), *(repr(ex.values[k]) for k in keys)))
        return rows

    live = execution()
    live.initialize()
    run(live, 2.0)
    state = live.get_state()
    straight = run(live, 4.0)
    world = live.system.units["{mapping}.cell"].world
    assert world.contacts  # the arms touched after the state was taken
    live.set_state(state)
    assert run(live, 4.0) == straight
    fork = execution()
    fork.set_state(state)
    assert run(fork, 4.0) == straight and fork.system.units["{mapping}.cell"].world.contacts == world.contacts
    for ex in (live, fork):
        ex.close()


def weak_panda(folder: Path) -> Path:
    """The cell's twin project in `folder` (3 s), the Panda's joint2 given 0.001 N m: its move never completes,
    the joint pushing at its effort limit at the end."""
    project = cell_copy(folder, "twin.toml", lambda text: text.replace("end = 16.0", "end = 3.0"))
    pm = folder / "panda.pm"
    text = pm.read_text()
    at = text.index("effort = ", text.index("jref panda_joint2 "))
    pm.write_text(text[:at] + "effort = 0.001" + text[text.index(" ", at + len("effort = ")):])
    return project


def test_a_cells_run_and_live_twin_name_the_robot_and_joint_at_its_effort_limit(tmp_path):
    """A single robot's run and live twin named the joints pushing at their effort limit when a move never
    completed (cotwin.twin.assembly.outcomes.saturated_joints); a cell's run and live twin said only '0 move(s)
    completed'. The Panda's joint2 given 0.001 N m: both name the Panda and its joint, on each side."""
    from conftest import cotwin_in_process

    from cotwin.twin.live.cell_live import run_cell_twin

    project = weak_panda(tmp_path)
    said = ("panda: 1 command(s) never completed, and at the end these joints pushed at their effort limit: "
            "panda_joint2 (0.001): too weak")
    ran = cotwin_in_process("run", project, "-o", tmp_path / "run")
    assert ran.returncode == 0, ran.stderr[-2000:]
    assert f"warning: {said}" in ran.stderr and "ur5e: 1 command(s) never" not in ran.stderr
    result = run_cell_twin(CellSystem(load_project(project)), tmp_path / "twin")
    for side in ("pt", "dt"):
        assert [w[:len(said)] for w in result.outcomes[side].warnings()] == [said], side


def test_a_cells_live_twin_says_its_outcomes_and_closes_with_its_count_as_a_run_does(tmp_path):
    """`cotwin twin` of a cell printed its sides' outcomes by a copy of the shared code and closed with no count.
    The weak Panda's saturation warned of on each side, counted in the closing line with the plan's commands after
    the end (three)."""
    from conftest import cotwin_in_process

    twin = cotwin_in_process("twin", weak_panda(tmp_path), "-o", tmp_path / "twin")
    assert twin.returncode == 0, twin.stderr[-2000:]
    assert "PT: panda: 1 command(s) applied" in twin.stdout and "DT: panda: 1 command(s) applied" in twin.stdout
    for side in ("PT", "DT"):
        assert f"{side}: warning: panda: 1 command(s) never completed" in twin.stderr, twin.stderr
    said = sum("warning:" in line for line in twin.stderr.splitlines())
    assert said == 5 and twin.stderr.strip().splitlines()[-1] == "0 error(s), 5 warning(s)", twin.stderr


def test_a_cells_outcomes_make_each_robots_summary_once_from_the_cells_own_mapping_unit(tmp_path):
    """CellOutcomes.warnings made a Summary per robot each time it was asked, and took any unit at the cell
    mapping's name that had a `units` attribute for the cell's mapping. Each robot's Summary is made once, as the
    run ends, its joints read only from the cell's CellMappingUnit."""
    from cotwin.cosim.algorithm import algorithm
    from cotwin.cosim.execution import Execution
    from cotwin.cosim.units import PythonUnit
    from cotwin.twin.assembly.cell import CELL_MAPPING, CellOutcomes
    from cotwin.twin.assembly.outcomes import Summary

    cell = CellSystem(load_project(weak_panda(tmp_path)))
    ran = run_cell(cell, tmp_path / "run", plot=False)
    summaries = ran.outcomes.summaries
    assert set(summaries) == set(ROBOTS) and all(isinstance(s, Summary) for s in summaries.values())
    assert [joint for joint, _ in summaries["panda"].saturated] == ["panda_joint2"]
    assert ran.outcomes.warnings() == [f"panda: {summaries['panda'].saturation()}"]
    summaries["panda"] = Summary([], saturated=summaries["panda"].saturated)  # warnings() reads the summaries
    assert ran.outcomes.warnings() == []  # made, not the ledgers again (whose move never completed)
    look_alike = PythonUnit(CELL_MAPPING.name, [])  # at the mapping's name, not the cell's mapping unit
    look_alike.units = ran.system.units[CELL_MAPPING.name].units
    ran.system.units[CELL_MAPPING.name] = look_alike
    other = CellOutcomes(cell)
    other.simulation_ended(Execution(ran.system, algorithm("jacobi"), cell.spec.step), None)
    assert set(other.summaries) == set(ROBOTS) and all(s.saturated == [] for s in other.summaries.values())
    assert other.warnings() == []
