"""The paper's second case study (its section 5.7): a TurtleBot3's random walk with obstacle avoidance, on
RoboTool's published models (read from ../shared, skipped where absent) and on cotwin's own
(examples/turtlebot), co-simulated by the d-model FMU and the mapping only, in two worlds."""

from __future__ import annotations

import csv
import math
import random
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.dmodel.fmu import build_fmu
from cotwin.dmodel.interpreter import Interpreter
from cotwin.cosim.driver import FMUDriver
from cotwin.pmodel.world import load_world
from cotwin.robosim.check import load_checked
from cotwin.dmodel.program import build_program
from cotwin.twin.project import load_project
from cotwin.twin.assembly.run import load, run_twin, simulated_endpoint
from cotwin.twin.assembly.system import DMODEL, MAPPING
from cotwin.twin.analysis.walks import walk

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "turtlebot"
MOBILE = ROOT.parent / "shared" / "robosim" / "mobile"
LIDAR = "Turtlebot3_Burger::BaseLink::TBLidar"


@pytest.fixture(scope="module")
def mobile() -> Path:
    """RoboTool's published mobile robot, read unchanged (absent in a user's fresh clone)."""
    if not (MOBILE / "ObstacleAvoidance_OneStateMachine.rst").is_file():
        pytest.skip(f"the paper's published mobile robot models are not at {MOBILE} (only in the project workspace)")
    return MOBILE


@pytest.fixture(scope="module")
def published(mobile):
    return load(EXAMPLE / "published.toml")


@pytest.fixture(scope="module")
def own():
    return load(EXAMPLE / "cotwin.toml")


@pytest.fixture(scope="module")
def rooms():
    return load_world(EXAMPLE / "rooms.toml")


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _check_walk(system, out: Path, seed: int) -> None:
    """A 30 s walk at 0.2 s: the robot goes somewhere, turns away from every obstacle the d-model sees
    near and ahead, and touches none."""
    w = walk(system, out, seed)
    assert w.collisions == 0, w.touches
    assert w.closest > 0.0
    assert w.length > 0.8 and w.turned > 1.0  # it walked and turned
    rows = _rows(out / "outputs.csv")
    assert len(rows) == 151 and float(rows[-1]["time"]) == pytest.approx(30.0)
    mapping, dmodel = "{mapping}.mapping", "{dmodel}.dmodel"
    near, turned_away = 0, []
    # Jacobi: what the mapping reports after step k, the d-model acts on in step k + 1 and the robot in k + 2
    for seen, acted, moved, after in zip(rows, rows[1:], rows[2:], rows[3:]):
        d, a = float(seen[f"{mapping}.closest_distance"]), float(seen[f"{mapping}.closest_angle"])
        seen_near = seen[f"{mapping}.closestDistance"] == "true" and 0.2 <= d < 1.0 and abs(a) <= 90
        if seen_near and acted[f"{dmodel}.move"] == "true":
            near += 1
            av = float(acted[f"{dmodel}.av"])
            assert av * a < 0 or av == pytest.approx((100 - abs(a)) * math.pi / 180 * -np.sign(a or -1)), (seen, acted)
            if abs(av) > 0.5:  # a firm turn away: the robot's heading follows in the step it is executed
                turn = math.remainder(float(after[f"{mapping}.yaw"]) - float(moved[f"{mapping}.yaw"]), math.tau)
                turned_away.append(turn * av > 0)
    assert near > 5  # obstacles came near, and the d-model steered away each time
    assert turned_away and sum(turned_away) >= 0.8 * len(turned_away)  # and the robot turned that way


def test_listing6_connections_come_from_the_models_and_no_controller(published):
    """Only the d-model FMU and the mapping, connected as the paper's Listing 6 (the value ports named
    after the variables the d-model binds them to)."""
    assert [u.instance for u in published.units] == ["dmodel", "mapping"] and published.source is None
    connections = {(f"{c.source.split('.')[1]}FMU.{c.output}", f"{c.target.split('.')[1]}FMU.{c.input}")
                   for c in published.connections}
    listing6 = {("mappingFMU.closestDistance", "dmodelFMU.closestDistance"),
                ("mappingFMU.closest_distance", "dmodelFMU.closest_distance"),
                ("mappingFMU.closestAngle", "dmodelFMU.closestAngle"),
                ("mappingFMU.closest_angle", "dmodelFMU.closest_angle"),
                ("dmodelFMU.move", "mappingFMU.move"), ("dmodelFMU.lv", "mappingFMU.lv"),
                ("dmodelFMU.av", "mappingFMU.av")}
    assert connections == listing6
    assert published.multimodel()["parameters"] == {f"{DMODEL.name}.seed": 7}
    assert published.models.monitored == ["x", "y", "yaw"]


