"""Which plan rows raise an event is decided once (`Command.raises`): the controller sends by it and the plan's
warnings count by it. The warning of rows raising nothing counted only rows with an event column set false, while the
controller raises no event for a row without an event column either: a plan giving an event's argument column alone
ran commanding nothing, with no word of it."""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import one_machine
from cotwin.diagnostics import Finding, Location, Severity
from cotwin.dmodel.program import build_program
from cotwin.robosim.check import load_checked
from cotwin.twin.assembly.scenario import AFTER_END_SHOWN, Command, ScenarioUnit, no_event_rows, plan_order, read_plan

H = 0.1  # s: the controller's step


@pytest.fixture(scope="module")
def program(tmp_path_factory):
    """A d-model taking `go` (carrying an int, its argument port `go_value`) and `halt`."""
    folder = tmp_path_factory.mktemp("dmodel")
    (folder / "m.rst").write_text(one_machine(("go: int", "halt"), "\tinitial i\n\tstate S {}\n"
                                              "\ttransition t { from i to S }\n"))
    return build_program(load_checked([folder / "m.rst"]))


def _sent_lines(program, commands: list[Command], end: float) -> set[int]:
    """The plan lines whose commands the controller applied (a real ScenarioUnit stepped to `end`)."""
    unit = ScenarioUnit("controller", program, commands)
    unit.instantiate(0.0)
    for k in range(round(end / H)):
        unit.step(k * H, H)
    return {int(a.command.origin.rsplit(":", 2)[1]) for a in unit.queue.applied}


def _plan(folder: Path, text: str, program) -> list[Command]:
    path = folder / "plan.csv"
    path.write_text(text)
    return read_plan(path, program)


@pytest.mark.parametrize("text", [
    "timestep,go,go_value,halt\n100,true,1,false\n300,false,2,false\n500,1,3,0\n700,0,4,0\n900,false,5,true\n",
    "timestep,go_value\n100,1\n300,2\n",  # an event's argument column without the event's: the rows raise nothing
], ids=["event-columns", "argument-column-alone"])
def test_the_rows_warned_of_raising_no_event_are_exactly_those_the_controller_sends_nothing_for(program, tmp_path, text):
    commands = _plan(tmp_path, text, program)
    lines = {int(c.where.rsplit(":", 2)[1]) for c in commands}
    sent = _sent_lines(program, commands, 1.5)
    warned = {f.location.line for f in no_event_rows(commands, program)}
    assert warned == lines - sent and warned, (warned, sent)
    said = [f.message for f in no_event_rows(commands, program)]
    if "halt" not in text:
        assert said[0] == ("this row at 0.1 s raises no event (no event column, only go_value: an event's arguments are "
                           "read with the event): it commands nothing and is not counted"), said


def test_a_command_raises_the_events_it_sets_true_as_the_controller_shows_them(program):
    """`raises` is the controller's rule: an event port set True (a plan's `true` or `1`), in the command's order."""
    events = {ev.name for ev in program.inputs}
    assert Command(0.0, (("halt", True), ("go", True), ("go_value", 1)), "x").raises(events) == ["halt", "go"]
    assert Command(0.0, (("go", False), ("go_value", 1), ("halt", 0)), "x").raises(events) == []
    assert Command(0.0, (("go_value", 1),), "x").raises(events) == []


def test_plan_order_sums_up_what_it_leaves_out_as_the_other_plan_warnings_do(program):
    """plan_order kept its first AFTER_END_SHOWN warnings and dropped the rest without a word; it ends with one
    saying how many more, as after_end and no_event_rows do (`_capped`)."""
    both = (("go", True), ("go_value", 1), ("halt", True))
    commands = [Command(1.0, both, f"p.csv:{line}:1") for line in range(2, 15)]
    said = plan_order(commands, {"go", "halt"})
    assert AFTER_END_SHOWN == 10 and len(said) == AFTER_END_SHOWN + 1
    # 25 warnings (13 rows raising two events, 12 sharing the first one's time), sorted by line: the 11th at line 7
    assert said[-1] == Finding(Location("p.csv", 7, 1), Severity.WARNING, "... and 15 more warning(s) of rows out of "
                               "time order, sharing a time or raising several events"), said[-1]
