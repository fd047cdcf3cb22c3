"""The verifier on models that draw random numbers and take real inputs: random draws are choice
points (the walk's search ends), an incomplete search judges nothing it did not reach, the sampled
inputs are named with --domain, and a long search shows progress."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import cotwin_in_process, one_machine
from cotwin.dmodel.interpreter import Interpreter
from cotwin.dmodel.program import build_program
from cotwin.dmodel.verify import format_report, verify
from cotwin.robosim.check import load_checked

ROOT = Path(__file__).resolve().parents[1]
WALK = ROOT / "examples" / "turtlebot" / "random_walk.rst"
# the domain docs/verification.md documents for the walk: one value on each side of every guard's bound
WALK_DOMAIN = {"closest_distance": [0.3, 0.5, 1.5], "closest_angle": [-45, 0, 45, 120]}

COIN = """package Coin
import Mathematics::*
interface I { event go }
interface O { event heads event tails }
stm M {
	var x: real
	var k: int = 1
	input context { uses I }
	output context { uses O }
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition idle { from A to A exec condition not $go }
	transition t1 { from A to B condition $go action x = random() }
	transition t2 { from B to A exec condition x >= 0.5 action $heads; k = 1 / (k - 1) }
	transition t3 { from B to A exec condition x < 0.5 action $tails }
}
controller C { uses I uses O sref m = M
	connection C on go to m on go (_async) connection m on heads to C on heads (_async)
	connection m on tails to C on tails (_async) }
module Mod { robotic platform P { uses I uses O } cref c = C
	connection P on go to c on go (_async) connection c on heads to P on heads (_async)
	connection c on tails to P on tails (_async) }
"""


def cotwin(*args, env=None, cwd=None):
    """`cotwin ARGS` in this process: the tests check its report and exit status, not the process."""
    return cotwin_in_process(*args, env=env, cwd=cwd)


@pytest.fixture(scope="module")
def walk():
    return build_program(load_checked([WALK]))


def test_random_draws_are_choice_points_so_the_walks_search_ends(walk):
    """A seeded pseudo-random sequence made every state new: 100 000 states and INCOMPLETE."""
    report = verify(walk)
    assert report.complete and report.states < 1000
    assert report.random_values == (0.0, 0.5)


def test_every_random_choice_is_explored_and_shown_in_the_trace(tmp_path):
    (tmp_path / "coin.rst").write_text(COIN)
    program = build_program(load_checked([tmp_path / "coin.rst"]))
    report = verify(program)
    assert report.complete and not report.unreached_transitions  # both sides of the coin
    [division] = [v for v in report.violations if "division by zero" in v.message]
    assert division.trace == [{"go": None}, {}] and division.draws[0] == (0.5,)
    assert "cycle 1: {go}, random draws 0.5" in division.format()
    only_tails = verify(program, random_values=(0.1, 0.2))
    assert not only_tails.violations
    assert only_tails.unreached_transitions == ["M: transition t2"]
    with pytest.raises(Exception, match="division by zero"):  # the trace replays (with the same draw)
        interp = Interpreter(program)
        interp.random.real = lambda: 0.5
        for inputs in division.trace:
            interp.step(inputs)


def test_an_incomplete_search_reports_no_coverage_failure_and_names_the_sampled_inputs(walk, tmp_path):
    report = verify(walk, max_states=40)
    assert not report.complete and report.sampled == ["closest_distance", "closest_angle"]
    text = format_report(walk, report)
    assert "FAIL" not in text, text
    assert "INCOMPLETE: the search stopped at its limit of 40 states" in text
    assert "--domain closest_distance=V1,V2" in text
    assert "?    every transition can be taken: not taken within the limit: Walker: transition" in text
    proc = cotwin("verify", WALK, "--max-states", 40)
    assert proc.returncode == 3 and "FAIL" not in proc.stdout, proc.stdout + proc.stderr


def test_a_complete_search_names_the_sampled_inputs_beside_what_it_never_took(walk):
    text = format_report(walk, verify(walk))
    line = next(x for x in text.splitlines() if x.startswith("FAIL every transition can be taken"))
    assert "obstacle" in line and "closest_distance, closest_angle took only sample values (0 and 1)" in line


def test_the_walk_with_its_documented_domain_is_verified(walk):
    """Every state and all but one transition: keep_going is dead in this model (Forward is entered after
    the clock has counted a cycle, and wander_time = random() < 1), which the verifier rightly says."""
    report = verify(walk, WALK_DOMAIN)
    assert report.complete and not report.violations and not report.unreached_states
    assert report.unreached_transitions == ["Walker: transition keep_going"]
    assert not report.sampled


def test_verify_shows_progress_and_takes_event_names_for_domains(tmp_path):
    env = {"COTWIN_PROGRESS_SECONDS": "0"}
    proc = cotwin("verify", WALK, "--domain", "closestDistance=0.3,0.5,1.5", "--domain", "closest_angle=-45,0,45,120",
                  env=env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr  # keep_going, and nothing else
    assert "FAIL every transition can be taken: never taken Walker: transition keep_going\n" in proc.stdout + "\n"
    progress = [line for line in proc.stderr.splitlines() if line.startswith("verifying: ")]
    assert progress and "states, limit 100000" in progress[-1] and "cycles/s" in progress[-1], proc.stderr
    twice = cotwin("verify", WALK, "--domain", "closestDistance=1", "--domain", "closest_distance=2")
    assert twice.returncode == 2 and "given twice" in twice.stderr


VIA_A_VARIABLE = """interface I { event go: int }
interface O { act(k: int) }
stm M {
	var n: int
	var k: int
	input context { uses I }
	output context { requires O }
	initial i
	state A { }
	state B { entry $act(k) }
	state C { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition not $go }
	transition t2 { from A to B condition $go?n action k = n % 3 }
	transition t3 { from B to A exec condition k == 1 }
	transition t4 { from B to C exec condition k != 1 }
	transition t5 { from C to C exec }
}
controller C { uses I requires O sref m = M
	connection C on go to m on go (_async) }
