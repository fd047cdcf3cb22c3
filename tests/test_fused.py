"""The fused loop (cotwin.cosim.fused) gives the same run as the master's step-by-step loop (the FMU path):
byte for byte in the CSV, on the paper's experiment, the pick-and-place and a random plan, under Jacobi and
Gauss-Seidel; `cotwin run` uses it and says so, `--fmu-path` forces the step-by-step loop."""

from __future__ import annotations

import random
import shutil

import pytest

from cotwin.cosim.algorithm import Jacobi
from cotwin.cosim.execution import Execution
from cotwin.diagnostics import CotwinError
from cotwin.cosim.fused import FusedLoop, applicable
from cotwin.twin.assembly.build import build
from cotwin.twin.assembly.run import load, run_twin
from cotwin.twin.assembly.scenario import Command

ALGORITHMS = ["jacobi", "gauss-seidel"]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    from conftest import EXAMPLES

    twins = {name: load(EXAMPLES / "ur5e" / name) for name in ("cotwin.toml", "pick_place_project.toml")}
    out = tmp_path_factory.mktemp("build")
    build(twins["cotwin.toml"], out)
    return twins, out


def random_plan(seed: int) -> list[Command]:
    """Moves to random holes of the plate and gripper commands at random times (some while moving)."""
    rng = random.Random(seed)
    plan, t = [], 0.3
    while t < 9.0:
        kind = rng.choice(["move", "move", "open", "close"])
        if kind == "move":
            values = (("moveDiscreteCommand", True), ("MovementArgs_target_X", rng.randrange(0, 10)),
                      ("MovementArgs_target_Y", rng.randrange(0, 24)), ("MovementArgs_target_Z", rng.randrange(0, 3)))
        else:
            values = ((f"{kind}GripperCommand", True),)
        plan.append(Command(round(t, 1), values, f"{kind} at {t:.1f} s"))
        t += rng.choice([0.1, 0.4, 1.0, 2.5])
    return plan


def twice(twin, built_dir, tmp_path, **options) -> tuple:
    runs = []
    for fused in (False, True):
        out = tmp_path / ("fused" if fused else "fmu")
        out.mkdir()
        for name in ("dmodel.fmu", "build.json"):
            shutil.copy(built_dir / name, out / name)
        ran = run_twin(twin, out, plot=False, fused=fused, **options)
        runs.append((ran, (out / "outputs.csv").read_bytes(), (out / "state").read_bytes()))
    return runs


@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize("case", ["paper", "pick-and-place", "random"])
def test_the_fused_loop_writes_the_csv_of_the_fmu_path_byte_for_byte(built, tmp_path, algorithm, case):
    from conftest import FUZZ_SEED

    twins, built_dir = built
    twin = {"paper": twins["cotwin.toml"], "pick-and-place": twins["pick_place_project.toml"],
            "random": twins["cotwin.toml"].with_plan(random_plan(FUZZ_SEED))}[case]
    end = {"paper": None, "pick-and-place": None, "random": 10.0}[case]
    (fmu, fmu_csv, fmu_state), (fused, fused_csv, fused_state) = twice(twin, built_dir, tmp_path, algorithm=algorithm,
                                                                        end=end, step=0.01 if case == "random" else None)
    assert fmu.result.stepping == "step by step" and fused.result.stepping == "fused"
    assert fused_csv == fmu_csv
    assert fused_csv.count(b"\n") == fused.result.rows + 1 > 100
    assert fused_state == fmu_state  # the state left for a what-if too
    assert [o.__dict__ for o in fused.outcomes.outcomes] == [o.__dict__ for o in fmu.outcomes.outcomes]


class Counter:
    """A unit counting its steps; fails at step `fail`."""

    def __init__(self, fail: int | None = None):
        from cotwin.cosim.units import Port, PythonUnit

        class Unit(PythonUnit):
            def step(unit, t, h):
                if fail is not None and round(t / h) >= fail:
                    from cotwin.diagnostics import CotwinError

                    raise CotwinError("the counter breaks")
                unit.values["n"] += 1

        self.unit = Unit("{c}.c", [Port("n", "Integer", "output")])
        self.unit.values["n"] = 0


