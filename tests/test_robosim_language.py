"""The RoboSim language as RoboTool reads it, one test per family of RoboSim.xtext's rules (and the
RoboChart.xtext rules it builds on): a small model using the family, checked, and where it can run,
run by the interpreter and by the generated C (an FMU through FMPy) with identical traces.

Families (RoboSim.xtext rule -> test):
  RCPackage, Import, `diagram`, qualified names, .rct declarations -> test_packages_imports_and_rct_declarations
  RCModule / SimModule, RoboticPlatformDef, `rref`, `cref`, Connection `(_async)`, `[mult]`  -> test_modules_platform_references_and_connections
  ControllerDef / SimControllerDef, OperationDef, OperationRef (`opref`), software operation calls -> test_operations_definitions_references_and_calls
  StateMachineDef / SimMachineDef, InputContext, OutputContext, Event, ConstCycle (`cycleDef`) -> test_machines_contexts_and_cycle_definitions
  Transition, ExecTrigger, `condition else`, Node kinds, state actions -> test_transitions_exec_else_and_state_actions
  Clock, ClockReset `#T`, ClockExp `since`, StateClockExp `sinceEntry`, CycleExp -> test_clocks_since_and_since_entry
    (and their bounded counts for the verifier -> test_clock_counts_stop_where_no_comparison_tells_them_apart)
  SimRefExp (`$e`, `$e?x`, `$e?x:p`, `$e.v`, `$v`), SendEvent, SimCall `$op()` -> test_dollar_expressions_sends_and_platform_calls
  BasicStatement (exec, if, skip, `( )`, assignment to fields and elements, `;`) -> test_statements
  Expression levels (quantifiers, iff, =>, \\/, /\\, not, chained comparisons, the, let, if, as) -> test_logic_comparisons_and_binding_forms
  PlusMinus, MultDivMod, Neg, Selection, CallExp, RefExp, EnumExp, RecordExp, TupleExp, functions -> test_arithmetic_records_tuples_enumerations_functions
  VectorOrMatrixExp `[|a, b; c, d|]`, vector and matrix types -> test_vectors_and_matrices
  SetExp, SetRange, SetComp, SeqExp, CatExp, the set and sequence toolkits -> test_sets_sequences_and_toolkits
  Types (product, function, relation, Set, Seq, ?X), TypeDecl (type, datatype, record, enumeration) -> test_type_forms
  RoboChart-only and unrunnable forms (probabilistic, wait, triggers, unbounded quantifiers) -> test_unrunnable_forms_are_located
"""

from __future__ import annotations

import pytest

from cotwin.diagnostics import CotwinError, Severity
from cotwin.dmodel.program import build_program
from cotwin.robosim.check import check_paths
from language_support import checked, run_both

# A platform with one input event carrying an int, a few outputs, and one operation; most tests plug
# a machine into it.
PLATFORM = """interface In { event go: int event stop }
interface Out { event out: int event flag: boolean event real_out: real }
interface Ops { move(x: real, y: int) }
controller C {
	cycleDef cycle == 1
	uses In uses Out requires Ops
	sref m = M
	connection C on go to m on go
	connection C on stop to m on stop
	connection m on out to C on out
	connection m on flag to C on flag
	connection m on real_out to C on real_out
}
module Mod {
	cycleDef cycle == 1
	robotic platform P { uses In uses Out provides Ops }
	cref c = C
	connection P on go to c on go (_async)
	connection P on stop to c on stop (_async)
	connection c on out to P on out (_async)
	connection c on flag to P on flag (_async)
	connection c on real_out to P on real_out (_async)
}
"""


def machine(body: str, extra: str = "") -> dict[str, str]:
    """A project: the platform above, the machine M with this body, and extra declarations."""
    return {"m.rst": PLATFORM + extra + "stm M {\n\tcycleDef cycle == 1\n\tinput context { uses In }\n"
                                        "\toutput context { uses Out requires Ops }\n" + body + "\n}\n"}


def errors(result) -> list[tuple[str, int, int, str]]:
    return [(f.location.path.rsplit("/", 1)[-1], f.location.line, f.location.column, f.message)
            for f in result.findings if f.severity is Severity.ERROR]


def test_packages_imports_and_rct_declarations(tmp_path):
    files = {
        # RoboChart declarations beside the d-models, in their own package
        "decl.rct": """package Shared
diagram shared
interface Ev { event go: Pos event out: int }
interface Ops { move(x: real, y: int) }
datatype Pos { x: int y: int }
enumeration Mode { Slow Fast }
robotic platform RP { uses Ev provides Ops }
function twice(n: int): int { postcondition result == 2 * n }
controller Unused { uses Ev stm S { uses Ev initial i state A { } transition t { from i to A trigger go } } }
""",
        # two machines called M in two packages: no clash
        "other.rst": """package Other
stm M { initial i state A { } transition t { from i to A } transition u { from A to A exec } }
""",
        "main.rst": """package Sim
import Shared::*
stm M {
	var p: Pos
	var mode: Shared::Mode = Mode::Slow
	input context { uses Ev } output context { uses Ev requires Ops }
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition t1 { from A to B condition $go?p action $out!twice(p.x + p.y); mode = Mode::Fast }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from B to A exec }
}
controller C { cycleDef cycle == 1 uses Ev requires Ops sref m = M
	connection C on go to m on go connection m on out to C on out }
module Mod { cycleDef cycle == 1 rref P = Shared::RP cref c = C
	connection P on go to c on go (_async) connection c on out to P on out (_async) }
""",
    }
    trace = run_both(tmp_path, files, [{}, {"go": {"x": 2, "y": 5}}, {}, {"go": {"x": -1, "y": 0}}],
                     module="Mod")
    assert [t[0] for t in trace] == [[], ["out!14"], [], ["out!-2"]]
    # names are per package: without the import, Pos and twice are unknown, with a hint
    (tmp_path / "main.rst").write_text(files["main.rst"].replace("import Shared::*\n", ""))
    found = errors(check_paths([tmp_path]))
    assert any(m.startswith("unknown type 'Pos' (there is Shared::Pos") for _, _, _, m in found)


def test_modules_platform_references_and_connections(tmp_path):
    files = machine("""	initial i
	state A { }
	transition t0 { from i to A }
	state B { }
	transition t1 { from A to B condition $go?x action $out!x }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from B to A exec }
	var x: int""")
    assert run_both(tmp_path, files, [{"go": 4}, {}])[0][0] == ["out!4"]
    # a connection to the platform must be asynchronous; [mult] marks a bidirectional connection
    text = files["m.rst"].replace("connection P on go to c on go (_async)", "connection P on go to c on go")
    (tmp_path / "m.rst").write_text(text.replace("connection c on out to P on out (_async)",
                                                 "connection c on out to P on out (_async) [mult]"))
    found = errors(check_paths([tmp_path]))
    assert [m for _, _, _, m in found] == [
        "connection in module Mod: a connection with the robotic platform must be asynchronous: add (_async)"]
    # a module holds one platform (or rref) and no state machine
    (tmp_path / "m.rst").write_text(files["m.rst"].replace("cref c = C", "cref c = C sref s = M"))
    assert any("must not have a state machine outside a controller" in m for *_, m in errors(check_paths([tmp_path])))