module Mod { robotic platform P { uses I provides O } cref c = C
	connection P on go to c on go (_async) }
"""


def test_a_value_that_reaches_a_guard_through_a_variable_is_not_data_independent(tmp_path):
    """A sorter's `leg = BIN0 + item % 3`, its guards reading `leg`: verify said the command's value was read by no
    condition and explored one representative value, so a value taking another branch (C, here) went unexplored
    while the report said 'every behaviour'. The value now steers: its domain is explored."""
    from cotwin.dmodel.verify import event_values

    (tmp_path / "v.rst").write_text(VIA_A_VARIABLE)
    program = build_program(load_checked([tmp_path / "v.rst"]))
    values, notes = event_values(program, {})
    assert notes == ["go: 2 value(s) from its domain"]
    report = verify(program)
    assert not report.unreached_states, report.unreached_states


COUNTER = """interface Ev { event tick event report: int }
controller C { cycleDef cycle == 1 uses Ev sref m = M
	connection C on tick to m on tick connection m on report to C on report }
module Mod { cycleDef cycle == 1 robotic platform P { uses Ev } cref c = C
	connection P on tick to c on tick (_async) connection c on report to P on report (_async) }
stm M {
	cycleDef cycle == 1
	input context { uses Ev }
	output context { uses Ev }
	var count: int = 0
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $tick action count = count + %s ; $report!count }
	transition t2 { from A to A exec condition not $tick }
}
"""


def test_a_search_that_hits_its_limit_names_the_variable_that_grows(tmp_path):
    """A counter that grows without bound makes every state new: verify and testgen stopped at their limit saying
    only 'raise --max-states' (a user's mutants ran 8 minutes); they name the variable and how to bound it, and
    say nothing of the kind where the search completes."""
    from cotwin.cli.testing import format_suite
    from cotwin.dmodel.testgen import generate
    from cotwin.dmodel.testgen_graph import explore

    # a value a division reads: not a counter the verifier proves unbounded early (test_verify_growth), so the
    # search runs to its limit
    (tmp_path / "d.rst").write_text((COUNTER % "1").replace("$report!count", "$report!(1000 / (count + 1))"))
    divided = build_program(load_checked([tmp_path / "d.rst"]))
    report = verify(divided, max_states=200)
    assert not report.complete
    assert "; M.count took" in format_report(divided, report) and "grows without bound" in report.growth
    graph = explore(divided, {}, max_states=100)  # a plain counter stops testgen early (test_testgen_growth)
    suite = generate(graph, "transitions")
    assert not graph.complete and not graph.unbounded
    header = format_suite(suite, 0.1, "", str(tmp_path / "s")).splitlines()[0]
    assert header.endswith("(INCOMPLETE: the state limit was reached; M.count took 50 values in the states explored: a "
                           "variable that grows without bound makes every state new, so bound it in the model (e.g. a "
                           "modulus) or compare it with a constant)"), header
    (tmp_path / "c.rst").write_text(COUNTER % "1 - count")  # 0, 1, 0, ...: bounded
    bounded = verify(build_program(load_checked([tmp_path / "c.rst"])), max_states=200)
    assert bounded.complete and bounded.growth == ""


VALUE_TESTED = """interface I { event sort: int }
interface O { a() b() }
stm M {
	input context { uses I }
	output context { requires O }
	initial i
	state Idle { }
	state A { entry $a() }
	state B { entry $b() }
	transition t0 { from i to Idle }
	transition one { from Idle to B condition $sort.1 }
	transition other { from Idle to A condition $sort /\\ not $sort.1 }
	transition idle { from Idle to Idle exec condition not $sort }
	transition ta { from A to A exec }
	transition tb { from B to B exec }
}
controller C { uses I requires O sref m = M
	connection C on sort to m on sort (_async) }
module Mod { robotic platform P { uses I provides O } cref c = C
	connection P on sort to c on sort (_async) }
"""

VIA_AN_OPERATION = """interface I { event go: int }
interface O { act() other() }
interface Soft { place(k: int) }
operation place(k: int) {
	requires O
	initial a
	junction j
	final f
	transition t { from a to j }
	transition ta { from j to f condition k == 1 action $act() }
	transition tb { from j to f condition k != 1 action $other() }
}
stm M {
	var n: int
	input context { uses I }
	output context { requires O requires Soft }
	initial i
	state A { }
	state B { entry place(n) }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition not $go }
	transition t2 { from A to B condition $go?n }
	transition t3 { from B to B exec }
}
controller C { uses I requires O sref m = M opref p = place
	connection C on go to m on go (_async) }
