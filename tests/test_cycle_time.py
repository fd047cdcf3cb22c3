"""A d-model counts time in cycles, one per communication step unless [cosim] parameters cycle_period fixes it: a
`cotwin run --step` other than the project's changed what its `since` and `sinceEntry` mean in seconds in
silence (a new user's dwell of 5 cycles lasted 0.05 s instead of 0.5 s). It is a warning at the first reading, which
`cotwin run` and `cotwin twin` both say before running (cotwin.twin.assembly.run.step_warnings)."""

from __future__ import annotations

import shutil

import pytest

from conftest import EXAMPLES, cotwin_in_process
from cotwin.dmodel.program import time_readings
from cotwin.twin.assembly.run import load, step_warnings
from cotwin.twin.project import cycle_time_warnings

TURTLEBOT = EXAMPLES / "turtlebot"  # random_walk.rst reads since(T) in four guards; the project's step is 0.2 s


@pytest.fixture(scope="module")
def walker():
    return load(TURTLEBOT / "cotwin.toml")


def test_the_d_models_readings_of_time_are_found_in_source_order(walker):
    readings = time_readings(walker.models.program)
    assert [(loc.path.rsplit("/", 1)[-1], loc.line) for loc in readings] == \
        [("random_walk.rst", 60), ("random_walk.rst", 66), ("random_walk.rst", 71), ("random_walk.rst", 76)]
    assert time_readings(load(EXAMPLES / "ur5e" / "cotwin.toml").models.program) == []  # the UR5e reads no time


@pytest.mark.parametrize("step, said", [(0.01, "a cycle is 20 times shorter than at the project's step of 0.2 s, "
                                                "so this reading of time (and 3 other reading(s) of time) reaches a "
                                                "value 20 times sooner"),
                                        (0.4, "a cycle is 2 times longer than at the project's step of 0.2 s, so this "
                                              "reading of time (and 3 other reading(s) of time) reaches a value 2 "
                                              "times later")])
def test_a_step_other_than_the_projects_is_a_warning_at_the_first_reading_of_time(walker, step, said):
    warnings = cycle_time_warnings(walker.spec, time_readings(walker.models.program), step)
    assert len(warnings) == 1 and str(warnings[0]).startswith(f"{TURTLEBOT / 'random_walk.rst'}:60:14: warning: ")
    assert said in warnings[0].message and "give [cosim] parameters cycle_period = 0.2" in warnings[0].message


def test_the_projects_own_step_or_a_cycle_period_says_nothing(walker, tmp_path):
    readings = time_readings(walker.models.program)
    assert cycle_time_warnings(walker.spec, readings, 0.2) == []
    pinned = walker.spec.with_overrides(parameters={**walker.spec.parameters, "cycle_period": 0.2})
    assert cycle_time_warnings(pinned, readings, 0.4) == []
    per_step = walker.spec.with_overrides(parameters={**walker.spec.parameters, "cycle_period": 0})  # a cycle a step
    assert len(cycle_time_warnings(per_step, readings, 0.4)) == 1


def test_cotwin_run_says_it_before_running(tmp_path):
    copy = tmp_path / "turtlebot"
    shutil.copytree(TURTLEBOT, copy)
    proc = cotwin_in_process("run", copy / "cotwin.toml", "-o", tmp_path / "out", "--step", "0.01", "--end", "0.1")
    assert proc.returncode == 0, proc.stderr
    assert f"{copy / 'random_walk.rst'}:60:14: warning: the d-model counts time in cycles" in proc.stderr
    same = cotwin_in_process("run", copy / "cotwin.toml", "-o", tmp_path / "same", "--step", "0.2", "--end", "0.4")
    assert same.returncode == 0 and "counts time in cycles" not in same.stderr, same.stderr


def test_a_twins_step_warnings_are_those_of_its_project_and_d_model_unless_a_clock_fixes_the_cycle(walker):
    """The one function both commands call: nothing without --step, nor with an FMI 3.0 clock's --cycle-period."""
    assert [str(w) for w in step_warnings(walker, 0.01)] == \
        [str(w) for w in cycle_time_warnings(walker.spec, time_readings(walker.models.program), 0.01)]
    assert len(step_warnings(walker, 0.01)) == 1
    assert step_warnings(walker, None) == [] and step_warnings(walker, 0.2) == []
    assert step_warnings(walker, 0.01, cycle_period=0.2) == []


def test_cotwin_twin_says_it_before_running(tmp_path):
    """The live twin's PT (an OPC UA plant) is not there: the warning comes before the twin tries to reach it."""
    copy = tmp_path / "turtlebot"
    shutil.copytree(TURTLEBOT, copy)
    absent = "opc.tcp://127.0.0.1:9"  # the discard port: nothing listens there
    proc = cotwin_in_process("twin", copy / "live.toml", "-o", tmp_path / "out", "--pt-url", absent,
                             "--step", "0.01", "--end", "0.1")
    assert proc.returncode != 0 and f"the plant at {absent} failed connect" in proc.stderr, proc.stderr
    warning = f"{copy / 'random_walk.rst'}:60:14: warning: the d-model counts time in cycles"
    assert warning in proc.stderr and proc.stderr.index(warning) < proc.stderr.index("failed connect"), proc.stderr
    same = cotwin_in_process("twin", copy / "live.toml", "-o", tmp_path / "same", "--pt-url", absent,
                             "--step", "0.2", "--end", "0.4")
    assert "failed connect" in same.stderr and "counts time in cycles" not in same.stderr, same.stderr
