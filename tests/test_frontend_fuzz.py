"""Mutated model text never makes the front end raise anything but its own findings: the example
models, and seeds that use the whole RoboSim/RoboChart syntax (packages, opref/rref, clocks,
operations, sets, sequences, matrices, records, quantifiers, .rct declarations)."""

from __future__ import annotations

from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cotwin.diagnostics import CotwinError, Diagnostics
from cotwin.dmodel.interpreter import Interpreter
from cotwin.dmodel.program import build_program
from cotwin.robosim.check import check_project
from cotwin.robosim.parser import parse_text
from cotwin.robosim.project import build_project

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "ur5e"
TEXTS = {p.name: p.read_text() for p in sorted(EXAMPLES.iterdir()) if p.suffix in (".rst", ".pm")}
TEXTS["lang.rst"] = """package Lang
import Decl::*
import set_toolkit::*
import sequence_toolkit::*
datatype Pair { a: int b: real }
enumeration Dir { N E(int) }
function f(x: int): int { postcondition result == x * 2 precondition x >= 0 }
interface Soft { step(k: int) }
interface Shared { var n: int }
operation step(k: int) { requires Shared terminates initial i final f transition t { from i to f action n = n + k } }
stm M {
	cycleDef cycle == 1
	requires Soft
	var n: int = 0
	var s: Set(int) = {1 to 3}
	var q: Seq(int) = <1, 2>
	var m: matrix(real, 2, 2) = [|1.0, 0.0; 0.0, 1.0|]
	var p: Pair = Pair(|a = 1, b = 2.0|)
	var t: int * boolean = (|1, true|)
	clock C
	input context { uses Ev }
	output context { uses Ev requires Ops }
	initial i
	state A { entry step(1); #C during $out!size(s) exit exec }
	junction J
	transition t0 { from i to A }
	transition t1 { from A to J condition $go?n:(n > 0) /\\ since(C) >= 2 /\\ 0 < n <= 10 }
	transition t2 { from J to A exec condition (forall x: int | x in s @ x > 0) /\\ sinceEntry(A) > 1 action
		s = union(s, {n}); q = q ^ <f(n)>; m = transpose(m) * 2.0; p.b = m[1, 1]; $move(q[1] * 1.0, t[1]) }
	transition t3 { from J to A exec condition else action if n in s then skip else $out!(let k == n @ k % 3) end }
}
controller C { cycleDef cycle == 1 uses Ev requires Ops sref m = M opref o = step
	connection C on go to m on go connection m on out to C on out }
module Mod { cycleDef 1 rref P = Decl::RP cref c = C
	connection P on go to c on go (_async) connection c on out to P on out (_async) [mult] }
"""
TEXTS["decl.rct"] = """package Decl
diagram decl
interface Ev { event go: int event out: int }
interface Ops { move(x: real, y: int) }
robotic platform RP { uses Ev provides Ops }
stm S { uses Ev initial i state A { entry wait(1) } transition t { from i to A trigger go?x <{ 2 } condition true } }
"""
TOKENS = ["{", "}", "(", ")", "$", "?", "::", ";", "exec", "state", "transition", "from", "to", "==", "/\\",
          "not", "0.5", "x", "pose", "link", "jref", "equation", "action", "condition", "//", "/*", "*/", "@", "|)",
          "opref", "rref", "package", "import", "::*", "[|", "|]", "<", ">", "since(C)", "#C", "cat", "^", "{}",
          "sinceEntry(A)", ":", "|", "the", "exists1", "<{", "[mult]", "terminates", "$go?n:", "Set(int)", "?X"]
PARSED = {name: parse_text(text, name)[0] for name, text in TEXTS.items()}


@st.composite
def mutated(draw):
    name = draw(st.sampled_from(sorted(TEXTS)))
    text = TEXTS[name]
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(text)))
        kind = draw(st.sampled_from(["delete", "insert", "duplicate", "token"]))
        if kind == "delete":
            end = min(len(text), pos + draw(st.integers(1, 12)))
            text = text[:pos] + text[end:]
        elif kind == "insert":
            text = text[:pos] + draw(st.text(min_size=1, max_size=4)) + text[pos:]
        elif kind == "duplicate":
            end = min(len(text), pos + draw(st.integers(1, 40)))
            text = text[:end] + text[pos:end] + text[end:]
        else:
            text = text[:pos] + " " + draw(st.sampled_from(TOKENS)) + " " + text[pos:]
    return name, text


def test_seeds_check_clean():
    diag = Diagnostics()
    check_project(build_project(list(PARSED.values()), diag), diag)
    assert [str(f) for f in diag.errors] == []


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_text_gives_findings_not_exceptions(case):
    name, text = case
    source, findings = parse_text(text, name)
    for f in findings:
        assert f.location.line >= 1 and f.location.column >= 1 and f.message
    others = [s for n, s in PARSED.items() if n != name]
    diag = Diagnostics()
    diag.extend(findings)
    project = build_project([s for s in [source, *others] if s is not None], diag)
    check_project(project, diag)  # must not raise
    for f in diag.findings:
        assert str(f).startswith(f"{f.location.path}:{f.location.line}:{f.location.column}: ")
    if not diag.has_errors and name == "lang.rst":  # a mutant that still checks: it builds and runs, or says why not
        try:
            interp = Interpreter(build_program(project, "Mod"))
            for _ in range(3):
                interp.step({"go": 2})
        except CotwinError:
            pass