@pytest.mark.parametrize("seed", [3, 11])
def test_published_models_walk_without_touching_in_two_worlds(published, rooms, tmp_path, seed):
    _check_walk(published, tmp_path / "arena", seed)
    _check_walk(published.in_world(rooms), tmp_path / "rooms", seed)


def test_own_models_walk_as_the_published_ones_decide(own, rooms, tmp_path):
    _check_walk(own, tmp_path / "arena", 5)
    _check_walk(own.in_world(rooms), tmp_path / "rooms", 5)


def test_own_dmodel_makes_the_published_moves(mobile):
    """cotwin's d-model is the published one read as cotwin documents it: same inputs, same seed, same moves."""
    theirs = build_program(load_checked([mobile / "ObstacleAvoidance_OneStateMachine.rst"]), None)
    ours = build_program(load_checked([EXAMPLE / "random_walk.rst"]), None)
    for seed in (0, 1, 2):
        a, b = Interpreter(theirs, {"seed": seed}), Interpreter(ours, {"seed": seed})
        rng = random.Random(seed)
        for _ in range(200):
            scan = {} if rng.random() < 0.1 else {"closestDistance": rng.choice([rng.uniform(0.1, 3.5), 0.3, 0.5]),
                                                   "closestAngle": float(rng.randint(-179, 180))}
            assert [str(o) for o in a.step(scan)] == [str(o) for o in b.step(scan)]


def test_dmodel_fmu_reproduces_the_interpreter_on_a_runs_recorded_inputs(published, tmp_path):
    """Differential test: the inputs the d-model got in a run (the mapping's events and values, row by row)
    replayed into the interpreter and into a freshly built FMU of the published model give the same
    operation calls, arguments and states, and those the run recorded."""
    from fmpy.validation import validate_fmu

    assert published.seed_port == "seed"
    ran = run_twin(published.with_seed(4), tmp_path / "run", plot=False)
    rows = _rows(ran.csv)
    program = published.models.program
    fmu = build_fmu(program, tmp_path / "dmodel.fmu")
    assert validate_fmu(str(fmu)) == []
    interp, driver = Interpreter(program, {"seed": 4}), FMUDriver(program, fmu, {"seed": 4}, step_size=0.2)
    mapping, dmodel = "{mapping}.mapping", "{dmodel}.dmodel"
    calls = 0
    try:
        for seen, acted in zip(rows, rows[1:]):
            scan = {ev: float(seen[f"{mapping}.{port}"]) for ev, port in
                    (("closestDistance", "closest_distance"), ("closestAngle", "closest_angle"))
                    if seen[f"{mapping}.{ev}"] == "true"}
            expected = [str(o) for o in interp.step(scan)]
            assert [str(o) for o in driver.step(scan)] == expected
            assert driver.state() == interp.state_index() == int(acted[f"{dmodel}.state"])
            recorded = [f"move({float(acted[f'{dmodel}.av'])!r}, {float(acted[f'{dmodel}.lv'])!r})"] \
                if acted[f"{dmodel}.move"] == "true" else []
            assert expected == recorded
            calls += bool(recorded)
    finally:
        driver.close()
    assert calls > 100