module Mod { robotic platform P { uses I provides O } cref c = C
	connection P on go to c on go (_async) }
"""


@pytest.mark.parametrize("text", [VALUE_TESTED, VIA_AN_OPERATION], ids=["value-test", "operation-argument"])
def test_a_value_a_guard_tests_directly_or_in_an_operation_is_not_data_independent(tmp_path, text):
    """`$sort.1` compares the event's value itself (no variable bound), and `place(n)` hands it to an operation
    whose guards read its parameter: verify called both values 'read by no condition' and explored one (0), so
    `$sort.1`'s state B was reported unreachable and place's k == 1 branch never explored."""
    from cotwin.dmodel.verify import event_values

    (tmp_path / "v.rst").write_text(text)
    program = build_program(load_checked([tmp_path / "v.rst"]))
    _, notes = event_values(program, {})
    assert notes[0].endswith("2 value(s) from its domain"), notes
    report = verify(program)
    assert not report.unreached_states, report.unreached_states


SPEED = one_machine(("speed: real",), """
	var v: real = 0
	initial i
	state A { }
	state Fast { }
	state Slow { }
	transition t0 { from i to A }
	transition t1 { from A to Fast exec condition $speed?v /\\ v > 0.5 }
	transition t2 { from A to Slow exec condition $speed?v /\\ (v < 0.5 \\/ v > 2.0) }
	transition t3 { from A to A exec condition not $speed }
	transition t4 { from Fast to A exec action $warn }
	transition t5 { from Slow to A exec }
