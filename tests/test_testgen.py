"""Generated co-simulation tests: cotwin testgen (coverage, minimisation, reasons), cotwin test (verdicts against
the oracle on the co-simulation, JUnit, divergences) and cotwin mutants (the suite's worth)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from conftest import EXAMPLES, cotwin_in_process
from cotwin.diagnostics import CotwinError
from cotwin.dmodel.program import build_program
from cotwin.dmodel.testgen import generate
from cotwin.dmodel.testgen_files import read_suite, write_suite
from cotwin.dmodel.testgen_graph import explore
from cotwin.robosim.check import load_checked
from cotwin.twin.assembly.run import load
from cotwin.twin.assembly.scenario import read_plan
from cotwin.twin.analysis.testing import run_suite

UR5E = EXAMPLES / "ur5e"
MODELS = [UR5E / "arm.rst", UR5E / "mapping.pm", UR5E / "ur5e.pm"]
FEASIBLE = ["--domain", "MovementArgs_target_X=8", "--domain", "MovementArgs_target_Y=10",
            "--domain", "MovementArgs_target_Z=1"]


LOCK = ".cotwin.lock"  # the folder's lock (cotwin.twin.assembly.build.folder_lock), not a file of the suite


def suite_files(folder: Path) -> dict[str, bytes]:
    """The files of the suite in `folder`, by name, without the lock a testgen leaves there."""
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.name != LOCK}


def cotwin(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([str(Path(sys.executable).parent / "cotwin"), *map(str, args)], capture_output=True,
                          text=True, cwd=cwd)


@pytest.fixture(scope="module")
def arm():
    return build_program(load_checked([UR5E / "arm.rst"]))


@pytest.fixture(scope="module")
def graph(arm):
    return explore(arm)


@pytest.fixture(scope="module")
def auto_suite(tmp_path_factory):
    """The UR5e suite with each case's answers chosen by trying it on the project's simulated platform."""
    out = tmp_path_factory.mktemp("auto") / "tests"
    proc = cotwin("testgen", *MODELS, *FEASIBLE, "--answers", "auto", "--project", UR5E / "cotwin.toml", "--no-drivers",
                  "-o", out)
    assert proc.returncode == 0, proc.stderr
    return out, proc.stdout


# ---- generation ----

def test_every_reachable_transition_of_the_ur5e_is_covered_by_four_excursions(graph):
    suite = generate(graph, "transitions")
    assert len(suite.total) == len(suite.reached) == len(suite.covered) == 25 and not suite.unreachable
    assert [c.cycles for c in suite.cases] == [8, 3, 3, 2]
    last = suite.cases[-1]
    assert last.covers == ["transition PickPlace.infeasible"]
    assert [s.states for s in last.steps] == [["Requested"], ["Idle"]]  # each case ends back at rest
    assert str(last.steps[0].outputs[0]) == "movediscrete(0, 0, 0)"
    # the same items by one long walk when cases are cut by length only
    assert [c.cycles for c in generate(graph, "transitions", split="length").cases] == [16]


def test_states_and_transition_pairs_are_covered_too(graph):
    states = generate(graph, "states")
    assert len(states.covered) == len(states.reached) == 10
    pairs = generate(graph, "transition-pairs")
    assert len(pairs.covered) == len(pairs.reached) == 54 and len(pairs.cases) > 4
    # the minimisation never keeps a case that adds nothing
    seen = set()
    for case in pairs.cases:
        assert set(case.covers) - seen
        seen |= set(case.items)


OWN = """
interface Io { event go event stop }
interface Ops { beep() }
stm Lamp {
  cycleDef cycle == 1
  input context { uses Io }
  output context { requires Ops }
  initial i
  state Off { }
  state On { entry $beep() }
  state Never { }
  state Broken { }
  transition t0 { from i to Off }
  transition wait { from Off to Off exec condition not $go }
  transition on { from Off to On condition $go }
  transition back { from On to Off exec }
  transition odd { from Off to Broken condition $go /\\ not $go }
  transition fix { from Broken to Off exec }
  transition lost { from Never to Off exec }
}
controller C { cycleDef cycle == 1 uses Io requires Ops sref s = Lamp
  connection C on go to s on go (_async) connection C on stop to s on stop (_async) }
module M { cycleDef cycle == 1 robotic platform P { provides Ops uses Io } cref c = C
  connection P on go to c on go (_async) connection P on stop to c on stop (_async) }