def test_an_input_event_the_controller_connects_to_nothing_is_warned_of_at_the_machine_reference(tmp_path):
    """A new user's controller without its connections checked clean, verified 'never reached', and ran with every
    command 'not taken (the d-model was in state Ready)': an input event of a machine's input context that no
    connection of its controller brings never occurs. It is a warning at the machine's reference, naming the events."""
    files = machine("""	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go /\\ not $stop }""")
    (tmp_path / "m.rst").write_text(files["m.rst"])
    assert not [f for f in check_paths([tmp_path]).findings if "connects nothing" in f.message]
    (tmp_path / "m.rst").write_text(files["m.rst"].replace("\tconnection C on stop to m on stop\n", ""))
    said = [(f.severity, f.location.line, f.message) for f in check_paths([tmp_path]).findings
            if "connects nothing" in f.message]
    assert said == [(Severity.WARNING, 7, "controller C connects nothing to input event stop of m: it never occurs "
                     "in M (add e.g. 'connection C on stop to m on stop (_async)')")]
    # and an event the controller passes on that the module connects to nothing
    (tmp_path / "m.rst").write_text(files["m.rst"].replace("\tconnection P on stop to c on stop (_async)\n", ""))
    said = [(f.severity, f.location.line, f.message) for f in check_paths([tmp_path]).findings
            if "connects nothing" in f.message]
    assert said == [(Severity.WARNING, 17, "module Mod connects nothing to event stop of c: controller C passes it to its "
                     "machines, which never see it (add e.g. 'connection P on stop to c on stop (_async)')")]


def test_operations_definitions_references_and_calls(tmp_path):
    extra = """interface Shared { var n: int }
interface Soft { add(k: int) twice(k: int) }
operation add(k: int) {
	requires Shared
	var before: int = n
	terminates
	precondition k >= 0
	initial i
	junction j
	final f
	transition t0 { from i to j }
	transition t1 { from j to f condition k > 0 action n = before + k }
	transition t2 { from j to f condition else }
}
"""
    files = machine("""	requires Soft
	var n: int = 1
	var x: int
	initial i
	state A { }
	state B { entry twice(x); $out!n }
	transition t0 { from i to A }
	transition t1 { from A to B condition $go?x }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from B to A exec }""", extra)
    # `twice` is defined inside the controller, `add` referenced with opref; twice calls add and waits a cycle
    files["m.rst"] = files["m.rst"].replace("sref m = M", """sref m = M
	opref a = add
	operation twice(k: int) {
		requires Shared requires Soft
		initial i
		state W { }
		final f
		transition t0 { from i to W action add(k) }
		transition t1 { from W to f exec action add(k) }
	}""")
    trace = run_both(tmp_path, files, [{}, {"go": 3}, {}, {}, {"go": 0}, {}, {}])
    assert [t[0] for t in trace] == [[], [], ["out!7"], [], [], ["out!7"], []]


def test_machines_contexts_and_cycle_definitions(tmp_path):
    # RoboTool accepts a non-boolean cycleDef and a condition on the transition out of an initial junction
    files = machine("""	cycleDef 2
	var started: boolean = true
	event local_tick
	initial i
	state A { }
	state Z { }
	transition t0 { from i to A condition started }
	transition t1 { from A to Z exec condition $stop }
	transition t2 { from A to A exec condition not $stop action $flag!true }
	transition t3 { from Z to Z exec }""")
    files["m.rst"] = files["m.rst"].replace("stm M {\n\tcycleDef cycle == 1", "stm M {")
    project, warnings = checked(tmp_path, files)
    assert warnings == []
    trace = run_both(tmp_path, files, [{}, {"stop": None}, {}])
    # exec transitions complete in the next cycle: t2's action comes a cycle after its guard held
    assert trace == [([], [0]), (["flag!true"], [0]), ([], [1])]
    # input contexts take events; RoboTool does not require the controller to declare the interfaces its
    # machines use (RoboSim's missingDeclaredInterface check is disabled), and neither does cotwin
    (tmp_path / "m.rst").write_text(files["m.rst"].replace("uses In uses Out requires Ops\n\tsref", "uses Out requires Ops\n\tsref"))
    found = errors(check_paths([tmp_path]))
    assert not any("missing the declared interfaces" in m for *_, m in found), found


def test_transitions_exec_else_and_state_actions(tmp_path):
    files = machine("""	var k: int = 0
	initial i
	state A {
		entry k = k + 1
		during $flag!(k > 2)
		exit $real_out!1.5; exec
	}
	junction j
	state B { }
	final F
	transition t0 { from i to A }
	transition t1 { from A to j condition $go }
	transition t2 { from j to B condition k > 1 action $out!k }
	transition t3 { from j to A condition else }
	transition t4 { from B to F exec condition $stop }
	transition t5 { from B to B exec condition not $stop }""")
    trace = run_both(tmp_path, files, [{}, {"go": 0}, {}, {"go": 0}, {}, {}, {"stop": None}, {}, {}])
    assert trace[0] == (["flag!false"], [0])
    assert trace[1][0] == ["real_out!1.5"]  # the exit action runs, then waits a cycle (exec in an exit action)
    assert trace[-1][1] == [2]  # final


def test_clocks_since_and_since_entry(tmp_path):
    files = machine("""	clock T
	var seen: int
	initial i
	state A { }
	state B { during $flag!true }
	transition t0 { from i to A action #T }
	transition t1 { from A to B condition since(T) >= 2 /\\ $go?seen action $out!cycle }
	transition t2 { from A to A exec condition not (since(T) >= 2 /\\ $go) }
	transition t3 { from B to A condition sinceEntry(B) > 1 action #T }""")
    # since(T) counts the cycles since the reset (0 in the cycle of the reset); sinceEntry(B) those
    # since B was entered; a self-transition would re-enter B, a during action does not
    trace = run_both(tmp_path, files, [{"go": 1}] * 9)
    assert [t[0] for t in trace] == [[], [], ["flag!true", "out!3"], ["flag!true"], [], [], ["flag!true", "out!7"],
                                     ["flag!true"], []]
    # timed expressions belong in guards, compared with a number
    bad = files["m.rst"].replace("action $out!cycle", "action $out!since(T)").replace(
        "condition sinceEntry(B) > 1", "condition sinceEntry(B) == since(T) /\\ (since(T) + 1 > 2)")
    (tmp_path / "m.rst").write_text(bad)
    messages = [m for *_, m in errors(check_paths([tmp_path]))]
    assert "timed expression (since, sinceEntry) not allowed in an action" in messages
    assert "unsupported use of a timed expression: compare it with a number" in messages


