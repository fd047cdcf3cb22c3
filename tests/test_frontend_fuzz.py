"""Mutated model text never makes the front end raise anything but its own findings: the example
models, and seeds that use the whole RoboSim/RoboChart syntax (packages, opref/rref, clocks,
operations, sets, sequences, matrices, records, quantifiers, .rct declarations). A mutant that still
checks clean must also run: the interpreter and its compiled FMU to the same trace (mutations that keep
the text well formed, such as another operator or literal, make such mutants common). Seeded by the
session's fuzz seed (pytest's header); more cases under CI."""

from __future__ import annotations

from pathlib import Path

import pytest

import os

from hypothesis import HealthCheck, Phase, assume, given, seed, settings
from hypothesis import strategies as st

from conftest import FUZZ_SEED

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


# mutations that keep the text well formed: another operator, comparison, literal or connective
SWAPS = [(" + ", " - "), (" - ", " + "), (" * ", " + "), (" < ", " <= "), (" <= ", " < "), (" > ", " >= "),
         (" >= ", " > "), (" == ", " != "), (" != ", " == "), (" /\\ ", " \\/ "), (" \\/ ", " /\\ "), ("true", "false"),
         ("false", "true"), ("= 0", "= 1"), ("1", "2"), ("2", "3"), ("0.5", "1.5"), ("not ", ""), (" % ", " / ")]


def swap(draw, text: str) -> str:
    """One occurrence of a SWAPS pattern replaced (the text unchanged if none occurs)."""
    old, new = draw(st.sampled_from(SWAPS))
    places = [k for k in range(len(text)) if text.startswith(old, k)]
    if not places:
        return text
    k = draw(st.sampled_from(places))
    return text[:k] + new + text[k + len(old):]


@st.composite
def mutated(draw, kinds=("delete", "insert", "duplicate", "token", "swap")):
    name = draw(st.sampled_from(sorted(TEXTS)))
    text = TEXTS[name]
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(text)))
        kind = draw(st.sampled_from(kinds))
        if kind == "swap":
            text = swap(draw, text)
            continue
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


@seed(FUZZ_SEED)
@settings(max_examples=1000 if os.environ.get("CI") else 200, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
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


def _go_inputs(draw, cycles: int = 12) -> list[dict]:
    return [({"go": draw(st.sampled_from([0, 1, 2, 3, -1, 7, 11]))} if draw(st.booleans()) else {}) for _ in range(cycles)]


@pytest.mark.timeout(3600)  # each clean mutant compiles an FMU
@seed(FUZZ_SEED)
@settings(max_examples=8 if os.environ.get("CI") else 2, deadline=None, database=None,
          phases=[Phase.explicit, Phase.generate], suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_a_mutant_that_checks_clean_runs_alike_in_the_interpreter_and_the_fmu(tmp_path_factory, data):
    """lang.rst (every construct) with well-formed mutations: where the mutant checks clean and builds
    (or says, located, what it cannot run), the interpreter and the FMU agree on every cycle."""
    from cotwin.dmodel.fmu import build_fmu
    from language_support import fmu_trace, interpreter_trace

    text = TEXTS["lang.rst"]
    for _ in range(data.draw(st.integers(1, 3))):
        text = swap(data.draw, text)
    source, findings = parse_text(text, "lang.rst")
    diag = Diagnostics()
    diag.extend(findings)
    project = build_project([s for s in [source, PARSED["decl.rct"]] if s is not None], diag)
    check_project(project, diag)
    assume(not diag.has_errors)  # too few clean mutants: hypothesis says the test cannot be satisfied
    try:
        program = build_program(project, "Mod")
    except CotwinError as err:  # what cannot run is said, located
        assert all(f.location.line >= 1 for f in err.findings)
        return
    steps = _go_inputs(data.draw)
    expected = interpreter_trace(program, steps)
    folder = tmp_path_factory.mktemp("mutant")
    (folder / "lang.rst").write_text(text)
    actual = fmu_trace(program, build_fmu(program, folder / "model.fmu"), steps)
    assert actual == expected, f"fuzz seed {FUZZ_SEED}: {folder / 'lang.rst'} on {steps}"