"""


def test_unreachable_items_are_listed_with_their_reason(tmp_path):
    (tmp_path / "lamp.rst").write_text(OWN)
    graph = explore(build_program(load_checked([tmp_path / "lamp.rst"])))
    suite = generate(graph, "transitions")
    reasons = dict(suite.unreachable)
    assert reasons["transition Lamp.odd"].startswith("its condition never holds while Off is active")
    assert reasons["transition Lamp.fix"] == "its source state Broken is never active"
    assert reasons["transition Lamp.lost"] == "its source state Never is never active"
    assert len(suite.covered) == len(suite.reached) == 4
    states = dict(generate(graph, "states").unreachable)
    assert "no input sequence takes a transition into it (odd)" in states["state Lamp.Broken"]
    assert states["state Lamp.Never"] == "no transition leads into it"


def test_the_suite_is_byte_identical_from_any_directory_and_its_plans_are_project_plans(tmp_path, arm):
    a, b = tmp_path / "a", tmp_path / "b"
    assert cotwin("testgen", *MODELS, "--no-drivers", "-o", a).returncode == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    proc = cotwin("testgen", *[m.resolve() for m in MODELS], "--no-drivers", "-o", b.resolve(), cwd=elsewhere)
    assert proc.returncode == 0, proc.stderr
    assert suite_files(a) == suite_files(b)
    assert "transitions: 25 of 25 reachable covered (100%)" in proc.stdout
    commands = read_plan(a / "case_01.csv", arm)  # the project's plan reader takes the case as it is
    assert [c.time for c in commands] == [0.1, 0.3, 0.5, 0.7]
    assert dict(commands[0].values)["moveDiscreteCommand"] is True
    data = json.loads((a / "suite.json").read_text())
    assert data["commands"] == ["moveDiscreteCommand", "openGripperCommand", "closeGripperCommand"]
    assert data["minimisation"] == {"walks": 4, "cases": 4, "cycles": 16}


def test_testgen_refuses_bad_options_by_name(tmp_path):
    proc = cotwin("testgen", *MODELS, "--command", "fly", "-o", tmp_path / "t")
    assert proc.returncode != 0 and "fly: not an input event of module FlexCellArm" in proc.stderr
    proc = cotwin("testgen", *MODELS, "--answers", "auto", "-o", tmp_path / "t")
    assert proc.returncode != 0 and "--answers auto tries the cases on a project's simulated platform" in proc.stderr
    proc = cotwin("testgen", *MODELS, "--domain", "target=1..2", "-o", tmp_path / "t")
    assert proc.returncode != 0 and "not a value port" in proc.stderr


# ---- running a suite ----

def test_answers_are_chosen_per_case_by_the_simulated_platform(auto_suite):
    out, text = auto_suite
    data = json.loads((out / "suite.json").read_text())
    answers = {c["name"]: c["answers"] for c in data["cases"]}
    # the gripper cases are left to the platform; the move case needs a robot still moving after stop(), the
    # last a rejected target: the simulated platform gives neither, so both carry their answers
    assert answers == {"case_01": "stub", "case_02": "platform", "case_03": "platform", "case_04": "stub"}
    why = {c["name"]: c["why"] for c in data["cases"]}
    assert "expected AwaitStop" in why["case_01"] and "expected Idle" in why["case_04"]
    platform_plan = (out / "case_02.csv").read_text().splitlines()
    assert platform_plan[0] == "timestep,openGripperCommand"  # commands only


def test_cotwin_test_passes_every_case_on_the_cosimulation_and_writes_junit(auto_suite, tmp_path):
    out, _ = auto_suite
    report = tmp_path / "report.xml"
    proc = cotwin("test", UR5E / "cotwin.toml", out, "--junit", report)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "4 of 4 case(s) passed" in proc.stdout and "transitions covered: 25 of 25 reachable (100%)" in proc.stdout
    assert "operations carried out place x1" in proc.stdout
    root = ET.parse(report).getroot()
    suite = root.find("testsuite")
    assert (suite.get("tests"), suite.get("failures")) == ("4", "0")
    assert [c.get("name") for c in suite.findall("testcase")] == ["case_01", "case_02", "case_03", "case_04"]


@pytest.fixture(scope="module")
def stub_suite(tmp_path_factory, graph):
    out = tmp_path_factory.mktemp("stub") / "tests"
    write_suite(generate(graph, "transitions"), out)
    return out


def test_a_suite_index_with_a_period_that_is_no_duration_or_cases_that_are_no_list_is_refused_at_it(stub_suite, tmp_path):
    """suite.json's period (NaN, 0, a string) and cases (not a list) are refused naming suite.json; the period
    reached the master as "step size must be positive, got nan", and cases as a TypeError."""
    copy = tmp_path / "tests"
    shutil.copytree(stub_suite, copy)
    data = json.loads((copy / "suite.json").read_text())
    for key, value, said in [("period", float("nan"), "period nan is not a number of seconds"),
                             ("period", 0, "period 0 is not a number of seconds"),
                             ("period", "0.1", "period '0.1' is not a number of seconds"),
                             ("cases", 3, "cases is not a list of case entries")]:
        (copy / "suite.json").write_text(json.dumps({**data, key: value}))
        with pytest.raises(CotwinError) as err:
            read_suite(copy)
        assert str(err.value).startswith(f"{copy / 'suite.json'}:1:1: error: {said}"), str(err.value)


@pytest.mark.parametrize("algorithm,fmi", [("gauss-seidel", 2), ("jacobi", 3)])
def test_stub_cases_pass_under_gauss_seidel_and_fmi3_clocks(stub_suite, tmp_path, algorithm, fmi):
    """The master's delay shifts a stub case's plan (one cycle under Jacobi, none here): its oracle holds."""
    result = run_suite(load(UR5E / "cotwin.toml"), read_suite(stub_suite), tmp_path, algorithm=algorithm, fmi=fmi)
    assert [c.passed for c in result.cases] == [True] * 4, [str(c.divergence) for c in result.cases]
    assert len(result.covered) == 25


def test_a_pair_in_the_first_cycle_says_why_jacobi_cannot_reach_it(graph, tmp_path):
    """A transition-pairs case whose pair needs an input in the d-model's first cycle (init -> open) cannot be
    covered under FMI 2.0 Jacobi, where a source's values reach the d-model a step late: its failure says so and
    what to run instead (it said only 'not reached: pair PickPlace.init -> open'); under Gauss-Seidel it passes."""
    out = tmp_path / "pairs"
    write_suite(generate(graph, "transition-pairs"), out)
    suite = read_suite(out)
    first = [c for c in suite.cases if c.cycles and c.cycles[0].get("inputs")]
    assert first, "the pairs suite has a case with an input in its first cycle"
    names = {c.name for c in first}
    jacobi = run_suite(load(UR5E / "cotwin.toml"), suite, tmp_path / "j", algorithm="jacobi", only=sorted(names))
    for case in jacobi.cases:
        assert not case.passed and "pair PickPlace.init -> " in str(case.divergence)
        assert "no source can under Jacobi" in str(case.divergence) and "--algorithm gauss-seidel" in str(case.divergence)
    seidel = run_suite(load(UR5E / "cotwin.toml"), suite, tmp_path / "g", algorithm="gauss-seidel", only=sorted(names))
    assert all(c.passed for c in seidel.cases), [str(c.divergence) for c in seidel.cases]


def test_a_platform_case_says_where_another_master_left_its_path(auto_suite, tmp_path):
    """With FMI 3.0 clocks the d-model's pick() reaches the gripper in the step it is called (under the project's
    Jacobi with FMI 2.0 a step later): the gripper reports closed a cycle earlier and the platform no longer
    leads the d-model through AwaitClosed. Stub cases do not depend on the platform's timing."""
    result = run_suite(load(UR5E / "cotwin.toml"), read_suite(auto_suite[0]), tmp_path, fmi=3)
    verdicts = {c.name: c for c in result.cases}
    assert all(verdicts[n].passed for n in ("case_01", "case_02", "case_04"))
    assert not verdicts["case_03"].passed
    assert str(verdicts["case_03"].divergence) == ("cycle 3: states (the case's path): expected AwaitClosed (the case's "
                                                   "cycle 2, after no input), got Idle after robotStopped, gripperClosed")
    assert verdicts["case_03"].missing == ["transition PickPlace.awaitClosed", "transition PickPlace.notClosed"]


