"""No silent wrong result, no crash: each class of fault found by a hostile user, now a located error or
the right result (the d-model's own arithmetic faults are tested with the C generator)."""

from __future__ import annotations

import csv
import json
import math
import shutil
import signal
import subprocess
import sys
import time

import pytest

from conftest import cotwin_in_process
from cotwin.cosim.algorithm import Jacobi
from cotwin.cosim.execution import Execution
from cotwin.cosim.multimodel import execution_for, read_multimodel
from cotwin.cosim.system import Connection, System
from cotwin.cosim.units import FMUUnit, Port, PythonUnit
from cotwin.diagnostics import CotwinError, Interrupted
from cotwin.twin.assembly.build import build, folder_lock
from cotwin.twin.project import load_project
from cotwin.twin.assembly.run import load
from cotwin.twin.assembly.scenario import read_plan, read_toml


def cotwin(*args) -> subprocess.CompletedProcess:
    """`cotwin ARGS` in this process: the tests using it check messages, artefacts and exit status (the
    SIGTERM test starts its run as a process of its own)."""
    return cotwin_in_process(*args)


def clean(proc: subprocess.CompletedProcess) -> bool:
    """A refusal: exit 1 or 2 with a message, no traceback, no crash report."""
    return proc.returncode in (1, 2) and "Traceback" not in proc.stderr and "internal error" not in proc.stderr


@pytest.fixture(scope="module")
def system():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


@pytest.fixture
def project(tmp_path):
    """A copy of the UR5e example project to break."""
    from conftest import EXAMPLES

    target = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", target)
    return target


def test_a_changed_dmodel_is_rebuilt_not_reused(project, tmp_path):
    out = tmp_path / "out"
    assert cotwin("run", project / "cotwin.toml", "-o", out, "--end", "1").returncode == 0
    before = (out / "dmodel.fmu").read_bytes()
    text = (project / "arm.rst").read_text()
    (project / "arm.rst").write_text(text.replace("state Idle", "state Resting").replace("to Idle", "to Resting")
                                     .replace("Idle", "Resting"))
    proc = cotwin("run", project / "cotwin.toml", "-o", out, "--end", "1")
    assert proc.returncode == 0, proc.stderr
    assert (out / "dmodel.fmu").read_bytes() != before
    import zipfile

    with zipfile.ZipFile(out / "dmodel.fmu") as z:  # the state names of the new model
        assert "Resting" in z.read("modelDescription.xml").decode()
    built = json.loads((out / "build.json").read_text())
    assert set(built) == {"dmodel.fmu", "digests"}  # the key of what was built, and the digest of what was written
    assert set(built["digests"]) == {"dmodel.fmu"} and built["digests"]["dmodel.fmu"]["key"] == built["dmodel.fmu"]
    # an interrupted build (an artefact without its record) is redone
    (out / "build.json").unlink()
    (out / "dmodel.fmu").write_bytes(b"half a zip")
    assert cotwin("run", project / "cotwin.toml", "-o", out, "--end", "1").returncode == 0
    assert (out / "dmodel.fmu").read_bytes()[:2] == b"PK"


