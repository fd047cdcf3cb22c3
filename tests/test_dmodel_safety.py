"""The generated C never traps (issue 10): integer division and remainder by zero and overflow make
the step fail with the model location, the same message as the interpreter's; constants are
evaluated at check time with located errors; every legal RoboSim name compiles."""

from __future__ import annotations

import pytest

from cotwin.diagnostics import Severity
from cotwin.dmodel.fmu import fmu_sources
from cotwin.dmodel.program import build_program
from cotwin.robosim.check import check_paths
from language_support import checked, run_both
from test_robosim_language import machine

ARITHMETIC = machine("""	var x: int
	initial i
	state A { }
	junction J
	state B { entry $out!(1000 / x) }
	state C { }
	transition t0 { from i to A }
	transition t1 { from A to J condition $go?x }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from J to B condition x % 3 != 2 }
	transition t4 { from J to C condition x % 3 == 2 action $out!(9223372036854775807 - 10 + x) }
	transition t5 { from B to A exec }
	transition t6 { from C to A exec }""")


@pytest.mark.parametrize("value, message, where", [
    (0, "division by zero", "state B"),
    (-3, None, None),
    (11, "integer overflow", "state machine M"),
])
def test_integer_errors_are_located_and_the_same_in_the_interpreter_and_the_fmu(tmp_path, value, message, where):
    trace = run_both(tmp_path, ARITHMETIC, [{"go": 4}, {"go": value}])
    if message is None:
        assert trace[1][0] == ["out!-333"]  # C's division truncates toward zero
        return
    kind, text = trace[1]
    line, column = (32, 24) if message == "division by zero" else (38, 64)
    assert kind == "error" and text.endswith(f"m.rst:{line}:{column}: {message} in {where} (cycle 2)"), text


def test_remainder_by_zero_is_located(tmp_path):
    files = machine("""	var x: int
	initial i
	state A { }
	junction J
	state B { }
	transition t0 { from i to A }
	transition t1 { from A to J condition $go?x }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from J to B condition 7 % x == 1 }
	transition t4 { from J to B condition else }
	transition t5 { from B to A exec }""")
    trace = run_both(tmp_path, files, [{"go": 3}, {"go": 0}])
    assert trace[1][0] == "error" and "remainder of a division by zero in junction J" in trace[1][1]


def test_constant_errors_are_located_at_check_time(tmp_path):
    files = machine("""	const K: int = 10 / (3 - 3)
	const L: int = 9223372036854775807 + 1
	initial i
	state A { }
	transition t0 { from i to A }""")
    (tmp_path / "m.rst").write_text(files["m.rst"])
    found = [(f.location.line, f.location.column, f.message) for f in check_paths([tmp_path]).findings
             if f.severity is Severity.ERROR]
    assert (28, 17, "division by zero (in constant K)") in found
    assert (29, 17, "integer overflow (in constant L)") in found


NAMES = ["int", "double", "NAN", "EOF", "bool", "struct", "main", "errno", "printf", "M", "s", "in", "on", "v", "n",
         "t1", "R1", "START", "FINAL", "LOC", "INFINITY", "stdin", "assert", "register", "auto", "signed", "_Bool"]


def test_every_legal_name_compiles_and_runs(tmp_path):
    decls = "\n".join(f"\tvar {n}: int = {k}" for k, n in enumerate(NAMES))
    total = " + ".join(NAMES)
    files = {"m.rst": f"""interface In {{ event int: int }}
interface Out {{ event double: int }}
interface Ops {{ errno(struct: int) }}
datatype EOF {{ NAN: int main: boolean }}
stm stdio {{
{decls}
	var rec: EOF
	input context {{ uses In }}
	output context {{ uses Out requires Ops }}
	initial exit
	state return {{ }}
	state goto {{ entry double = double + 1 }}
	transition t0 {{ from exit to return }}
	transition switch {{ from return to goto condition $int?int action rec.NAN = {total}; $double!rec.NAN; $errno(struct + int) }}
	transition case {{ from return to return exec condition not $int }}
	transition default {{ from goto to return exec }}
}}
controller float {{ uses In uses Out requires Ops sref char = stdio
	connection float on int to char on int connection char on double to float on double }}
module unsigned {{ robotic platform long {{ uses In uses Out provides Ops }} cref sizeof = float
	connection long on int to sizeof on int (_async) connection sizeof on double to long on double (_async) }}
"""}
    trace = run_both(tmp_path, files, [{}, {"int": 100}, {}])
    expected = sum(range(len(NAMES))) - NAMES.index("int") + 100
    assert trace[1][0] == sorted([f"double!{expected}", f"errno({NAMES.index('struct') + 100})"])


def test_generated_sources_are_deterministic_for_a_rich_model(tmp_path):
    project, _ = checked(tmp_path, ARITHMETIC)
    assert fmu_sources(build_program(project)) == fmu_sources(build_program(project))


WIDE = machine("""	var x: int
	initial i
	state A { }
	state B { }
	transition t0 { from i to A }
	transition t1 { from A to B condition $go?x action $out!(x + 2147483646) }
	transition t2 { from B to A exec }
	transition t3 { from A to A exec condition not $go }""")


def test_integer_ports_beyond_int32_are_an_error_naming_the_port_not_wrapped(tmp_path):
    """The model computes in int64; an FMI Integer port holds 32 bits, so sending a value beyond it is a
    run-time error located at the send, naming the port, in the interpreter as in the C (the interpreter
    used to show the value the FMU could not hold: the random models of test_dmodel_random found the two
    traces apart), instead of reaching an importer wrapped (fmpy's fmi2GetInteger) or the master unchecked."""
    trace = run_both(tmp_path, WIDE, [{"go": 1}, {"go": 2}, {"go": 0}])
    assert trace[0][0] == ["out!2147483647"]
    kind, text = trace[1]
    assert kind == "error" and text.endswith("does not fit an FMI Integer (int32) in state machine M (cycle 2)"), text
    assert "= 2147483648" in text and "m.rst:" in text
    assert len(trace) == 2
