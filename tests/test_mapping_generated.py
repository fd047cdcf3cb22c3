"""The mapping's input events as generated Python (cotwin.mapping.generated): the same occurrences, values
and errors as the interpreting evaluator, from deterministic source."""

from __future__ import annotations

import math

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.runtime import Mapping
from cotwin.twin.assembly.run import load, simulated_endpoint


def _pair(project):
    system = load(project)
    return [Mapping(system.models.project, simulated_endpoint(system), compiled=compiled,
                    monitor=system.spec.readings) for compiled in (True, False)]


def _events(mapping: Mapping) -> dict:
    return {name: (mapping.get_event(name), mapping.event_value(name)) for name in sorted(mapping.events)}


def test_generated_events_agree_with_the_interpreter_on_a_walking_robot_and_its_lidar():
    """The TurtleBot's events carry the LiDAR's nearest return (`e?x`): inf and NaN readings (nothing seen)
    make them not occur; the generated form says so at the same steps, with the same values."""
    from conftest import EXAMPLES

    generated, interpreted = _pair(EXAMPLES / "turtlebot" / "cotwin.toml")
    seen = []
    for m in (generated, interpreted):
        m.start_mapping()
        record = []
        for k in range(40):
            m.execute_operation("move", {"lv": 0.2, "av": 0.6 if k % 10 < 5 else -0.8})
            m.step(0.1)
            record.append(_events(m))
        seen.append(record)
    assert seen[0] == seen[1]
    assert any(ev["closestDistance"][0] for ev in seen[0])


def test_generated_events_agree_on_the_arm_through_a_pick_and_place():
    from conftest import EXAMPLES

    generated, interpreted = _pair(EXAMPLES / "ur5e" / "pick_place_project.toml")
    records = []
    for m in (generated, interpreted):
        m.start_mapping()
        record = []
        for name in sorted(m.operations):
            op = m.operations[name]
            args = {p: (1 if p.startswith("target") else 0.03) for p in op.params}
            try:
                m.execute_operation(name, args)
            except CotwinError as err:  # both forms must fail alike
                record.append(str(err))
            for _ in range(5):
                m.step(0.1)
                record.append((_events(m), m.report()))
        records.append(record)
    assert records[0] == records[1]


def test_the_source_is_generated_deterministically_from_the_model():
    from conftest import EXAMPLES

    sources = [{name: ev.occurs.source for name, ev in m.events.items()}
               for m in (_pair(EXAMPLES / "ur5e" / "cotwin.toml")[0], _pair(EXAMPLES / "ur5e" / "cotwin.toml")[0])]
    assert sources[0] == sources[1]
    assert "def occurs():" in sources[0]["moveCompleted"]


def test_an_event_that_cannot_be_evaluated_names_its_place_as_the_interpreter_does():
    from conftest import EXAMPLES

    messages = []
    for m in _pair(EXAMPLES / "ur5e" / "cotwin.toml"):
        m.start_mapping()
        del m.variables["motion"]  # a variable without a value (a restored state that lost it, say)
        with pytest.raises(CotwinError) as err:
            m.get_event("moveCompleted")
        messages.append(str(err.value))
        m.variables["motion"] = 0
        m.variables["target_q"] = (0.0,)  # too short a vector: index 1 out of range
        m.variables["motion"] = _moving(m)
        with pytest.raises(CotwinError) as err:
            m.get_event("moveCompleted")
        messages.append(str(err.value))
    assert messages[:2] == messages[2:]
    assert "'motion' has no value" in messages[0] and "out of range" in messages[1]


def _moving(m: Mapping) -> int:
    from cotwin.robosim import syntax as s

    return m.enum_value(s.QName(("Motion", "moving")))


def test_a_reading_that_is_no_measurement_makes_a_valued_event_not_occur():
    from conftest import EXAMPLES

    for m in _pair(EXAMPLES / "turtlebot" / "cotwin.toml"):
        m.start_mapping()
        key = next(k for k in m.sensor_readings() if k.endswith("closestDistance"))
        for reading in (math.inf, math.nan):
            m._readings = {**m.sensor_readings(), key: reading}
            assert not m.get_event("closestDistance")
        m._readings = {**m.sensor_readings(), key: 1.25}
        assert m.get_event("closestDistance") and m.event_value("closestDistance") == 1.25
