"""The mapping runtime on the expression core: closures compiled once give exactly what the
interpreting evaluator gives, on the example twin's mapping (every operation and input event)."""

from __future__ import annotations

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.mapping.runtime import Mapping
from cotwin.twin.assembly.run import load
from cotwin.pmodel.simulator import PlatformSimulator


def _mapping(twin, compiled: bool) -> Mapping:
    return Mapping(twin.project, SimulatedEndpoint(PlatformSimulator(twin.tree, twin.scene)), compiled=compiled)


def _run(mapping: Mapping) -> list:
    mapping.start_mapping()
    record = []
    calls = [("movediscrete", {"target_X": 1, "target_Y": 20, "target_Z": 2}), ("pick", None), ("place", None)]
    for name, args in calls:
        op = mapping.operations[name]
        mapping.execute_operation(name, args if args is not None else {p: 0.03 for p in op.params})
        for _ in range(6):
            mapping.step(0.1)
            record.append(({e: mapping.get_event(e) for e in sorted(mapping.events)}, dict(mapping.variables)))
    return record


def test_compiled_mapping_agrees_with_the_interpreting_evaluator():
    from conftest import EXAMPLES

    twin = load(EXAMPLES / "ur5e" / "cotwin.toml").models
    compiled, interpreted = _run(_mapping(twin, True)), _run(_mapping(twin, False))
    assert compiled == interpreted
    assert any(events["feasibleMoveDiscreteCommand"] for events, _ in compiled)


def test_mapping_errors_name_the_place_in_both_forms():
    from conftest import EXAMPLES

    twin = load(EXAMPLES / "ur5e" / "cotwin.toml").models
    for compiled in (True, False):
        mapping = _mapping(twin, compiled)
        mapping.start_mapping()
        with pytest.raises(CotwinError, match="operation movediscrete: unknown argument"):
            mapping.execute_operation("movediscrete", {"target_W": 1})


@pytest.mark.parametrize("project", ["cotwin.toml", "pick_place_project.toml"])
def test_compiled_and_interpreted_mappings_run_the_same_twin(project, tmp_path, monkeypatch):
    """The paper's experiment and the pick-and-place, end to end: the same events, commands and
    operation calls, to the last digit of every CSV cell, whichever form evaluates the mapping."""
    from conftest import EXAMPLES

    import cotwin.mapping.runtime as runtime
    from cotwin.twin.assembly.run import run_twin

    twin = load(EXAMPLES / "ur5e" / project)
    compiled = run_twin(twin, tmp_path / "compiled", plot=False)

    class Interpreted(runtime.Mapping):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **{**kwargs, "compiled": False})

    monkeypatch.setattr(runtime, "Mapping", Interpreted)
    interpreted = run_twin(twin, tmp_path / "interpreted", plot=False)
    assert interpreted.mapping.mapping.env.compiled is False and compiled.mapping.mapping.env.compiled is True
    assert compiled.mapping.executed == interpreted.mapping.executed
    assert len(compiled.mapping.executed) >= 4
    assert compiled.csv.read_bytes() == interpreted.csv.read_bytes()


def test_a_sensor_the_platform_stops_providing_is_a_located_error_in_both_forms():
    """A reading missing from the platform's sensors (compiled form: looked up in the step's readings
    directly) fails naming the sensor and the place, as the interpreting form does, never a KeyError."""
    from conftest import EXAMPLES

    twin = load(EXAMPLES / "ur5e" / "cotwin.toml").models
    missing = "ur5e::base_link::VS1.output_vel"
    for compiled in (True, False):
        mapping = _mapping(twin, compiled)
        mapping.start_mapping()
        assert mapping.get_event("robotStopped") in (True, False)
        read = mapping.endpoint.read_sensors
        mapping.endpoint.read_sensors = lambda: {k: v for k, v in read().items() if k != missing}
        mapping.step(0.01)
        with pytest.raises(CotwinError, match=rf"mapping\.pm:\d+:\d+.*does not provide sensor '{missing}'"):
            mapping.get_event("robotStopped")