""", outputs=("warn",))


def test_a_complete_search_of_sampled_values_is_not_called_verified(tmp_path):
    """A user's model whose two guards on a real are both enabled at 3 only: without --domain the search tried 0 and
    1, printed ok on every line and exited 0, 'all hold' (found by the hostile probe). It says the values were only
    sampled and exits 3 (not verified); with the values that matter, the nondeterminism is found."""
    (tmp_path / "speed.rst").write_text(SPEED)
    proc = cotwin_in_process("verify", tmp_path / "speed.rst")
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert ("  NOT VERIFIED for every value: v took only sample values (0 and 1): give the values that matter with "
            "--domain v=V1,V2,...; what holds below holds for those values only") in proc.stdout
    assert "ok   determinism" in proc.stdout
    given = cotwin_in_process("verify", tmp_path / "speed.rst", "--domain", "speed=0,1,3")
    assert given.returncode == 1 and "FAIL determinism" in given.stdout and "NOT VERIFIED" not in given.stdout
    enough = cotwin_in_process("verify", tmp_path / "speed.rst", "--domain", "speed=0,1")
    assert enough.returncode == 0 and "NOT VERIFIED" not in enough.stdout  # values given: the user's choice


CLOCKED = one_machine(("tick",), """
	%s limit: int = 3
	clock T
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition t1 { from A to B exec condition $tick }
	transition tA { from A to A exec condition not $tick }
	transition tB { from B to B exec condition since(T) <= limit }
	transition t4 { from B to A exec condition since(T) > limit action #T ; $report!1 }
""")


def test_a_search_stopped_by_a_clock_compared_with_a_variable_says_so(tmp_path):
    """`since(T) > limit` with `var limit`: T's count is never capped and A never resets it, so every cycle is a new
    state; the search ran to its limit advising only 'raise --max-states' (found by the hostile probe). It names the
    clock; compared with a constant, the same model is explored to the end."""
    (tmp_path / "clock.rst").write_text(CLOCKED % "var")
    program = build_program(load_checked([tmp_path / "clock.rst"]))
    text = format_report(program, verify(program, max_states=500))
    assert ("INCOMPLETE: the search stopped at its limit of 500 states: what it found holds, what it did not reach is "
            "not judged (raise --max-states; clock M.T is compared with other than a constant, so its count is never "
            "capped and, while it is not reset, every cycle is a new state: the search may never end") in text, text
    (tmp_path / "clock.rst").write_text(CLOCKED % "const")
    program = build_program(load_checked([tmp_path / "clock.rst"]))
    report = verify(program, max_states=500)
    assert report.complete and report.ok, format_report(program, report)


@pytest.mark.parametrize("values, named", [("0.5,1", "1"), ("2,3", "2"), ("-0.25,0", "-0.25")])
def test_random_values_random_never_draws_are_refused(values, named):
    """`--random 2,3` explored draws random() never makes (it draws from [0, 1), as the FMU): the search judged
    behaviour no run has, and none it has (found by the hostile probe). Refused, naming the value."""
    proc = cotwin_in_process("verify", WALK, "--random", values, "--max-states", 10)
    assert proc.returncode == 2 and f"Invalid value for --random: {named}: random() draws from [0, 1)" in proc.stderr, \
        proc.stderr


@pytest.mark.parametrize("values, said", [("0.1,,0.2", "'0.1,,0.2': values must be numbers"),
                                          ("", "'': expected LOW..HIGH or v1,v2,..."),
                                          ("0.5,nan", "'0.5,nan': values must be finite numbers")])
def test_random_values_that_are_no_numbers_are_quoted_as_written(values, said):
    """`--random 0.1,,0.2` was refused as ''random=0.1,,0.2'', a NAME= the user never wrote (the option takes the
    values alone); the refusal quotes what was written."""
    proc = cotwin_in_process("verify", WALK, "--random", values, "--max-states", 10)
    assert proc.returncode == 2 and f"Invalid value for --random: {said}" in proc.stderr, proc.stderr
    assert "random=" not in proc.stderr


def module_line(path: Path) -> int:
    """The line of the module declared in `path`."""
    return next(n for n, line in enumerate(path.read_text().splitlines(), 1) if line.lstrip().startswith("module "))


def test_more_input_combinations_than_a_search_holds_are_refused_before_any_is_made(tmp_path, monkeypatch):
    """`--domain MovementArgs_target_X=0..99999` on the UR5e arm made 204 million input combinations for each state,
    and MemoryError ('a cotwin bug') after 20 s and 3 GB (found by the hostile probe): refused at once, saying how
    many and which event brings them, by verify and testgen alike; testgen leaves no folder of its own behind.
    (Here the limit is lowered, so that a regression fails without filling the memory.)"""
    from cotwin.dmodel import verify as search

    monkeypatch.setattr(search, "MAX_COMBINATIONS", 5000)
    arm = ROOT / "examples" / "ur5e" / "arm.rst"
    domain = ("--domain", "MovementArgs_target_X=0..9")  # 40 values with Y and Z sampled: 512 x 41 combinations
    proc = cotwin_in_process("verify", arm, *domain)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert (f"{arm}:{module_line(arm)}:8: error: 20,992 input combinations in each state, more than 5,000 (10 input "
            "events; values: moveDiscreteCommand 40): give fewer values with --domain") in proc.stderr  # at the module
    proc = cotwin_in_process("testgen", arm, *domain, "--no-drivers", "-o", tmp_path / "tests")
    assert proc.returncode == 1 and "more than 5,000" in proc.stderr, proc.stderr
    assert not (tmp_path / "tests").exists()
    assert search.MAX_COMBINATIONS == 5000 and cotwin_in_process("verify", arm).returncode == 0  # 1024: explored


def _interrupt_after(monkeypatch, cycles: int) -> None:
    """Ctrl-C as the search's cycle `cycles` + 1 starts (the interpreter's step raising KeyboardInterrupt)."""
    step = Interpreter.step
    count = [0]

    def stepping(self, inputs):
        count[0] += 1
        if count[0] > cycles:
            raise KeyboardInterrupt
        return step(self, inputs)

    monkeypatch.setattr(Interpreter, "step", stepping)


def test_an_interrupted_search_reports_the_violations_found_so_far(tmp_path, monkeypatch):
    """Ctrl-C mid-search threw away the division by zero already found (a traceback-free 'interrupted' and
    nothing else); now the report says what it found, that it was interrupted, and exits 1 (a violation)."""
    (tmp_path / "coin.rst").write_text(COIN)
    program = build_program(load_checked([tmp_path / "coin.rst"]))
    whole = verify(program).cycles
    _interrupt_after(monkeypatch, whole - 1)
    report = verify(program)
    assert report.interrupted and not report.complete and not report.ok
    assert any("division by zero" in v.message for v in report.violations)
    text = format_report(program, report)
    assert "INTERRUPTED" in text and "FAIL deadlock" not in text
    monkeypatch.undo()
    _interrupt_after(monkeypatch, whole - 1)
    result = cotwin("verify", tmp_path / "coin.rst", cwd=tmp_path)
    assert result.returncode == 1, result.stderr
    assert "INTERRUPTED" in result.stdout and "division by zero" in result.stdout


def test_an_interrupted_search_without_a_violation_is_not_called_verified(tmp_path, monkeypatch):
    """Interrupted before any violation: the report says so and the exit is 130, not 0 (nothing verified)."""
    (tmp_path / "coin.rst").write_text(COIN)
    _interrupt_after(monkeypatch, 1)
    result = cotwin("verify", tmp_path / "coin.rst", cwd=tmp_path)
    assert result.returncode == 130, result.stdout + result.stderr
    assert "INTERRUPTED" in result.stdout and "ok   " not in result.stdout.replace("ok   every", "")
    assert "nothing is verified" in result.stderr


CHOICE_THEN_TIMELOCK = one_machine(("go",), """
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition idle { from A to A exec condition not $go }
	transition t1 { from A to B condition $go }
	transition t2 { from A to A exec condition $go action $report!1 }