def test_a_failing_step_leaves_the_time_and_rows_of_the_last_step_done(tmp_path):
    from cotwin.cosim.observers import CSVWriter
    from cotwin.cosim.system import System
    from cotwin.diagnostics import CotwinError

    times = []
    for fused in (False, True):
        unit = Counter(fail=37).unit
        writer = CSVWriter(tmp_path / f"{fused}.csv")
        execution = Execution(System.of([unit], [], log={unit.name: ["n"]}), Jacobi(), 0.1, observers=[writer],
                              fused=fused)
        with pytest.raises(CotwinError, match="the counter breaks"):
            execution.run(10.0)
        times.append((execution.time, execution.steps, (tmp_path / f"{fused}.partial.csv").read_bytes()))
    assert times[0] == times[1] and times[0][1] == 37


def test_the_fused_loop_says_when_it_does_not_apply(tmp_path):
    from cotwin.cosim.algorithm import Algorithm
    from cotwin.cosim.system import System

    class Other(Jacobi):
        pass

    unit = Counter().unit
    execution = Execution(System.of([unit], [], log={unit.name: ["n"]}), Other(), 0.1, fused=True)
    result = execution.run(1.0)
    assert "does not apply" in result.stepping and "Other" in result.stepping and result.steps == 10
    assert issubclass(Other, Algorithm)


def test_the_generated_loop_is_deterministic_and_straight_line(tmp_path):
    from cotwin.cosim.system import System

    sources = []
    for _ in range(2):
        unit = Counter().unit
        execution = Execution(System.of([unit], [], log={unit.name: ["n"]}), Jacobi(), 0.1)
        execution.initialize()
        assert applicable(execution) is None
        loop = FusedLoop(execution)
        loop.run(5)
        assert execution.steps == 5 and unit.values["n"] == 5 and execution.time == pytest.approx(0.5)
        sources.append(loop.source)
        execution.close()
    assert sources[0] == sources[1] and "for k in range(1, n + 1):" in sources[0]


@pytest.mark.parametrize("fused", [False, True])
def test_advance_steps_until_asked_to_stop_and_continues_from_there(fused):
    from cotwin.cosim.system import System

    unit = Counter().unit
    execution = Execution(System.of([unit], [], log={unit.name: ["n"]}), Jacobi(), 0.1, fused=fused)
    seen = []
    done = execution.advance(100, until=lambda ex: seen.append(ex.time) or unit.values["n"] == 7)
    assert done == 7 and execution.steps == 7 and seen[-1] == execution.time == pytest.approx(0.7)
    assert execution.advance(3) == 3 and unit.values["n"] == 10 and execution.time == pytest.approx(1.0)
    assert execution.stepping == ("fused" if fused else "step by step")
    execution.close()


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_a_what_if_in_the_fused_loop_predicts_what_the_step_by_step_loop_predicts(built, tmp_path, algorithm):
    """From the DT's state at the end of the paper's run: the same outcomes, states, trajectory, collisions."""
    from conftest import FUZZ_SEED

    from cotwin.twin.services.whatif import predict

    twins, built_dir = built
    twin = twins["cotwin.toml"]
    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(built_dir / name, tmp_path / name)
    run_twin(twin, tmp_path, plot=False, algorithm=algorithm)
    state = (tmp_path / "state").read_bytes()
    plan = [Command(c.time - 0.3, c.values, c.where) for c in random_plan(FUZZ_SEED)[:4]]
    predictions = []
    for fused in (False, True):
        p = predict(twin, plan, state, horizon=12.0, algorithm=algorithm, artefacts=tmp_path, fused=fused)
        data = p.as_dict()
        data.pop("wall_seconds")
        data.pop("native_steps")
        predictions.append(data)
    assert predictions[0] == predictions[1]
    assert len(predictions[0]["trajectory"]["time"]) > 10


