"""A whole twin's state: snapshotted while the arm moves, run on, restored (in the same execution, and
in a fresh one: a fork) and re-run with the same inputs, it gives the same values bit for bit; the
same through cotwin's Python FMUs and the d-model FMU in an FMI master."""

from __future__ import annotations

import shutil

import pytest

from cotwin.cosim.algorithm import algorithm
from cotwin.cosim.execution import Execution
from cotwin.diagnostics import CotwinError
from cotwin.twin.assembly.build import build, dmodel_fmu
from cotwin.twin.assembly.run import dt_endpoint, load

FORK = 1.5  # s: the first command (1.0 s) is being executed, its trajectory in flight
UNTIL = 6.5  # s: past the second command (5.5 s)


@pytest.fixture(scope="module")
def twin():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


@pytest.fixture(scope="module")
def fmu(twin, tmp_path_factory):
    return dmodel_fmu(twin, tmp_path_factory.mktemp("dmodel"))


def _execution(twin, fmu, name: str, step: float = 0.1) -> Execution:
    return Execution(twin.instantiate(fmu, dt_endpoint(twin)), algorithm(name), step)


def _run(execution: Execution, until: float) -> list[tuple]:
    """Every observed value after every step, as exact text (repr of floats)."""
    keys = list(execution.values.keys())
    rows = []
    while execution.time < until - 1e-9:
        execution.step()
        rows.append((repr(execution.time), *(repr(execution.values[k]) for k in keys)))
    return rows


@pytest.mark.parametrize("name", ["jacobi", "gauss-seidel"])
def test_snapshot_run_on_restore_rerun_is_bit_identical(twin, fmu, name):
    live = _execution(twin, fmu, name)
    live.initialize()
    _run(live, FORK)
    mapping = live.system.units["{mapping}.mapping"]
    assert mapping.mapping.endpoint.segment is not None  # a trajectory is in flight
    state = live.get_state()
    straight = _run(live, UNTIL)
    assert len({row[1:] for row in straight}) > 10  # the arm moved: the values changed

    live.set_state(state)  # a rollback
    assert live.time == pytest.approx(FORK) and live.steps == 15
    assert _run(live, UNTIL) == straight

    fork = _execution(twin, fmu, name)  # a fork: fresh units, the saved state
    fork.set_state(state)
    assert _run(fork, UNTIL) == straight
    assert fork.result().steps == len(straight)
    for execution in (live, fork):
        execution.close()


def test_a_fork_runs_a_different_plan_without_touching_the_live_twin(twin, fmu):
    from cotwin.twin.assembly.scenario import Command, ScenarioUnit

    live = _execution(twin, fmu, "jacobi")
    live.initialize()
    _run(live, FORK)
    state = live.get_state()
    reference = _run(live, UNTIL)
    live.set_state(state)

    command = Command(3.0, (("moveDiscreteCommand", True), ("MovementArgs_target_X", 8),
                            ("MovementArgs_target_Y", 4), ("MovementArgs_target_Z", 1)), "what-if")
    source = ScenarioUnit("{controller}.controller", twin.models.program, [command])
    fork = Execution(twin.instantiate(fmu, dt_endpoint(twin), source=source), algorithm("jacobi"), 0.1)
    fork.set_state(state)
    _run(fork, UNTIL)
    executed = [a for _, op, a in fork.system.units["{mapping}.mapping"].executed if op == "movediscrete"]
    assert executed[-1] == {"target_X": 8, "target_Y": 4, "target_Z": 1}
    assert _run(live, UNTIL) == reference  # the live twin continues as if nothing happened
    for execution in (live, fork):
        execution.close()


def test_states_of_another_system_or_algorithm_are_refused(twin, fmu):
    live = _execution(twin, fmu, "jacobi")
    live.initialize()
    state = live.get_state()
    other = _execution(twin, fmu, "gauss-seidel")
    with pytest.raises(CotwinError, match="taken under jacobi"):
        other.set_state(state)
    with pytest.raises(CotwinError, match="not a cotwin state"):
        live.set_state(b"\x80\x05junk")
    live.close()
    other.close()
    with pytest.raises(CotwinError, match="only a running execution"):
        live.get_state()


def test_python_fmus_and_dmodel_fmu_roll_back_in_an_fmi_master(twin, tmp_path):
    """The multimodel of FMUs only (d-model in C, mapping and controller through pythonfmu): every
    FMU saves and restores its state through FMI, so the whole co-simulation rolls back."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    from cotwin.cosim.multimodel import execution_for, read_multimodel

    build(twin, tmp_path)
    for name in ("mapping.fmu", "controller.fmu"):
        cs = read_model_description(str(tmp_path / name)).coSimulation
        assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    assert validate_fmu(str(tmp_path / "mapping.fmu")) == []
    mm = read_multimodel(tmp_path / "multimodel.json")
    execution = execution_for(mm)
    execution.initialize()
    _run(execution, FORK)
    state = execution.get_state()
    straight = _run(execution, 3.0)
    execution.set_state(state)
    assert _run(execution, 3.0) == straight
    execution.close()
    shutil.rmtree(tmp_path, ignore_errors=True)
