"""The fleet command asks its Fleet whether a stop was requested through Fleet.stop_requested: it read the private
`runner._stop` (as the live command once read LiveTwin's, tests/test_live_twin.py). Neither test starts Ray or a
twin: a Fleet is built and stopped, never run."""

from __future__ import annotations

import ast
from pathlib import Path

from cotwin.twin.analysis.fleet.spec import FleetSpec
from cotwin.twin.analysis.fleet.supervisor import Fleet

SRC = Path(__file__).resolve().parents[1] / "src" / "cotwin"


def test_a_fleet_says_whether_a_stop_was_requested(tmp_path):
    fleet = Fleet(FleetSpec(tmp_path / "fleet.toml", "empty", ()), tmp_path / "out", ray=None)
    assert fleet.stop_requested is False
    fleet.stop()
    assert fleet.stop_requested is True


def test_nothing_outside_the_supervisor_reads_a_fleets_private_state():
    """Every name bound to a Fleet(...) outside cotwin.twin.analysis.fleet.supervisor is read through public
    attributes only, so that the supervisor may change its own."""
    supervisor = SRC / "twin" / "analysis" / "fleet" / "supervisor.py"
    found, fleets = [], 0
    for path in sorted(SRC.rglob("*.py")):
        if path == supervisor:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = {target.id for node in ast.walk(tree) if isinstance(node, ast.Assign)
                 and isinstance(node.value, ast.Call) and isinstance(node.value.func, ast.Name)
                 and node.value.func.id == "Fleet" for target in node.targets if isinstance(target, ast.Name)}
        fleets += len(names)
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__") \
                    and isinstance(node.value, ast.Name) and node.value.id in names:
                found.append(f"{path.relative_to(SRC)}:{node.lineno}: {ast.unparse(node)}")
    assert fleets >= 1  # the fleet command's runner is scanned
    assert not found, found