def test_a_wrong_oracle_fails_at_its_first_divergence(auto_suite, tmp_path):
    out = tmp_path / "tests"
    out.mkdir()
    for f in auto_suite[0].iterdir():
        (out / f.name).write_bytes(f.read_bytes())
    oracle = json.loads((out / "case_01.oracle.json").read_text())
    oracle["cycles"][4]["states"] = ["Stopping"]  # cycle 5: the d-model is still Moving
    (out / "case_01.oracle.json").write_text(json.dumps(oracle))
    report = tmp_path / "report.xml"
    proc = cotwin("test", UR5E / "cotwin.toml", out, "--junit", report)
    assert proc.returncode == 1
    assert "FAIL case_01" in proc.stdout and "first divergence: cycle 5: states: expected Stopping, got Moving" in proc.stdout
    assert "3 of 4 case(s) passed" in proc.stdout
    failure = ET.parse(report).getroot().find("testsuite/testcase/failure")
    assert failure is not None and "expected Stopping, got Moving" in failure.get("message")


def test_a_changed_dmodel_fails_the_suite_it_no_longer_meets(auto_suite, tmp_path):
    """A regression: the project's d-model no longer stops the arm on arrival (its entry action dropped)."""
    models = tmp_path / "models"
    models.mkdir()
    for name in ("mapping.pm", "ur5e.pm", "plan.csv", "ur.profile.toml"):
        (models / name).write_bytes((UR5E / name).read_bytes())
    (models / "arm.rst").write_text((UR5E / "arm.rst").read_text().replace("state Stopping { entry $stop() }",
                                                                           "state Stopping { }"))
    (models / "cotwin.toml").write_text((UR5E / "cotwin.toml").read_text())
    proc = cotwin("test", models / "cotwin.toml", auto_suite[0])
    assert proc.returncode == 1
    assert "warning:" in proc.stdout and "another version of module FlexCellArm" in proc.stdout
    assert "first divergence: cycle 7: outputs (conformance" not in proc.stdout  # the FMU does what its model says
    assert "first divergence: cycle 6: outputs: expected stop(), got no call" in proc.stdout


def test_cotwin_test_refuses_what_it_cannot_run_by_name(tmp_path, auto_suite):
    proc = cotwin("test", UR5E / "cotwin.toml", tmp_path / "nothing")
    assert proc.returncode == 1 and "cannot read test suite index" in proc.stderr
    proc = cotwin("test", UR5E / "cotwin.toml", auto_suite[0], "--pt", "http://x")
    assert proc.returncode != 0 and "give an OPC UA URL" in proc.stderr
    proc = cotwin("test", UR5E / "cotwin.toml", auto_suite[0], "--pt")
    assert proc.returncode != 0 and "has no [pt] table" in proc.stderr
    proc = cotwin("test", UR5E / "cotwin.toml", auto_suite[0], "--case", "case_09")
    assert proc.returncode == 1 and "no case(s) case_09" in proc.stderr


