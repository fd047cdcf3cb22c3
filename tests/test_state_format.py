"""Saved states that can neither run code nor corrupt memory (issue 22): no pickle anywhere, every field
checked against what it is restored into, and a d-model FMU that refuses malformed serialised bytes
in its own C. The crafted states of the issue are here: numpy.dtype's __setstate__ through the old
restricted unpickler (rc 139), a NaN time (a fork "at t = nan s"), a missing key ("a cotwin bug")."""

from __future__ import annotations

import math
import pickle
import random
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cotwin.cosim.algorithm import algorithm
from cotwin.cosim.execution import Execution
from cotwin.cosim.state import MAGIC, OLD_MAGIC, StateError, pack, unpack
from cotwin.diagnostics import CotwinError
from cotwin.robosim.values import FrozenRecord, MatrixValue, SeqValue, SetValue, TupleValue, VectorValue
from test_twin_state import fmu, twin  # noqa: F401 - the UR5e example twin and its d-model FMU, per module

FORK = 1.5  # s: the first command is being executed, a trajectory in flight


def test_plain_data_reads_back_with_its_types():
    held = {
        "goal": VectorValue((0.1, 0.2, 0.3)), "pose": MatrixValue((VectorValue((1.0, 0.0)), VectorValue((0.0, 1.0)))),
        "pair": TupleValue((1, True)), "queue": SeqValue((2, 3)), "seen": SetValue({1, 2}),
        "records": SetValue({FrozenRecord((("x", 1), ("y", 2)))}), "mode": 2, "busy": False, "none": None,
        "odd": [math.inf, -math.inf, 1e308, -0.0, 2 ** 62], "text": "état", "raw": b"\x00\xff",
        "by port": {("{a}.a", "x"): 1.5, ("{a}.a", "y"): False}, "$dollar": {"$tuple": "not a tag"},
        "sets": ({1, 2}, frozenset({"a"})), "q": np.arange(12, dtype=np.float64).reshape(3, 4),
        "flags": np.array([True, False]), "small": np.arange(3, dtype=np.int32), "scalar": np.float64(2.5),
        "count": np.int64(7), "empty": np.zeros((0, 3)),
    }
    back = unpack(pack("Mapping", held), "Mapping")
    assert back.keys() == held.keys()
    for key, value in held.items():
        assert type(back[key]) is type(value), key
        if isinstance(value, np.ndarray):
            assert back[key].dtype == value.dtype and back[key].shape == value.shape and np.array_equal(back[key], value)
        elif key != "odd":
            assert back[key] == value, key
    assert back["odd"][:2] == [math.inf, -math.inf] and math.copysign(1, back["odd"][3]) == -1
    assert type(back["pose"][0]) is VectorValue and math.isnan(unpack(pack("X", math.nan), "X"))


def test_only_plain_data_is_saved_and_no_pickle_is_ever_read(tmp_path):
    with pytest.raises(StateError, match="holds only plain data, not a builtins.builtin_function_or_method"):
        pack("Mapping", {"x": __import__("os").getcwd})
    with pytest.raises(StateError, match="arrays of numbers only"):
        pack("Mapping", np.array([object()], dtype=object))
    marker = tmp_path / "ran"
    evil = pickle.dumps(("Mapping", _Run(f"touch {marker}")))
    with pytest.raises(StateError, match="earlier cotwin .*never reads"):
        unpack(OLD_MAGIC + evil, "Mapping")
    with pytest.raises(StateError, match="damaged"):
        unpack(MAGIC + evil, "Mapping")
    assert not marker.exists()
    with pytest.raises(StateError, match="a state of a Mapping, not of a FMU"):
        unpack(pack("Mapping", {}), "FMU")


class _Run:
    def __init__(self, command: str):
        self.command = command

    def __reduce__(self):
        import os

        return (os.system, (self.command,))


@pytest.mark.parametrize("damage", [
    lambda b: b[:-1], lambda b: b + b"x", lambda b: b[:20], lambda b: b.replace(b'"blobs":[', b'"blobs":[99999,'),
    lambda b: b.replace(b'"data":', b'"data":{"$array":0,"dtype":"|O","shape":[1]},"x":'),
    lambda b: b.replace(b'"kind"', b'"kinds"'), lambda b: b.replace(b'[1,2', b'[1e999,2'),
    lambda b: MAGIC + (10 ** 9).to_bytes(8, "little") + b"{}",
])
def test_damaged_bytes_are_a_state_error(damage):
    blob = pack("Mapping", {"a": [1, 2, np.arange(3.0)], "b": b"xyz"})
    with pytest.raises(StateError):
        unpack(damage(blob), "Mapping")


