"""What-ifs in the native loop (cotwin.twin.services.whatif.Watch, issue 23): a what-if's quiet stretches run in C
and it predicts what the step-by-step loop predicts (trajectory, states, outcomes, collisions, contacts, the
step at which it is over); the simulator's contact watch ends a stretch at a step with a contact, as the
Python check would see it."""

from __future__ import annotations

import ctypes
import shutil

import numpy as np
import pytest

from cotwin.twin.assembly.run import run_twin
from cotwin.twin.assembly.scenario import Command

from test_fused import built, random_plan  # noqa: F401 - the examples' twins and their build, a fixture


def without_wall_time(prediction) -> dict:
    data = prediction.as_dict()
    data.pop("wall_seconds")
    data.pop("native_steps")
    return data


def end_state(twin, built_dir, out, algorithm="jacobi") -> bytes:
    """The DT's state at the end of the paper's run."""
    out.mkdir()
    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(built_dir / name, out / name)
    run_twin(twin, out, plot=False, algorithm=algorithm)
    return (out / "state").read_bytes()


@pytest.mark.parametrize("step", [0.1, 0.01])
@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_what_if_in_the_native_loop_predicts_what_the_step_by_step_loop_predicts(built, tmp_path, algorithm, step):
    """The paper's plan and a random one from the end of the paper's run, and from the start: most steps are
    made natively, and every field of the prediction (its end step included) is the step-by-step loop's."""
    from conftest import FUZZ_SEED

    from cotwin.twin.services.whatif import predict

    twins, built_dir = built
    twin = twins["cotwin.toml"]
    state = end_state(twin, built_dir, tmp_path / "run", algorithm)
    plans = [(twin.commands, None), ([Command(c.time - 0.3, c.values, c.where) for c in random_plan(FUZZ_SEED)[:4]], state)]
    for plan, start in plans:
        native = predict(twin, plan, start, horizon=12.0, step=step, algorithm=algorithm, artefacts=tmp_path)
        stepped = predict(twin, plan, start, horizon=12.0, step=step, algorithm=algorithm, artefacts=tmp_path,
                          fused=False)
        assert without_wall_time(native) == without_wall_time(stepped)
        steps = round((native.end - native.start) / step)
        assert native.native_steps > (steps // 2 if plan is twin.commands else 0) and stepped.native_steps == 0
        assert len(native.trajectory["time"]) == steps + 1


def test_a_decimated_trajectory_keeps_the_steps_the_step_by_step_loop_keeps(built, tmp_path):
    from cotwin.twin.services.whatif import predict

    twins, _ = built
    twin = twins["cotwin.toml"]
    native = predict(twin, twin.commands[:2], None, horizon=8.0, step=0.01, artefacts=tmp_path, decimate=7)
    stepped = predict(twin, twin.commands[:2], None, horizon=8.0, step=0.01, artefacts=tmp_path, decimate=7,
                      fused=False)
    assert without_wall_time(native) == without_wall_time(stepped) and native.native_steps > 100


def driven_into_the_scene(twin, sim, seed: int = 5) -> None:
    """The arm's servos given set-points of a pose in which the robot (not its fingers) touches the scene, the
    arm where it is: it swings into the scene over the next steps (the pose found on a simulator of its own)."""
    from cotwin.pmodel.ik import arm_joints, find_tool
    from cotwin.twin.assembly.run import simulated_endpoint
    from cotwin.twin.services.whatif import _Contacts

    probe = simulated_endpoint(twin)
    contacts, rng = _Contacts(probe, twin.models.tree), np.random.default_rng(seed)
    arm = arm_joints(twin.models.tree, find_tool(twin.models.tree))
    for _ in range(500):
        inside = {j: float(rng.uniform(-3.1, 3.1)) for j in arm}
        probe.sim.set_joint_state(inside)
        contacts.check(0.0)
        if contacts.seen:
            sim.write_actuators(inside)
            return
    raise AssertionError("no contact pose found")


def test_the_c_contact_check_finds_what_the_what_if_records(built):
    """cotwin.mapping.cstep's contact check (MuJoCo's mjData read through its headers) against the what-if's own
    (numpy over the contact arrays) on random poses: it says 'a contact' exactly when the what-if records one."""
    from cotwin.cbuild import compile_library
    from cotwin.mapping.cstep import mujoco_headers
    from cotwin.twin.assembly.run import simulated_endpoint
    from cotwin.twin.services.whatif import DEPTH, _Contacts

    headers = mujoco_headers()
    if headers is None:
        pytest.skip("MuJoCo's C headers are not installed with the mujoco package here")
    lib = compile_library(headers[1] + "int probe(const void *d, const unsigned char *w, double limit) "
                          "{ return m_contact(d, w, limit); }\n", "contactprobe", include_dirs=headers[0])
    lib.probe.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_double]
    twins, _ = built
    twin = twins["cotwin.toml"]
    endpoint = simulated_endpoint(twin)
    contacts = _Contacts(endpoint, twin.models.tree)
    contacts.start()
    sim, rng, found = endpoint.sim, np.random.default_rng(3), 0
    mask, depth = sim.contact_watch
    assert depth == DEPTH and sorted(np.flatnonzero(mask)) == sorted(contacts.robot)
    for k in range(300):
        sim.set_joint_state({j: float(rng.uniform(-3.1, 3.1)) for j in sim.joint_names})
        contacts.seen.clear()
        contacts.check(0.01 * k)
        seen = bool(contacts.seen)
        assert bool(lib.probe(sim.data._address, mask.ctypes.data, -depth)) == seen, k
        found += seen
    assert 10 < found < 290
    contacts.stop()
    assert sim.contact_watch is None