def test_clock_counts_stop_where_no_comparison_tells_them_apart(tmp_path):
    from cotwin.dmodel.verify import verify

    body = """	clock T
	const limit: int
	initial i
	state A { }
	state B { during $flag!true }
	transition t0 { from i to A action #T }
	transition t1 { from A to B condition since(T) > 3 action $out!1 }
	transition t2 { from A to A exec condition since(T) <= 3 }
	transition t3 { from B to A condition sinceEntry(B) >= 2 /\\ $go action #T }"""
    files = machine(body)
    steps = [{}] * 8 + [{"go": 1}] + [{}] * 6 + [{"go": 2}]
    trace = run_both(tmp_path, files, steps, parameters={"limit": 0})  # the same in the interpreter and the C
    assert [k for k, t in enumerate(trace) if "out!1" in t[0]] == [4, 12]  # T reset in cycle 8, > 3 again in 12
    program = build_program(checked(tmp_path, files)[0])
    [m] = program.machines
    assert m.clock_caps == {"T": 4} and set(m.entry_caps.values()) == {3}  # one above the constants
    report = verify(program, max_states=1000)
    assert report.complete and report.states < 30
    # compared with a parameter, a count cannot stop: the explored states grow with it
    unbounded = machine(body.replace("> 3", "> limit").replace("<= 3", "<= limit"))
    program = build_program(checked(tmp_path, unbounded)[0])
    assert program.machines[0].clock_caps == {"T": None}
    assert not verify(program, max_states=200, parameters={"limit": 1000}).complete


def test_dollar_expressions_sends_and_platform_calls(tmp_path):
    files = machine("""	var x: int
	var last: int = -1
	initial i
	state A { }
	transition t0 { from i to A }
	state B { }
	transition t1 { from A to B condition $go?x:(x > 10) action $out!x; $move(x, x); last = x }
	transition t2 { from A to B condition $go.7 action $flag!true }
	transition t3 { from A to B condition not ($go?x:(x > 10) \\/ $go.7) action $real_out!$last }
	transition t4 { from B to A exec }""")
    trace = run_both(tmp_path, files, [{"go": 20}, {"go": 7}, {"go": 3}, {}])
    assert [t[0] for t in trace] == [["move(20.0, 20)", "out!20"], ["flag!true"], ["real_out!20.0"], ["real_out!20.0"]]


def test_robosim_dollar_forms_as_robotool_reads_them(tmp_path):
    """RoboSim.xtext: SimRefExp is an Atomic (`$v[1]`), its value and predicate are CallExps (`$e.f(x)`,
    `$e?x:ok(x)`), and OutputCommunication sends with `.` as with `!` (`$e.v`, `$e.(n + 1)`, `$e.f(x)`; `$e.r.a` and
    `$e.v[1]`, whose value is no CallExp there, are read too, with a warning: see
    test_an_output_value_robotool_refuses_is_warned_with_the_fix)."""
    files = machine("""	var x: int
	var v: vector(int, 2) = [| 5, 6 |]
	var r: Pair
	initial i
	state A { }
	transition t0 { from i to A }
	state B { }
	transition t1 { from A to B condition $go?x:big(x) action r.a = x; $out.r.a; $flag.(x > $v[2]) }
	transition t2 { from A to B condition $go.twice($v[1]) action $out.twice(x); $flag.true }
	transition t3 { from A to B exec condition not ($go?x:big(x) \\/ $go.twice($v[1])) action $out.v[1] }
	transition t4 { from B to A exec }""", """datatype Pair { a: int b: int }
function big(n: int): boolean { postcondition result == (n > 10) }
function twice(n: int): int { postcondition result == 2 * n }
""")
    trace = run_both(tmp_path, files, [{"go": 20}, {"go": 10}, {"go": 3}, {}])
    assert [t[0] for t in trace] == [["flag!true", "out!20"], ["flag!true", "out!40"], [], ["out!5"]]


def test_rct_synchronisations_with_a_value_are_read(tmp_path):
    """RoboChart.xtext's CommunicationStmt `send? e.v` (SyncType, value a CallExp) in .rct files: `e.E::lit`,
    `send e . 90`, `e.C` (RoboTool's own test models ChemicalDetector and test9 were syntax errors)."""
    (tmp_path / "a.rct").write_text("""package rc
enumeration Color { red amber }
interface I { event light: Color event turn: int event e: int }
stm M {
	uses I
	const C: int = 3
	initial i
	state S { entry send light . Color::amber; turn.90; e.C; e.(C + 1) }
	transition t0 { from i to S action light.Color::red }
}
""")
    assert errors(check_paths([tmp_path])) == []


def test_robosim_dollar_index_alone_is_no_statement(tmp_path):
    files = machine("""	var v: vector(int, 2)
	initial i
	state A { }
	transition t0 { from i to A action $v[1] }""")
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert errors(check_paths([tmp_path])) == [
        ("m.rst", 31, 37, "'$v[...]' is not a statement: assign it ('$v[i] = e')")]


def test_robosim_dollar_field_of_a_variable_is_its_field(tmp_path):
    """RoboSim's scope provider reads `$p.a` on a record variable (or constant) p as p's field a, of the field's
    type (RoboSimTypeProvider); cotwin refused it ('write p.a'). It runs, in the interpreter and the C alike."""
    files = machine("""	var p: Pair
	const c: Pair = Pair(|a = 5, b = 7|)
	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?n /\\ $p.a == 0 action
		p = Pair(|a = n, b = $c.b|); $out!($p.a * 100 + $p.b + $c.a) }
	transition t2 { from A to A exec condition not $go \\/ $p.a != 0 }""", "datatype Pair { a: int b: int }\n")
    trace = run_both(tmp_path, files, [{"go": 3}, {"go": 4}, {}])
    assert [t[0] for t in trace] == [[], ["out!312"], []]  # p.a is 3 after the first: the condition is false


@pytest.mark.parametrize("written", ["$p.3", "$p.f(1)"])
def test_robosim_dollar_on_a_variable_takes_a_field_name_only(tmp_path, written):
    """After `$p.` RoboSim's scope offers the fields of p's type: anything else is one located error."""
    files = machine(f"""	var p: Pair
	initial i
	state A {{ }}
	transition t0 {{ from i to A }}
	transition t1 {{ from A to A exec condition {written} == 1 }}""", "datatype Pair { a: int b: int }\n")
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    [(path, line, column, message)] = errors(check_paths([tmp_path]))
    assert (path, line, column) == ("m.rst", 33, 48), message
    assert message == "'$p.': 'p' is not an input event but a name with a value, and after '$p.' RoboSim reads the " \
                      "name of a field of its type"


