"""The generated multimodel: every FMU validates, cotwin's master and libcosim run it alike."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import pytest
from fmpy.validation import validate_fmu

from cotwin.cosim.libcosim import run_libcosim
from cotwin.cosim.algorithm import Jacobi
from cotwin.cosim.execution import Execution
from cotwin.cosim.multimodel import execution_for, read_multimodel
from cotwin.cosim.observers import CSVWriter, RealTimePacer
from cotwin.cosim.system import Connection, System, topological_order
from cotwin.diagnostics import CotwinError
from cotwin.twin.assembly.build import build
from cotwin.twin.assembly.run import load


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    from conftest import EXAMPLES

    out = tmp_path_factory.mktemp("twin")
    build(load(EXAMPLES / "ur5e" / "cotwin.toml"), out)
    return out


def test_every_fmu_of_the_multimodel_validates(built):
    for name in ("dmodel.fmu", "mapping.fmu", "controller.fmu"):
        assert validate_fmu(str(built / name)) == [], name


def test_simulate_runs_the_multimodel_through_fmpy(built):
    out = built / "fmpy.csv"
    proc = subprocess.run([sys.executable, "-m", "cotwin", "simulate", str(built / "multimodel.json"), "--end", "4",
                           "-o", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == 41 and rows[0]["time"] == "0.0"
    assert any(r["{dmodel}.dmodel.movediscrete"] == "true" for r in rows)
    assert abs(float(rows[-1]["{mapping}.mapping.q0"])) > 0.5  # the arm moved towards (0, 23, 1)


def test_libcosim_runs_the_same_multimodel_with_the_same_trajectory(built):
    mm = read_multimodel(built / "multimodel.json")
    joints = [f"q{i}" for i in range(6)]
    theirs = run_libcosim(mm, {"{mapping}.mapping": joints, "{dmodel}.dmodel": ["state"]}, end=4.0)
    master_csv = built / "ours.csv"
    execution_for(mm, master_csv, algorithm="jacobi").run(4.0)
    ours = {r["time"]: r for r in csv.DictReader(open(master_csv))}
    assert len(theirs["time"]) == 40
    for k, t in enumerate(theirs["time"]):
        row = ours[repr(round(t, 12))]
        assert int(row["{dmodel}.dmodel.state"]) == theirs["{dmodel}.dmodel.state"][k]
        for q in joints:
            assert float(row[f"{{mapping}}.mapping.{q}"]) == pytest.approx(theirs[f"{{mapping}}.mapping.{q}"][k], abs=1e-6)


def test_multimodel_typos_are_reported(built, tmp_path):
    data = json.loads((built / "multimodel.json").read_text())
    data["conections"] = {}
    data["connections"]["{dmodel}.dmodel.movediscret"] = ["{mapping}.mapping.movediscrete"]
    data["connections"]["{robot}.x.y"] = ["{mapping}.mapping.movediscrete"]
    data["fmus"] = {k: str(built / v) for k, v in data["fmus"].items()}
    path = tmp_path / "mm.json"
    path.write_text(json.dumps(data))
    with pytest.raises(CotwinError) as err:
        read_multimodel(path)
    assert "unknown key 'conections'" in str(err.value) and "names FMU {robot}" in str(err.value)
    del data["conections"], data["connections"]["{robot}.x.y"]
    path.write_text(json.dumps(data))
    with pytest.raises(CotwinError, match="unit {dmodel}.dmodel has no output 'movediscret'"):
        execution_for(read_multimodel(path))
    path.write_text("{ bad json")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "simulate", str(path)], capture_output=True, text=True)
    assert proc.returncode == 1 and f"{path}:1:3: error: bad JSON" in proc.stderr and "Traceback" not in proc.stderr


def test_cycles_are_reported_unless_a_unit_is_delayed():
    connections = [Connection("a", "x", "b", "x"), Connection("b", "y", "a", "y")]
    with pytest.raises(CotwinError, match="cycle a -> b -> a"):
        topological_order(["a", "b"], connections, set())
    assert topological_order(["a", "b"], connections, {"b"}) == ["a", "b"]


class _Failing:
    """A unit whose step fails at t = 0.3: the master must flush the CSV and terminate every unit."""

    def __init__(self, name):
        from cotwin.cosim.units import Port, PythonUnit

        self.unit = PythonUnit(name, [Port("out", "Real", "output")])
        self.unit.terminated = False

        def step(t, h, unit=self.unit):
            if t >= 0.3 - 1e-9:
                from cotwin.cosim.units import UnitError

                raise UnitError(unit.name, t, "fmi2DoStep", "returned fmi2Error")
            unit.values["out"] = t + h

        def terminate(unit=self.unit):
            unit.terminated = True

        self.unit.step = step
        self.unit.terminate = terminate


def test_failure_names_unit_time_and_call_keeps_the_rows_and_the_previous_result(tmp_path):
    previous = "time,{f}.f.out\n0.0,0\n"
    (tmp_path / "out.csv").write_text(previous)
    failing = _Failing("{f}.f").unit
    system = System.of([failing], [], log={"{f}.f": ["out"]})
    execution = Execution(system, Jacobi(), 0.1, observers=[CSVWriter(tmp_path / "out.csv")])
    with pytest.raises(CotwinError, match=r"unit \{f\}.f: fmi2DoStep failed at t = 0.3 s"):
        execution.run(1.0)
    rows = list(csv.reader(open(tmp_path / "out.partial.csv")))
    assert rows[0] == ["time", "{f}.f.out"] and [r[0] for r in rows[1:]] == ["0.0", "0.1", "0.2", "0.3"]
    assert (tmp_path / "out.csv").read_text() == previous  # the earlier good result is untouched
    assert failing.terminated


def test_realtime_pacing_keeps_wall_clock_behind_simulated_time():
    import time

    from cotwin.cosim.units import Port, PythonUnit

    unit = PythonUnit("{u}.u", [Port("out", "Real", "output")])
    unit.step = lambda t, h: None
    execution = Execution(System.of([unit], [], log={"{u}.u": ["out"]}), Jacobi(), 0.05, observers=[RealTimePacer()])
    started = time.perf_counter()
    result = execution.run(0.3)
    assert time.perf_counter() - started >= 0.3 - 1e-3
    assert result.rows == 7


def test_an_end_before_the_start_or_within_one_step_is_located_at_endtime(tmp_path):
    """A multimodel whose endTime is -1 was refused without a line ('-1 s is shorter than one step'): the error is
    at its endTime key."""
    import json as _json

    from cotwin.cosim.multimodel import read_multimodel
    from cotwin.diagnostics import CotwinError

    path = tmp_path / "mm.json"
    text = _json.dumps({"fmus": {}, "connections": {}, "algorithm": {"type": "fixed-step", "size": 0.1},
                        "startTime": 0.0, "endTime": -1}, indent=1)
    path.write_text(text)
    with pytest.raises(CotwinError) as err:
        read_multimodel(path)
    (finding,) = err.value.findings
    line = next(k + 1 for k, row in enumerate(text.splitlines()) if '"endTime"' in row)
    assert finding.location.line == line and "shorter than one step" in finding.message


@pytest.mark.parametrize("change, said", [
    (lambda m: m.update(fmus=["a.fmu"]), "fmus must be an object"),
    (lambda m: m.update(connections=[1, 2]), "connections must be an object"),
    (lambda m: m.update(parameters=[1]), "parameters must be an object"),
    (lambda m: m.update(logVariables=[1]), "logVariables must be an object"),
    (lambda m: m["logVariables"].update({"{a}.a": 5}), "logVariables.{a}.a must be a list of strings"),
    (lambda m: m["logVariables"].update({"{a}.a": "x"}), "logVariables.{a}.a must be a list of strings"),
    (lambda m: m.update(algorithm=[0.1]), "algorithm must be an object"),
    (lambda m: m.update(cotwin=[1]), "cotwin must be an object"),
    (lambda m: m.update(cotwin={"delayed": "{a}.a"}), "cotwin.delayed must be a list of strings"),
    (lambda m: m.update(cotwin={"delayed": [5]}), "cotwin.delayed must be a list of strings"),
    (lambda m: m.update(cotwin={"algorithm": "magic"}), "cotwin.algorithm must be one of jacobi, gauss-seidel"),
    (lambda m: m.update(parameters={"{a}.a.p": [1]}), "'{a}.a.p' must be a number, a Boolean or a string"),
    (lambda m: m["algorithm"].update(size="0.1"), "algorithm.size must be a finite number"),
])
def test_a_multimodel_section_of_the_wrong_kind_is_one_located_error(tmp_path, change, said):
    """`fmus` as a list, `algorithm` as a number, `cotwin` as a list were internal errors (AttributeError); a
    string for `cotwin.delayed` or a log list was read one character per unit or variable; a size given as a
    string was said twice."""
    (tmp_path / "a.fmu").write_bytes(b"")
    mm = {"fmus": {"{a}": "a.fmu"}, "connections": {}, "logVariables": {"{a}.a": ["x"]},
          "algorithm": {"type": "fixed-step", "size": 0.1}, "startTime": 0.0, "endTime": 1.0}
    change(mm)
    path = tmp_path / "mm.json"
    path.write_text(json.dumps(mm))
    with pytest.raises(CotwinError) as err:
        read_multimodel(path)
    (finding,) = [f for f in err.value.findings if "not a known" not in f.message]  # a bad `fmus` leaves {a} unknown
    assert said in finding.message and finding.location.line == 1 and finding.location.column > 1, finding


@pytest.mark.parametrize("text, said", [
    ('{"fmus": {}, "startTime": 0, "endTime": 1, "startTime": 3}', "the key 'startTime' appears twice"),
    ('{"fmus": {}, "endTime": 1' + "0" * 5000 + "}", "a number of 5001 digits"),
    ('{"fmus": {}, "algorithm": {"type": "fixed-step", "size": NaN}}', "NaN is not a JSON number"),
])
def test_a_multimodel_key_given_twice_or_a_number_json_lacks_is_refused(tmp_path, text, said):
    """A second startTime silently won; an endTime of 5000 digits was an internal error (Python's int limit)."""
    path = tmp_path / "mm.json"
    path.write_text(text)
    with pytest.raises(CotwinError) as err:
        read_multimodel(path)
    (finding,) = err.value.findings
    assert said in finding.message and finding.location.path == str(path), finding


def test_a_number_constant_or_key_json_refuses_is_located_where_it_is_written(tmp_path):
    """Infinity, NaN, 1e400 and a key given twice are refused by the JSON reader before any key is checked: the
    error named the file's start (1:1); it names the line and column of what was refused."""
    from cotwin.cosim.multimodel import read_multimodel

    cases = {'{\n  "fmus": {},\n  "endTime": Infinity\n}\n': (3, 14, "Infinity is not a JSON number"),
             '{"note": "NaN here",\n "endTime":   -Infinity}': (2, 15, "-Infinity is not a JSON number"),
             '{"x": 1,\n  "x": 2}': (2, 3, "the key 'x' appears twice"),
             '{"s": "1e400", "e":\n 1e400}': (2, 2, "the number 1e400 is beyond the range of a double")}
    for k, (text, (line, column, said)) in enumerate(cases.items()):
        path = tmp_path / f"m{k}.json"
        path.write_text(text)
        with pytest.raises(CotwinError) as err:
            read_multimodel(path)
        assert str(err.value).startswith(f"{path}:{line}:{column}: error: bad JSON: {said}"), str(err.value)
