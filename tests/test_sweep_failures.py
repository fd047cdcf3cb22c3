"""A sweep reports each failed what-if with its real error and grid point, and exits non-zero; every
cotwin error class survives pickling (a worker's error crosses a process boundary, which turned a
UnitError into BrokenProcessPool)."""

from __future__ import annotations

import csv
import importlib
import inspect
import os
import pickle
import pkgutil
import re
import shutil
import subprocess
import sys

import pytest

import cotwin
from cotwin.diagnostics import Location

SAMPLES = {"str": "a detail", "float": 1.5, "int": 3, "tuple": ("machine", "node"), "Location | None": Location("m.rst", 2, 3)}


def error_classes() -> list[type]:
    """Every exception class defined in a cotwin module."""
    found = set()
    for info in pkgutil.walk_packages(cotwin.__path__, "cotwin."):
        if info.name.endswith("__main__"):
            continue
        try:
            module = importlib.import_module(info.name)
        except ImportError:  # an optional extra that is not installed
            continue
        found |= {obj for obj in vars(module).values() if inspect.isclass(obj) and issubclass(obj, BaseException)
                  and obj.__module__.startswith("cotwin")}
    return sorted(found, key=lambda c: f"{c.__module__}.{c.__qualname__}")


def sample(cls: type) -> BaseException:
    """An instance of `cls` made through its own __init__, each required argument a value of its type."""
    args = []
    for p in list(inspect.signature(cls.__init__).parameters.values())[1:]:
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            args.append("a message") if p.kind is p.VAR_POSITIONAL else None
        elif p.default is p.empty or p.name == "loc":
            args.append(SAMPLES.get(str(p.annotation), "a detail"))
    return cls(*args)


def test_every_cotwin_error_class_pickles_with_its_message_and_attributes():
    classes = error_classes()
    names = {c.__name__ for c in classes}
    assert {"CotwinError", "UnitError", "ExecutionError", "StateError", "EvalError"} <= names, names
    for cls in classes:
        error = sample(cls)
        again = pickle.loads(pickle.dumps(error))
        assert type(again) is cls and str(again) == str(error), cls
        assert again.__dict__.keys() == error.__dict__.keys(), cls
        assert repr(again.__dict__) == repr(error.__dict__), cls


def test_a_unit_error_from_a_worker_process_arrives_whole():
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from cotwin.cosim.units import UnitError

    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        with pytest.raises(UnitError, match=r"unit dmodel: fmi2DoStep failed at t = 0.6 s: division by zero") as caught:
            pool.submit(_raise_unit_error).result()
    assert (caught.value.unit, caught.value.time, caught.value.call) == ("dmodel", 0.6, "fmi2DoStep")


def _raise_unit_error():
    from cotwin.cosim.units import UnitError

    raise UnitError("dmodel", 0.6, "fmi2DoStep", "division by zero")


@pytest.fixture
def dividing(tmp_path):
    """The UR5e project whose d-model divides by the move's X: a move to X = 0 fails inside the FMU."""
    from conftest import EXAMPLES

    project = tmp_path / "dividing"
    shutil.copytree(EXAMPLES / "ur5e", project)
    arm = project / "arm.rst"
    text = arm.read_text()
    text = text.replace("var margs: MovementArgs", "var margs: MovementArgs\n\tvar k: int")
    text = text.replace("state Requested { entry $movediscrete(", "state Requested { entry k = 10 / margs.target_X; $movediscrete(")
    arm.write_text(text)
    return project


def test_a_sweep_reports_each_failed_whatif_with_its_error_and_grid_point_and_exits_non_zero(dividing, tmp_path):
    out = tmp_path / "answers.csv"
    env = dict(os.environ, COTWIN_PROGRESS_SECONDS="0")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "sweep", "cotwin.toml", "--event", "moveDiscreteCommand",
                           "--arg", "target_X=0..2", "--arg", "target_Y=3", "--arg", "target_Z=0", "--horizon", "3",
                           "--workers", "2", "-o", str(out)], cwd=dividing, capture_output=True, text=True, timeout=300,
                          env=env)
    assert proc.returncode == 1, proc.stderr
    assert "BrokenProcessPool" not in proc.stderr and "internal error" not in proc.stderr, proc.stderr
    failed = [line for line in proc.stderr.splitlines() if "failed:" in line]
    assert len(failed) == 1, proc.stderr
    # (the arguments' names are the sweep's columns: MovementArgs_target_X, or target_X where plans' naming is used)
    assert re.search(r"what-if 1 of 3 \((MovementArgs_)?target_X=0, (MovementArgs_)?target_Y=3, (MovementArgs_)?target_Z=0\)",
                     failed[0]), failed[0]
    assert "arm.rst:" in failed[0] and "division by zero in state Requested" in failed[0]
    assert "3 what-ifs" in proc.stdout and "1 FAILED" in proc.stdout
    assert "sweeping: 3/3 what-ifs (100%)" in proc.stderr  # the progress lines of a log
    rows = list(csv.DictReader(open(out)))
    x = next(c for c in rows[0] if c.endswith("target_X"))
    assert [r[x] for r in rows] == ["0", "1", "2"]
    assert "division by zero" in rows[0]["error"] and rows[1]["error"] == rows[2]["error"] == ""
    assert rows[1]["accepted"] == "True" and rows[0]["accepted"] == ""


