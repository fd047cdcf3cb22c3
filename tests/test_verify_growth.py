"""A counter that grows without bound is found after a few rounds of one cycle, and the search stops there with the
variable, where it steps and the cycle's inputs (it ran to its 100 000-state limit first); a counter that a modulus or
a guard bounds, or that a round resets, is explored to the end and verified."""

from __future__ import annotations

import pytest

from conftest import cotwin_in_process, one_machine
from cotwin.dmodel import growth
from cotwin.dmodel.program import build_program
from cotwin.dmodel.verify import format_report, verify
from cotwin.robosim.check import load_checked

COUNTER = one_machine(("tick", "clear"), """
	var count: int = 0
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $tick%(guard)s action count = %(step)s ; $report!count }
	transition t2 { from A to A exec condition not $tick%(otherwise)s }
	transition t3 { from A to A exec condition $clear /\\ not $tick action count = 0 }
""")


def program_of(tmp_path, step: str, guard: str = "", otherwise: str = " /\\ not $clear"):
    (tmp_path / "c.rst").write_text(COUNTER % {"step": step, "guard": guard, "otherwise": otherwise})
    return build_program(load_checked([tmp_path / "c.rst"]))


def test_an_unbounded_counter_stops_the_search_in_a_few_rounds_naming_it_and_where_it_steps(tmp_path):
    """`count = count + 1` on every tick, reset by `clear` (the reset does not bound it: tick may come for ever): the
    search ran to 100 000 states before saying anything; it stops after a few rounds of the cycle."""
    program = program_of(tmp_path, "count + 1")
    report = verify(program)
    assert not report.complete and report.states < 20, report.states
    text = format_report(program, report)
    assert report.unbounded and report.growth == ""
    assert (f"INCOMPLETE: the search stopped after {report.states} states: M.count grows without bound: no condition "
            f"reads it and only constant steps change it (count = count + 1 at {tmp_path / 'c.rst'}:14:") in text, text
    assert "round of the cycle through M: A (1 cycle, inputs [1] {tick})" in text and "M.count took 0, 1, 2, 3" in text
    assert "?    deadlock/timelock freedom: no violation in the states explored" in text
    proc = cotwin_in_process("verify", tmp_path / "c.rst")
    assert proc.returncode == 3 and "M.count grows without bound" in proc.stdout, proc.stdout + proc.stderr


@pytest.mark.parametrize("step, guard, otherwise", [
    ("(count + 1) % 5", "", " /\\ not $clear"),  # a modulus: five values
    ("count + 1", " /\\ count < 30", " /\\ not $clear \\/ $tick /\\ count >= 30"),  # a guard stops it after 30 rounds
], ids=["modulus", "guard"])
def test_a_bounded_counter_is_explored_to_the_end_and_verified(tmp_path, step, guard, otherwise):
    program = program_of(tmp_path, step, guard, otherwise)
    report = verify(program)
    assert report.complete and report.ok and not report.unbounded, format_report(program, report)
    assert "count" not in growth.counters(program)


def test_a_round_that_resets_the_counter_proves_nothing(tmp_path, monkeypatch):
    """`count = 0 ; count = count + 1`: the state after one round differs from the one before in count alone, but
    the round sets it: repeating it gives the same state. Replaying the round tells (each round is taken as proof, so
    one round is checked here)."""
    monkeypatch.setattr(growth, "REPETITIONS", 1)
    program = program_of(tmp_path, "count + 1 ; count = 0 ; count = count + 1")
    assert "count" in growth.counters(program)
    report = verify(program)
    assert report.complete and report.ok and not report.unbounded, format_report(program, report)


def test_a_counter_whose_value_can_fail_is_not_watched(tmp_path):
    """`$report!(1000 / count)`: a division by its value may fail, so the value matters; not a counter."""
    (tmp_path / "c.rst").write_text((COUNTER % {"step": "count + 1", "guard": "", "otherwise": " /\\ not $clear"})
                                    .replace("$report!count", "$report!(1000 / (count + 1))"))
    program = build_program(load_checked([tmp_path / "c.rst"]))
    assert growth.counters(program) == {}
    report = verify(program, max_states=100)
    assert not report.complete and not report.unbounded and "M.count took" in report.growth


GRID = one_machine(("a", "b"), """
	var x: int = 0
	var y: real = 0
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition t1 { from A to B exec condition $a action x = x + 1 ; $report!(x * 2 + 1) }
	transition t2 { from A to A exec condition not $a /\\ $b action y = y - 0.5 }
	transition t3 { from A to A exec condition not $a /\\ not $b }
	transition t4 { from B to A exec }
""")


def test_two_counters_on_two_inputs_are_found_among_a_grid_of_states(tmp_path):
    """Every state is (control, x, y): many states alike but for counters, most of them no ancestor of the new one.
    A round of two cycles (A, B) or one cycle stepping a real counter down is found all the same."""
    (tmp_path / "g.rst").write_text(GRID)
    program = build_program(load_checked([tmp_path / "g.rst"]))
    assert set(growth.counters(program)) == {"x", "y"}
    report = verify(program)
    assert not report.complete and report.states < 100 and "grows without bound" in report.unbounded, report.states