ANN_DECLARATIONS = """package nets
interface Ctl { event go: int }
anncontroller Net {
	params {
		inputcontext { event in0: real }
		outputcontext { event out0: real }
		layerstructure <1, 1>
		weights <<<0.5>>, <<1.0>>>
		biases <<-1.0>, <0.0>>
		activationfunction relu
	}
}
annoperation Approx(x: real) {
	requires Ctl
	params { inputcontext { event in0: real } outputcontext { event out0: real } file "net.json" }
}
generalcontroller Abstract { uses Ctl var k: int }
generaloperation Black(x: int) { terminates precondition x > 0 }
"""


def test_robochart_general_and_ann_components_are_read_and_refused_where_used(tmp_path):
    """RoboChart.xtext's GeneralController, GeneralOperation, ANNController and ANNOperation (RoboSim's grammar
    inherits them): a RoboTool project holding them was a syntax error for cotwin. They are read; a `cref` or
    `opref` to one is an error there, saying what it is, since cotwin has no behaviour of it to run."""
    (tmp_path / "nets.rct").write_text(ANN_DECLARATIONS)
    files = machine("""	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec }""")
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert errors(check_paths([tmp_path])) == []  # declared, unused: the project is RoboTool's and cotwin's
    files["m.rst"] = "import nets::*\n" + files["m.rst"].replace("\tcref c = C\n", "\tcref c = C\n\tcref n = Net\n")
    files["m.rst"] = files["m.rst"].replace("\tsref m = M\n", "\tsref m = M\n\topref o = Approx\n")
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    why = "RoboTool reads it, and cotwin cannot run it (it has no state machine to simulate)"
    assert errors(check_paths([tmp_path])) == [
        ("m.rst", 9, 12, f"'Approx' is a RoboChart ANN operation (declared at {tmp_path / 'nets.rct'}:13:14): {why}"),
        ("m.rst", 20, 11, f"'Net' is a RoboChart ANN controller (declared at {tmp_path / 'nets.rct'}:3:15): {why}")]
    # one written in the module itself (RoboChart's ConnectionNode)
    files["m.rst"] = files["m.rst"].replace("\tcref n = Net\n", "\tgeneralcontroller G { uses In }\n")
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert errors(check_paths([tmp_path]))[1:] == [
        ("m.rst", 20, 20, f"G in module Mod is a RoboChart general controller: {why}")]


def test_strings_take_xtext_escapes_and_stay_on_one_line(tmp_path):
    """Xtext's STRING terminal decodes \\" \\' \\\\ \\n \\t \\uXXXX; cotwin keeps a string on its line so that
    an unclosed quote is reported where it is."""
    from cotwin.robosim.parser import parse_text

    source, findings = parse_text('function f(): string { postcondition result == "a\\"b\\\\c\\n\\u0041\\q" }\n', "f.rct")
    assert not findings
    literal = source.elements[0].postconditions[0].right
    assert literal.value == 'a"b\\c\nA\\q'
    _, findings = parse_text('function f(): string { postcondition result == "a\nb" }\n', "f.rct")
    assert [(f.location.line, f.location.column, f.message) for f in findings] == [
        (1, 48, 'unterminated string: " without a closing " on its line (a line break in a string is written \\n)')]


def test_rct_trigger_guards_binding_the_sender_are_read(tmp_path):
    """RoboChart.xtext's Communication: `e[| s = from |]` and `e[| s = from | p |]` (was a syntax error,
    which refused the whole RoboTool project holding the .rct file)."""
    (tmp_path / "a.rct").write_text("""package rc
interface I { event g: int }
stm M {
	uses I
	var x: int
	initial i
	state S {}
	transition t0 { from i to S }
	transition t1 { from S to S trigger g[| y = from | y > 2 |]?x }
	transition t2 { from S to S trigger g[| z = from |] }
}
""")
    result = check_paths([tmp_path])
    assert errors(result) == []


def test_statements(tmp_path):
    files = machine("""	var r: Pair
	var v: vector(int, 3)
	var n: int
	initial i
	state A { }
	transition t0 { from i to A action r = Pair(|a = 1, b = 2|) }
	state B { }
	transition t3 { from B to A exec }
	transition t1 { from A to B condition $go?n action
		if n > 0 then (r.a = r.a + n; v[2] = n) else skip end;
		if r.a == 5 then $flag!true end;
		$out!(r.a * 10 + v[2]) }
	transition t2 { from A to A exec condition not $go }""", "datatype Pair { a: int b: int }\n")
    trace = run_both(tmp_path, files, [{"go": 4}, {"go": -1}, {"go": 0}])
    assert [t[0] for t in trace] == [["flag!true", "out!54"], ["flag!true", "out!54"], ["flag!true", "out!54"]]


def test_logic_comparisons_and_binding_forms(tmp_path):
    files = machine("""	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	state B { }
	transition t3 { from B to A exec }
	transition t1 { from A to B condition $go?n action
		$flag!((0 < n <= 10 => n != 3) iff (let m == n * 2 @ (m > 0 /\\ not (m == 6))));
		$out!(if 1 <= n < 5 then (the k: int | k in {1, 2, 3} /\\ k == n @ k * 100) else n end);
		$real_out!(n as real) }
	transition t2 { from A to A exec condition not $go }""")
    trace = run_both(tmp_path, files, [{"go": 2}, {"go": 3}, {"go": 7}, {"go": 4}])
    assert [t[0] for t in trace[:3]] == [["flag!true", "out!200", "real_out!2.0"],
                                         ["flag!true", "out!300", "real_out!3.0"],
                                         ["flag!true", "out!7", "real_out!7.0"]]
    # `the` with no value: the same located error from both
    assert trace[3][0] == "error" and "'the' found 0 values, not exactly one" in trace[3][1]


def test_let_and_the_bind_tighter_than_comparisons_as_robotool_reads_them(tmp_path):
    """RoboChart.xtext's DefiniteDescription and LetExpression sit between Comp and TypedExpression: a body ends
    where a comparison or a logical operator begins, and a let or `the` may be an operand of one. cotwin read
    them as the loosest forms: `let x == n @ x + 0 == x` was `n + 0 == n` (always true), where RoboTool compares
    n with the constant x; `true /\\ let ...` and `n == the ...` were syntax errors."""
    files = machine("""	const x: int = 10
	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?n action
		$flag!(let x == n @ x + 0 == x);
		$out!((if the x: int | x in {n} @ x * 1 == x then 1 else 0 end)
			+ (if true /\\ let y == n @ y > 1 then 10 else 0 end)
			+ (if n + 0 == the k: int | k in {n, 10} /\\ k > 5 @ k then 100 else 0 end)) }
	transition t2 { from A to A exec condition not $go }""")
    trace = run_both(tmp_path, files, [{"go": 2}, {"go": 10}, {"go": 1}, {}])
    assert [t[0] for t in trace] == [[], ["flag!false", "out!10"], ["flag!true", "out!111"], ["flag!false", "out!0"]]


