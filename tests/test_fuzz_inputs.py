"""Fuzzing every input surface a user or a peer controls, beside the model fuzz of test_frontend_fuzz:
project files, TOML scenarios, plan CSVs, multimodels and live command messages. Each mutant must be
accepted or refused with a CotwinError (or, for a message, a reason): never another exception, never a
hang. `FUZZ_EXAMPLES` scales the number of cases (the closing note's figures used 2000 per surface)."""

from __future__ import annotations

import json
import math
import os
import shutil

import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from cotwin.cosim.multimodel import read_multimodel
from cotwin.diagnostics import CotwinError
from cotwin.twin.project import load_project
from cotwin.twin.assembly.rabbitmq import parse_message
from cotwin.twin.assembly.scenario import read_plan, read_toml

from conftest import FUZZ_SEED  # noqa: E402

# other cases every run (the session's seed, printed in pytest's header; COTWIN_FUZZ_SEED repeats them),
# more under CI
EXAMPLES_PER_SURFACE = int(os.environ.get("FUZZ_EXAMPLES") or (600 if os.environ.get("CI") else 150))
_SETTINGS = settings(max_examples=EXAMPLES_PER_SURFACE, deadline=None, database=None,
                     suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def FUZZ(test):
    return seed(FUZZ_SEED)(_SETTINGS(test))

PIECES = ["", "0", "-1", "2.5", "-3.75", "1e400", "nan", "inf", "true", '"x"', "[1, 2]", "{ a = 1 }", "\xff", "\x00", "[[x]]",
          "[models]", "=", '"""', "4294967296", "9" * 400, "#", "\n", ",", '"', "\\", "'", "{", "}", "]"]


def mutate(text: str, data) -> bytes:
    """A few edits of `text`: replace, insert or delete a slice, duplicate or drop a line, or flip bytes."""
    raw = text.encode()
    for _ in range(data.draw(st.integers(1, 4))):
        kind = data.draw(st.sampled_from(["replace", "insert", "delete", "dup", "drop", "byte"]))
        at = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if kind == "replace":
            end = min(len(raw), at + data.draw(st.integers(1, 12)))
            raw = raw[:at] + data.draw(st.sampled_from(PIECES)).encode("utf-8", "surrogateescape") + raw[end:]
        elif kind == "insert":
            raw = raw[:at] + data.draw(st.sampled_from(PIECES)).encode("utf-8", "surrogateescape") + raw[at:]
        elif kind == "delete":
            raw = raw[:at] + raw[at + data.draw(st.integers(1, 20)):]
        elif kind in ("dup", "drop"):
            lines = raw.split(b"\n")
            k = data.draw(st.integers(0, len(lines) - 1))
            lines[k:k + 1] = [lines[k], lines[k]] if kind == "dup" else []
            raw = b"\n".join(lines)
        else:
            raw = raw[:at] + bytes([data.draw(st.integers(0, 255))]) + raw[at + 1:]
    return raw


@pytest.fixture(scope="module")
def project_dir(tmp_path_factory):
    from conftest import EXAMPLES

    target = tmp_path_factory.mktemp("fuzz") / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", target)
    return target


class Held:
    """A fixture's value shown by name in a failing example (Hypothesis prints every argument: a d-model program's
    repr ran to half a million lines of CI log)."""

    def __init__(self, value, name: str):
        self.value, self.name = value, name

    def __repr__(self) -> str:
        return self.name


@pytest.fixture(scope="module")
def program(project_dir):
    from cotwin.twin.assembly.run import load

    return Held(load(project_dir / "cotwin.toml").models.program, "<the UR5e example's d-model program>")


@FUZZ
@given(data=st.data())
def test_project_files(project_dir, data):
    original = (project_dir / "twin.toml").read_text()
    path = project_dir / "fuzzed.toml"
    path.write_bytes(mutate(original, data))
    try:
        load_project(path)
    except CotwinError as err:
        assert all(str(f.location.path) == str(path) and f.location.line >= 1 for f in err.findings)


@FUZZ
@given(data=st.data())
def test_toml_scenarios(project_dir, program, data):
    path = project_dir / "fuzzed_scenario.toml"
    path.write_bytes(mutate((project_dir / "pick_place.toml").read_text(), data))
    try:
        commands = read_toml(path, program.value)
    except CotwinError:
        return
    assert all(c.time >= 0 for c in commands)


@FUZZ
@given(data=st.data())
def test_plan_csvs(project_dir, program, data):
    path = project_dir / "fuzzed_plan.csv"
    path.write_bytes(mutate((project_dir / "plan.csv").read_text(), data))
    try:
        commands = read_plan(path, program.value)
    except CotwinError:
        return
    for c in commands:  # what is accepted is in range
        assert c.time >= 0 and all(not isinstance(v, int) or -2 ** 31 <= v < 2 ** 31 for _, v in c.values)


@pytest.fixture(scope="module")
def multimodel_dir(project_dir, tmp_path_factory):
    from cotwin.twin.assembly.build import build
    from cotwin.twin.assembly.run import load

    out = tmp_path_factory.mktemp("fuzzmm")
    build(load(project_dir / "cotwin.toml"), out)
    return out


@FUZZ
@given(data=st.data())
def test_multimodels(multimodel_dir, data):
    from cotwin.cosim.multimodel import system_of

    path = multimodel_dir / "fuzzed.json"
    path.write_bytes(mutate((multimodel_dir / "multimodel.json").read_text(), data))
    try:
        mm = read_multimodel(path)
        system_of(mm)  # instantiates no FMU: checks units, ports, connections
    except CotwinError:
        pass


TYPES = {"moveDiscreteCommand": "Boolean", "MovementArgs_target_X": "Integer", "MovementArgs_target_Y": "Integer",
         "speed": "Real"}
GOOD = json.dumps({"time": "2025-01-31T16:01:03.066+01:00", "moveDiscreteCommand": True, "MovementArgs_target_X": 3,
                   "MovementArgs_target_Y": 20, "speed": 0.5})


def _expected(value, kind: str):
    """What a port of FMI type `kind` must receive for a JSON value, from the message rules (the RMQ FMU's
    typing), written apart from the parser: None where the value must be dropped."""
    if kind == "Boolean":
        return value if isinstance(value, bool) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        if not math.isfinite(float(value)):
            return None
    except OverflowError:
        return None
    if kind == "Integer":
        return int(value) if -2 ** 31 <= int(value) < 2 ** 31 else None
    return float(value)


@FUZZ
@given(data=st.data())
def test_live_command_messages(data):
    """A message taken is applied exactly as sent: every known key the rules accept reaches its port with
    the value sent (typed as its port), every other one is dropped and said so; refusals give a reason."""
    body = mutate(GOOD, data) if data.draw(st.booleans()) else data.draw(st.binary(max_size=300))
    try:
        parsed = parse_message(body, TYPES)
    except ValueError as err:
        assert str(err)  # refused with a reason
        return
    sent = json.loads(body.decode("utf-8"))
    for key, kind in TYPES.items():
        expected = _expected(sent[key], kind) if key in sent else None
        if expected is None:
            assert key not in parsed.values and (key not in sent or any(d.startswith(key) for d in parsed.dropped))
        else:
            assert parsed.values[key] == expected and type(parsed.values[key]) is type(expected), (key, sent[key])
    assert set(parsed.values) <= set(TYPES) & set(sent)