def test_plan_values_out_of_range_or_ill_timed_are_located_errors(system, tmp_path):
    plan = tmp_path / "plan.csv"
    header = "timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,MovementArgs_target_Z\n"
    cases = {
        "1000,true,4294967296,0,0": r"plan.csv:2:\d+: error: column 'MovementArgs_target_X': '4294967296' does not fit",
        "1000,true,2147483648,0,0": "does not fit an FMI Integer",
        "1000,true,1e300,0,0": "does not fit an FMI Integer",
        "1000,true,nan,0,0": "is not a finite number",
        "1000,true,inf,0,0": "is not a finite number",
        "-5,true,1,1,1": r"plan.csv:2:1: error: timestep '-5' is negative",
        "nan,true,1,1,1": "timestep 'nan' is not a finite number",
        "1000,yes,1,1,1": "is not true/false",
        "1000,true," + "9" * 100_000 + ",0,0": "longer than",
        "1000,true,1,1,1\n2000,true," + "9" * 5_000_000 + ",0,0": r"plan.csv:3:1: error: a cell longer than",
        '1000,true,1,1,1\n2000,true,"' + "9\n" * 200_000: r"plan.csv:\d{4,}:1: error: bad CSV: field larger",
    }
    for row, message in cases.items():
        plan.write_text(header + row + "\n")
        with pytest.raises(CotwinError, match=message):
            read_plan(plan, system.models.program)
    plan.write_text(header + "1000,true,1,1,1\n1000,true,2,2,2\n")  # two at one time: both kept, in order (issue 19)
    assert [dict(c.values)["MovementArgs_target_X"] for c in read_plan(plan, system.models.program)] == [1, 2]
    plan.write_text("timestep,moveDiscreteCommand,MovementArgs_target_X\n1000,true,1\n")
    with pytest.raises(CotwinError, match=r"plan.csv:1:10: error: column 'moveDiscreteCommand' without its argument "
                                          r"column\(s\) MovementArgs_target_Y, MovementArgs_target_Z"):
        read_plan(plan, system.models.program)
    plan.write_bytes(header.encode() + b"1000,true,1,\xff,1\n")
    with pytest.raises(CotwinError, match=r"plan.csv:2:\d+: error: the plan is not UTF-8"):
        read_plan(plan, system.models.program)


def test_two_commands_of_one_event_in_one_step_are_both_applied_in_order(system, tmp_path):
    """At the plan's own times they are apart, but a step of 0.1 s makes both due in one step: one step
    carries one occurrence, so the second is applied in the next step, with its own arguments (issue 19:
    every accepted command applied, once, in order; it used to be refused); a step that separates them
    applies each in its own step."""
    from cotwin.twin.assembly.run import run_twin

    plan = tmp_path / "plan.csv"
    plan.write_text("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,MovementArgs_target_Z\n"
                    "1000,true,0,23,1\n1050,true,3,20,2\n")
    twin = system.with_plan(read_plan(plan, system.models.program))
    for step in (0.1, 0.05):
        ran = run_twin(twin, tmp_path / f"step{step}", step=step, end=2.0, plot=False)
        rows = list(csv.DictReader(open(ran.csv)))
        pulses = [(k, r["{controller}.controller.MovementArgs_target_X"]) for k, r in enumerate(rows)
                  if r["{controller}.controller.moveDiscreteCommand"] == "true"]
        assert [x for _, x in pulses] == ["0", "3"]  # both delivered, each in its own step, in order
        assert pulses[1][0] - pulses[0][0] == 1
        applied = ran.units["source"].queue.applied
        assert [round(a.time, 6) for a in applied] == [round(float(rows[k]["time"]), 6) for k, _ in pulses]


def test_scenario_and_project_tomls_are_strict(system, tmp_path, project):
    scenario = tmp_path / "s.toml"
    cases = {
        '[[command]]\ntime = 1.0\nevent = "moveDiscreteCommand"\nargs = 5\n': r"s.toml:4:1: error: \[\[command\]\] 1 args must be a table",
        '[[command]]\ntime = -1\nevent = "moveDiscreteCommand"\n': r"s.toml:2:1: error: \[\[command\]\] 1 time must be a number >= 0",
        '[[command]]\ntime = nan\nevent = "moveDiscreteCommand"\n': "time must be a number >= 0",
        '[[command]]\ntime = 1\nevent = "moveDiscreteCommand"\nargs = { target_X = 4294967296 }\n': "does not fit",
        '[[command]]\ntime = 1\nevent = 42\n': "event must be a string",
        '[[command]]\ntime = 1\nevent = "moveDiscreteCommand"\nspeed = 2\n': "unknown key 'speed'",
        '[[command]]\ntime = 1\nevent = "moveDiscreteCommand"\nargs = { target_X = 1 }\n':
            r"s.toml:1:1: error: \[\[command\]\] 1: event moveDiscreteCommand carries "
            r"MovementArgs_target_Y, MovementArgs_target_Z: a command gives every argument",
        "[[command]\n": r"s.toml:1:\d+: error: bad TOML",
        '[[command]]\ntime = 1.0\nevent = = "x"\n': r"s.toml:3:\d+: error: bad TOML",  # at its line, not 1:1
    }
    for text, message in cases.items():
        scenario.write_text(text)
        with pytest.raises(CotwinError, match=message):
            read_toml(scenario, system.models.program)
    toml = project / "cotwin.toml"
    original = toml.read_text()
    for old, new, message in [('dmodel = "arm.rst"', "dmodel = 42", r"cotwin.toml:\d+:1: error: \[models\] dmodel must be a string"),
                              ("[cosim]", '[cosim]\nrealtime = "no"', r"\[cosim\] realtime must be true or false"),
                              ("step = 0.1", "step = inf", r"\[cosim\] step must be a positive number"),
                              ("[platform]", '[platform]\nurl = "amqp://u:secret@h/"', "a password in the project file is refused")]:
        assert old in original
        toml.write_text(original.replace(old, new, 1))
        with pytest.raises(CotwinError, match=message) as err:
            load_project(toml)
        assert "secret" not in str(err.value)
    toml.write_bytes(original.encode() + b"\n# \xff\n")
    with pytest.raises(CotwinError, match=r"cotwin.toml:\d+:\d+: error: the project file is not UTF-8"):
        load_project(toml)