def test_lidar_sees_the_closest_obstacle_in_degrees_counter_clockwise(own, tmp_path):
    """The LiDAR's nearest return: its range, and its bearing in degrees (0 ahead, counter-clockwise
    positive); not the robot itself nor the floor; nothing in range is inf, and the event does not occur."""
    from cotwin.mapping.runtime import Mapping
    from cotwin.pmodel.world import World, Obstacle

    world = World("one box", [Obstacle("box_1", "box", 0.0, 1.0, (0.4, 0.2, 0.3))], (0.0, 0.0, 0.0), (-3, 3, -3, 3))
    system = own.in_world(world)
    endpoint = simulated_endpoint(system)
    readings = endpoint.read_sensors()
    # the LiDAR sits 3.2 cm behind the base's origin (turtlebot3_burger.pm): the box's near face, 0.9 m to
    # its left, is nearest straight across
    assert readings[f"{LIDAR}.closestDistance"] == pytest.approx(0.9, abs=0.005)
    assert readings[f"{LIDAR}.closestAngle"] == 90.0
    turned = own.in_world(World("one box", world.obstacles, (0.0, 0.0, math.radians(-60.0)), (-3, 3, -3, 3)))
    assert simulated_endpoint(turned).read_sensors()[f"{LIDAR}.closestAngle"] == pytest.approx(150.0, abs=1.0)
    mapping = Mapping(system.models.project, endpoint, monitor=system.spec.readings)
    mapping.start_mapping()
    assert mapping.get_event("closestAngle")
    assert mapping.event_value("closestAngle") == readings[f"{LIDAR}.closestAngle"]
    empty = own.in_world(World("nothing", [], (0.0, 0.0, 0.0), (-3, 3, -3, 3)))
    nothing = simulated_endpoint(empty).read_sensors()
    assert nothing[f"{LIDAR}.closestDistance"] == math.inf and math.isnan(nothing[f"{LIDAR}.closestAngle"])
    blind = Mapping(empty.models.project, simulated_endpoint(empty))
    blind.start_mapping()
    assert not blind.get_event("closestDistance") and not blind.get_event("closestAngle")


def test_lidar_scans_at_its_rate_and_holds_between_scans(own):
    """5 scans a second: a reading changes only at multiples of 0.2 s, while the robot moves between."""
    endpoint = simulated_endpoint(own)
    sim = endpoint.sim
    endpoint.command({"LeftMotor": 10.0, "RightMotor": 10.0})
    seen = [sim.read_sensors()[f"{LIDAR}.closestDistance"]]
    for k in range(1, 21):
        sim.advance(0.05)
        seen.append(sim.read_sensors()[f"{LIDAR}.closestDistance"])
    changes = [k for k in range(1, len(seen)) if seen[k] != seen[k - 1]]
    assert changes and all(k % 4 == 0 for k in changes)


def test_run_writes_fig18_and_a_top_view(own, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(EXAMPLE / "cotwin.toml"), "-o", str(tmp_path),
                           "--end", "4"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "figure.png").stat().st_size > 10_000 and (tmp_path / "path.png").stat().st_size > 10_000
    from cotwin.twin.assembly.run import figure_panels

    assert [(label, names) for label, names, _ in figure_panels(own)] == [
        ("(1) closest distance [m]", [f"{MAPPING.name}.closest_distance"]),
        ("(2) closest angle [deg]", [f"{MAPPING.name}.closest_angle"]),
        ("(3) lv [m/s]", [f"{DMODEL.name}.lv"]), ("(4) av [rad/s]", [f"{DMODEL.name}.av"])]


def test_nothing_of_the_arm_is_set_up_for_a_mobile_robot(own, tmp_path):
    """No Flex-cell, no inverse kinematics, no joint mirrors: the second robot needs no arm."""
    ran = run_twin(own, tmp_path, end=1.0, plot=False)
    mapping = ran.mapping.mapping
    assert mapping._registry is None and mapping.monitored == ["x", "y", "yaw"]
    assert type(own.models.scene).__name__ == "World"
    assert load(ROOT / "examples" / "ur5e" / "cotwin.toml").models.scene.__class__.__name__ == "FlexCell"


# ---- worlds and project options: strict, located errors ----

def _project(tmp_path: Path, extra: str, world: str | None = None) -> Path:
    for name in ("random_walk.rst", "turtlebot3_burger.pm", "walk_mapping.pm"):
        shutil.copy(EXAMPLE / name, tmp_path / name)
    if world is not None:
        (tmp_path / "world.toml").write_text(world)
    path = tmp_path / "cotwin.toml"
    path.write_text('[models]\ndmodel = "random_walk.rst"\npmodel = "turtlebot3_burger.pm"\n'
                    'mapping = "walk_mapping.pm"\n' + extra)
    return path