def test_a_contact_inside_a_stretch_ends_it_where_the_what_if_records_it(built, tmp_path):
    """A what-if from a state with the arm swinging into the scene: a contact begins some steps in, and deepens
    over the next. Its first time and depth are the step-by-step loop's: each stretch ended at a step with one."""
    from cotwin.twin.services.whatif import Forks, predict

    twins, _ = built
    twin = twins["cotwin.toml"]
    with Forks(twin, None, artefacts=tmp_path) as forks:  # from the project's initial state
        fork, execution, endpoint, _, _ = forks._build([])
        driven_into_the_scene(twin, endpoint.sim)
        pushed = execution.get_state()
        execution.close()
    plan = twin.commands[:1]
    native = predict(twin, plan, pushed, horizon=3.0, step=0.01, artefacts=tmp_path)
    stepped = predict(twin, plan, pushed, horizon=3.0, step=0.01, artefacts=tmp_path, fused=False)
    assert [c for c in native.collisions if c["kind"] == "contact"], "the pose was meant to touch the scene"
    assert without_wall_time(native) == without_wall_time(stepped)
    assert native.native_steps > 50


def test_a_what_if_from_a_blocked_state_says_it_blocked_since_its_first_step(tmp_path):
    """A mapping that forgets to set `motion` (tests/test_events.py): the DT waits in Moving for an answer
    that cannot come. A what-if from that state starts with its first steps in the native loop, and the wait
    watch, told of them at once, finds the same wait at the same step since the same time as step by step."""
    from conftest import EXAMPLES

    from cotwin.twin.assembly.run import load
    from cotwin.twin.services.whatif import Forks, predict

    project = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", project)
    mapping = project / "mapping.pm"
    forgot = mapping.read_text().replace("\t\taction motion = if ok then Motion::moving else motion end\n", "")
    mapping.write_text(forgot)
    (project / "plan.csv").write_text("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,"
                                      "MovementArgs_target_Z\n1000,true,0,23,1\n")
    twin = load(project / "cotwin.toml")
    ran = run_twin(twin, tmp_path / "out", end=3.0, plot=False)
    assert len(ran.blocked) == 1
    state = (tmp_path / "out" / "state").read_bytes()
    plan = twin.commands[:1]
    native = predict(twin, plan, state, horizon=4.0, step=0.01, artefacts=tmp_path / "out")
    stepped = predict(twin, plan, state, horizon=4.0, step=0.01, artefacts=tmp_path / "out", fused=False)
    assert native.blocked and native.blocked == stepped.blocked
    assert without_wall_time(native) == without_wall_time(stepped) and native.native_steps > 0
    # a sweep's plans sharing their first second (no command due): the wait found in it is found once, since
    # the same time, by every plan (Forks restores the shared start and what the wait watch had seen by then)
    later = [[Command(1.0, c.values, c.where)] for c in (plan[0], plan[0])]
    with Forks(twin, state, artefacts=tmp_path / "out") as forks:
        shared = [without_wall_time(forks.predict(p, horizon=2.0)) for p in later]
        assert forks._shared, "the plans were meant to share their start"
    alone = [without_wall_time(predict(twin, p, state, horizon=2.0, artefacts=tmp_path / "out")) for p in later]
    assert shared == alone and len(alone[0]["blocked"]) == 1