@pytest.mark.parametrize("from_state", [False, True])
def test_forks_reused_for_plan_after_plan_predict_what_a_fresh_fork_predicts(built, tmp_path, from_state):
    """A sweep's what-ifs on one fork restored plan after plan: each prediction is `predict`'s, in any order,
    reachable holes and not, from the initial state and from the end of the paper's run, the physics steps the
    plans share taken from the fork's memo."""
    from cotwin.twin.analysis.sweep import grid
    from cotwin.twin.services.whatif import Forks, predict

    twins, built_dir = built
    twin = twins["cotwin.toml"]
    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(built_dir / name, tmp_path / name)
    state = None
    if from_state:
        run_twin(twin, tmp_path, plot=False)
        state = (tmp_path / "state").read_bytes()
    plans = grid(twin.models.program, "moveDiscreteCommand", {"target_X": [0, 15], "target_Y": [2, 23], "target_Z": [0]})
    plans += [plans[0], random_plan(7)[:3]]  # the same plan again; another shape (gripper commands too)
    with Forks(twin, state, artefacts=tmp_path) as forks:
        reused = [forks.predict(plan, horizon=6.0).as_dict() for plan in plans]
        remembered, stepped = forks.remembered
    assert remembered > 0 and stepped > 0  # the plans' shared held steps were taken from the memo (cotwin.pmodel.memo)
    fresh = [predict(twin, plan, state, horizon=6.0, artefacts=tmp_path).as_dict() for plan in plans]
    for data in reused + fresh:
        data.pop("wall_seconds")
        data.pop("native_steps")
    assert reused == fresh
    assert {c["feasible"] for p in fresh for c in p["commands"]} >= {True, False}


def test_a_forks_checkpoint_is_not_changed_by_the_plans_run_from_it(built, tmp_path):
    """Forks go back to their start with Execution.rollback, which takes each Python unit's snapshot as it is (no
    bytes): plan after plan (operations run, answers held, a move made), the kept snapshots stay as they were."""
    from cotwin.cosim.state import pack
    from cotwin.twin.analysis.sweep import grid
    from cotwin.twin.services.whatif import Forks

    twins, _ = built
    twin = twins["cotwin.toml"]
    plans = grid(twin.models.program, "moveDiscreteCommand", {"target_X": [0, 15], "target_Y": [2, 23], "target_Z": [0]})
    with Forks(twin, None, artefacts=tmp_path) as forks:
        forks.predict(plans[0], horizon=6.0)
        (_, execution, _, start, _), = forks._forks.values()
        shared = [value[0] for value in forks._shared.values()]
        kept = [pack("checkpoint", {"units": c.units, "values": c.values}) for c in [start, *shared]]
        for plan in plans[1:]:
            forks.predict(plan, horizon=6.0)
        assert [pack("checkpoint", {"units": c.units, "values": c.values}) for c in [start, *shared]] == kept
        with pytest.raises(CotwinError, match="only to the execution that kept it"):
            forks._build(plans[0])[1].rollback(start)


def test_contacts_read_from_the_arrays_are_those_read_contact_by_contact(built):
    """The what-if's contact check (cotwin.twin.services.whatif._Contacts) on random arm poses, many into the table or
    the plate: the same contacts, first times and depths as reading MuJoCo's contacts one by one."""
    import numpy as np

    from cotwin.twin.assembly.run import simulated_endpoint
    from cotwin.twin.services.whatif import _Contacts

    twins, _ = built
    twin = twins["cotwin.toml"]
    endpoint = simulated_endpoint(twin)
    contacts = _Contacts(endpoint, twin.models.tree)
    sim, seen, rng = endpoint.sim, {}, np.random.default_rng(5)
    model, data = sim.model, sim.data
    for k in range(300):
        sim.set_joint_state({j: float(rng.uniform(-3.1, 3.1)) for j in sim.joint_names})
        contacts.check(0.01 * k)
        for c in data.contact[: data.ncon]:  # the reference: contact by contact
            g1, g2 = int(c.geom1), int(c.geom2)
            if (g1 in contacts.robot) == (g2 in contacts.robot) or c.dist > -0.001:
                continue
            robot, other = (g1, g2) if g1 in contacts.robot else (g2, g1)
            key = (model.body(model.geom_bodyid[robot]).name, model.body(model.geom_bodyid[other]).name)
            entry = seen.setdefault(key, {"kind": "contact", "robot": key[0], "with": key[1], "first": 0.01 * k,
                                          "depth": 0.0})
            entry["depth"] = max(entry["depth"], -float(c.dist))
    assert contacts.seen == seen and list(contacts.seen) == list(seen) and len(seen) >= 3


