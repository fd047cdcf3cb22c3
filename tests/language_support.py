"""Run one d-model in the interpreter and as a compiled FMU with the same inputs, and compare.

A trace is, per cycle, the outputs (in a canonical order) and the active leaf state, or the error
that stopped the run (location and message), so that the two executions must agree on both.
"""

from __future__ import annotations

from pathlib import Path

from cotwin.diagnostics import CotwinError, Severity
from cotwin.dmodel.fmu import build_fmu
from cotwin.dmodel.interpreter import ExecutionError, Interpreter
from cotwin.dmodel.program import build_program
from cotwin.cosim.driver import FMUDriver
from cotwin.robosim.check import check_paths


def checked(folder: Path, files: dict[str, str]):
    """Write the files, check them as one project; (project, warnings). Errors fail the test."""
    for name, text in files.items():
        (folder / name).write_text(text)
    result = check_paths([folder])
    errors = [str(f) for f in result.findings if f.severity is Severity.ERROR]
    assert not errors, "\n".join(errors)
    return result.project, [f for f in result.findings if f.severity is Severity.WARNING]


def _canonical(outputs) -> list[str]:
    return sorted(str(o) for o in outputs)


def interpreter_trace(program, steps: list[dict], parameters: dict | None = None) -> list:
    """Errors located as the FMU locates them: the file relative to the folder of the model files."""
    from cotwin.dmodel.ccode import model_root, portable_location

    interp = Interpreter(program, parameters)
    trace = []
    for inputs in steps:
        try:
            outputs = interp.step(inputs)
        except ExecutionError as err:
            finding = err.findings[0]
            trace.append(("error", f"{portable_location(finding.location, model_root(program))}: {finding.message}"))
            break
        trace.append((_canonical(outputs), [interp.state_index(m.index) for m in program.machines]))
    return trace


def fmu_trace(program, fmu: Path, steps: list[dict], parameters: dict | None = None) -> list:
    driver = FMUDriver(program, fmu, parameters=parameters)
    trace = []
    try:
        for inputs in steps:
            try:
                outputs = driver.step(inputs)
            except CotwinError as err:  # the unit's error ends with what the model logged
                logged = driver.unit.messages[-1][2]
                assert err.findings[0].message.endswith(logged)
                trace.append(("error", logged.removeprefix("fmi2DoStep: ")))
                break
            trace.append((_canonical(outputs), [driver.state(m.index) for m in program.machines]))
    finally:
        driver.close()
    return trace


def run_both(folder: Path, files: dict[str, str], steps: list[dict], parameters: dict | None = None,
             module: str | None = None) -> list:
    """Check, build, run the interpreter and the FMU; assert identical traces; return the trace."""
    project, _ = checked(folder, files)
    program = build_program(project, module)
    expected = interpreter_trace(program, steps, parameters)
    fmu = build_fmu(program, folder / "model.fmu")
    actual = fmu_trace(program, fmu, steps, parameters)
    assert actual == expected, f"FMU {actual}\ninterpreter {expected}"
    return expected