""")


def test_a_choice_made_in_a_cycle_that_then_fails_is_reported_as_nondeterminism(tmp_path):
    """t1 and t2 are both enabled on go; the interpreter takes t1 and the cycle then times out in B. The
    nondeterminism it noted went with the failed cycle: verify said 'ok determinism' and reported the timelock
    alone. Both are reported now, each with its shortest trace."""
    (tmp_path / "m.rst").write_text(CHOICE_THEN_TIMELOCK)
    program = build_program(load_checked([tmp_path / "m.rst"]))
    report = verify(program)
    assert sorted(v.property for v in report.violations) == ["determinism", "timelock"]
    [choice] = [v for v in report.violations if v.property == "determinism"]
    assert "t1, t2 enabled" in choice.message and choice.trace == [{"go": None}]
    assert "FAIL determinism: 1 violation(s)" in format_report(program, report)


KINDS = "enumeration Mode { Slow Fast }\n" + one_machine(("flag: boolean", "mode: Mode", "level: int", "count: nat"), """
	var b: boolean
	var m: Mode
	var k: int
	var c: nat
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition idle { from A to A exec condition else }
	transition f { from A to B condition $flag?b:b }
	transition md { from A to B condition $mode?m:(m == Mode::Fast) }
	transition l { from A to B condition $level?k:(k > 2) }
	transition n { from A to B condition $count?c:(c > 2) }
	transition back { from B to A exec }