def test_any_bytes_are_a_state_or_a_state_error():
    """Random damage to a state's structure and binary parts: every outcome is data or a StateError."""
    blob = bytearray(pack("Mapping", {"a": [1, 2.5, {"$x": (1, 2)}], "q": np.arange(6.0).reshape(2, 3),
                                      "v": VectorValue((1, 2)), "s": SetValue({3}), "b": b"xy"}))
    rng = random.Random(22)
    outcomes = set()
    for _ in range(3000):
        bad = bytearray(blob)
        for _ in range(rng.randint(1, 4)):
            at = rng.randrange(len(MAGIC), len(bad))
            bad[at] = rng.choice([rng.randrange(256), ord("$"), ord("["), ord("{"), ord('"'), ord("9")])
        try:
            unpack(bytes(bad), "Mapping")
            outcomes.add("data")
        except StateError:
            outcomes.add("error")
    assert outcomes == {"data", "error"}


# ---- the crafted states of the issue, through the commands that read them -----------------------------------

class _ObjectDtype:
    """numpy.dtype('O') whose __setstate__ clears its flags: numpy.frombuffer then reads raw bytes as
    object pointers (what the old restricted unpickler allowed)."""

    def __reduce__(self):
        return (np.dtype, ("O8", False, True), (3, "|", None, None, None, -1, -1, 0))


class _PointerArray:
    def __reduce__(self):
        from numpy._core.numeric import _frombuffer

        return (_frombuffer, (b"\x41" * 8, _ObjectDtype(), (), "C"))


def _cotwin(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *args], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_the_numpy_dtype_state_is_refused_by_whatif_and_sweep_without_a_crash(tmp_path):
    from conftest import EXAMPLES

    payload = pickle.dumps(("Execution", {"time": _PointerArray()}), protocol=5)
    project = EXAMPLES / "ur5e" / "cotwin.toml"
    for magic in (OLD_MAGIC, MAGIC):
        (tmp_path / "state").write_bytes(magic + payload)
        whatif = _cotwin("whatif", str(project), "--plan", str(EXAMPLES / "ur5e" / "plan.csv"), "--from", "state",
                         cwd=tmp_path)
        assert whatif.returncode == 1, whatif.stderr[-2000:]  # not 139 (a dereferenced pointer)
        refusal = "earlier cotwin" if magic == OLD_MAGIC else "damaged cotwin state"
        assert refusal in whatif.stderr
        sweep = _cotwin("sweep", str(project), "--event", "moveDiscreteCommand", "--arg", "target_X=0",
                        "--arg", "target_Y=23", "--arg", "target_Z=1", "--from", "state", "--workers", "1",
                        "-o", "sweep.csv", cwd=tmp_path)
        assert sweep.returncode == 1, sweep.stderr[-2000:]
        assert refusal in sweep.stderr and "cotwin bug" not in sweep.stderr


def _execution(twin, fmu) -> Execution:
    from cotwin.twin.assembly.run import dt_endpoint

    return Execution(twin.instantiate(fmu, dt_endpoint(twin)), algorithm("jacobi"), 0.1)


@pytest.fixture(scope="module")
def saved(twin, fmu) -> bytes:
    live = _execution(twin, fmu)
    live.initialize()
    while live.time < FORK - 1e-9:
        live.step()
    assert live.system.units["{mapping}.mapping"].mapping.endpoint.segment is not None
    try:
        return live.get_state()
    finally:
        live.close()


def _edited(state: bytes, edit, unit: str | None = None, kind: str | None = None) -> bytes:
    """`state` with `edit` applied to its data (or to one unit's, packed as `kind`)."""
    data = unpack(state, "Execution")
    if unit is None:
        edit(data)
    else:
        inner = unpack(data["units"][unit], kind)
        edit(inner)
        data["units"][unit] = pack(kind, inner)
    return pack("Execution", data)


def _restore(twin, fmu, state: bytes) -> None:
    fork = _execution(twin, fmu)
    try:
        fork.set_state(state)
        fork.step()
    finally:
        fork.close()


def test_a_nan_time_and_a_missing_key_are_located_by_whatif(saved, tmp_path):
    from conftest import EXAMPLES, cotwin_in_process

    project, plan = EXAMPLES / "ur5e" / "cotwin.toml", EXAMPLES / "ur5e" / "plan.csv"
    for name, edit, message in (("nan", lambda d: d.update(time=math.nan), "the saved state's time is nan, not a finite number"),
                                ("missing", lambda d: d.pop("units"), "the saved state's execution lacks units")):
        (tmp_path / name).write_bytes(_edited(saved, edit))
        run = cotwin_in_process("whatif", project, "--plan", plan, "--from", name, cwd=tmp_path)  # a message: no process needed
        assert run.returncode == 1 and message in run.stderr, run.stderr[-2000:]
        assert "nan s" not in run.stderr and "cotwin bug" not in run.stderr