def test_a_monitored_reading_the_platform_lacks_says_the_nearest_few_not_every_reading():
    """The last line of defence behind load_models' check of [monitor] readings (a Mapping made from the models,
    a platform that reads less than its p-model): the nearest paths first, then how many more, not all of them."""
    from conftest import EXAMPLES

    twin = load(EXAMPLES / "ur5e" / "cotwin.toml").models
    mapping = Mapping(twin.project, SimulatedEndpoint(PlatformSimulator(twin.tree, twin.scene)),
                      monitor={"elbow": "ur5e::upper_arm_link::PS3.position"})
    with pytest.raises(CotwinError) as err:  # read as the mapping starts
        mapping.start_mapping()
    said = str(err.value)
    assert "monitored variable elbow: the platform has no reading 'ur5e::upper_arm_link::PS3.position' (the nearest: " \
        "ur5e::upper_arm_link::PS3.output_position, " in said and said.endswith(", ... and 17 more)"), said


def test_a_function_error_is_located_at_its_call_in_the_mapping(monkeypatch):
    """The IK's refusal of a 2-joint arm ('needs 6 or more') named no place: `cotwin run` printed
    'error: inverse_kinematics: ...' without the mapping's file and line. It is placed at the call."""
    from conftest import EXAMPLES

    from cotwin.mapping.runtime import FunctionRegistry

    def refuse(self, *args):
        raise CotwinError("inverse_kinematics: the arm has 2 moving joint(s); needs 6 or more")

    monkeypatch.setattr(FunctionRegistry, "reachable", refuse)
    twin = load(EXAMPLES / "ur5e" / "cotwin.toml").models
    for compiled in (True, False):
        mapping = _mapping(twin, compiled)
        mapping.start_mapping()
        with pytest.raises(CotwinError) as err:
            mapping.execute_operation("movediscrete", {"target_X": 1, "target_Y": 20, "target_Z": 2})
        [finding] = err.value.findings
        assert finding.location.path.endswith("mapping.pm") and finding.location.line > 0, str(err.value)
        assert "needs 6 or more" in finding.message


def test_dollar_names_a_value_and_its_field_in_a_mapping(tmp_path):
    """RoboSim's SimRefExp on a name with a value: `$v` is v, `$p.f` p's field f (its scope reads the name after
    '.' among the fields of p's type). cotwin refused `$p.f` ("write 'p.f'") and could not evaluate `$v` in a
    mapping; the example's mapping written with them runs as written without, in both forms."""
    import shutil

    from conftest import EXAMPLES

    shutil.copytree(EXAMPLES / "ur5e", tmp_path / "ur5e")
    mapping_file = tmp_path / "ur5e" / "mapping.pm"
    text = mapping_file.read_text()
    for old, new in [("enumeration Motion {", "datatype Pt { x: real y: real }\n\nenumeration Motion {"),
                     ("\tconst HOLE_DIST: real = 0.05\n", "\tconst HOLE_DIST: real = 0.05\n\tconst P0: Pt = "
                      "Pt(|x = 0.05, y = 0.2|)\n\tvar probe: real = $P0.y + $HOLE_DIST\n"),
                     ("(target_Y + 1) * HOLE_DIST", "($target_Y + 1) * $P0.x")]:
        assert old in text
        text = text.replace(old, new)
    mapping_file.write_text(text)
    written = load(tmp_path / "ur5e" / "cotwin.toml").models
    plain = load(EXAMPLES / "ur5e" / "cotwin.toml").models
    runs = [_run(_mapping(twin, compiled)) for twin in (written, plain) for compiled in (True, False)]
    for _, variables in runs[0] + runs[1]:
        assert variables.pop("probe") == pytest.approx(0.25) and variables.pop("P0") == {"x": 0.05, "y": 0.2}
    assert runs[0] == runs[1] == runs[2] == runs[3]