# ---- mutation ----

def test_mutants_of_the_ur5e_dmodel_are_killed_and_survivors_explained(auto_suite, tmp_path):
    report = tmp_path / "mutants.json"
    proc = cotwin("mutants", auto_suite[0], UR5E / "arm.rst", "-o", report)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(report.read_text())
    assert data["valid"] >= 30
    operators = {o["operator"] for o in data["outcomes"]}
    assert {"guard-negated", "action-dropped", "target-swapped", "exec-dropped", "constant-changed"} <= operators
    assert data["kill_rate_non_equivalent"] >= 0.8
    survivors = [o for o in data["outcomes"] if o["status"] == "survived"]
    assert survivors and all(o["explanation"] for o in survivors)
    equivalent = {o["change"] for o in survivors if o["equivalent"]}
    # `close` needs `not $moveDiscreteCommand` only when `move` (tried first) would not take the cycle anyway
    assert "transition close: operand not $moveDiscreteCommand dropped" in equivalent
    apart = {o["change"]: o["explanation"] for o in survivors if o["equivalent"] is False}
    assert apart and all("told apart after" in why for why in apart.values())
    # `close` testing $openGripperCommand instead: with open and close in one cycle neither open (not close) nor
    # close (not open) is enabled in the mutant: a timelock the suite never provokes (it sends one command a cycle)
    why = apart["transition close: $moveDiscreteCommand becomes $openGripperCommand"]
    assert why.startswith("told apart after 1 cycle(s) (the mutant fails: timelock") and \
        "[1] {openGripperCommand, closeGripperCommand}" in why
    killed = [o for o in data["outcomes"] if o["status"] == "killed"]
    assert any(o["change"].startswith("entry action $stop()") and "case_01 cycle 6" in o["by"] for o in killed)
    assert f"kill rate {round(100 * data['kill_rate'])}%" in proc.stdout


# ---- against the PT: the perturbed OPC UA plant ----

