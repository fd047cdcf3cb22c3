"""Random well-typed d-models (tests/dmodel_models.py: every type the C generator handles) run in the
interpreter and as a compiled FMU on random inputs: the two traces (every observed value, operation
call, active state and run-time error, cycle by cycle) must be identical.

Seeded (conftest's fuzz seed, printed in the header; COTWIN_FUZZ_SEED repeats a run); a few models
per run on a user's machine, more under CI (each FMU compiles two machines: the C compiler's start-up
is most of a model's cost). No shrinking: a failing model and its inputs are written out and named."""

from __future__ import annotations

import json
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

import dmodel_models as models
from conftest import FUZZ_SEED
from cotwin.dmodel.fmu import build_fmu
from cotwin.dmodel.program import build_program
from language_support import checked, fmu_trace, interpreter_trace

MACHINES = 2  # per FMU
CYCLES = 25
EXAMPLES = 16 if os.environ.get("CI") else 4


@pytest.mark.timeout(3600)  # under load a model's FMU takes half a minute to compile
def test_random_models_run_alike_in_the_interpreter_and_the_fmu(tmp_path_factory):
    cases = []  # (text, inputs): drawn first by Hypothesis, seeded; then run

    @seed(FUZZ_SEED)
    @settings(max_examples=EXAMPLES, deadline=None, database=None, phases=[Phase.explicit, Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(data=st.data())
    def draw(data):
        cases.append((models.project(data.draw, MACHINES)[0], models.inputs(data.draw, CYCLES, MACHINES)))

    draw()
    programs = []
    for text, steps in cases:
        folder = tmp_path_factory.mktemp("random")
        project, _ = checked(folder, {"m.rst": text})
        program = build_program(project)
        programs.append((folder, program, steps, interpreter_trace(program, steps)))
    # the C compiler is most of a model's cost: compile the FMUs side by side, one per core
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        fmus = list(pool.map(lambda case: build_fmu(case[1], case[0] / "model.fmu"), programs))
    for (folder, program, steps, expected), fmu in zip(programs, fmus):
        actual = fmu_trace(program, fmu, steps)
        if actual != expected:
            (folder / "inputs.json").write_text(json.dumps(steps))
            cycle = next((k for k, (a, b) in enumerate(zip(actual, expected)) if a != b), min(len(actual), len(expected)))
            pytest.fail(f"fuzz seed {FUZZ_SEED}: the FMU and the interpreter differ at cycle {cycle + 1} of "
                        f"{folder / 'm.rst'} on {folder / 'inputs.json'}\n"
                        f"FMU:         {actual[cycle] if cycle < len(actual) else 'nothing'}\n"
                        f"interpreter: {expected[cycle] if cycle < len(expected) else 'nothing'}")


def test_the_generator_reaches_every_type_and_form(tmp_path):
    """The models use what they are meant to: every variable type, sets, sequences, matrices, clocks,
    both kinds of operation; and most runs go past their first cycles (an error ends a trace)."""
    seen = ""

    @seed(FUZZ_SEED)
    @settings(max_examples=300, deadline=None, database=None, phases=[Phase.generate],  # text only: cheap
              suppress_health_check=list(HealthCheck))
    @given(data=st.data())
    def draw(data):
        nonlocal seen
        seen += models.project(data.draw, MACHINES)[0]

    draw()
    for form in ("union(", "inter(", "diff(", " to ", "^ <", "tail(q)", "reverse(q)", "transpose(m)", "(m * m)",
                 "Pt(|x = ", "(|", "[|", "Colour::", "since(C)", "sinceEntry(", "#C", "$op", "bump(", "$go",
                 "?p", " in s)", "% ", "/ ", "condition else", "during ", " to J "):
        assert form in seen, form


def test_operations_sharing_a_port_cannot_both_be_called_in_one_cycle(tmp_path):
    """Two platform operations whose parameters have the same name and type share one FMU port (pick
    and place both pass `diameter`); called in the same cycle, the FMU reported the second call's value
    for both. Both executions now stop there with an error naming the two and the port (found by the
    random models above)."""
    from language_support import run_both
    from test_robosim_language import machine

    files = machine("""	initial i
	state A { entry $move(1.5, 2); $jump(7.5, 9) }
	transition t0 { from i to A }
	transition t1 { from A to A exec }""", "interface Jump { jump(x: real, y: int) }\n")
    files["m.rst"] = (files["m.rst"].replace("uses In uses Out requires Ops\n", "uses In uses Out requires Ops requires Jump\n")
                      .replace("{ uses Out requires Ops }", "{ uses Out requires Ops requires Jump }")
                      .replace("provides Ops }", "provides Ops provides Jump }"))
    trace = run_both(tmp_path, files, [{}])
    assert trace[0][0] == "error" and "operations 'move' and 'jump' called in one cycle: both pass argument port" \
        in trace[0][1] and ":30:33:" in trace[0][1], trace  # at the second call
