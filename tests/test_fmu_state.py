"""The d-model FMU as an artefact: its C sources (the FMI wrapper a source file, the ports a generated
header), the compiler it is built with, every call checked, and its state saved, serialised and
restored through FMPy and through cotwin's FMU unit."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from cotwin.cosim.state import StateError
from cotwin.cosim.units import FMUUnit, UnitError
from cotwin.diagnostics import CotwinError
from cotwin.dmodel.fmu import WRAPPER, build_fmu, fmu_sources
from cotwin.dmodel.ports import PortLayout
from cotwin.dmodel.program import build_program
from cotwin.robosim.check import load_checked

COMMAND = {"moveDiscreteCommand": True, "MovementArgs_target_X": 3, "MovementArgs_target_Y": 20,
           "MovementArgs_target_Z": 2}
# a command, feasibility, completion, stop: every transition of the arm's move
SCRIPT = [COMMAND, {"feasibleMoveDiscreteCommand": True}, {}, {"moveCompleted": True}, {"robotStopped": True}, {}]


@pytest.fixture(scope="module")
def program():
    from conftest import EXAMPLES

    return build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"]))


@pytest.fixture(scope="module")
def fmu(program, tmp_path_factory):
    return build_fmu(program, tmp_path_factory.mktemp("fmu") / "arm.fmu")


def _inputs(program, present: dict) -> dict:
    """Every input event false but those present, value ports as given."""
    events = {ev.name: False for ev in program.inputs}
    return {**events, **present}


def _outputs(layout: PortLayout) -> list[str]:
    return [v.name for v in layout.variables if v.causality == "output"]


def test_wrapper_is_a_source_file_and_the_sources_are_deterministic(program, fmu, tmp_path):
    files = fmu_sources(program)
    assert files["sources/fmi2.c"] == WRAPPER.read_text()
    assert "#define N_VARIABLES" in files["sources/ports.h"] and "STATE_TAG" in files["sources/ports.h"]
    again = build_fmu(build_program(program.project), tmp_path / "again.fmu")
    assert again.read_bytes() == fmu.read_bytes()  # byte-identical, binary included
    md = read_model_description(str(fmu))
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert validate_fmu(str(fmu)) == []


def _compiler_wrapper(tmp_path):
    log = tmp_path / "cc.log"
    script = tmp_path / "my-cc"
    script.write_text(f'#!/bin/sh\necho "$@" >> {log}\nexec cc "$@"\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script, log


def test_the_given_compiler_builds_the_fmu(program, tmp_path):
    script, log = _compiler_wrapper(tmp_path)
    out = build_fmu(program, tmp_path / "a.fmu", cc=str(script))
    assert "fmi2.c" in log.read_text() and validate_fmu(str(out)) == []
    with pytest.raises(CotwinError, match="no C compiler 'no-such-cc'"):
        build_fmu(program, tmp_path / "b.fmu", cc="no-such-cc")
    failing = tmp_path / "bad-cc"
    failing.write_text("#!/bin/sh\necho 'bad-cc: refused' >&2\nexit 3\n")
    failing.chmod(0o755)
    with pytest.raises(CotwinError, match="bad-cc: refused"):
        build_fmu(program, tmp_path / "c.fmu", cc=str(failing))


def test_cli_honours_cc(tmp_path):
    """Every build runs the given compiler (with no cache: a cached binary would be copied, not compiled)."""
    from conftest import EXAMPLES

    script, log = _compiler_wrapper(tmp_path)
    env = {**os.environ, "COTWIN_CACHE": "off"}
    proc = subprocess.run([sys.executable, "-m", "cotwin", "build-dmodel", str(EXAMPLES / "ur5e" / "arm.rst"), "-o",
                           str(tmp_path / "arm.fmu"), "--cc", str(script)], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    assert log.is_file()
    log.unlink()
    out = tmp_path / "twin"
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(EXAMPLES / "ur5e" / "cotwin.toml"), "-o",
                           str(out), "--end", "0.5", "--cc", str(script)], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    assert log.is_file() and (out / "outputs.csv").is_file()


def test_a_dmodel_compiled_once_is_copied_from_the_cache(program, tmp_path, monkeypatch):
    """The same sources and compiler compile once: a second build (another folder, as a what-if's or a new
    run's) copies the cached binary; a changed compiler command compiles again."""
    monkeypatch.setenv("COTWIN_CACHE", str(tmp_path / "cache"))
    script, log = _compiler_wrapper(tmp_path)
    first = build_fmu(program, tmp_path / "a.fmu", cc=str(script))
    assert log.read_text().count("fmi2.c") == 1
    second = build_fmu(program, tmp_path / "b.fmu", cc=str(script))
    assert log.read_text().count("fmi2.c") == 1 and first.read_bytes() == second.read_bytes()
    build_fmu(program, tmp_path / "c.fmu", cc=f"{script} -DCOTWIN_OTHER=1")
    assert log.read_text().count("fmi2.c") == 2


def test_rollback_through_fmpy(program, fmu):
    """A third-party importer saves the state, runs on, restores it and gets the same future."""
    layout = PortLayout(program)
    vr = {v.name: v.vr for v in layout.variables}
    folder = extract(str(fmu))
    md = read_model_description(folder)
    slave = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="arm")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()

    def run(steps, t0):
        seen = []
        for k, present in enumerate(steps):
            inputs = _inputs(program, present)
            slave.setBoolean([vr[n] for n, v in inputs.items() if isinstance(v, bool)],
                             [v for v in inputs.values() if isinstance(v, bool)])
            ints = {n: v for n, v in inputs.items() if not isinstance(v, bool)}
            if ints:
                slave.setInteger([vr[n] for n in ints], list(ints.values()))
            slave.doStep(t0 + k, 1.0)
            seen.append((slave.getInteger([vr["state"]])[0], slave.getBoolean([vr["movediscrete"], vr["stop"]]),
                         slave.getInteger([vr["target_X"], vr["target_Y"], vr["target_Z"]])))
        return seen

    try:
        run(SCRIPT[:1], 0.0)
        state = slave.getFMUstate()
        first = run(SCRIPT[1:], 1.0)
        slave.setFMUstate(state)
        assert run(SCRIPT[1:], 1.0) == first
        assert len({s for s, _, _ in first}) > 2  # the future visited several states
        blob = slave.serializeFMUstate(state)
        slave.freeFMUstate(state)
        restored = slave.deSerializeFMUstate(blob)
        slave.setFMUstate(restored)
        assert run(SCRIPT[1:], 1.0) == first
        slave.freeFMUstate(restored)
    finally:
        slave.terminate()
        slave.freeInstance()