def test_command_line_values_are_checked(project, tmp_path):
    for args, message in [(["--end", "0"], "--end"), (["--end", "nan"], "not a finite number"),
                          (["--step", "inf"], "not a finite number"), (["--step", "-1"], "--step")]:
        proc = cotwin("run", project / "cotwin.toml", "-o", tmp_path / "o", *args)
        assert clean(proc) and message in proc.stderr, proc.stderr
    proc = cotwin("verify", project / "arm.rst", "--domain", "nosuchport=0..3")
    assert clean(proc) and "nosuchport: not a value port" in proc.stderr


def test_multimodel_phantom_instances_fan_in_and_types_are_errors(system, tmp_path):
    build(system, tmp_path)
    mm = json.loads((tmp_path / "multimodel.json").read_text())

    def problems(data) -> str:
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(data, indent=2))
        with pytest.raises(CotwinError) as err:
            execution_for(read_multimodel(path))
        return str(err.value)

    def line_of(data, needle: str) -> int:
        lines = json.dumps(data, indent=2).splitlines()
        return next(k for k, line in enumerate(lines, 1) if needle in line)

    typo = json.loads(json.dumps(mm))
    typo["connections"]["{dmodel}.dmodel.movediscrete"] = ["{mapping}.mappin.movediscrete"]
    text = problems(typo)
    assert "instance {mapping}.mappin receives inputs but nothing reads its outputs" in text
    assert f"bad.json:{line_of(typo, 'mappin.')}:" in text  # the line of the misspelt name, not 1:1
    sender = json.loads(json.dumps(mm))  # misspelt where it sends: the d-model would read a copy nobody drives
    sender["connections"]["{mapping}.maping.feasibleMoveDiscreteCommand"] = \
        sender["connections"].pop("{mapping}.mapping.feasibleMoveDiscreteCommand")
    text = problems(sender)
    assert "instance {mapping}.maping only sends outputs" in text and "{mapping}.mapping" in text
    assert f"bad.json:{line_of(sender, 'maping.')}:" in text
    fan_in = json.loads(json.dumps(mm))
    fan_in["connections"]["{dmodel}.dmodel.stop"].append("{mapping}.mapping.movediscrete")
    assert "input {mapping}.mapping.movediscrete has two sources" in problems(fan_in)
    types = json.loads(json.dumps(mm))
    types["connections"]["{mapping}.mapping.q0"] = ["{dmodel}.dmodel.moveCompleted"]
    text = problems(types)
    assert "a Real output cannot feed a Boolean input" in text
    bad = json.loads(json.dumps(mm))
    bad["endTime"], bad["simulationProgramDelay"] = float("inf"), "no"
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(bad, indent=2))  # Infinity, which JSON lacks: refused where it is written
    with pytest.raises(CotwinError, match=rf"bad.json:{line_of(bad, 'Infinity')}:\d+: error: "
                                          "bad JSON: Infinity is not a JSON number"):
        read_multimodel(path)
    bad["endTime"] = -1.0
    path.write_text(json.dumps(bad))
    with pytest.raises(CotwinError, match="simulationProgramDelay must be true or false"):
        read_multimodel(path)
    path.write_bytes(b'{"fmus": {"\xff": 1}}')
    with pytest.raises(CotwinError, match=r"bad.json:1:\d+: error: the multimodel is not UTF-8"):
        read_multimodel(path)