def test_a_name_past_the_end_of_its_lets_body_is_located_with_the_fix(tmp_path):
    """RoboTool does not resolve `m` in `let m == n @ m > 0 /\\ m < 9` (the let's body is `m`): one error where
    it is used, naming the let and the parentheses that bind it; in a function's postcondition, which cotwin
    only checks (the published UR5e mapping's IK function is written so), a warning."""
    files = machine("""	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?n /\\ let m == n @ m > 0 /\\ m < 9 /\\ m != 3 }""",
                    "function f(a: int): int { postcondition let b == a @ result == b + 1 }\n"
                    "operation op(k: int) { postcondition let j == k @ j > 0 /\\ j < 9 initial i final e "
                    "transition t { from i to e } }\n")
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    result = check_paths([tmp_path])
    hint = ("'m' is bound by the let at line 34, whose body ends before '>' (a let binds tighter than a comparison "
            "or a logical operator, as in RoboChart; RoboTool does not resolve 'm' here): to bind it, put the body in "
            "parentheses, 'let ... @ (... > ...)'")
    assert errors(result) == [("m.rst", 34, 76, hint)]
    warnings = [f for f in result.findings if f.severity is Severity.WARNING]
    assert [(w.location.line, w.location.column, w.message.split(",")[0]) for w in warnings] == [
        (24, 64, "'b' is bound by the let at line 24"), (25, 60, "'j' is bound by the let at line 25")]
    assert all(w.message.endswith("cotwin reads it as the let's in this pre/postcondition") for w in warnings)


@pytest.mark.parametrize("written, column, fixed", [
    ("1 + let x == 1 @ x == 2", 43, "1 + (let x == 1 @ x) == 2"),
    ("- the x: int | x in {1} @ x == -1", 41, "-(the x: int | x in {1} @ x) == -1"),
    ("let x == 1 @ the y: int | y in {x} @ y == 1", 52, "let x == 1 @ (the y: int | y in {x} @ y) == 1")])
def test_a_let_or_the_where_robotool_refuses_it_is_located(written, column, fixed):
    """RoboChart's grammar refuses a let or `the` as an operand of arithmetic or of unary minus, and a `the` as a
    let's body: the error is at the word, saying so (the lexer had read it as a name, and the error fell on the
    next token); in parentheses, as the message says, each is read."""
    from cotwin.robosim.parser import parse_text

    word = written[column - 39:column - 36]
    _, findings = parse_text(f"function f(): boolean {{ postcondition {written} }}\n", "f.rct")
    assert [(f.location.line, f.location.column) for f in findings] == [(1, column)]
    assert findings[0].message.startswith(f"'{word}' cannot start here") and f"'({word} ... @ ...)'" in findings[0].message
    assert parse_text(f"function f(): boolean {{ postcondition {fixed} }}\n", "f.rct")[1] == []


def test_equality_chains_nest_to_the_left_as_robotool_reads_them(tmp_path):
    """RoboChart.xtext's Comp nests `b1 == b2 == b3` as `(b1 == b2) == b3` (cotwin read `b1 == b2 /\\ b2 == b3`,
    true where RoboTool's is false, and refused `n == 1 == b`); ordering chains keep Z's reading."""
    files = machine("""	var n: int
	var b: boolean = false
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?n action
		$flag!(b == b == b); $out!(if n == 1 == b then 1 else 0 end); $real_out!(if 0 < n <= 2 then 1.0 else 0.0 end) }
	transition t2 { from A to A exec condition not $go }""")
    trace = run_both(tmp_path, files, [{"go": 1}, {"go": 2}, {}])
    assert [t[0] for t in trace] == [[], ["flag!false", "out!0", "real_out!1.0"], ["flag!false", "out!1", "real_out!1.0"]]


def test_arithmetic_records_tuples_enumerations_functions(tmp_path):
    extra = """datatype Pos { x: int y: int }
enumeration Dir { North East South West }
function turn(d: Dir): Dir { postcondition result == if d == Dir::West then Dir::North else Dir::East end }
function norm1(p: Pos): int { postcondition result == (if p.x < 0 then -p.x else p.x end) + (if p.y < 0 then -p.y else p.y end) }
"""
    files = machine("""	var p: Pos
	var d: Dir = Dir::West
	var t: int * real
	var n: int
	const K: int = 7 % 4 - -2
	initial i
	state A { }
	transition t0 { from i to A action t = (|K, 2.5|) }
	state B { }
	transition t3 { from B to A exec }
	transition t1 { from A to B condition $go?n action
		p = Pos(|x = n / 2, y = -n % 3|); d = turn(d);
		$out!(norm1(p) * t[1]); $real_out!(t[2] * n / 4); $flag!(p == Pos(|y = -n % 3, x = n / 2|) /\\ d == Dir::North) }
	transition t2 { from A to A exec condition not $go }""", extra)
    trace = run_both(tmp_path, files, [{"go": 7}, {"go": -8}, {}])
    assert [t[0] for t in trace[:2]] == [["flag!true", "out!20", "real_out!4.375"],
                                         ["flag!false", "out!30", "real_out!-5.0"]]


def test_min_and_max_of_signed_zeros_are_the_same_in_the_interpreter_and_the_fmu(tmp_path):
    """min/max of equal values give the first one (Python's rule) in both: C's fmin(0.0, -0.0) gives -0.0, which
    atan2 tells apart (pi against -pi); NaN is skipped in both."""
    import math

    outputs = ["atan2(min(z, -z), -1.0)", "atan2(max(-z, z), -1.0)", "atan2(min(-z, z), -1.0)",
               "atan2(max(z, -z), -1.0)", "min(sqrt(-1.0) * 0.0 + 2.0, 1.0)"]
    states = "".join(f"\tstate S{k} {{ }}\n" for k in range(len(outputs) + 1))
    moves = "".join(f"\ttransition t{k} {{ from S{k} to S{k + 1} exec action $real_out!({e}) }}\n"
                    for k, e in enumerate(outputs))
    files = machine("\tvar z: real = 0.0\n\tinitial i\n" + states + "\ttransition ti { from i to S0 }\n" + moves
                    + f"\ttransition rest {{ from S{len(outputs)} to S{len(outputs)} exec }}\n",
                    "function atan2(y: real, x: real): real { }\nfunction sqrt(x: real): real { }\n"
                    "function min(a: real, b: real): real { }\nfunction max(a: real, b: real): real { }\n")
    trace = run_both(tmp_path, files, [{}] * (len(outputs) + 1))
    said = [float(o.split("!")[1]) for outs, _ in trace for o in outs]
    assert said == [math.pi, -math.pi, -math.pi, math.pi, 1.0], trace