def test_bad_worlds_are_reported_at_their_keys(tmp_path):
    path = _project(tmp_path, '[platform]\nworld = "world.toml"\nbase = "free"\n',
                    'name = "bad"\n[arena]\nsize = [4.0]\n[start]\nx = 0.5\nyaw = "north"\n'
                    '[[box]]\ncenter = [9.0, 0.0]\nsize = [0.2, 0.2, 0.2]\n[[cylinder]]\ncenter = [0, 0]\n'
                    '[[wall]]\nfrom = [0, 0]\nto = [1, 1]\ncolour = "red"\n')
    with pytest.raises(CotwinError) as err:
        load_project(path)
    text, world = str(err.value), tmp_path / "world.toml"
    assert f"{world}:3:1: error: [arena] size: must be a list of 2 numbers" in text
    assert f"{world}:6:1: error: [start] yaw must be a finite number, got 'north'" in text
    assert f"{world}:10:1: error: [[cylinder]] 1 needs 'radius'" in text
    assert f"{world}:15:1: error: unknown key 'colour' in [[wall]] 1" in text
    (tmp_path / "world.toml").write_text('[arena]\nsize = [2.0, 2.0]\n[[box]]\ncenter = [5.0, 0.0]\n'
                                         'size = [0.2, 0.2, 0.2]\n')
    with pytest.raises(CotwinError, match=rf"{world}:3:1: error: box_1 at \(5, 0\) is outside the arena"):
        load_project(path)
    (tmp_path / "world.toml").write_text('[[cylinder]]\ncenter = [0.05, 0.0]\nradius = 0.1\n[start]\nx = 0.0\n')
    with pytest.raises(CotwinError, match=rf"{world}:4:1: error: the robot \(Turtlebot3_Burger, 0.1\d+ m from its "
                                          r"base to its farthest point\) would start touching cylinder_1"):
        simulated_endpoint(load(path))


def test_bad_project_options_are_reported_at_their_keys(tmp_path):
    path = _project(tmp_path, '[platform]\nbase = "floating"\n[[platform.stand_in]]\nmesh = "base.stl"\nshape = "box"\n'
                    'size = [0.1, 0.1]\n[monitor]\njoints = 3\n[cosim]\nparameters = { seed = "x" }\n'
                    '[figure]\npanels = [{ variables = ["lv"] }]\n[world]\nsize = 1\n')
    with pytest.raises(CotwinError) as err:
        load_project(path)
    text = str(err.value)
    for where, message in ((6, "[platform] base must be one of 'fixed', 'free'"),
                           (10, "size of a box is 3 positive number(s) (length, width, height)"),
                           (12, "[monitor] joints: must be \"arm\", \"actuated\" or a list of joint names"),
                           (14, "[cosim] parameters: each parameter is a number or a Boolean: seed"),
                           (16, "panel variables are written unit.variable"),
                           (18, "unknown key 'size' in [world]")):
        assert f"{path}:{where}:1: error: " in text and message in text, (where, message, text)
    path = _project(tmp_path, '[cosim]\nparameters = { sed = 1 }\n[[platform.stand_in]]\nmesh = "none.stl"\n'
                    'shape = "sphere"\nsize = [0.1]\n')
    with pytest.raises(CotwinError, match=r"p-model Turtlebot3_Burger names no such mesh that cannot be read"):
        load(path)
    path.write_text(path.read_text().split("[[platform")[0])
    with pytest.raises(CotwinError, match=r"the d-model has no parameter 'sed'; did you mean 'seed'\? \(it has cycle_period, seed\)"):
        load(path)


def test_an_event_binding_a_value_must_say_what_it_is(tmp_path, own):
    from cotwin.mapping.runtime import Mapping

    text = (EXAMPLE / "walk_mapping.pm").read_text().replace(
        "equation closest_distance == Turtlebot3_Burger::BaseLink::TBLidar.closestDistance",
        "equation Turtlebot3_Burger::BaseLink::TBLidar.closestDistance > 0")
    for name in ("random_walk.rst", "turtlebot3_burger.pm"):
        shutil.copy(EXAMPLE / name, tmp_path / name)
    (tmp_path / "walk_mapping.pm").write_text(text)
    project = load_checked([tmp_path])
    with pytest.raises(CotwinError, match=r"walk_mapping.pm:\d+:\d+: input event closestDistance binds "
                                          r"'closest_distance' but no equation 'closest_distance == \.\.\.'"):
        Mapping(project, simulated_endpoint(own))