@pytest.mark.parametrize("profile", ["quintic", "trapezoid"])
def test_set_points_written_per_control_period_are_those_of_the_segment(built, profile):
    """The endpoint's set-point written without a dict per control period (SimulatedEndpoint._set_point) puts
    in MuJoCo's controls exactly what write_actuators(segment.at(t)) puts, clipping included."""
    import numpy as np

    from cotwin.mapping.motion import JointMove, Quintic
    from cotwin.twin.assembly.run import simulated_endpoint

    twins, _ = built
    twin = twins["cotwin.toml"]
    ours, theirs = simulated_endpoint(twin), simulated_endpoint(twin)
    rng = np.random.default_rng(11)
    for endpoint in (ours, theirs):
        endpoint.profile = Quintic() if profile == "quintic" else JointMove()
    joints = [j for j in ours.sim.joint_names if j in ours._positioned]
    for k in range(20):
        goals = {ours.actuator_names()[i]: float(rng.uniform(-7, 7)) for i in range(len(joints))}  # some out of range
        for endpoint in (ours, theirs):
            endpoint.command(goals)
        segment = ours.segment
        for t in np.linspace(segment.t0 - 0.1, segment.t0 + segment.duration + 0.1, 37):
            ours._set_point(segment, float(t))
            theirs.sim.write_actuators(segment.at(float(t)))
            assert np.array_equal(ours.sim.controls, theirs.sim.controls)


@pytest.mark.parametrize("profile", ["quintic", "trapezoid"])
def test_the_native_control_loop_moves_the_robot_as_the_python_loop_does(built, profile, monkeypatch):
    """cotwin.mapping.native: the endpoint's moves stepped by the C loop leave MuJoCo's whole state (positions,
    velocities, controls, time) bit for bit where the Python loop leaves it, over moves that end inside a
    step and others that do not, some clipped at a servo's range."""
    import numpy as np

    import cotwin.mapping.native as native
    from cotwin.mapping.motion import JointMove, Quintic
    from cotwin.twin.assembly.run import simulated_endpoint

    real = native.advance_function()
    assert real is not None  # a C compiler is here (the d-model needs one too)
    twins, _ = built
    twin = twins["cotwin.toml"]
    ours, theirs = simulated_endpoint(twin), simulated_endpoint(twin)
    for endpoint in (ours, theirs):
        endpoint.profile = Quintic() if profile == "quintic" else JointMove()
    made, natively = [], ours._advance_natively
    monkeypatch.setattr(ours, "_advance_natively", lambda *args: made.append(natively(*args)) or made[-1])
    names = ours.actuator_names()
    rng = np.random.default_rng(3)
    for k in range(12):
        goals = {names[i]: float(rng.uniform(-4, 4)) for i in range(6)}
        for endpoint in (ours, theirs):
            endpoint.command(goals)
        for dt in (0.001, 0.01, 0.013, 0.1, 0.5):
            monkeypatch.setattr(native, "_LIB", real)
            ours.advance(dt)
            monkeypatch.setattr(native, "_LIB", False)  # the Python loop
            theirs.advance(dt)
            for name in ("qpos", "qvel", "ctrl", "act", "qacc_warmstart"):
                assert np.array_equal(getattr(ours.sim.data, name), getattr(theirs.sim.data, name)), name
            assert ours.sim.data.time == theirs.sim.data.time and ours.sim._steps == theirs.sim._steps
            assert (ours._held is ours.segment) == (theirs._held is theirs.segment)
    assert sum(made) > 1000