def test_vectors_and_matrices(tmp_path):
    files = machine("""	var v: vector(int, 3) = [|1, 2, 3|]
	var w: vector(real, 2)
	var m: matrix(int, 2, 3) = [|1, 2, 3; 4, 5, 6|]
	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	state B { }
	transition t3 { from B to A exec }
	transition t1 { from A to B condition $go?n action
		v = v + 2 * v; v[n] = 0; w = [|0.5, 1|] * 2;
		$out!((m * v)[2] + m[2, 1] + transpose(m)[3, 2]);
		$real_out!(w[1] + w[2]); $flag!(v == [|3, 6, 0|]) }
	transition t2 { from A to A exec condition not $go }""")
    trace = run_both(tmp_path, files, [{"go": 3}, {"go": 4}])
    assert trace[0][0] == ["flag!true", "out!52", "real_out!3.0"]
    assert trace[1][0] == "error" and trace[1][1].endswith("index 4 out of range 1..3 in state machine M (cycle 2)")


def test_an_index_out_of_range_of_a_0_based_statement_names_that_statements_range(tmp_path):
    # `v[0]` makes the statement 0-based, `v[3]` in it too (docs/robosim-notation.md, section 5): its range is 0..2, which the
    # interpreter and the C both said as 1..3, where 3 was the index refused
    files = machine("""	var v: vector(int, 3) = [|1, 2, 3|]
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go action v[0] = v[3] }
	transition t2 { from A to A exec condition not $go }""")
    trace = run_both(tmp_path, files, [{"go": 1}, {}])  # the exec transition's action runs in cycle 2
    assert trace[1][0] == "error" and trace[1][1].endswith("index 3 out of range 0..2 in state machine M (cycle 2)")


def test_a_mapping_index_out_of_range_names_the_0_based_range_mappings_count_in():
    from cotwin.robosim.evaluator import index
    from cotwin.robosim.values import EvalError

    with pytest.raises(EvalError, match=r"index 6 out of range 0\.\.5"):  # q[6] of a 6-joint arm's vector
        index((0.0,) * 6, 6, None, first=0)
    with pytest.raises(EvalError, match=r"index 4 out of range 1\.\.3"):  # RoboChart's, from 1
        index((0.0,) * 3, 4, None)


def test_sets_sequences_and_toolkits(tmp_path):
    files = machine("""	var s: Set(int) = {1, 2}
	var q: Seq(int) = <5>
	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	state B { }
	transition t3 { from B to A exec }
	transition t1 { from A to B condition $go?n action
		s = union(s, {n, n + 1}); q = q cat <n> ^ reverse(<1, 2>);
		$out!(size(s) * 1000 + size(q) * 100 + head(tail(q)) * 10 + last(q));
		$flag!(n in s /\\ notin(0, s) /\\ subseteq({1}, s) /\\ (forall x: int | x in s @ x > 0)
		       /\\ (exists1 y: int | y in {1 to 3} @ y * y == 4) /\\ size({x: int | x in s /\\ x > 1 @ x * 2}) == size(s) - 1)
		}
	transition t2 { from A to A exec condition not $go }""",
                    "")
    files["m.rst"] = "import set_toolkit::*\nimport sequence_toolkit::*\n" + files["m.rst"]
    trace = run_both(tmp_path, files, [{"go": 7}, {"go": 7}, {"go": 9}] + [{"go": k} for k in range(20, 40)])
    assert trace[0][0] == ["flag!true", "out!4471"]
    assert trace[1][0] == ["flag!true", "out!4771"]  # a set keeps each element once; a sequence grows
    assert trace[-1][0] == "error" and "exceeds cotwin's bound of 32 elements" in trace[-1][1]


def test_type_forms(tmp_path):
    files = machine("""	var f: int -> int
	var r: int <-> boolean
	var g: (int * real) * Seq(Set(boolean))
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec }""", """type Opaque
record R { o: Opaque e: Colour }
enumeration Colour { Red Green(int) }
function pick(s: Set(?X)): ?X { }
""")
    project, warnings = checked(tmp_path, files)
    assert warnings == []
    with pytest.raises(CotwinError) as err:  # function values cannot be executed
        build_program(project)
    assert any("f: values of type (int) -> int cannot be executed yet" in f.message for f in err.value.findings)


def test_unrunnable_forms_are_located(tmp_path):
    files = machine("""	var n: int
	initial i
	probabilistic p
	state A { entry wait(1) }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition exists k: int @ k * k == n }""")
    project, _ = checked(tmp_path, files)
    with pytest.raises(CotwinError) as err:
        build_program(project)
    messages = sorted((f.location.line, f.message) for f in err.value.findings)
    assert [m for _, m in messages] == [
        "probabilistic junction p cannot be executed (in state machine M)",
        "wait is RoboChart's, not RoboSim's: it cannot be executed (in state machine M)",
        "a quantifier over all values of int ('k' is not bounded by 'k in S') cannot be executed (in state machine M)",
    ]


def test_published_mobile_model_reads_with_documented_warnings_and_runs(published, tmp_path):
    from cotwin.dmodel.fmu import build_fmu
    from language_support import fmu_trace, interpreter_trace

    path = published / "mobile" / "ObstacleAvoidance_OneStateMachine.rst"
    result = check_paths([path])
    assert errors(result) == []
    warnings = sorted((f.location.line, f.location.column, f.message.split(":")[0].split(" (")[0])
                      for f in result.findings if f.severity is Severity.WARNING)
    assert warnings == [
        (1, 16, "package Mathematics is not part of the project"),  # imported, never published
        (66, 35, "'randcoef' is a constant but is assigned"),  # read as a variable
        (66, 46, "unknown function 'randomcoef'"),  # read as uninterpreted () -> real
        (72, 35, "'randcoef' is a constant but is assigned"),
        (110, 88, "function 'abs' is declared with 0 parameter(s) and no definition but called with 1"),
        (133, 93, "function 'abs' is declared with 0 parameter(s) and no definition but called with 1"),
        (139, 13, "function 'abs' is declared with 0 parameter(s) and no definition but called with 1"),
        (172, 14, "function 'abs' is declared with 0 parameter(s) and no definition but called with 1"),
        (202, 25, "'NOA_Move[0]'"),  # vectors index from 1: that statement is read 0-based
    ]
    program = build_program(result.project)
    assert "seed" in [p.port for p in program.parameters]  # randomcoef() and random_sign() draw from it
    steps = ([{}] * 3 + [{"closestDistance": 0.5, "closestAngle": 20.0}] + [{}] * 3
             + [{"closestDistance": 0.3, "closestAngle": -40.0}] * 3 + [{}] * 4)
    for seed in (0, 7):
        expected = interpreter_trace(program, steps, {"seed": seed})
        assert all(t[0] != "error" for t in expected)
        assert fmu_trace(program, build_fmu(program, tmp_path / f"oa{seed}.fmu"), steps, {"seed": seed}) == expected
    # the obstacle seen in cycle 4 turns the robot away: av = (20 - 100) * pi / 180, lv = 0.6 / 2
    assert expected[3][0] == ["move(-1.3962622222222223, 0.3)"]