""")


@pytest.mark.parametrize("domain, port, value, said", [
    ("b=0..3", "b", 2, "b: 2 is not a value of its type boolean: give 0 (false) or 1 (true)"),
    ("m=0..5", "m", 2, "m: 2 is not a value of its type Mode: give a literal's index: 0 (Slow), 1 (Fast)"),
    ("mode=-1", "m", -1, "m: -1 is not a value of its type Mode"),
    ("k=0.5,3", "k", 0.5, "k: 0.5 is not a value of its type int: give an integer from -2147483648 to 2147483647"),
    ("k=1e300", "k", 1e300, "k: 1e+300 is not a value of its type int"),
    ("level=99999999999999999999", "k", 99999999999999999999, "k: 99999999999999999999 is not a value of its type int"),
    ("c=-1..3", "c", -1, "c: -1 is not a value of its type nat: give an integer from 0 to 2147483647"),
])
def test_a_domain_value_its_port_cannot_carry_is_refused_naming_the_values_it_can(tmp_path, domain, port, value, said):
    """--domain b=0..3 for a Boolean, m=0..5 for an enumeration of two literals, k=0.5 for an int: the search
    explored them as inputs (a Boolean 2, a third literal), states no run can reach, and reported on them. The
    command refuses the option; verify() and testgen's exploration (event_values) a CotwinError."""
    from cotwin.diagnostics import CotwinError
    from cotwin.dmodel.verify import event_values

    (tmp_path / "k.rst").write_text(KINDS)
    proc = cotwin("verify", tmp_path / "k.rst", "--domain", domain)
    assert proc.returncode == 2 and f"Invalid value for --domain: {said}" in proc.stderr, proc.stderr
    program = build_program(load_checked([tmp_path / "k.rst"]))
    with pytest.raises(CotwinError, match=re.escape(said)):
        event_values(program, {port: [value]})


def test_domain_values_of_every_kind_of_port_are_taken_as_its_type_holds_them(tmp_path):
    (tmp_path / "k.rst").write_text(KINDS)
    program = build_program(load_checked([tmp_path / "k.rst"]))
    from cotwin.dmodel.verify import event_values

    values, _ = event_values(program, {"b": [0, 1], "m": [0, 1.0], "k": [3.0, -5], "c": [0, 2 ** 31 - 1]})
    assert values == {"flag": [False, True], "mode": [0, 1], "level": [3, -5], "count": [0, 2 ** 31 - 1]}
    assert all(type(v) is bool for v in values["flag"]) and all(type(v) is int for v in values["level"])
    report = verify(program, {"b": [0, 1], "m": [0, 1], "k": [3], "c": [3]})
    assert not report.unreached_transitions and not report.sampled


SEQUENCES = """package Sq
import sequence_toolkit::*
interface I { event go: Seq(int) event v: vector(real, 3) }
interface O { event done }
stm M {
	var s: Seq(int)
	input context { uses I }
	output context { uses O }
	initial i
	state A { }
	transition t0 { from i to A }
	transition idle { from A to A exec condition not $go }
	transition g { from A to A exec condition %s action $done }
}
controller C { uses I uses O sref m = M
	connection C on go to m on go (_async) connection C on v to m on v (_async) connection m on done to C on done (_async) }
module Mod { robotic platform P { uses I uses O } cref c = C
	connection P on go to c on go (_async) connection P on v to c on v (_async) connection c on done to P on done (_async) }
"""