def test_a_dead_worker_is_reported_per_whatif_not_as_a_broken_pool(tmp_path, monkeypatch):
    """A worker killed by a signal (a crash in an FMU) fails its what-ifs, with the others answered."""
    from conftest import EXAMPLES

    from cotwin.twin.analysis import sweep
    from cotwin.twin.assembly.run import load

    plans = sweep.grid(load(EXAMPLES / "ur5e" / "cotwin.toml").models.program, "moveDiscreteCommand",
                       {"target_X": [0, 1], "target_Y": [3], "target_Z": [0]})
    monkeypatch.setattr(sweep, "_run_chunk", _die_on_x1)
    rows = sweep.run_sweep(EXAMPLES / "ur5e" / "cotwin.toml", plans, horizon=2.0, workers=2, artefacts=tmp_path)
    assert [r.get("error") for r in rows][1] == sweep.DIED
    assert next(v for k, v in rows[1].items() if k.endswith("target_X")) == 1


def _die_on_x1(plans, state, horizon, step, physics=None):
    if any(dict(p[0].values).get("MovementArgs_target_X") == 1 for p in plans):
        os.kill(os.getpid(), 9)
    return [{"ok": True} for _ in plans]


def test_a_sweep_row_spells_a_completion_time_as_the_csv_of_a_run_does():
    """A completion time is a step count times the step (264 * 0.1 = 26.400000000000002): the sweep's row holds it
    rounded as outputs.csv rounds its times (26.4), not with the float's noise."""
    from types import SimpleNamespace

    from cotwin.twin.analysis.sweep import summary

    assert 264 * 0.1 != 26.4
    row = summary(SimpleNamespace(completion_time=264 * 0.1, collisions=[], commands=[]))
    assert row["completion_time"] == 26.4 and repr(row["completion_time"]) == "26.4"
    assert summary(SimpleNamespace(completion_time=None, collisions=[], commands=[]))["completion_time"] is None


def test_a_sweep_without_feasibility_answers_tallies_completions_not_zero_feasible():
    """A d-model without feasibility events (a sorter on an imported arm) answered every what-if with
    feasible empty: the sweep said '4 what-ifs ..., 0 feasible' of four completed moves. It says how many
    completed, and how many were feasible only where some answer said so."""
    from cotwin.twin.analysis.sweep import ERROR, tally

    plain = [{"item": k, "feasible": None, "accepted": True, "time_to_done": 17.7} for k in range(4)]
    assert tally(plain) == "4 completed"
    answered = [{"target_X": 0, "feasible": True, "time_to_done": 3.1}, {"target_X": 1, "feasible": False,
                "time_to_done": None}, {"target_X": 2, ERROR: "boom"}]
    assert tally(answered) == "1 completed, 1 feasible, 1 infeasible"
    # an infeasible move the d-model came back to rest from (its time_to_done set) did not complete: the
    # ledger's verdict is 'infeasible'; the tally said '2 completed, 0 feasible' of two infeasible holes
    refused = [{"target_X": k, "feasible": False, "accepted": True, "time_to_done": 0.4} for k in range(2)]
    assert tally(refused) == "0 completed, 0 feasible, 2 infeasible"
    several = [{"c0_item": 1, "c0_feasible": True, "c0_time_to_done": 2.0, "c1_item": 2, "c1_feasible": False,
                "c1_time_to_done": 0.3}]
    assert tally(several) == "1 completed, 1 feasible, 1 infeasible"


def test_a_sweep_row_gives_no_time_to_done_for_an_infeasible_move(tmp_path):
    """A hole out of reach: the d-model comes back to rest 0.4 s after the command, which the row gave as its
    time_to_done beside an empty completion_time; a move that did not complete has no time to be done."""
    from conftest import EXAMPLES

    from cotwin.twin.analysis.sweep import grid, run_sweep
    from cotwin.twin.assembly.run import load

    project = EXAMPLES / "ur5e" / "cotwin.toml"
    plans = grid(load(project).models.program, "moveDiscreteCommand",
                 {"target_X": [0, 8], "target_Y": [0, 10], "target_Z": [1, 0]})
    rows = {(r["MovementArgs_target_X"], r["MovementArgs_target_Y"], r["MovementArgs_target_Z"]): r
            for r in run_sweep(project, plans, workers=1)}
    refused, reached = rows[(0, 0, 1)], rows[(8, 10, 0)]
    assert refused["feasible"] is False and refused["time_to_done"] is None and refused["completion_time"] is None
    assert reached["feasible"] is True and reached["time_to_done"] > 0 and reached["completion_time"] is not None


def test_a_sweep_says_which_arguments_it_sends_without_values(tmp_path):
    """`--event moveDiscreteCommand --arg target_X=0..1 --arg MovementArgs_target_Z=1`: target_Y, given no values,
    went as 0 in every what-if, a value no column of the CSV shows; the sweep warns, naming the port."""
    from conftest import EXAMPLES

    from cotwin.dmodel.program import build_program
    from cotwin.robosim.check import load_checked
    from cotwin.twin.analysis.sweep import unswept

    program = build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"]))
    ranges = {"target_X": [0, 1], "MovementArgs_target_Z": [1]}
    assert unswept(program, "moveDiscreteCommand", ranges) == ["MovementArgs_target_Y"]
    assert unswept(program, "moveDiscreteCommand", {**ranges, "target_Y": [0]}) == []
    assert unswept(program, "openGripperCommand", {}) == []  # no arguments: nothing to say


def test_feasibility_is_a_question_only_for_a_d_model_that_takes_its_answers():
    """`cotwin whatif` said 'feasibility unknown' of every command of a d-model with no feasibility events."""
    from conftest import EXAMPLES

    from cotwin.dmodel.program import build_program
    from cotwin.robosim.check import load_checked
    from cotwin.twin.assembly.outcomes import answers_feasibility

    assert answers_feasibility(build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"])))
    assert not answers_feasibility(build_program(load_checked([EXAMPLES / "turtlebot" / "random_walk.rst"])))