def test_a_what_if_at_a_coarser_physics_step_runs_its_simulator_at_it(built, tmp_path):
    """--physics-step 0.002: the fork's MuJoCo steps 2 ms (half the physics steps of the default), the paper's
    plan still completes, at the same times to within a step; Forks give what predict gives at it."""
    from cotwin.twin.services.whatif import Forks, predict

    twins, _ = built
    twin = twins["cotwin.toml"]
    fine = predict(twin, twin.commands, None, horizon=20.0, artefacts=tmp_path)
    coarse = predict(twin, twin.commands, None, horizon=20.0, artefacts=tmp_path, physics_step=0.002)
    with Forks(twin, None, artefacts=tmp_path, physics_step=0.002) as forks:
        assert forks._build([])[2].sim.model.opt.timestep == 0.002
        reused = [forks.predict(twin.commands, horizon=20.0) for _ in range(2)]
    assert [without_wall_time(p) for p in reused] == [without_wall_time(coarse)] * 2
    assert [c.done for c in coarse.commands] == pytest.approx([c.done for c in fine.commands], abs=0.1 + 1e-9)
    assert coarse.trajectory["q0"] != fine.trajectory["q0"]  # other physics, other digits



@pytest.mark.parametrize("step", [0.0125, 0.0015])
def test_a_step_that_is_not_a_whole_number_of_the_default_physics_step_is_refused(built, tmp_path, step):
    """A what-if's step (predict's, Forks', a sweep's) with the default physics step is checked as a project's
    is: at 1.5 ms the simulator made 2 ms a step (its time ran a third ahead of the co-simulation's) and
    predicted the move a third faster; at 12.5 ms it made 12. A physics step that divides it is taken."""
    from cotwin.diagnostics import CotwinError
    from cotwin.twin.analysis.sweep import grid, run_sweep
    from cotwin.twin.services.whatif import Forks, predict

    twins, _ = built
    twin = twins["cotwin.toml"]
    with pytest.raises(CotwinError, match="not a whole number of the simulator's 1 ms physics steps"):
        predict(twin, twin.commands[:1], None, horizon=1.0, step=step, artefacts=tmp_path)
    with pytest.raises(CotwinError, match="not a whole number"):
        Forks(twin, None, step=step, artefacts=tmp_path)
    plans = grid(twin.models.program, "moveDiscreteCommand", {"target_X": [0], "target_Y": [0], "target_Z": [0]})
    with pytest.raises(CotwinError, match="not a whole number"):
        run_sweep(twin.spec.path, plans, step=step, workers=1, artefacts=tmp_path)
    assert predict(twin, twin.commands[:1], None, horizon=0.5, step=step, artefacts=tmp_path, physics_step=0.0005).end


@pytest.mark.parametrize("physics, said", [(0.003, "is not a whole number of them"), (0.0, "from 0.0001 to 0.01"),
                                           (float("nan"), "from 0.0001"), (0.02, "to 0.01"), (1e-320, "from 0.0001"),
                                           (1e-9, "from 0.0001"), (True, "from 0.0001"), ("0.002", "from 0.0001")])