def test_a_sweep_from_a_state_of_other_models_is_refused_once_before_any_whatif(saved, tmp_path):
    """Each what-if failed alike (one line per grid point, a CSV of failures written, exit 1): a state of
    other models is refused once, by the state's name, before any runs, as cotwin whatif does."""
    from conftest import EXAMPLES, cotwin_in_process

    (tmp_path / "other").write_bytes(_edited(saved, lambda d: d.update(models={"arm.rst": "0" * 64})))
    run = cotwin_in_process("sweep", EXAMPLES / "ur5e" / "cotwin.toml", "--event", "moveDiscreteCommand",
                            "--arg", "target_X=0..2", "--arg", "target_Y=23", "--arg", "target_Z=1", "--from", "other",
                            "--workers", "1", "-o", "sweep.csv", cwd=tmp_path)
    assert run.returncode == 1, run.stderr[-2000:]
    assert run.stderr.count("the state was saved from other models than these: arm.rst changed") == 1
    assert "other: error:" in run.stderr and "what-if 1 of" not in run.stderr
    assert not (tmp_path / "sweep.csv").exists()


MAPPING, DMODEL, CONTROLLER = "{mapping}.mapping", "{dmodel}.dmodel", "{controller}.controller"


def _mapping(edit):
    return lambda d: edit(d["mapping"])


def _set(path: tuple, value):
    def edit(d):
        for key in path[:-1]:
            d = d[key]
        d[path[-1]] = value
    return edit


def _drop(path: tuple):
    def edit(d):
        for key in path[:-1]:
            d = d[key]
        del d[path[-1]]
    return edit