@pytest.fixture()
def plant(tmp_path):
    """`cotwin plant` with examples/ur5e/twin.toml's perturbation (0.5 kg payload, 40 ms actuator latency) on a
    free loopback port, in its own process, stopped by its PID whatever happens."""
    pytest.importorskip("asyncua")
    import os
    import signal
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"opc.tcp://127.0.0.1:{port}"
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    process = subprocess.Popen([str(Path(sys.executable).parent / "cotwin"), "plant", str(UR5E / "twin.toml"),
                                "--opcua", url], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = process.stdout.readline()
        assert line.startswith(f"serving ur5e on {url} (lockstep; perturbation:"), line + process.stderr.read()
        yield url, env
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(10)
        process.stdout.close()
        process.stderr.close()


def test_cotwin_test_passes_every_case_on_the_perturbed_plant_over_opcua(auto_suite, plant, tmp_path):
    url, env = plant
    report = tmp_path / "pt.xml"
    proc = subprocess.run([str(Path(sys.executable).parent / "cotwin"), "test", str(UR5E / "cotwin.toml"),
                           str(auto_suite[0]), "--pt", url, "--junit", str(report)], capture_output=True, text=True,
                          env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"4 of 4 case(s) passed on the PT (OPC UA plant at {url})" in proc.stdout
    assert "transitions covered: 25 of 25 reachable (100%)" in proc.stdout
    suite = ET.parse(report).getroot().find("testsuite")
    assert suite.get("failures") == "0" and suite.get("name") == f"FlexCellArm on the PT (OPC UA plant at {url})"


# ---- the cases as test driver FMUs ----

def test_a_stub_case_is_a_test_driver_fmu_that_reports_its_verdict(tmp_path, arm):
    """The driver FMU beside the d-model FMU in a multimodel, run by cotwin's master and by libcosim: verdict 1;
    beside a faulty d-model (no stop() on arrival): verdict -1 at the cycle of the difference."""
    from fmpy.validation import validate_fmu

    from cotwin.cosim.libcosim import run_libcosim
    from cotwin.cosim.multimodel import read_multimodel
    from cotwin.dmodel.fmu import build_fmu

    tests = tmp_path / "tests"
    proc = cotwin("testgen", UR5E / "arm.rst", "-o", tests)
    assert proc.returncode == 0, proc.stderr
    assert "test driver FMUs of the 4 stub case(s)" in proc.stdout
    assert validate_fmu(str(tests / "case_01.fmu")) == []
    faulty = tmp_path / "faulty.rst"
    faulty.write_text((UR5E / "arm.rst").read_text().replace("state Stopping { entry $stop() }", "state Stopping { }"))
    build_fmu(arm, tmp_path / "dmodel.fmu")
    build_fmu(build_program(load_checked([faulty])), tmp_path / "faulty.fmu")
    inputs = [ev.name for ev in arm.inputs] + [p for ev in arm.inputs for p, _ in ev.value_ports]
    outputs = [op.name for op in arm.operations] + [p for op in arm.operations for g in op.arg_ports for p, _ in g]
    outputs = list(dict.fromkeys(outputs)) + ["state"]
    for dmodel, verdict in (("dmodel.fmu", ("1", "0")), ("faulty.fmu", ("-1", "6"))):
        connections = {f"{{driver}}.case.{p}": [f"{{dmodel}}.dmodel.{p}"] for p in inputs}
        connections.update({f"{{dmodel}}.dmodel.{p}": [f"{{driver}}.case.{p}"] for p in outputs})
        mm = {"fmus": {"{driver}": str(tests / "case_01.fmu"), "{dmodel}": str(tmp_path / dmodel)},
              "connections": connections, "logVariables": {"{driver}.case": ["verdict", "divergence_cycle"]},
              "algorithm": {"type": "fixed-step", "size": 0.1}, "endTime": 1.0, "cotwin": {"delayed": ["{driver}.case"]}}
        path = tmp_path / f"{dmodel}.json"
        path.write_text(json.dumps(mm))
        out = tmp_path / f"{dmodel}.csv"
        proc = cotwin("simulate", path, "-o", out)
        assert proc.returncode == 0, proc.stderr
        last = list(__import__("csv").DictReader(open(out)))[-1]
        assert (last["{driver}.case.verdict"], last["{driver}.case.divergence_cycle"]) == verdict, dmodel
    theirs = run_libcosim(read_multimodel(tmp_path / "dmodel.fmu.json"), {"{driver}.case": ["verdict"]}, end=1.0)
    assert theirs["{driver}.case.verdict"][-1] == 1


def test_a_failed_testgen_leaves_the_earlier_suite_whole(tmp_path):
    """A C compiler that fails, or a --project that cannot be loaded, is reported (exit 1) and leaves the suite
    already in the folder as it was: its driver FMUs are not removed (they were, and the new index left)."""
    tests = tmp_path / "tests"
    proc = cotwin("testgen", UR5E / "arm.rst", "-o", tests)
    assert proc.returncode == 0, proc.stderr
    before = suite_files(tests)
    assert "case_01.fmu" in before
    proc = cotwin("testgen", UR5E / "arm.rst", "--max-cycles", "5", "--cc", "false", "-o", tests)
    assert proc.returncode == 1 and "the C compiler 'false' failed" in proc.stderr
    proc = cotwin("testgen", *MODELS, "--answers", "auto", "--project", tmp_path / "none.toml", "-o", tests)
    assert proc.returncode == 1 and "none.toml" in proc.stderr
    assert suite_files(tests) == before
    proc = cotwin("testgen", *MODELS, "--answers", "auto", "--project", tmp_path / "none.toml", "-o", tmp_path / "new")
    assert proc.returncode == 1 and not (tmp_path / "new").exists()


def test_a_failure_during_the_final_write_of_a_suite_leaves_the_earlier_suite_whole(graph, tmp_path, monkeypatch):
    """The suite's last file failing half-way through its write (a full disk, an interrupt) leaves every file of
    the suite already in the folder as it was, and no part-written file beside them: nothing of the new suite
    is in the folder before all of it is written (it was written file by file over the earlier one)."""
    import errno
    import io

    out = tmp_path / "tests"
    write_suite(generate(graph, "transitions"), out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    suite = generate(graph, "transition-pairs", split="length")  # other cases, in other files
    opened, last = [], 1 + 2 * len(suite.cases)  # the index, and a plan and an oracle per case
    real_open = io.open

    class Full:
        """A file that takes half of what is written to it, then fails as a full disk does."""

        def __init__(self, f):
            self.f = f

        def write(self, text):
            self.f.write(text[:len(text) // 2])
            self.f.flush()
            raise OSError(errno.ENOSPC, "No space left on device")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def __getattr__(self, name):
            return getattr(self.f, name)

    def failing_open(file, mode="r", *args, **kwargs):
        f = real_open(file, mode, *args, **kwargs)
        if "w" in mode:
            opened.append(file)
            if len(opened) == last:
                return Full(f)
        return f

    monkeypatch.setattr(io, "open", failing_open)
    with pytest.raises(OSError, match="No space left"):
        write_suite(suite, out)
    monkeypatch.undo()
    assert len(opened) == last  # the failure was injected into the suite's last write
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert read_suite(out).data["criterion"] == "transitions"


def test_an_interrupt_while_a_suite_moves_into_place_comes_after_its_last_file(graph, tmp_path, monkeypatch):
    """^C between two of the renames that put a suite in place left the folder with some case files of the new
    suite beside the earlier suite's index and other files: the interrupt now comes once all are moved."""
    import os
    import signal

    from cotwin.dmodel import testgen_files

    out = tmp_path / "tests"
    write_suite(generate(graph, "transitions"), out)
    suite = generate(graph, "transition-pairs", split="length")
    moved, real_replace = [], os.replace

    def replace(src, dst):  # os is one module: files.output's renames into the stage come here too
        real_replace(src, dst)
        if Path(dst).parent != out:
            return
        moved.append(dst)
        if len(moved) == 2:
            os.kill(os.getpid(), signal.SIGINT)  # Python's handler raises KeyboardInterrupt at once, unless held

    monkeypatch.setattr(testgen_files.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        write_suite(suite, out)
    monkeypatch.undo()
    assert len(moved) == 1 + 2 * len(suite.cases)  # every file, the index last
    read = read_suite(out)
    assert read.criterion == "transition-pairs" and [c.name for c in read.cases] == [c.name for c in suite.cases]


def test_a_suite_removes_its_predecessors_files_and_no_other(graph, tmp_path):
    """A suite written into a folder removed every case_* .csv/.json/.fmu it did not write, a user's case_study.csv
    and case_99.csv too, where no suite had ever been (found by the hostile probe). Only files the earlier suite's
    index names go: a suite of fewer cases, or without drivers, leaves none of the earlier one behind."""
    out = tmp_path / "tests"
    out.mkdir()
    mine = {"case_study.csv": b"precious", "case_99.csv": b"mine", "case_notes.json": b"{}", "case_1.fmu": b"PK"}
    for name, data in mine.items():
        (out / name).write_bytes(data)
    many = generate(graph, "transitions")
    write_suite(many, out)
    assert all((out / name).read_bytes() == data for name, data in mine.items())
    (out / "case_01.fmu").write_bytes(b"a driver")  # as testgen puts a stub case's driver beside it
    suite = json.loads((out / "suite.json").read_text())
    suite["cases"][0]["driver"] = "case_01.fmu"
    (out / "suite.json").write_text(json.dumps(suite))
    few = generate(graph, "transitions", max_cycles=100, split="length")
    assert len(few.cases) < len(many.cases)
    write_suite(few, out)
    left = {p.name for p in out.iterdir()}
    assert left == set(mine) | {"suite.json"} | {f"{c.name}{ext}" for c in few.cases for ext in (".csv", ".oracle.json")}


def test_a_testgen_into_a_folder_another_run_is_writing_is_refused(tmp_path):
    """Two testgens into one folder at once both said their suite was written there, and the folder held one of
    them (found by the hostile probe): testgen holds the folder as cotwin run does, and one into a folder held
    is refused naming it, writing nothing there."""
    from cotwin.twin.assembly.build import folder_lock

    out = tmp_path / "tests"
    with folder_lock(out):
        proc = cotwin_in_process("testgen", UR5E / "arm.rst", "--no-drivers", "-o", out)
    assert proc.returncode == 1 and f"{out} is in use by another cotwin run" in proc.stderr
    assert suite_files(out) == {}


@pytest.fixture
def interrupt_restored():
    """SIGINT's handler put back after a test whose in-process command ended interrupted (cotwin.cli.entry then
    ignores a second one)."""
    import signal

    handler = signal.getsignal(signal.SIGINT)
    yield
    signal.signal(signal.SIGINT, handler)


def test_an_interrupt_as_a_suite_moves_into_place_keeps_its_drivers_with_it(tmp_path, monkeypatch, interrupt_restored):
    """^C as testgen's suite moved into place came once its plans, oracles and index were there, before its driver
    FMUs: the folder held the new index beside the earlier suite's drivers (found by the hostile probe). The
    drivers now move in with the rest, and the interrupt is said once the suite is whole."""
    import os
    import signal

    out, reference = tmp_path / "tests", tmp_path / "reference"
    assert cotwin_in_process("testgen", UR5E / "arm.rst", "--coverage", "states", "--max-cycles", "3",
                             "-o", out).returncode == 0
    assert cotwin_in_process("testgen", UR5E / "arm.rst", "-o", reference).returncode == 0
    expected = suite_files(reference)
    assert expected["case_01.fmu"] != suite_files(out)["case_01.fmu"]  # the earlier suite's drivers are others
    real_replace = os.replace

    def replace(src, dst):  # os is one module: every rename comes here
        real_replace(src, dst)
        if Path(dst) == out / "suite.json":
            os.kill(os.getpid(), signal.SIGINT)  # raised at once, unless held

    monkeypatch.setattr(os, "replace", replace)
    proc = cotwin_in_process("testgen", UR5E / "arm.rst", "-o", out)
    monkeypatch.undo()
    assert proc.returncode == 130, proc.stderr
    assert f"{out}: interrupted after the suite was written (it is whole there)" in proc.stderr
    assert suite_files(out) == expected


def test_an_interrupted_testgen_says_that_nothing_was_written(tmp_path, monkeypatch, interrupt_restored):
    """^C during a long exploration said 'interrupted' and no more (found by the hostile probe): it says that none
    of the suite was written and the earlier one is as it was."""
    from cotwin.dmodel import testgen_graph

    out = tmp_path / "tests"
    assert cotwin_in_process("testgen", UR5E / "arm.rst", "--no-drivers", "-o", out).returncode == 0
    before = suite_files(out)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(testgen_graph, "explore", interrupted)
    proc = cotwin_in_process("testgen", UR5E / "arm.rst", "--coverage", "states", "-o", out)
    assert proc.returncode == 130
    assert (f"{out}: interrupted before the suite was written: none of it is there; the earlier suite there is as it "
            "was") in proc.stderr
    assert suite_files(out) == before


def test_testgen_in_a_log_says_how_far_its_exploration_is(tmp_path):
    """testgen's exploration showed its progress on a terminal only: in a log, 12 minutes of exploring printed
    nothing (found by the hostile probe); it writes a progress line there as verify does."""
    proc = cotwin_in_process("testgen", UR5E / "arm.rst", "--no-drivers", "-o", tmp_path / "tests",
                             env={"COTWIN_PROGRESS_SECONDS": "0"})
    assert proc.returncode == 0, proc.stderr
    assert "exploring the d-model's states: " in proc.stderr and "states (" in proc.stderr


def test_test_and_mutants_never_write_over_what_they_read(tmp_path, stub_suite):
    """cotwin test --junit and cotwin mutants -o naming the project file, a model or a file of the suite are
    refused by name before anything runs (the JUnit XML replaced cotwin.toml; the JSON replaced arm.rst)."""
    import shutil

    project = tmp_path / "ur5e"
    shutil.copytree(UR5E, project)
    kept = {p.name: p.read_bytes() for p in project.iterdir()}
    proc = cotwin("test", project / "cotwin.toml", stub_suite, "--junit", project / "cotwin.toml")
    assert proc.returncode == 1 and "the output would replace" in proc.stderr and "(--junit)" in proc.stderr
    proc = cotwin("test", project / "cotwin.toml", stub_suite, "--junit", stub_suite / "case_01.csv")
    assert proc.returncode == 1 and "the output would replace" in proc.stderr
    proc = cotwin("test", project / "cotwin.toml", stub_suite, "--junit", tmp_path)
    assert proc.returncode == 2 and "Invalid value for --junit" in proc.stderr and "[1/" not in proc.stderr
    proc = cotwin("mutants", stub_suite, project / "arm.rst", "-o", project / "arm.rst")
    assert proc.returncode == 1 and "the output would replace" in proc.stderr
    proc = cotwin("mutants", stub_suite, project / "arm.rst", "-o", stub_suite / "suite.json")
    assert proc.returncode == 1 and "the output would replace" in proc.stderr
    assert {p.name: p.read_bytes() for p in project.iterdir()} == kept
    assert (stub_suite / "suite.json").read_text().startswith("{")


def test_nan_and_too_short_periods_are_refused_by_option(tmp_path, stub_suite):
    """testgen --period nan or --settle nan crashed (internal error: NaN is not JSON); --period 1e-320 wrote plans
    whose every row was at time 0; mutants --min-kill nan made the gate never fail; build-dmodel --cycle-period
    nan said so without naming the option."""
    for args, option in ((["testgen", UR5E / "arm.rst", "--period", "nan"], "--period"),
                         (["testgen", UR5E / "arm.rst", "--settle", "nan"], "--settle"),
                         (["testgen", UR5E / "arm.rst", "--period", "1e-320"], "'--period'"),
                         (["mutants", stub_suite, UR5E / "arm.rst", "--min-kill", "nan"], "--min-kill"),
                         (["build-dmodel", UR5E / "arm.rst", "--fmi", "3", "--cycle-period", "nan"], "--cycle-period"),
                         (["build-dmodel", UR5E / "arm.rst", "--fmi", "3", "--cycle-period", "1e-320"], "'--cycle-period'")):
        out = tmp_path / ("d.fmu" if args[0] == "build-dmodel" else "t")
        proc = cotwin(*args, *(["-o", out] if args[0] != "mutants" else []))
        assert proc.returncode == 2 and f"Invalid value for {option}" in proc.stderr, (args, proc.stderr)
        assert "internal error" not in proc.stderr and not out.exists()


def test_mutants_of_a_suite_without_cases_is_refused(tmp_path, stub_suite):
    """A suite whose index lists no case gave "0 killed ... kill rate 0%" and exit 0."""
    import shutil

    empty = tmp_path / "empty"
    shutil.copytree(stub_suite, empty)
    data = json.loads((empty / "suite.json").read_text())
    (empty / "suite.json").write_text(json.dumps(data | {"cases": []}))
    proc = cotwin("mutants", empty, UR5E / "arm.rst")
    assert proc.returncode == 2 and "suite.json holds no case: nothing to run on the mutants" in proc.stderr


def test_a_suite_file_that_is_a_fifo_or_huge_is_refused_not_waited_on_or_read_whole(tmp_path, stub_suite):
    """cotwin test waited forever on an oracle that was a FIFO, and read an oracle of any size whole."""
    import os
    import shutil

    for name, make in (("fifo", lambda p: os.mkfifo(p)), ("huge", lambda p: p.write_bytes(b" " * (65 << 20) + b"{}"))):
        suite = tmp_path / name
        shutil.copytree(stub_suite, suite)
        (suite / "case_01.oracle.json").unlink()
        make(suite / "case_01.oracle.json")
        proc = subprocess.run([str(Path(sys.executable).parent / "cotwin"), "test", str(UR5E / "cotwin.toml"),
                               str(suite)], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 1 and f"{suite}/case_01.oracle.json:1:1: error:" in proc.stderr, proc.stderr
        assert ("not a regular file" if name == "fifo" else "over the 64 MiB cotwin reads") in proc.stderr


def test_a_domain_bound_beyond_an_integer_domain_says_so_not_that_it_is_no_number(tmp_path):
    proc = cotwin("testgen", *MODELS, "--domain", "MovementArgs_target_X=0..1e308", "-o", tmp_path / "t")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "must be numbers" not in proc.stderr
    assert "the range is too large: bound 1e308 is beyond what an integer domain" in proc.stderr
    proc = cotwin("testgen", *MODELS, "--domain", "MovementArgs_target_X=0..2.5", "-o", tmp_path / "t")
    assert proc.returncode == 2 and "bound 2.5 is not written as an integer" in proc.stderr
    proc = cotwin("testgen", *MODELS, "--domain", "MovementArgs_target_X=0..nan", "-o", tmp_path / "t")
    assert proc.returncode == 2 and "values must be numbers" in proc.stderr


def test_an_oracle_without_cycles_is_refused_at_the_oracle_not_at_the_index(stub_suite, tmp_path):
    copy = tmp_path / "tests"
    shutil.copytree(stub_suite, copy)
    oracle = copy / json.loads((copy / "suite.json").read_text())["cases"][0]["oracle"]
    record = json.loads(oracle.read_text())
    for broken in ({k: v for k, v in record.items() if k != "cycles"}, {**record, "cycles": 3}, [1, 2]):
        oracle.write_text(json.dumps(broken))
        with pytest.raises(CotwinError) as err:
            read_suite(copy)
        assert str(err.value).startswith(f"{oracle}:1:1: error: not a case oracle: it has no list of cycles"), \
            str(err.value)
        assert "suite.json" not in str(err.value)


def test_case_files_outside_the_suite_folder_are_refused_at_the_index_by_entry(stub_suite, tmp_path):
    """A case entry's plan or oracle that is an absolute path or climbs out with .. was followed as written."""
    copy = tmp_path / "tests"
    shutil.copytree(stub_suite, copy)
    data = json.loads((copy / "suite.json").read_text())
    outside = tmp_path / "outside.oracle.json"
    shutil.copy(copy / data["cases"][0]["oracle"], outside)
    first, second = data["cases"][0]["name"], data["cases"][1]["name"]
    data["cases"][0]["oracle"] = str(outside)
    data["cases"][1]["plan"] = "../tests/" + data["cases"][1]["plan"]
    data["cases"][2]["plan"] = "sub/../" + data["cases"][2]["plan"]  # within the folder: fine
    (copy / "suite.json").write_text(json.dumps(data))
    with pytest.raises(CotwinError) as err:
        read_suite(copy)
    index = copy / "suite.json"
    assert str(err.value).splitlines() == [
        f"{index}:1:1: error: case entry {first!r}: its oracle {str(outside)!r} lies outside the suite's folder "
        "(a suite's files live in its folder)",
        f"{index}:1:1: error: case entry {second!r}: its plan '../tests/{second}.csv' lies outside the suite's folder "
        "(a suite's files live in its folder)"], str(err.value)


def test_a_long_distinguishing_sequence_reads_as_runs_of_equal_cycles():
    """A mutant of a sorter's leg timeout (since(T) > 150) is told apart after 152 cycles; its explanation
    listed `[1] {} [2] {} ... [151] {}` one by one, a line of a thousand characters. Runs are folded."""
    from cotwin.dmodel.verify import format_trace

    trace = [{}] * 151 + [{"sortCommand": 0}]
    assert format_trace(trace) == "[1..151] {} [152] {sortCommand(0)}"
    assert format_trace([{"a": None}, {}, {}, {"a": None}]) == "[1] {a} [2..3] {} [4] {a}"
    assert format_trace([]) == ""


def test_a_stub_cases_cycle_of_several_inputs_reaches_the_d_model_in_one_step():
    """A sorter's transition-pairs case stubs `poseReached` and `stalled` in one cycle (the stall must win over the
    arrival); `cotwin test` played them one per step, as a plan's commands, so every such case failed ('expected
    poseReached, stalled, got poseReached'). A stub case's source shows a cycle's inputs together."""
    from conftest import EXAMPLES

    from cotwin.dmodel.program import build_program
    from cotwin.robosim.check import load_checked
    from cotwin.twin.assembly.scenario import Command, ScenarioUnit

    program = build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"]))
    cycle = Command(0.0, (("moveCompleted", True), ("collision", True)), "case_01 cycle 1")

    def shown(together: bool) -> list[set[str]]:
        unit = ScenarioUnit("{controller}.controller", program, [cycle], together=together)
        unit.instantiate(0.0)
        steps = []
        for k in range(2):
            unit.step(k * 0.1, 0.1)
            steps.append({e for e in unit.events if unit.values[e] is True})
        return steps

    assert shown(True) == [{"moveCompleted", "collision"}, set()]
    assert shown(False) == [{"moveCompleted"}, {"collision"}]  # a plan's, as a broker's: one per step


@pytest.mark.parametrize("events, expected", [
    ({"noCollision": 3, "collisionFree": 1}, 0),  # said the opposite: no collision
    ({"protectiveStop": 2, "robotCollision": 1, "moveDone": 4}, 3),  # stops named as the project's rule names them
])
def test_a_suites_collision_count_uses_the_projects_rule_for_a_stopping_event(events, expected):
    """`cotwin test` counted as a collision every platform event whose name held 'collision' (noCollision,
    collisionFree) and missed protectiveStop: its own rule, not the project's (outcomes.EventRoles.stops)."""
    from types import SimpleNamespace

    from cotwin.twin.analysis.testing import CaseRun

    run = SimpleNamespace(mapping=SimpleNamespace(executed=[]), platform_events=events,
                          system=SimpleNamespace(spec=SimpleNamespace(outcome_events={})))
    assert CaseRun.platform_report(run)["collisions"] == expected