def test_an_input_event_of_a_sequence_or_vector_is_explored_or_refused_at_its_declaration(tmp_path):
    """An input event whose type has no FMU ports (Seq(int), vector(real, 3)) ended `cotwin verify` and `testgen`
    with an internal error (KeyError: ()). A value no condition reads is one representative value (data
    independence, as for numbers); one a condition reads is refused where the event is declared, and
    build-dmodel's refusal of such events is located there too."""
    model = tmp_path / "seq.rst"
    model.write_text(SEQUENCES % "$go?s")
    proc = cotwin("verify", model)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    note = ("note: go: its value is read by no condition and can make no cycle fail (data independent): "
            "1 representative value (<>)")
    assert note in proc.stdout and "ok   every transition can be taken" in proc.stdout
    model.write_text(SEQUENCES % "$go?s:(size(s) > 0)")
    proc = cotwin("verify", model)
    assert proc.returncode == 1 and "internal error" not in proc.stderr, proc.stderr
    assert (f"{model}:3:21: error: event go: values of type Seq(int) cannot be FMU ports (only boolean, int, nat, real, "
            "enumerations and records of them), and a condition reads its value: the search has no values of its "
            "type to try") in proc.stderr
    proc = cotwin("build-dmodel", model, "-o", tmp_path / "seq.fmu")
    assert proc.returncode == 1 and f"{model}:3:21: error: event go: values of type Seq(int)" in proc.stderr
    assert f"{model}:3:40: error: event v: values of type vector(real, 3)" in proc.stderr


UNSET = one_machine(("go: int",), """
	const lim: int
	var k: int
	initial i
	state A { }
	transition t0 { from i to A }
	transition idle { from A to A exec condition not $go }
	transition g { from A to A exec condition $go?k:(k > lim) action $report!k }
	transition h { from A to A exec condition $go?k:(k <= lim) }
""")


def test_a_constant_without_a_value_is_said_at_the_value_the_search_took(tmp_path):
    """`const lim: int` with no value is an FMU parameter; verify took its default 0 without a word and said 'ok'
    for every property, which holds for lim = 0 only (with lim = 5 and k in {0, 1}, g is never taken)."""
    (tmp_path / "p.rst").write_text(UNSET)
    program = build_program(load_checked([tmp_path / "p.rst"]))
    text = format_report(program, verify(program))
    assert ("note: constant M.lim has no value in the model: the search takes 0, its default (FMU parameter lim); "
            "what holds below holds for that value") in text, text
    report = verify(program, {"k": [0, 1]}, parameters={"lim": 5})
    assert "the search takes 5, as given" in format_report(program, report)
    assert report.unreached_transitions == ["M: transition g"]


DIVIDES = one_machine(("go: int",), """
	var x: int
	var k: int
	initial i
	state A { }
	transition t0 { from i to A }
	transition idle { from A to A exec condition not $go }
	transition g { from A to A exec condition $go?x action k = 10 / (x - 5); $report!k }
""")


def test_a_value_that_can_make_a_cycle_fail_is_not_data_independent(tmp_path):
    """`k = 10 / (x - 5)` with x bound from go: verify said go's value was read by no condition, explored 0 alone
    and called the model verified (exit 0), though go(5) divides by zero. A value read by a divisor, an index or a
    function's argument decides whether a cycle fails: it is explored over its domain (sampled without one: exit 3),
    and the division is found where the domain holds 5."""
    from cotwin.dmodel.verify import event_values

    (tmp_path / "d.rst").write_text(DIVIDES)
    program = build_program(load_checked([tmp_path / "d.rst"]))
    assert event_values(program, {})[1] == ["go: 2 value(s) from its domain"]
    proc = cotwin("verify", tmp_path / "d.rst")
    assert proc.returncode == 3 and "NOT VERIFIED for every value: x took only sample values" in proc.stdout, \
        proc.stdout + proc.stderr
    report = verify(program, {"x": [0, 5]})
    assert [v.property for v in report.violations] == ["division"] and report.violations[0].trace[0] == {"go": 5}