@pytest.mark.parametrize("unit, kind, edit, message", [
    (None, None, _set(("steps",), -1), "number of steps is -1"),
    (None, None, _set(("steps",), 10 ** 12), "number of steps is 1000000000000"),
    (None, None, _set(("step_size",), 0.0), "step size is 0.0, not a positive"),
    (None, None, _set(("origin",), (0.0, 5)), "time 1.5 s is not 10 steps"),
    (None, None, _set(("time",), math.inf), "time is inf"),
    (None, None, _set(("algorithm",), "gauss-seidel"), "taken under gauss-seidel"),
    (None, None, _set(("values", (MAPPING, "moveCompleted")), 2.5), r"value of \{mapping\}.mapping.moveCompleted is 2.5, not a Boolean"),
    (None, None, _set(("values", ("{x}.x", "y")), 1.0), r"value of \{x\}.x.y, which this system does not observe"),
    (None, None, _set(("units", "{x}.x"), b""), "saved state is of units"),
    (None, None, _set(("models", "arm.rst"), "0" * 64), "arm.rst changed"),
    (None, None, _set(("extra",), 1), "has unexpected 'extra'"),
    (DMODEL, "FMU", _set(("guid",), "{0}"), "state is of another FMU: FlexCellArm"),
    (DMODEL, "FMU", _drop(("time",)), r"unit \{dmodel\}.dmodel lacks time"),
    (DMODEL, "FMU", _set(("time",), math.nan), "time is nan"),
    (DMODEL, "FMU", _set(("fmu",), b"\x00" * 16), "fmi2DeSerializeFMUstate failed.*wrong size"),
    (CONTROLLER, "ScenarioUnit", _set(("next",), 99), "next command is 99, not a whole number from 0 to 4"),
    (CONTROLLER, "ScenarioUnit", _set(("values", "MovementArgs_target_X"), "8"), "MovementArgs_target_X is '8', not an Integer"),
    (CONTROLLER, "ScenarioUnit", _drop(("values", "moveDiscreteCommand")), "values lacks moveDiscreteCommand"),
    (MAPPING, "MappingUnit", _set(("executed",), [(0.5, "rm -rf", {})]), "ran .*rm -rf.*not \\(time, operation"),
    (MAPPING, "MappingUnit", _mapping(_set(("variables", "target_q"), (1.0, 2.0))), "target_q is not a VectorValue of 6"),
    (MAPPING, "MappingUnit", _mapping(_set(("variables", "motion"), "fast")), "variables.motion is 'fast', not a int"),
    (MAPPING, "MappingUnit", _mapping(_drop(("variables", "q0"))), "variables lacks q0"),
    (MAPPING, "MappingUnit", _mapping(_set(("started",), 1)), "started is 1, not a bool"),
    (MAPPING, "MappingUnit", _mapping(_set(("events", "feasibleMoveDiscreteCommand2"), True)), "does not define"),
    (MAPPING, "MappingUnit", _mapping(_set(("endpoint", "simulator"), np.zeros(5))), "has 5 numbers, this model's has"),
    (MAPPING, "MappingUnit", _mapping(lambda m: m["endpoint"]["simulator"].__setitem__(3, np.nan)), "not finite"),
    (MAPPING, "MappingUnit", _mapping(lambda m: m["endpoint"]["simulator"].__setitem__(3, 1e11)), "beyond MuJoCo's"),
    (MAPPING, "MappingUnit", _mapping(_set(("endpoint", "segment", "fields", "goal", "elbow"), 1.0)), "moves 'elbow'"),
    (MAPPING, "MappingUnit", _mapping(_set(("endpoint", "segment", "fields", "duration"), math.nan)), "duration is nan"),
    (MAPPING, "MappingUnit", _mapping(_set(("endpoint", "segment", "kind"), "os.system")), "unknown kind 'os.system'"),
    (MAPPING, "MappingUnit", _mapping(_set(("endpoint", "direct", "elbow_joint"), 1.0)), "not a speed- or effort-driven"),
    (MAPPING, "MappingUnit", _mapping(_set(("functions", (1.0, 2.0)), {})), "keyed by a grid point"),
    (MAPPING, "MappingUnit", _mapping(_set(("pending",), [("q0", 1.0)])), "pending answer .*not one of its answers"),
    (MAPPING, "MappingUnit", _mapping(_set(("held", "noSuchEvent"), (True, None))), "holds 'noSuchEvent' as an event"),
    (MAPPING, "MappingUnit", _mapping(_set(("asked",), ["os"])), "asked about 'os'"),
    (MAPPING, "MappingUnit", _mapping(_set(("reports",), -3)), "reports is -3"),
    (MAPPING, "MappingUnit", _mapping(lambda m: m.update(reports=2, delivered={"moveCompleted": 9})),
     "report delivering moveCompleted is 9, not a whole number from 0 to 2"),
    (CONTROLLER, "ScenarioUnit", _set(("queue", "waiting"), [("rm", (), "x", 0.0, None)]), "event 'rm' this unit does not send"),
    (CONTROLLER, "ScenarioUnit", _set(("queue", "waiting"), [("moveDiscreteCommand", (("MovementArgs_target_X", "8"),),
                                                               "x", 0.0, None)]), "MovementArgs_target_X is '8', not an Integer"),
    (CONTROLLER, "ScenarioUnit", _set(("queue", "accepted"), -1), "accepted count is -1"),
])
def test_every_field_is_checked_against_the_system_it_restores_into(twin, fmu, saved, unit, kind, edit, message):
    with pytest.raises(CotwinError, match=message):
        _restore(twin, fmu, _edited(saved, edit, unit, kind))


def test_the_saved_state_restores_after_all_those_checks(twin, fmu, saved):
    _restore(twin, fmu, saved)  # the untouched state passes every check
    again = _execution(twin, fmu)
    again.set_state(saved)
    assert again.time == pytest.approx(FORK) and again.get_state() == saved
    again.close()


def test_random_damage_to_a_whole_twin_state_is_refused_or_restored(twin, fmu, saved):
    """Bytes of the structure changed at random: each restore raises a CotwinError or runs."""
    rng = random.Random(7)
    head = len(MAGIC) + 8 + int.from_bytes(saved[len(MAGIC):len(MAGIC) + 8], "little")
    fork = _execution(twin, fmu)
    fork.initialize()
    refused = 0
    try:
        for _ in range(60):
            bad = bytearray(saved)
            at = rng.randrange(len(MAGIC) + 8, head)
            bad[at] = rng.choice(b'0123456789-.e"[]{},:ntf$')
            try:
                fork.set_state(bytes(bad))
                fork.step()
            except CotwinError:
                refused += 1
                if fork.closed:
                    fork = _execution(twin, fmu)
                    fork.initialize()
    finally:
        fork.close()
    assert refused > 10


# ---- the d-model FMU's own check of serialised bytes --------------------------------------------------------