def test_serialised_state_restored_in_a_new_instance_steps_the_same(program, fmu):
    layout = PortLayout(program)
    outputs = _outputs(layout)
    a, b = FMUUnit("a", fmu), FMUUnit("b", fmu)
    try:
        for u in (a, b):
            u.instantiate(0.0)
            u.initialize()
        for k, present in enumerate(SCRIPT[:2]):
            a.set(_inputs(program, present))
            a.step(float(k), 1.0)
        state = a.get_state()
        b.set_state(state)
        assert b.time == a.time
        states = []
        for k, present in enumerate(SCRIPT[2:], start=2):
            for u in (a, b):
                u.set(_inputs(program, present))
                u.step(float(k), 1.0)
            assert a.get(outputs) == b.get(outputs)
            states.append(b.get(["state"])["state"])
        assert len(set(states)) > 2  # the restored instance went through the move's states
    finally:
        a.terminate()
        b.terminate()


OTHER = """interface I { event go }
stm M { input context { uses I } initial i state A { } transition t0 { from i to A } }
controller C { uses I sref m = M connection C on go to m on go (_async) }
module Other { robotic platform P { uses I } cref c = C connection P on go to c on go (_async) }
"""


def test_foreign_or_damaged_states_are_refused(program, fmu, tmp_path):
    (tmp_path / "other.rst").write_text(OTHER)
    other = FMUUnit("other", build_fmu(build_program(load_checked([tmp_path / "other.rst"])), tmp_path / "o.fmu"))
    unit = FMUUnit("a", fmu)
    for u in (unit, other):
        u.instantiate(0.0)
        u.initialize()
    try:
        state = unit.get_state()
        with pytest.raises(StateError, match="not a cotwin state"):
            unit.set_state(b"garbage")
        with pytest.raises(StateError, match="damaged"):
            unit.set_state(state[:40])
        from cotwin.cosim.state import pack, unpack

        data = unpack(state, "FMU")
        with pytest.raises(UnitError, match="state is of another FMU"):
            unit.set_state(pack("FMU", {**data, "guid": "{0}"}))
        # the FMU itself refuses bytes of another module, and says why
        with pytest.raises(UnitError, match="fmi2DeSerializeFMUstate failed.*not a state of this FMU"):
            other.set_state(pack("FMU", {**data, "guid": other.md.guid}))
    finally:
        unit.terminate()
        other.terminate()


def test_failed_calls_name_the_call_and_what_the_fmu_said(fmu):
    unit = FMUUnit("arm", fmu)
    unit.instantiate(0.0)
    try:
        with pytest.raises(CotwinError, match="moveDiscreteCommand takes a Boolean"):
            unit.set({"moveDiscreteCommand": 2.5})
        from ctypes import c_double, c_uint

        with pytest.raises(UnitError, match="fmi2SetReal failed at t = 0 s: returned fmi2Error: fmi2SetReal: "
                                            "no variable has value reference 999"):
            unit._call("fmi2SetReal", unit._fn["fmi2SetReal"], unit.component, (c_uint * 1)(999), 1,
                       (c_double * 1)(0.0))
        assert unit.status == "error"
    finally:
        unit.terminate()
    assert unit.fmu is None and (unit.folder is None or not os.path.exists(unit.folder))
    assert zipfile.is_zipfile(fmu)


