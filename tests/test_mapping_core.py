"""The mapping runtime on the expression core: closures compiled once give exactly what the
interpreting evaluator gives, on the example twin's mapping (every operation and input event)."""

from __future__ import annotations

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.mapping.runtime import Mapping
from cotwin.twin.run import load
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