def _fuzz_model() -> str:
    """A module whose state has everything model_check looks at: a machine calling an operation that calls
    another (frames, return points), a set, a sequence of records, a Boolean vector (test_robosim_language's
    platform and its operations test's interfaces)."""
    from test_robosim_language import machine

    extra = """interface Shared { var n: int }
interface Soft { add(k: int) twice(k: int) }
datatype Pos { x: int y: int }
operation add(k: int) {
	requires Shared
	initial i
	state Adding { entry n = n + k }
	final f
	transition t0 { from i to Adding }
	transition t1 { from Adding to f exec condition n > k \\/ k <= 0 }
	transition t2 { from Adding to Adding exec condition n <= k /\\ k > 0 }
}
"""
    text = machine("""	requires Soft
	var n: int = 1
	var x: int
	var s: Set(int) = {1, 2}
	var q: Seq(Pos) = <Pos(|x = 1, y = 2|)>
	var v: vector(boolean, 3) = [|true, false, true|]
	var b: boolean = false
	initial i
	state A { }
	state B { entry twice(x); s = union(s, {x}); q = q cat <Pos(|x = x, y = n|)>; b = not b; $out!(n + size(s) + size(q)); $flag!(v[2] \\/ b) }
	transition t0 { from i to A }
	transition t1 { from A to B condition $go?x }
	transition t2 { from A to A exec condition not $go }
	transition t3 { from B to A exec }""", extra)["m.rst"]
    return "import set_toolkit::*\nimport sequence_toolkit::*\n" + text.replace("sref m = M", """sref m = M
	opref a = add
	operation twice(k: int) {
		requires Shared requires Soft
		var c: int = 0
		initial i
		state Calling { entry add(k); c = c + 1 }
		final f
		transition t0 { from i to Calling }
		transition t1 { from Calling to Calling exec condition c < 2 }
		transition t2 { from Calling to f exec condition c >= 2 }
	}""")


FUZZ = """
import sys
from cotwin.cosim.state import pack, unpack
from cotwin.cosim.units import FMUUnit, UnitError

unit = FMUUnit("m", sys.argv[1])
unit.instantiate(0.0)
unit.initialize()
inputs = [{}, {"go": 3}, {}, {}, {"go": 0}, {}, {"go": 5}]
states, t = [], 0.0
for given in inputs:  # states in every phase: idle, in the operation's frames, after
    unit.set({"go": "go" in given, "go_value": given.get("go", 0)})
    unit.step(t, 1.0)
    t += 1.0
    states.append(unit.get_state())
accepted = refused = 0
for state in states:
    data = unpack(state, "FMU")
    raw = data["fmu"]
    for at in range(len(raw)):
        for change in (0xFF, 0x80, 0x01, 0x20):
            bad = bytearray(raw)
            bad[at] ^= change
            try:
                unit.set_state(pack("FMU", {**data, "fmu": bytes(bad)}))
            except UnitError:
                refused += 1
                unit.status = "instantiated"
                continue
            accepted += 1
            for given in inputs[:3]:
                try:
                    unit.set({"go": "go" in given, "go_value": given.get("go", 0)})
                    unit.step(t, 1.0)
                except UnitError:  # a located model error (e.g. a changed value overflows): fine
                    unit.status = "instantiated"
                    break
print(accepted, refused)
"""


