"""testgen's exploration stops early, with the verifier's located message, on a counter that grows without bound
(the same GrowthWatch as `cotwin verify`); it used to run to its state limit and say only "raise --max-states"."""

from __future__ import annotations

from conftest import one_machine
from cotwin.dmodel.program import build_program
from cotwin.dmodel.testgen import generate
from cotwin.dmodel.testgen_graph import explore
from cotwin.robosim.check import load_checked

TICKS = one_machine(("tick", "go"), """
	var ticks: int = 0
	initial i
	state Idle { }
	state Busy { }
	transition t0 { from i to Idle }
	transition t1 { from Idle to Busy exec condition $go }
	transition t2 { from Busy to Idle exec condition $go }
	transition t3 { from Busy to Busy exec condition $tick /\\ not $go action ticks = ticks + 1 ; $report!ticks }
	transition t4 { from Idle to Idle exec condition not $go }
	transition t5 { from Busy to Busy exec condition not $go /\\ not $tick }
""")


def test_an_unbounded_counter_stops_testgen_early_naming_it_and_where_it_steps(tmp_path):
    (tmp_path / "t.rst").write_text(TICKS)
    program = build_program(load_checked([tmp_path / "t.rst"]))
    graph = explore(program, max_states=5_000)
    assert not graph.complete and len(graph.snapshots) < 50, len(graph.snapshots)
    assert graph.unbounded.startswith("M.ticks grows without bound"), graph.unbounded
    assert f"ticks = ticks + 1 at {tmp_path / 't.rst'}:17:" in graph.unbounded, graph.unbounded
    suite = generate(graph)
    assert suite.cases and {"transition M.t1", "transition M.t2", "transition M.t3"} <= set(suite.covered)
    for _, why in suite.unreachable:
        assert "M.ticks grows without bound" in why and "raise --max-states" not in why, why


def test_a_bounded_model_is_explored_to_the_end(tmp_path):
    (tmp_path / "t.rst").write_text(TICKS.replace("ticks = ticks + 1", "ticks = (ticks + 1) % 4"))
    graph = explore(build_program(load_checked([tmp_path / "t.rst"])), max_states=5_000)
    assert graph.complete and graph.unbounded == "", graph.unbounded


def test_the_cli_summary_and_suite_json_name_the_counter(tmp_path):
    from cotwin.cli.testing import format_suite
    from cotwin.dmodel.testgen_files import write_suite

    (tmp_path / "t.rst").write_text(TICKS)
    suite = generate(explore(build_program(load_checked([tmp_path / "t.rst"]))), "transitions")
    header = format_suite(suite, 0.1, "", str(tmp_path / "s")).splitlines()[0]
    assert "(stopped: after " in header and "M.ticks grows without bound" in header, header
    assert "INCOMPLETE: a counter grows without bound" in header and "state limit" not in header, header
    write_suite(suite, tmp_path / "s", 0.1, 0)
    import json
    assert json.loads((tmp_path / "s" / "suite.json").read_text())["exploration"]["unbounded"].startswith("M.ticks")