def test_a_broker_twin_multimodel_drives_the_robot_not_mujoco(project, tmp_path):
    import zipfile

    toml = project / "cotwin.toml"
    toml.write_text(toml.read_text().replace('endpoint = "mujoco"', 'endpoint = "broker"\nqueue = "my.robot"'))
    build(load(toml), tmp_path)
    with zipfile.ZipFile(tmp_path / "mapping.fmu") as z:
        staged = next(n for n in z.namelist() if n.endswith("twin/cotwin.toml"))
        text = z.read(staged).decode()
    assert 'endpoint = "broker"' in text and 'queue = "my.robot"' in text


def test_an_fmu_without_binaries_is_a_clear_error(system, tmp_path):
    import zipfile

    build(system, tmp_path)
    stripped = tmp_path / "stripped.fmu"
    with zipfile.ZipFile(tmp_path / "dmodel.fmu") as src, zipfile.ZipFile(stripped, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    unit = FMUUnit("{d}.d", stripped)
    with pytest.raises(CotwinError, match=r"unit \{d\}.d: load failed at t = 0 s: .*shared library"):
        Execution(System.of([unit], []), Jacobi(), 0.1).run(1.0)


FATAL_SLAVE = '''
from pythonfmu import Fmi2Slave, Fmi2Causality, Real

class Fatal(Fmi2Slave):
    author = "cotwin tests"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.out = 0.0
        self.register_variable(Real("out", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        if current_time >= 0.25:
            raise RuntimeError("the slave gives up")
        self.out = current_time
        return True
'''

RUN_FATAL = '''
import sys
from cotwin.cosim.algorithm import Jacobi
from cotwin.cosim.execution import Execution
from cotwin.cosim.observers import CSVWriter
from cotwin.cosim.system import System
from cotwin.cosim.units import FMUUnit
from cotwin.diagnostics import CotwinError
unit = FMUUnit("{f}.f", sys.argv[1])
try:
    Execution(System.of([unit], [], log={"{f}.f": ["out"]}), Jacobi(), 0.1, observers=[CSVWriter(sys.argv[2])]).run(1.0)
except CotwinError as err:
    print("ERROR", err, unit.status)
'''


def test_a_python_fmu_failing_fatally_ends_the_run_cleanly(tmp_path):
    from pythonfmu import FmuBuilder

    (tmp_path / "fatal.py").write_text(FATAL_SLAVE)
    fmu = FmuBuilder.build_FMU(tmp_path / "fatal.py", dest=tmp_path)
    for _ in range(5):  # it used to crash in most runs
        proc = subprocess.run([sys.executable, "-c", RUN_FATAL, str(fmu), str(tmp_path / "out.csv")],
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
        assert "ERROR" in proc.stdout and "fmi2DoStep failed at t = 0.3 s" in proc.stdout
        assert proc.stdout.strip().endswith(("fatal", "error"))
        rows = list(csv.reader(open(tmp_path / "out.partial.csv")))
        assert [r[0] for r in rows[1:]] == ["0.0", "0.1", "0.2", "0.3"]


def test_a_folder_in_use_is_refused(tmp_path):
    with folder_lock(tmp_path):
        with pytest.raises(CotwinError, match="in use by another cotwin run"):
            with folder_lock(tmp_path):
                pass
    with folder_lock(tmp_path):  # released
        pass


def test_sigterm_ends_a_run_with_its_rows_kept(project, tmp_path):
    toml = project / "cotwin.toml"
    toml.write_text(toml.read_text().replace("[cosim]", "[cosim]\nrealtime = true", 1))
    out = tmp_path / "out"
    built = cotwin("build", toml, "-o", out)
    assert built.returncode == 0 and (out / "dmodel.fmu").is_file(), built.stderr[-2000:]
    (out / "outputs.csv").write_text("a previous result\n")
    proc = subprocess.Popen([sys.executable, "-m", "cotwin", "run", str(toml), "-o", str(out)], stderr=subprocess.PIPE,
                            text=True)
    part, deadline = out / "outputs.csv.part", time.monotonic() + 60
    while time.monotonic() < deadline and (not part.is_file() or part.read_text().count("\n") < 8):
        time.sleep(0.1)  # rows are flushed every 0.5 s: wait for some, however long starting took
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and "interrupted at t = " in err and "Traceback" not in err
    assert (out / "outputs.csv").read_text() == "a previous result\n"
    rows = list(csv.reader(open(out / "outputs.partial.csv")))
    assert len(rows) > 5 and all(len(r) == len(rows[0]) for r in rows)


def test_values_into_an_fmu_are_checked_not_wrapped(system, tmp_path):
    build(system, tmp_path)
    unit = FMUUnit("{d}.d", tmp_path / "dmodel.fmu")
    source = PythonUnit("{s}.s", [Port("x", "Integer", "output")])
    source.step = lambda t, h: source.values.__setitem__("x", 2 ** 32)
    execution = Execution(System.of([source, unit], [Connection("{s}.s", "x", "{d}.d", "MovementArgs_target_X")]),
                          Jacobi(), 0.1)
    with pytest.raises(CotwinError, match=r"MovementArgs_target_X = 4294967296 does not fit an FMI Integer"):
        execution.run(0.5)
    assert unit.fmu is None  # ended properly
    for bad, kind in ((math.nan, "Real"), (True, "Integer"), ("yes", "Boolean")):
        from cotwin.cosim.units import checked_value

        with pytest.raises(CotwinError):
            checked_value("{u}.u", Port("p", kind, "input"), bad)


def test_an_interrupt_while_the_figure_is_drawn_says_the_run_is_complete(project, tmp_path, monkeypatch):
    """Ctrl-C after the last step, while figure.png is drawn, said only 'interrupted': the user could not tell
    that outputs.csv was whole. The interrupt arrives in the drawing (as SIGINT raises it there)."""
    import cotwin.plot
    from cotwin.twin.assembly.run import run_twin

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cotwin.plot, "figure", interrupted)
    out = tmp_path / "out"
    with pytest.raises(CotwinError) as err:
        run_twin(load(project / "cotwin.toml"), out, end=0.5)
    assert isinstance(err.value, Interrupted)
    assert str(err.value) == ("error: interrupted while drawing the figure; the run is complete: 6 row(s) to "
                              f"t = 0.5 s in {out / 'outputs.csv'}")
    assert len((out / "outputs.csv").read_text().splitlines()) == 1 + 6


def test_an_interrupt_located_at_its_file_stays_an_interrupt():
    """placed() (a what-if's or sweep's error put at its state or plan file) keeps the error's class and what it
    carries: an interrupted sweep so located still exits 130 with its answers kept, not 1 with them lost."""
    import pickle

    from cotwin.diagnostics import Location, placed
    from cotwin.twin.analysis.sweep import SweepInterrupted

    rows = [{"target_X": 1, "feasible": True}]
    err = placed(SweepInterrupted(rows, 4, running=1), Location("state.bin", 0, 0))
    assert type(err) is SweepInterrupted and isinstance(err, Interrupted)
    assert (err.rows, err.total, err.running) == (rows, 4, 1)
    assert [(f.location.path, f.message) for f in err.findings] == [("state.bin", "interrupted after 1 of 4 what-ifs")]
    again = pickle.loads(pickle.dumps(err))  # as it comes back from a worker process
    assert type(again) is SweepInterrupted and again.rows == rows and str(again) == str(err)
    assert type(placed(CotwinError("bad"), Location("plan.csv", 0, 0))) is CotwinError