def test_the_fmu_refuses_malformed_serialised_bytes_without_undefined_behaviour(tmp_path):
    """Every byte of serialised FMU states (idle, inside operation frames, with sets, sequences of records,
    Boolean vectors) changed in turn, restored and stepped, in an FMU built with UBSan's bounds and bool
    checks: any read outside an array or of a Boolean that is neither 0 nor 1 aborts the process."""
    import shutil

    from cotwin.dmodel.fmu import build_fmu
    from cotwin.dmodel.program import build_program
    from cotwin.robosim.check import load_checked

    if shutil.which("cc") is None:
        pytest.skip("no C compiler")
    (tmp_path / "m.rst").write_text(_fuzz_model())
    fmu = build_fmu(build_program(load_checked([tmp_path / "m.rst"])), tmp_path / "m.fmu",
                    cc="cc -fsanitize=undefined,bounds -fno-sanitize-recover=all")
    (tmp_path / "fuzz.py").write_text(FUZZ)
    run = subprocess.run([sys.executable, str(tmp_path / "fuzz.py"), str(fmu)], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    accepted, refused = map(int, run.stdout.split())
    assert refused > 1000 and accepted > 1000  # malformed fields refused; harmless changes (values) run


@pytest.mark.parametrize("name", ["jacobi", "gauss-seidel"])
def test_a_fork_at_any_step_goes_on_bit_for_bit(twin, fmu, name):
    """Forks every half second of a run (moves starting, in flight, a stop at 6 s under Gauss-Seidel) read
    what the straight run read: the simulator's sensors and body poses as its last step left them, not as
    mj_forward recomputes them at the restored positions (which made a fork at 6 s differ by 1e-6 rad)."""
    from cotwin.twin.assembly.run import dt_endpoint

    def execution() -> Execution:
        return Execution(twin.instantiate(fmu, dt_endpoint(twin)), algorithm(name), 0.1)

    straight, states = [], {}
    live = execution()
    live.initialize()
    while live.time < 8.0 - 1e-9:
        live.step()
        straight.append([repr(v) for v in live.values.values()])
        if live.steps % 5 == 0:
            states[live.steps] = live.get_state()
    live.close()
    for steps, state in states.items():
        fork = execution()
        fork.set_state(state)
        rows = []
        while fork.time < 8.0 - 1e-9:
            fork.step()
            rows.append([repr(v) for v in fork.values.values()])
        fork.close()
        assert rows == straight[steps:], f"a fork at t = {steps / 10:g} s"


def test_a_state_of_another_format_version_is_named_so_not_called_no_cotwin_state():
    blob = pack("Mapping", {"a": 1})
    with pytest.raises(StateError, match=r"a cotwin state of an unsupported version 3 \(this cotwin reads version 2"):
        unpack(b"cotwin-state 3\n" + blob[len(MAGIC):], "Mapping")
    with pytest.raises(StateError, match="not a cotwin state"):
        unpack(b"cotwin-state x\n" + blob[len(MAGIC):], "Mapping")


def test_a_state_of_an_unknown_algorithm_is_refused_by_whatif_and_sweep_at_the_state_file(saved, tmp_path):
    from conftest import EXAMPLES, cotwin_in_process

    project = EXAMPLES / "ur5e" / "cotwin.toml"
    (tmp_path / "odd").write_bytes(_edited(saved, lambda d: d.update(algorithm="jacobx")))
    message = "odd: error: the saved state's algorithm 'jacobx' is unknown (known: jacobi, gauss-seidel)"
    run = cotwin_in_process("whatif", project, "--plan", EXAMPLES / "ur5e" / "plan.csv", "--from", "odd", cwd=tmp_path)
    assert run.returncode == 1 and message in run.stderr, run.stderr[-2000:]
    run = cotwin_in_process("sweep", project, "--event", "moveDiscreteCommand", "--arg", "target_X=0..1",
                            "--arg", "target_Y=23", "--arg", "target_Z=1", "--from", "odd", "--workers", "1",
                            "-o", "sweep.csv", cwd=tmp_path)
    assert run.returncode == 1 and message in run.stderr and "what-if 1 of" not in run.stderr, run.stderr[-2000:]
    assert not (tmp_path / "sweep.csv").exists()


from cotwin.cosim.state import _Writer as _WRITER  # noqa: E402 - the writer of today, the one tested


class _Before:
    """The state writer as it was before it kept plain items without a call each (a969638): the reference the
    faster one must match byte for byte (a saved state is compared and hashed by its bytes)."""

    def __init__(self):
        from cotwin.cosim import state

        self.state, self.blobs = state, []
        self.writer = _WRITER()
        self.writer.encode = self.encode  # _items and the blobs go on through the same writer

    def encode(self, value, depth: int = 0):
        s, w = self.state, self.writer
        if depth > s.MAX_DEPTH:
            raise StateError(f"a state nested deeper than {s.MAX_DEPTH} levels cannot be saved")
        cls = value.__class__
        if value is None or cls in (bool, str) or (cls is int and not isinstance(value, bool)):
            return value
        if cls is float:
            return value if math.isfinite(value) else {"$float": repr(value)}
        if isinstance(value, np.ndarray):
            array = w._numeric(value)
            return {"$array": w.blob(array.tobytes()), "dtype": array.dtype.str, "shape": list(array.shape)}
        if isinstance(value, np.generic):
            array = w._numeric(np.asarray(value))
            return {"$scalar": w.blob(array.tobytes()), "dtype": array.dtype.str}
        if cls in (bytes, bytearray, memoryview):
            return {"$bytes": w.blob(bytes(value))}
        if cls.__name__ in s._VALUES and s._VALUES[cls.__name__] is cls:
            return {"$value": cls.__name__, "items": w._items(value, depth, cls is SetValue)}
        if cls is list:
            return [self.encode(v, depth + 1) for v in value]
        if cls is tuple:
            return {"$tuple": [self.encode(v, depth + 1) for v in value]}
        if cls in (set, frozenset):
            return {"$set" if cls is set else "$frozenset": w._items(value, depth, True)}
        if cls is dict:
            if all(k.__class__ is str and not k.startswith("$") for k in value):
                return {k: self.encode(v, depth + 1) for k, v in value.items()}
            return {"$dict": [[self.encode(k, depth + 1), self.encode(v, depth + 1)] for k, v in value.items()]}
        raise StateError(f"a state holds only plain data, not a {cls.__module__}.{cls.__qualname__}")


def _random_state(rng: random.Random, depth: int):
    """Plain data of every kind a state holds, nested up to `depth` (past the limit, too)."""
    scalars = [lambda: rng.choice(["", "a", "$x", "$float", "é"]), lambda: rng.randrange(-2 ** 70, 2 ** 70),
               lambda: rng.choice([True, False, None]), lambda: rng.choice([0.0, -0.0, 1.5, math.nan, math.inf,
                                                                           -math.inf, rng.uniform(-1e9, 1e9)]),
               lambda: np.float32(rng.random()), lambda: np.arange(rng.randrange(4), dtype="<i4"),
               lambda: bytes(rng.randrange(256) for _ in range(3)), lambda: np.int64(7)]
    if depth <= 0 or rng.random() < 0.3:
        return rng.choice(scalars)()
    items = [_random_state(rng, depth - 1) for _ in range(rng.randrange(4))]
    keys = [rng.choice(["k", "$k", "v", 1, (1, 2), None]) if rng.random() < 0.2 else f"k{n}" for n in range(len(items))]
    return rng.choice([lambda: items, lambda: tuple(items), lambda: dict(zip(keys, items)),
                       lambda: {x for x in items if isinstance(x, (str, int))},
                       lambda: frozenset(x for x in items if isinstance(x, (str, float)))])()


def _deep(rng: random.Random, levels: int, leaf):
    for _ in range(levels):
        leaf = rng.choice([lambda v: [1, v, 2.5], lambda v: (v, None), lambda v: {"a": v, "b": "s"}])(leaf)
    return leaf


def test_state_bytes_are_those_of_the_writer_before_it_was_made_faster(monkeypatch):
    """Random states of every kind, and states at and past the depth limit, give the same bytes (or the same
    refusal) as the writer before a969638 gave."""
    from conftest import FUZZ_SEED
    from cotwin.cosim import state

    rng = random.Random(FUZZ_SEED)
    cases = [_random_state(rng, 6) for _ in range(2000)]
    cases += [_deep(rng, state.MAX_DEPTH + extra, leaf) for extra in (-2, -1, 0, 1) for leaf in
              (1, 1.5, math.nan, "s", [], {}, (), [1, 2], {"$a": 1}, np.float64(2.0))]

    def written(writer_class, data):
        monkeypatch.setattr(state, "_Writer", writer_class)
        try:
            return pack("unit", data)
        except StateError as err:
            return str(err)
        finally:
            monkeypatch.undo()

    for data in cases:
        assert written(_WRITER, data) == written(lambda: _Before().writer, data), (FUZZ_SEED, data)


from cotwin.cosim.state import _Reader as _READER  # noqa: E402 - the reader of today, the one tested


class _ReaderBefore(_READER):
    """The state reader as it was before it read plain items without a call each and floats by json's own parser
    (issue 23, stop 36): the reference the faster one must match, value for value and refusal for refusal."""

    def __init__(self, blobs):
        from cotwin.cosim import state

        super().__init__(blobs)
        self.s = state

    def decode(self, node, depth: int = 0):
        s = self.s
        if depth > s.MAX_DEPTH:
            raise StateError(f"a damaged cotwin state (nested deeper than {s.MAX_DEPTH} levels)")
        cls = node.__class__
        if node is None or cls in (bool, int, float, str):
            return node
        if cls is list:
            return [self.decode(v, depth + 1) for v in node]
        if any(k.startswith("$") for k in node):
            return self._tagged(node, depth)
        return {k: self.decode(v, depth + 1) for k, v in node.items()}

    def _tagged(self, node: dict, depth: int):
        s = self.s
        tag = next(k for k in node if k.startswith("$"))
        shapes = {"$float": {"$float"}, "$tuple": {"$tuple"}, "$set": {"$set"}, "$frozenset": {"$frozenset"},
                  "$dict": {"$dict"}, "$bytes": {"$bytes"}, "$array": {"$array", "dtype", "shape"},
                  "$scalar": {"$scalar", "dtype"}, "$value": {"$value", "items"}}
        if tag not in shapes or set(node) != shapes[tag]:
            raise StateError(f"a damaged cotwin state (an entry {sorted(node)!r:.80} is not plain data)")
        body = node[tag]
        if tag == "$float":
            if body not in s._CONSTANTS:
                raise StateError(f"a damaged cotwin state ({body!r:.40} is not nan, inf or -inf)")
            return s._CONSTANTS[body]
        if tag == "$bytes":
            return bytes(self.blob(body))
        if tag in ("$array", "$scalar"):
            return self._array(node, tag)
        items = node["items"] if tag == "$value" else body
        if items.__class__ is not list:
            raise StateError(f"a damaged cotwin state ({tag} holds no list)")
        if tag == "$dict":
            if not all(p.__class__ is list and len(p) == 2 for p in items):
                raise StateError("a damaged cotwin state ($dict holds no [key, value] pairs)")
            out = {}
            for key, value in items:
                key = self.decode(key, depth + 1)
                try:
                    out[key] = self.decode(value, depth + 1)
                except TypeError:  # an unhashable key (a list, a dict)
                    raise StateError(f"a damaged cotwin state (a key {key!r:.60} that cannot be a key)") from None
            return out
        values = [self.decode(v, depth + 1) for v in items]
        try:
            if tag == "$value":
                kind = s._VALUES.get(body) if body.__class__ is str else None
                if kind is None:
                    raise StateError(f"a damaged cotwin state ({body!r:.60} is not a RoboSim value)")
                if kind in (SeqValue, SetValue) and len(values) > s.CAPACITY:
                    raise StateError(f"a damaged cotwin state (a {body} of {len(values)} elements, more than {s.CAPACITY})")
                return kind(values)
            return {"$tuple": tuple, "$set": set, "$frozenset": frozenset}[tag](values)
        except TypeError:  # unhashable elements of a set
            raise StateError(f"a damaged cotwin state (a {tag[1:]} of elements that cannot be in one)") from None


def _finite_float(text: str) -> float:
    """The reader before: each JSON float parsed by this call, refused there unless finite."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text[:40]} is not a finite number")
    return value


def _unpack_before(blob: bytes, kind: str):
    """`unpack` with the reader before (its JSON floats parsed by a call each, each checked finite there)."""
    import json as _json

    from cotwin.cosim import state

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(state, "_Reader", _ReaderBefore)
        real = _json.loads
        patch.setattr(state.json, "loads", lambda text, **kw: real(text, parse_float=_finite_float, **kw))
        return state.unpack(blob, kind)


def _read(unpacker, blob: bytes):
    """What a reader makes of the bytes: the data written again (bytes: the writer keeps every type), or the error
    (the finite-number refusal names the JSON text before and the number now: the same refusal)."""
    try:
        return pack("unit", unpacker(blob, "unit"))
    except StateError as err:
        return re.sub(r"\(([^()]*) is not a finite number\)", "(not a finite number)", str(err))


def _nested_json(levels: int, leaf: str) -> bytes:
    """A state whose data nests `levels` lists deep around `leaf` (JSON text), past what the writer writes."""
    head = ('{"kind":"unit","blobs":[],"data":' + "[" * levels + leaf + "]" * levels + "}").encode()
    return MAGIC + len(head).to_bytes(8, "little") + head


def test_states_read_as_the_reader_before_it_was_made_faster():
    """Random states of every kind, states at and past the depth limit (written, and crafted past what the
    writer writes) and random damage to their bytes read as the reader before gave: the same data, the same
    refusal. A sweep restores its fork's state once a plan: the reader was a tenth of a what-if (issue 23)."""
    from conftest import FUZZ_SEED
    from cotwin.cosim import state

    rng = random.Random(FUZZ_SEED)
    blobs = []
    for data in [_random_state(rng, 6) for _ in range(1500)] + \
            [_deep(rng, state.MAX_DEPTH + extra, leaf) for extra in (-3, -2, -1) for leaf in
             (1, 1.5, math.nan, "s", [], {}, (), [1, 2], {"$a": 1}, np.float64(2.0))]:
        try:
            blobs.append(pack("unit", data))
        except StateError:
            continue
    blobs += [_nested_json(state.MAX_DEPTH + extra, leaf) for extra in (-1, 0, 1, 2)
              for leaf in ("1", "1.5", "1e999", '"s"', "[]", "{}", '{"$tuple":[1]}', '{"a":-1e999}', "null")]
    for blob in list(blobs[:300]):
        for _ in range(3):  # damaged: a byte of the structure or of a binary part changed
            bad = bytearray(blob)
            at = rng.randrange(len(MAGIC) + 8, len(bad))
            bad[at] = rng.choice([rng.randrange(256), ord("$"), ord("["), ord("{"), ord('"'), ord("9"), ord("e")])
            blobs.append(bytes(bad))
    for blob in blobs:
        now, before = _read(unpack, blob), _read(_unpack_before, blob)
        if isinstance(now, str) and isinstance(before, str) and "(not a finite number)" in now + before:
            continue  # refused both ways: before, at the float as JSON was parsed; now, maybe for a problem found first
        assert now == before, (FUZZ_SEED, blob[:200])