def test_a_physics_step_a_what_if_cannot_keep_is_refused_before_anything_runs(built, tmp_path, physics, said):
    from cotwin.diagnostics import CotwinError
    from cotwin.twin.analysis.sweep import grid, run_sweep
    from cotwin.twin.services.whatif import predict

    twins, _ = built
    twin = twins["cotwin.toml"]
    with pytest.raises(CotwinError, match=said):
        predict(twin, twin.commands, None, artefacts=tmp_path, physics_step=physics)
    plans = grid(twin.models.program, "moveDiscreteCommand", {"target_X": [0], "target_Y": [0], "target_Z": [0]})
    with pytest.raises(CotwinError, match=said):
        run_sweep(twin.spec.path, plans, workers=1, artefacts=tmp_path, physics_step=physics)


def test_a_plan_ending_before_the_shared_start_ends_where_it_would_alone(built, tmp_path):
    """Forks share a start only with plans whose what-if lasts past it: one of 0.3 s after one of 6 s (both
    with their command at 0.5 s) ends at 0.3 s, as predict makes it alone."""
    from cotwin.twin.analysis.sweep import grid
    from cotwin.twin.services.whatif import Forks, predict

    twins, _ = built
    twin = twins["cotwin.toml"]
    plans = grid(twin.models.program, "moveDiscreteCommand", {"target_X": [3, 4], "target_Y": [5], "target_Z": [0]})
    with Forks(twin, None, artefacts=tmp_path) as forks:
        long = without_wall_time(forks.predict(plans[0], horizon=6.0))
        short = without_wall_time(forks.predict(plans[1], horizon=0.3))
    assert long == without_wall_time(predict(twin, plans[0], None, horizon=6.0, artefacts=tmp_path))
    assert short == without_wall_time(predict(twin, plans[1], None, horizon=0.3, artefacts=tmp_path))
    assert short["end"] == pytest.approx(0.3)


def test_the_first_step_a_condition_turns_true_is_found_from_any_guess():
    """whatif._first: the smallest k for a monotone condition, whatever the guess (far off either way, past the
    limit), None when it never holds within the limit."""
    import random

    from cotwin.twin.services.whatif import _first

    rng = random.Random(1)
    for _ in range(5000):
        limit = rng.choice([1, 5, 50, 1 << 20])
        turns = rng.randint(1, limit + 3)
        guess = turns + rng.uniform(-40, 40)
        assert _first(lambda k: k >= turns, guess, limit) == (turns if turns <= limit else None)


def test_a_physics_step_computed_with_numpy_is_a_number_like_any_other(built, tmp_path):
    from cotwin.twin.services.whatif import physics_timing

    assert physics_timing(0.1, np.float64(0.002)) == 0.002 and physics_timing(0.1, np.float32(0.002)) is not None


@pytest.mark.parametrize("step", [0.1, 0.01])
@pytest.mark.parametrize("settle", [0.0, 1e-9, 0.05])
def test_an_empty_plan_settles_at_the_step_the_step_by_step_loop_settles_at(built, tmp_path, step, settle):
    """Nothing to apply, the arm at rest from the start: the what-if is over once it has rested `settle`, counted
    from the first step; the native loop stopped a step late where `settle` is within a step (the bound on
    the stretch knew of no rest before the stretch began)."""
    from cotwin.twin.services.whatif import Forks, predict

    twins, _ = built
    twin = twins["cotwin.toml"]
    native = predict(twin, [], None, horizon=1.0, step=step, settle=settle, artefacts=tmp_path)
    stepped = predict(twin, [], None, horizon=1.0, step=step, settle=settle, artefacts=tmp_path, fused=False)
    with Forks(twin, None, step=step, artefacts=tmp_path) as forks:
        forked = forks.predict([], horizon=1.0, settle=settle)
    assert without_wall_time(native) == without_wall_time(stepped) == without_wall_time(forked)
    assert native.end < 1.0
