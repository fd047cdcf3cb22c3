"""Isolated FMUs (issue 22): an FMU run in a process of its own that segfaults, aborts, loops forever or
corrupts its heap at a chosen step ends the run with a located error (the unit, the FMU, the call, the
simulated time) and the rows computed so far; with --on-unit-failure=restart-from-state the run, and
the live twin, go on from the FMU's last good state. The FMUs are built here (tests/fault_fmus.py)."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cotwin.cosim.isolated import IsolatedUnit, fmu_unit
from cotwin.cosim.units import FMUUnit, UnitError
from fault_fmus import FAULTS, fault_fmu, faulty_dmodel_fmu


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    if shutil.which("cc") is None:
        pytest.skip("no C compiler (cc) to build the test FMUs")
    folder = tmp_path_factory.mktemp("fault-fmus")
    return {"saves": fault_fmu(folder), "forgets": fault_fmu(folder, "forgetful", can_save=False, number=2)}


def _multimodel(folder: Path, fmu: Path, parameters: dict, timeout: float = 30.0, isolate: dict | None = None) -> Path:
    """Two instances of the test FMU: `a` (faulting as `parameters` say) feeding `b`, both logged."""
    shutil.copy(fmu, folder / fmu.name)
    data = {"fmus": {"{f}": fmu.name}, "connections": {"{f}.a.y": ["{f}.b.u"]},
            "parameters": {f"{{f}}.a.{k}": v for k, v in parameters.items()},
            "logVariables": {"{f}.a": ["y", "n"], "{f}.b": ["y", "n"]},
            "algorithm": {"type": "fixed-step", "size": 0.1}, "startTime": 0.0, "endTime": 1.0,
            "cotwin": {"unit_timeout": timeout, **({"isolate": isolate} if isolate else {})}}
    path = folder / "multimodel.json"
    path.write_text(json.dumps(data))
    return path


def _cotwin(*args: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("fault, said", [
    ("segfault", "crashed its process with a memory fault (SIGSEGV)"),
    ("abort", "crashed its process with an abort (SIGABRT)"),
    ("hang", "did not return within 2 s (a hang?); its process was stopped"),
    ("heap", "crashed its process with an abort (SIGABRT); it wrote: malloc"),
    ("error", "returned fmi2Error: the test FMU refuses this step"),
])
def test_a_faulting_fmu_ends_the_run_with_a_located_error_and_the_rows_so_far(fmus, tmp_path, fault, said):
    model = _multimodel(tmp_path, fmus["saves"], {"fault": FAULTS[fault], "fault_at": 0.5}, timeout=2.0)
    started = time.monotonic()
    run = _cotwin("simulate", str(model), "-o", "out.csv", cwd=tmp_path)
    assert run.returncode == 1, run.stderr
    assert f"unit {{f}}.a: fmi2DoStep failed at t = 0.5 s: the FMU faulty.fmu {said}" in run.stderr \
        if fault != "error" else f"unit {{f}}.a: fmi2DoStep failed at t = 0.5 s: {said}" in run.stderr
    assert "cotwin bug" not in run.stderr and "Traceback" not in run.stderr
    rows = _rows(tmp_path / "out.partial.csv")  # the rows up to the failed step are kept
    assert [r["time"] for r in rows] == ["0.0", "0.1", "0.2", "0.3", "0.4", "0.5"]
    assert [r["{f}.a.n"] for r in rows] == ["0", "1", "2", "3", "4", "5"]
    assert time.monotonic() - started < 120  # a hang costs its timeout, not forever


def test_which_fmus_run_isolated(fmus, tmp_path):
    from conftest import EXAMPLES
    from cotwin.twin.assembly.build import dmodel_fmu
    from cotwin.twin.assembly.run import load

    assert isinstance(fmu_unit("x", fmus["saves"]), IsolatedUnit)  # not built by cotwin: isolated by default
    assert isinstance(fmu_unit("x", fmus["saves"], isolate=False), FMUUnit)
    ours = dmodel_fmu(load(EXAMPLES / "ur5e" / "cotwin.toml"), tmp_path)
    assert isinstance(fmu_unit("x", ours), FMUUnit)  # cotwin's own d-model FMU: in the master's process
    assert isinstance(fmu_unit("x", ours, isolate=True), IsolatedUnit)
    assert isinstance(fmu_unit("x", ours, isolate=False, restart=True), IsolatedUnit)  # a restart needs a process
    from cotwin.cosim.multimodel import read_multimodel, system_of

    model = _multimodel(tmp_path, fmus["saves"], {}, isolate={"{f}.b": False})
    units = system_of(read_multimodel(model)).units
    assert isinstance(units["{f}.a"], IsolatedUnit) and isinstance(units["{f}.b"], FMUUnit)
    model.write_text(model.read_text().replace('"{f}.b": false', '"{f}.c": 1'))
    with pytest.raises(Exception, match="cotwin.isolate: '\\{f\\}.c' is not a '\\{key\\}.instance' of a listed FMU"):
        read_multimodel(model)


def test_restart_from_state_continues_a_transient_fault_as_if_nothing_happened(fmus, tmp_path):
    """The 4th fmi2DoStep of every process crashes: restarted from the state after the last good step, the
    run gives the rows of a run without the fault; a fault that comes back at the same step ends it."""
    clean = tmp_path / "clean"
    clean.mkdir()
    expected = _cotwin("simulate", str(_multimodel(clean, fmus["saves"], {})), "-o", "out.csv", cwd=clean)
    assert expected.returncode == 0, expected.stderr
    model = _multimodel(tmp_path, fmus["saves"], {"fault": FAULTS["segfault"], "fault_call": 4})
    run = _cotwin("simulate", str(model), "-o", "out.csv", "--on-unit-failure", "restart-from-state", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "unit {f}.a: fmi2DoStep failed at t = 0.3 s (the FMU faulty.fmu crashed its process with a memory fault " \
           "(SIGSEGV)); restarted its FMU faulty.fmu from its state at t = 0.3 s" in run.stderr
    assert "unit {f}.a: restarted 3 time(s) from its last good state, at t = 0.3, 0.6, 0.9 s" in run.stderr
    assert _rows(tmp_path / "out.csv") == _rows(clean / "out.csv")
    stuck = _multimodel(tmp_path, fmus["saves"], {"fault": FAULTS["abort"], "fault_at": 0.5})
    again = _cotwin("simulate", str(stuck), "-o", "out.csv", "--on-unit-failure", "restart-from-state", cwd=tmp_path)
    assert again.returncode == 1
    assert "fmi2DoStep failed at t = 0.5 s: the FMU faulty.fmu crashed its process with an abort (SIGABRT) (again " \
           "after a restart from its state at t = 0.5 s)" in again.stderr
    assert len(_rows(tmp_path / "out.partial.csv")) == 6


def test_an_fmu_that_cannot_save_its_state_says_it_cannot_be_restarted(fmus, tmp_path):
    model = _multimodel(tmp_path, fmus["forgets"], {"fault": FAULTS["segfault"], "fault_call": 4})
    run = _cotwin("simulate", str(model), "-o", "out.csv", "--on-unit-failure", "restart-from-state", cwd=tmp_path)
    assert run.returncode == 1
    assert "its FMU forgetful.fmu cannot save its state (canGetAndSetFMUstate and canSerializeFMUstate are not both " \
           "true): a failure ends the run, it cannot be restarted" in run.stderr
    assert "unit {f}.a: fmi2DoStep failed at t = 0.3 s: the FMU forgetful.fmu crashed its process with a memory fault " \
           "(SIGSEGV); it cannot be restarted from a state: its FMU cannot save one" in run.stderr


def test_an_isolated_dmodel_runs_bit_for_bit_as_in_process_and_their_states_are_interchangeable(tmp_path):
    from conftest import EXAMPLES
    from cotwin.cosim.algorithm import algorithm
    from cotwin.cosim.execution import Execution
    from cotwin.twin.assembly.build import dmodel_fmu
    from cotwin.twin.assembly.run import dt_endpoint, load

    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    fmu = dmodel_fmu(system, tmp_path)
    runs, states = {}, {}
    for kind in ("in-process", "isolated"):
        unit = IsolatedUnit("{dmodel}.dmodel", fmu) if kind == "isolated" else FMUUnit("{dmodel}.dmodel", fmu)
        execution = Execution(system.instantiate(fmu, dt_endpoint(system), dmodel=unit), algorithm("gauss-seidel"), 0.1)
        execution.initialize()
        rows = []
        while execution.time < 8.0 - 1e-9:
            execution.step()
            rows.append([repr(v) for v in execution.values.values()])
            if abs(execution.time - 6.0) < 1e-9:
                states[kind] = execution.get_state()
        runs[kind] = rows
        execution.close()
    assert runs["isolated"] == runs["in-process"] and len({tuple(r) for r in runs["isolated"]}) > 20
    assert states["isolated"] == states["in-process"]
    for into in ("in-process", "isolated"):  # a state of one restores into the other and goes on the same way
        unit = IsolatedUnit("{dmodel}.dmodel", fmu) if into == "isolated" else FMUUnit("{dmodel}.dmodel", fmu)
        fork = Execution(system.instantiate(fmu, dt_endpoint(system), dmodel=unit), algorithm("gauss-seidel"), 0.1)
        fork.set_state(states["isolated" if into == "in-process" else "in-process"])
        rows = []
        while fork.time < 8.0 - 1e-9:
            fork.step()
            rows.append([repr(v) for v in fork.values.values()])
        fork.close()
        assert rows == runs["in-process"][60:]
    with pytest.raises(UnitError, match="state is of another FMU"):
        unit = IsolatedUnit("{dmodel}.dmodel", fmu)
        unit.instantiate(0.0)
        try:
            from cotwin.cosim.state import pack, unpack

            data = unpack(unpack(states["isolated"], "Execution")["units"]["{dmodel}.dmodel"], "FMU")
            unit.set_state(pack("FMU", {**data, "guid": "{0}"}))
        finally:
            unit.terminate()


@pytest.fixture(scope="module")
def crashing_project(tmp_path_factory):
    """A copy of examples/ur5e whose d-model FMU, built elsewhere ([models] fmu), segfaults at the 40th
    fmi2DoStep of every process it runs in; and the outputs of the project as it is."""
    from conftest import EXAMPLES
    from cotwin.twin.assembly.run import load, run_twin

    if shutil.which("cc") is None:
        pytest.skip("no C compiler (cc) to build the test FMUs")
    folder = tmp_path_factory.mktemp("crashing") / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", folder)
    system = load(folder / "cotwin.toml")
    faulty_dmodel_fmu(system.models.program, folder, folder / "crashing.fmu", "segfault", 40)
    text = (folder / "cotwin.toml").read_text().replace('mapping = "mapping.pm"', 'mapping = "mapping.pm"\nfmu = "crashing.fmu"')
    (folder / "crashing.toml").write_text(text.replace("end = 20.0", "end = 12.0"))
    clean = folder.parent / "clean"
    run_twin(system, clean, end=12.0, plot=False)
    return folder, clean


def test_a_twin_run_survives_a_crashing_dmodel_fmu_with_restart_from_state(crashing_project, tmp_path):
    folder, clean = crashing_project
    ended = _cotwin("run", "crashing.toml", "-o", str(tmp_path / "ended"), cwd=folder)
    assert ended.returncode == 1  # isolated by default (cotwin did not build it): a located error, not rc 139
    assert "unit {dmodel}.dmodel: fmi2DoStep failed at t = 3.9 s: the FMU dmodel.fmu crashed its process with a " \
           "memory fault (SIGSEGV)" in ended.stderr
    assert len(_rows(tmp_path / "ended" / "outputs.partial.csv")) == 40
    survived = _cotwin("run", "crashing.toml", "-o", str(tmp_path / "survived"), "--on-unit-failure=restart-from-state",
                       cwd=folder)
    assert survived.returncode == 0, survived.stderr
    assert "unit {dmodel}.dmodel: restarted 3 time(s) from its last good state, at t = 3.9, 7.8, 11.7 s" in survived.stderr
    assert (tmp_path / "survived" / "outputs.csv").read_text() == (clean / "outputs.csv").read_text()


def test_the_live_twin_survives_a_crashing_dmodel_fmu_with_restart_from_state(crashing_project, tmp_path):
    from cotwin.twin.assembly.run import load, simulated_endpoint
    from cotwin.twin.live.runtime import LiveTwin

    folder, clean = crashing_project
    system = load(folder / "crashing.toml")
    result = LiveTwin(system, tmp_path, pt=simulated_endpoint(system), end=6.0, restart=True).run()
    assert result.pt.steps == result.dt.steps == 60
    dt = _rows(tmp_path / "dt" / "outputs.csv")
    expected = _rows(clean / "outputs.csv")[:61]
    assert [r["{mapping}.mapping.q0"] for r in dt] == [r["{mapping}.mapping.q0"] for r in expected]
    with pytest.raises(Exception, match="fmi2DoStep failed at t = 3.9 s: the FMU dmodel.fmu crashed its process"):
        LiveTwin(load(folder / "crashing.toml"), tmp_path / "again", pt=simulated_endpoint(system), end=6.0).run()


@pytest.mark.parametrize("answer, said", [
    (b"\x00" + (1 << 31).to_bytes(4, "little"), "answer with a frame of 2147483648 bytes"),
    (b"\x07\x00\x00\x00\x00", "answer with an answer of kind 7"),
    (b"\x00\x03\x00\x00\x00abc", "answered 3 bytes for 12 bytes of outputs"),
    (b"\x00\x00\x00", "closed its connection|ended its process|crashed"),
])
def test_a_worker_that_answers_nonsense_is_stopped_with_a_located_error(fmus, answer, said):
    """Whatever a damaged worker writes, the master reads only frames of its own layout: a length beyond
    bounds, an unknown kind of answer or outputs of the wrong size end the unit with a located error."""
    import os

    unit = IsolatedUnit("{f}.a", fmus["saves"], timeout=5)
    unit.instantiate(0.0)
    read = unit.getter(["y", "n"])
    unit.initialize()
    unit.step(0.0, 0.1)
    assert read() == (0.0, 1)
    worker = unit._worker
    fake_r, fake_w = os.pipe()
    os.write(fake_w, answer)
    os.close(fake_w)
    real, worker.from_worker = worker.from_worker, fake_r
    try:
        # the call named is the one the worker is in when the master gives up on it (a live worker here)
        with pytest.raises(UnitError, match=f"unit \\{{f\\}}.a: fmi2\\w+ failed at t = 0.1 s: .*({said})"):
            unit.step(0.1, 0.1)
        assert worker.process.poll() is not None  # the worker was stopped
    finally:
        os.close(real)
        unit.terminate()