def test_port_memory_and_fmi_calls_move_the_same_values(program, fmu):
    """A cotwin-built FMU's ports are read and written in its memory (cotwin_ports); the same run
    through fmi2Set/fmi2Get calls gives the same outputs, and bad values are refused either way."""
    layout = PortLayout(program)
    outputs = _outputs(layout)
    direct, calls = FMUUnit("direct", fmu), FMUUnit("calls", fmu)
    try:
        for u in (direct, calls):
            u.instantiate(0.0)
            u.initialize()
        assert direct._memory is not None
        calls._memory = None  # as for an FMU built elsewhere
        inputs = list(_inputs(program, {}))
        setters = [u.setter(inputs) for u in (direct, calls)]
        getters = [u.getter(outputs) for u in (direct, calls)]
        for k, present in enumerate(SCRIPT):
            values = [_inputs(program, present)[n] for n in inputs]
            for u, write in zip((direct, calls), setters):
                write(values)
                u.step(float(k), 1.0)
            assert getters[0]() == getters[1]()
            assert [type(v) for v in getters[0]()] == [type(v) for v in getters[1]()]
        for u in (direct, calls):
            with pytest.raises(CotwinError, match="does not fit an FMI Integer"):
                u.set({"MovementArgs_target_X": 2 ** 31})
            with pytest.raises(CotwinError, match="takes a Real"):
                u.set({"cycle_period": float("nan")})
    finally:
        direct.terminate()
        calls.terminate()



def test_instances_of_a_cotwin_fmu_share_one_cached_folder_and_step_apart(program, fmu, tmp_path, monkeypatch):
    """Extracting the d-model FMU and removing its nine files cost each run ~2 ms: a cotwin-built FMU is
    extracted once into the cache and shared; its instances still keep their own state, and the folder
    outlives the instance that ends first."""
    monkeypatch.setenv("COTWIN_CACHE", str(tmp_path / "cache"))
    a, b = FMUUnit("a", fmu), FMUUnit("b", fmu)
    try:
        for u in (a, b):
            u.instantiate(0.0)
            u.initialize()
        assert a.folder == b.folder and a.folder.startswith(str(tmp_path / "cache" / "fmu"))
        a.set(_inputs(program, COMMAND))
        a.step(0.0, 1.0)
        b.set(_inputs(program, {}))
        b.step(0.0, 1.0)
        assert a.get(["state"]) != b.get(["state"])  # the command moved a, not b
        a.terminate()
        b.set(_inputs(program, COMMAND))
        b.step(1.0, 1.0)  # the library and folder are still b's after a ended
        assert os.path.isdir(b.folder)
        folder = b.folder
    finally:
        a.terminate()
        b.terminate()
    assert os.path.isdir(folder)  # kept for the next run
    again = FMUUnit("c", fmu)
    again.instantiate(0.0)
    assert again.folder == folder
    again.terminate()


def test_without_a_cache_or_for_a_damaged_one_an_instance_has_its_own_folder(program, fmu, tmp_path, monkeypatch):
    monkeypatch.setenv("COTWIN_CACHE", "off")
    unit = FMUUnit("a", fmu)
    unit.instantiate(0.0)
    own = unit.folder
    assert "cache" not in own and os.path.isdir(own)
    unit.terminate()
    assert not os.path.exists(own)  # removed with the instance
    monkeypatch.setenv("COTWIN_CACHE", str(tmp_path / "cache"))
    unit = FMUUnit("b", fmu)
    unit.instantiate(0.0)
    shared = unit.folder
    unit.terminate()
    for binary in (tmp_path / "cache" / "fmu").glob("*/binaries/*/*"):
        binary.unlink()  # the cached folder damaged: an instance extracts its own
    unit = FMUUnit("c", fmu)
    unit.instantiate(0.0)
    assert unit.folder != shared and os.path.isfile(os.path.join(unit.folder, "modelDescription.xml"))
    unit.initialize()
    unit.terminate()


@pytest.mark.parametrize("cache", ["read-only", "a file"])
def test_a_cache_that_cannot_be_written_gives_an_instance_its_own_folder(program, fmu, tmp_path, monkeypatch, cache):
    """The cache is an optimisation: a read-only cache folder, or COTWIN_CACHE naming a file, failed the run
    ('extract failed at t = 0 s: [Errno 20] Not a directory: .../fmu')."""
    if cache == "a file":
        (tmp_path / "cache").write_text("not a folder")
    monkeypatch.setenv("COTWIN_CACHE", str(tmp_path / "cache"))

    def refused(folder, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(folder))

    if cache == "read-only":  # chmod 555 does not stop root, who may run the tests: the refusal made by hand
        monkeypatch.setattr(Path, "mkdir", refused)
    unit = FMUUnit("a", fmu)
    unit.instantiate(0.0)
    own = unit.folder
    assert os.path.isfile(os.path.join(own, "modelDescription.xml")) and not own.startswith(str(tmp_path / "cache"))
    unit.initialize()
    unit.step(0.0, 1.0)
    unit.terminate()
    assert not os.path.exists(own)  # removed with the instance
    assert not list(tmp_path.glob("cache/fmu/.*"))  # no staged folder left behind