def test_operation_required_variables_come_from_the_caller(tmp_path):
    # as robochart-tests/robosim-ops-4: opB requires `e`, which its caller opA declares
    extra = """interface Soft { opA(d: int) }
interface SoftB { opB(d: int) }
interface IVars { var e: int }
operation opA(d: int) { requires SoftB var e: int = 2 initial i final f transition t { from i to f action opB(d) } }
operation opB(d: int) { requires IVars output context { uses Out } initial i final f transition t { from i to f action $out!(e * 10 + d); e = 0 } }
"""
    files = machine("""	requires Soft
	var n: int
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition t1 { from A to B condition $go?n action opA(n) }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from B to A exec }""", extra)
    files["m.rst"] = files["m.rst"].replace("sref m = M", "sref m = M opref a = opA opref b = opB")
    trace = run_both(tmp_path, files, [{"go": 3}, {"go": 4}])
    assert [t[0] for t in trace] == [["out!23"], ["out!24"]]  # each call of opA starts with its own e = 2


def test_functions_declared_without_definition_named_like_builtins(tmp_path):
    # as the Acrobot test model of RoboTool's physmod repository: sin, cos, floor declared, never defined
    files = machine("""	var x: real
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition t1 { from A to B condition $go?x action $real_out!(sin(x / 2) + floor(x / 3)) }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from B to A exec }""", "function sin(x: real): real {}\nfunction floor(x: real): real {}\n")
    files["m.rst"] = files["m.rst"].replace("event go: int", "event go: real")
    project, warnings = checked(tmp_path, files)
    assert sorted(w.message for w in warnings) == [
        "function 'floor' is declared without a definition: read as Mathematics::floor",
        "function 'sin' is declared without a definition: read as Mathematics::sin"]
    trace = run_both(tmp_path, files, [{"go": 7.0}])
    assert trace[0][0] == [f"real_out!{__import__('math').sin(3.5) + 2}"]


def test_robotool_projects_group_their_folders_and_rct_duplicates_warn(tmp_path):
    project = tmp_path / "Proj"
    (project / "rc2rs" / "robosim").mkdir(parents=True)
    (project / "rc2rs" / "robochart").mkdir(parents=True)
    (project / ".project").write_text("<projectDescription/>")
    decl = "package Decl\ninterface Ev { event go: int }\n"
    (project / "decl.rct").write_text(decl)
    (project / "rc2rs" / "robochart" / "decl.rct").write_text(decl)  # RoboChart copy made by rc2rs
    (project / "rc2rs" / "robosim" / "m.rst").write_text(
        "package Sim\nimport Decl::*\nstm M { cycleDef { cycle == 1 } input context { uses Ev } initial i state A { }"
        " transition t { from i to A } transition u { from A to A exec } }\n")
    result = check_paths([tmp_path])
    assert len(result.projects) == 1 and result.ok  # one RoboTool project: the .rst sees the .rct
    [warning] = [f for f in result.findings if f.severity is Severity.WARNING]
    assert warning.message.startswith("duplicate interface 'Decl::Ev'") and warning.message.endswith("the first one is used")


def test_a_composite_states_entry_goes_through_its_initial_junction_before_its_own_transitions(tmp_path):
    """Entering Q runs its initial transition into A (A's entry action, A the active leaf): a junction is part of
    the transition through it, so Q's own transitions, chosen first from Q's states, are not chosen at the junction
    (an exec one ended the cycle there: no leaf active, A never entered), in the interpreter and the FMU alike."""
    files = machine("""	initial i
	state S { }
	transition t0 { from i to S }
	state Q {
		initial qi
		state A { entry $out!1 during skip }
		transition a { from qi to A }
	}
	transition t1 { from S to Q exec }
	transition b { from Q to S exec condition $stop }
	transition c { from Q to S condition $go }""")
    trace = run_both(tmp_path, files, [{}, {}, {"go": 9}, {}, {"stop": None}, {}, {}])
    outputs, states = [t[0] for t in trace], [t[1][0] for t in trace]
    assert outputs == [[], ["out!1"], [], ["out!1"], [], [], ["out!1"]]  # Q entered into A each time it is entered
    assert min(states) >= 0  # every cycle ends in a leaf state, never at a junction
    assert states == [0, 1, 0, 1, 1, 0, 1]  # S, then A; Q's transitions taken from A (c at once, b's exec next cycle)


def test_a_variables_field_alone_as_a_statement_is_one_clear_error(tmp_path):
    """`p.a` (or `$p.a`) alone reads as RoboSim's output `$e.v` on an event p: a record variable p drew 'unknown
    output event 'p'' and 'unknown name 'a'' besides, two errors for one mistake. One says what p is."""
    for written in ("p.a", "$p.a"):
        files = machine(f"""	var p: Pair
	initial i
	state A {{ }}
	transition t0 {{ from i to A action {written} }}""", "datatype Pair { a: int b: int }\n")
        for name, text in files.items():
            (tmp_path / name).write_text(text)
        [(path, line, _, message)] = errors(check_paths([tmp_path]))
        assert (path, line) == ("m.rst", 32), message
        assert message.startswith("'p' is not an output event but a name with a value"), message


FUNCTION = "function f(n: int): int { postcondition result == "