# ---- the live twin: the PT a TurtleBot plant over OPC UA, the DT the embedded simulator ----

def _live(project: Path, out: Path, perturbation=None, end: float = 12.0):
    from cotwin.mapping.opcua import OPCUAEndpoint
    from cotwin.twin.services.plant import load_plant
    from cotwin.twin.live.runtime import LiveTwin

    system = load(project)
    options = {} if perturbation is None else {k: v for k, v in vars(perturbation).items()}
    plant = load_plant(project, "opc.tcp://127.0.0.1:0", **options).start()
    dt = simulated_endpoint(system)
    try:
        with OPCUAEndpoint(system.models.tree, plant.url, timeout=5, reset=True) as pt:
            result = LiveTwin(system, out, pt=pt, dt=dt, end=end).run()
    finally:
        plant.stop()
    return result, plant.endpoint.sim.touches, dt.sim.touches


def test_live_twin_of_the_walk_with_a_nominal_plant_walks_the_same_walk(tmp_path):
    """PT and DT run the same d-model with the same seed: a plant without perturbation walks the DT's
    very walk (the twin runtime is not the arm's: wheels by speed, a LiDAR and a free base over OPC UA)."""
    from cotwin.pmodel.perturbation import Perturbation

    result, pt_touches, dt_touches = _live(EXAMPLE / "live.toml", tmp_path, Perturbation())
    assert result.pt.steps == result.dt.steps == 60 and result.deviation["alarms"] == 0
    pt, dt = _rows(tmp_path / "pt" / "outputs.csv"), _rows(tmp_path / "dt" / "outputs.csv")
    assert pt == dt and float(pt[-1]["{mapping}.mapping.x"]) != float(pt[0]["{mapping}.mapping.x"])
    assert not pt_touches and not dt_touches


def test_live_twin_of_the_walk_sees_the_reality_gap_of_a_perturbed_plant(tmp_path):
    """The project's [plant] (a dragging wheel, a late drive, a noisy LiDAR): the same seed drives both, the
    walks part by the reality gap, which the deviation service measures; neither robot touches anything."""
    result, pt_touches, dt_touches = _live(EXAMPLE / "live.toml", tmp_path)
    assert not pt_touches and not dt_touches
    deviation = result.deviation["variables"]
    assert set(deviation) == {"x", "y"} and 0 < max(v["max_deviation"] for v in deviation.values()) < 0.5
    pt, dt = _rows(tmp_path / "pt" / "outputs.csv"), _rows(tmp_path / "dt" / "outputs.csv")
    moves = [(p["{dmodel}.dmodel.move"], d["{dmodel}.dmodel.move"]) for p, d in zip(pt, dt)]
    assert moves[:5] == [(d, d) for _, d in moves[:5]]  # the same random walk starts on both sides
    assert (tmp_path / "figure.png").is_file() and (tmp_path / "deviation.json").is_file()


@pytest.mark.parametrize("project", ["cotwin.toml", "published.toml"])
def test_the_multimodel_with_the_mapping_fmu_walks_the_same_walk(project, tmp_path):
    """`cotwin build`'s multimodel.json (the mapping packaged as an FMU carrying the project, its world and the
    p-model's mesh files) run by `cotwin simulate` gives `cotwin run`'s very trace."""
    if project == "published.toml" and not (MOBILE / "OA_mapping.pm").is_file():
        pytest.skip(f"the paper's published mobile robot models are not at {MOBILE}")
    from cotwin.cosim.multimodel import execution_for, read_multimodel
    from cotwin.twin.assembly.build import build

    system = load(EXAMPLE / project)
    written = build(system, tmp_path / "build")
    mm = read_multimodel(written["multimodel"])
    execution_for(mm, tmp_path / "simulated.csv", None, None).run(10.0)
    ran = run_twin(system, tmp_path / "run", end=10.0, plot=False)
    simulated, direct = _rows(tmp_path / "simulated.csv"), _rows(ran.csv)
    assert simulated == direct and len(direct) == 51
    assert float(direct[-1]["{mapping}.mapping.x"]) != float(direct[0]["{mapping}.mapping.x"])