@pytest.mark.parametrize("written, at, says, fixed", [
    ("1 + if n > 0 then 1 else 2 end", "if", "'if ... end' as an operand of '+'", "1 + (if n > 0 then 1 else 2 end)"),
    ("if n > 0 then 1 else 2 end * 2", "if", "'if ... end' as an operand of '*'", "(if n > 0 then 1 else 2 end) * 2"),
    ("-if n > 0 then 1 else 2 end", "if", "'if ... end' as an operand of '-'", "-(if n > 0 then 1 else 2 end)"),
    ("size(<if n > 0 then 1 else 2 end>)", "if", "operand of a sequence", "size(<(if n > 0 then 1 else 2 end)>)"),
    ("if n > 0 then r else r end.a", "if", "operand of a selection", "(if n > 0 then r else r end).a"),
    ("r.v[1]", "r", "an index after a field", "(r.v)[1]"),
    ("g($go?x:if n > 0 then true else false end)", "if", "operand of a '$e?x:' predicate",
     "g($go?x:(if n > 0 then true else false end))"),
    ("g($go.if n > 0 then 1 else 2 end)", "if", "operand of '$e.'", "g($go.(if n > 0 then 1 else 2 end))"),
    ("m[1][2]", "m", "an index of an index", "m[1, 2]"),
    ("g(n)(n)", "g", "a call of a call", "(g(n))(n)"),
    ("r.f(1)", "r", "a call of a call, an index or a field ('a.f(x)'", "(r.f)(1)"),
    ("m[1](2)", "m", "a call of a call, an index or a field ('a[i](x)'", "(m[1])(2)"),
])
def test_expressions_robotool_refuses_are_warned_with_the_fix(written, at, says, fixed):
    """RoboChart.xtext's levels: IfExpression sits between LetExpression and TypedExpression (an operand of a
    comparison or a logical operator, not of arithmetic, `-`, a selection, a call or a sequence's PlusMinus
    values); Selection = ArrayExp ('.' member)*, ArrayExp = CallExp ('[' ... ']')?, CallExp = Atomic ('(' ... ')')?.
    cotwin reads each form (models that run keep running) with one warning at it saying how both read it; the
    parenthesised form RoboTool reads (ParExp is an Atomic) has none, and the if as a comparison's or a logical
    operator's operand, or as an argument, has none."""
    from cotwin.robosim.parser import parse_text

    source, findings = parse_text(FUNCTION + written + " }\n", "f.rst")
    assert source is not None
    [warning] = findings
    assert warning.severity is Severity.WARNING
    assert (warning.location.line, warning.location.column) == (1, len(FUNCTION) + written.index(at) + 1)
    assert warning.message.startswith("RoboTool refuses") and says in warning.message, warning.message
    assert parse_text(FUNCTION + fixed + " }\n", "f.rst")[1] == []
    for accepted in ("if n > 0 then 1 else 2 end == n /\\ if n > 0 then true else false end",
                     "g(if n > 0 then 1 else 2 end) + (if n > 0 then 1 else 2 end)", "g(n)[1].a.b", "$n"):
        assert parse_text(FUNCTION + accepted + " }\n", "f.rst")[1] == [], accepted


@pytest.mark.parametrize("written, fixed", [
    ("$out!n + 1", "$out!(n + 1)"), ("$out!-n", "$out!(-n)"), ("send $out!r.a", "send $out!(r.a)"),
    ("$out.r.a", "$out.(r.a)"), ("$out!(r.v)[1]", "$out!((r.v)[1])"), ("$out!n == 1", "$out!(n == 1)"),
])
def test_an_output_value_robotool_refuses_is_warned_with_the_fix(written, fixed):
    """RoboSim.xtext's OutputCommunication is `'$' event ('!'|'.') value=CallExp` (and RoboChart's Communication
    `e!v` takes a CallExp too): a name, a literal, a call or a parenthesised expression. cotwin sends any value
    (the model runs as before) with a warning at the value; in parentheses, none. Calls and names need none."""
    from cotwin.robosim.parser import parse_text

    def found(statement: str, path: str = "m.rst"):
        text = f"stm M {{ initial i state A {{ entry {statement} }} transition t {{ from i to A }} }}\n"
        return text.index(statement), parse_text(text, path)[1]

    start, [warning] = found(written)
    value = written.split("!", 1)[-1] if "!" in written else written.split(".", 1)[1]
    assert warning.severity is Severity.WARNING and warning.location.column == start + written.index(value) + 1
    event = written.removeprefix("send ").split("!")[0].split(".")[0]
    mark = "!" if "!" in written else "."
    assert warning.message.startswith(f"RoboTool refuses this value after '{event}{mark}'")
    assert warning.message.endswith(f"write '{event}{mark}(...)' so that both read it")
    assert found(fixed)[1] == []
    assert found("$out!g(n); $out!3; $out!r; $out.g(n); $out!E::a; $out!{1, 2}")[1] == []
    _, [rct] = found(written.replace("$", ""), "m.rct")  # RoboChart's synchronisation, alike
    assert rct.message.startswith(f"RoboTool refuses this value after '{event.lstrip('$')}{mark}'")


@pytest.mark.parametrize("kind", ["Set", "Seq"])
def test_a_collection_type_with_a_space_before_its_parenthesis_is_warned(kind):
    """RoboChart.xtext's type keywords are 'Set(' and 'Seq(' (TypeRef: {SetType} 'Set(' domain=Type ')'), single
    tokens: Xtext's lexer skips whitespace between tokens, not inside one, so `Set (int)` is the type name Set
    followed by '(' there, a syntax error. cotwin reads it, with a warning at the word."""
    from cotwin.robosim.parser import parse_text

    source, [warning] = parse_text(f"stm M {{ var s: {kind} (int) var t: {kind}(int) }}\n", "m.rst")
    assert source is not None and warning.severity is Severity.WARNING
    assert (warning.location.line, warning.location.column) == (1, 16)
    assert warning.message.startswith(f"RoboTool refuses '{kind}' apart from its '('") and f"'{kind}(T)'" in warning.message


def test_forms_robotool_refuses_keep_running_as_before(tmp_path):
    """The warned forms are read as before: a model written with them runs alike in the interpreter and the FMU."""
    files = machine("""	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?n action $out!n * 2 + if n > 5 then 100 else 0 end; $flag!n == 7 }
	transition t2 { from A to A exec condition not $go }""")
    project, warnings = checked(tmp_path, files)
    assert len(warnings) == 3  # the value after '$out!', the if as an operand of '+', the value after '$flag!'
    trace = run_both(tmp_path, files, [{"go": 3}, {"go": 7}, {}])
    assert [t[0] for t in trace] == [[], ["flag!false", "out!6"], ["flag!true", "out!114"]]


def test_a_qualified_name_after_dollar_and_to_from_are_errors_saying_why(tmp_path):
    """RoboSim.xtext's SimRefExp reads `'$' element=[NamedElement|QualifiedName]`, but RoboSimScopeProvider scopes
    the element by simple names only (Scopes::scopeFor over the machine's contexts, NULLSCOPE outside), so
    `$In::go` never resolves in RoboTool: the error says to write `$go`. `to` and `from` are RoboChart's Atomic
    ToExp and FromExp (inherited by RoboSim), which RoboCalcTypeProvider gives no type: an error saying so."""
    files = machine("""	var n: int
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $In::go?n action $out!n }
	transition t2 { from A to A exec condition to == 1 \\/ from == 2 }""")
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    found = errors(check_paths([tmp_path]))
    assert [(line, column) for _, line, column, _ in found] == [(32, 46), (33, 45), (33, 56)]
    assert found[0][3] == ("'$In::go': RoboTool resolves the name after '$' by its simple name among the machine's "
                           "events and variables (RoboSim's scope offers no qualified name there): write '$go'")
    assert found[1][3].startswith("'to' is RoboChart's ToExp") and "gives it no type" in found[1][3]
    assert found[2][3].startswith("'from' is RoboChart's FromExp")
