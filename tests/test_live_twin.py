"""The live twin: deviation checking, a PT replaying the real UR5e's log beside the DT, and the history
store in SQLite and in PostgreSQL."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from cotwin.twin.services.deviation import DeviationMonitor
from cotwin.twin.services.history import database_url, export_csv, list_runs, read_run
from cotwin.twin.assembly.run import load
from cotwin.twin.live.runtime import LiveTwin

ROOT = Path(__file__).resolve().parents[1]
RTDE_LOG = ROOT.parent / "shared" / "data" / "ur5e" / "rtde_run1.csv"


def test_deviation_is_symmetric_in_sign_tolerates_lag_and_is_debounced():
    monitor = DeviationMonitor(["q"], absolute=0.1, relative=0.0, lag_steps=2, debounce_steps=2)
    ramp = [0.0, -0.2, -0.4, -0.6, -0.8, -1.0, -1.0, -1.0, -1.0]
    for k, p in enumerate(ramp):  # the DT follows the same ramp two steps late: not deviating
        monitor.observe(k * 0.1, {"q": p}, {"q": ramp[max(0, k - 2)]})
    assert monitor.events == [] and monitor.report()["variables"]["q"]["max_deviation"] == 0.0
    monitor = DeviationMonitor(["q"], absolute=0.1, relative=0.0, lag_steps=0, debounce_steps=2)
    for k, p in enumerate([-1.0, -1.3, -1.0, -1.3, -1.3, -1.3, -1.0, -1.0, -1.0]):  # negative angles
        monitor.observe(k * 0.1, {"q": p}, {"q": -1.0})
    states = [(e["state"], round(e["time"], 1)) for e in monitor.events]
    assert states == [("raised", 0.4), ("cleared", 0.7)]  # one-step blips do not alarm
    alarm = monitor.report()["variables"]["q"]["alarms"][0]
    assert alarm["first_deviating"] == pytest.approx(0.3) and alarm["peak"] == pytest.approx(0.3)
    relative = DeviationMonitor(["q"], absolute=0.0, relative=0.1, lag_steps=0, debounce_steps=1)
    relative.observe(0.0, {"q": -2.0}, {"q": -2.15})  # within 10 % of |-2|
    relative.observe(0.1, {"q": -2.0}, {"q": -2.3})
    assert [e["state"] for e in relative.events] == ["raised"]
    assert monitor.report()["variables"]["q"]["rmse"] == pytest.approx((4 * 0.09 / 9) ** 0.5)


@pytest.fixture
def recorded() -> Path:
    if not RTDE_LOG.is_file():
        pytest.skip(f"the real UR5e's recorded log is not at {RTDE_LOG} (only in the project workspace)")
    return RTDE_LOG


def test_replayed_pt_beside_the_dt_gives_a_deviation_report(recorded, tmp_path):
    from conftest import EXAMPLES

    system = load(EXAMPLES / "ur5e" / "replay.toml")
    system.spec.pt = type(system.spec.pt)("replay", log=recorded)
    result = LiveTwin(system, tmp_path, end=12.0).run()
    assert result.pt.steps == result.dt.steps == 120
    pt = list(csv.DictReader(open(tmp_path / "pt" / "outputs.csv")))
    dt = list(csv.DictReader(open(tmp_path / "dt" / "outputs.csv")))
    assert len(pt) == len(dt) == 121
    command = "{controller}.controller.moveDiscreteCommand"
    assert [r["time"] for r in pt if r[command] == "true"] == [r["time"] for r in dt if r[command] == "true"]
    report = json.loads((tmp_path / "deviation.json").read_text())
    assert set(report["variables"]) == {f"q{i}" for i in range(6)} and report["steps"] == 120
    # the report's figures recomputed from the two CSVs by the documented definition (twin/deviation.py):
    # RMSE of PT - DT over the steps, and the deviation aligned over time shifts of up to lag_steps
    lag = report["settings"]["lag_steps"]
    for i in range(6):
        column = f"{{mapping}}.mapping.q{i}"
        p = [float(r[column]) for r in pt[1:]]
        d = [float(r[column]) for r in dt[1:]]
        aligned = [min(min(abs(p[k] - x) for x in d[max(0, k - lag):k + 1]),
                       min(abs(d[k] - x) for x in p[max(0, k - lag):k + 1])) for k in range(len(p))]
        figures = report["variables"][f"q{i}"]
        assert figures["samples"] == 120
        assert figures["rmse"] == pytest.approx((sum((a - b) ** 2 for a, b in zip(p, d)) / len(p)) ** 0.5, rel=1e-9)
        assert figures["max_deviation"] == pytest.approx(max(aligned), abs=1e-12)
        assert figures["max_deviation_time"] == pytest.approx(float(pt[1 + aligned.index(max(aligned))]["time"]))
    assert report["variables"]["q0"]["rmse"] > 1e-3  # the twins do differ: the check above is not 0 == 0
    # the PT is the recording: its joints at rest equal the log's first sample in the p-model convention
    from conftest import EXAMPLES
    from cotwin.mapping.profile import read_profile
    from cotwin.mapping.replay import read_rtde_log

    log = read_rtde_log(recorded, [f"j{i}" for i in range(6)], read_profile(EXAMPLES / "ur5e" / "ur.profile.toml"))
    assert float(pt[0]["{mapping}.mapping.q1"]) == pytest.approx(log.q[0, 1], abs=1e-9)
    assert float(dt[0]["{mapping}.mapping.q1"]) == pytest.approx(log.q[0, 1], abs=1e-3)  # the DT starts there too
    assert (tmp_path / "figure.png").stat().st_size > 10_000
    runs = list_runs(result.history_url)
    assert runs[-1]["samples"] == 2 * 121 and runs[-1]["status"] == "done"


@pytest.fixture
def postgres(postgres_database):
    """A fresh database on the loopback PostgreSQL, dropped afterwards (conftest.postgres_database)."""
    return postgres_database[0]


def test_history_in_sqlite_and_postgresql_has_the_same_content_and_round_trips(postgres, tmp_path):
    from conftest import EXAMPLES

    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.pmodel.simulator import PlatformSimulator

    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    contents = {}
    for name, url in (("sqlite", None), ("postgresql", postgres)):
        out = tmp_path / name
        pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
        result = LiveTwin(system, out, pt=pt, end=4.0, history_url=url).run()
        data = read_run(result.history_url, result.run_id)
        contents[name] = (data["columns"], data["samples"], [(c["step"], c["port"], c["value"]) for c in data["commands"]],
                          [(s["side"], s["step"], s["name"]) for s in data["states"]])
        for side in ("pt", "dt"):  # the store gives back exactly what the run wrote
            exported = export_csv(result.history_url, result.run_id, side, out / f"{side}.csv")
            assert exported.read_text() == (out / side / "outputs.csv").read_text()
    assert contents["sqlite"] == contents["postgresql"]
    columns, samples, commands, states = contents["sqlite"]
    assert len(samples["pt"]) == len(samples["dt"]) == 41
    assert ("moveDiscreteCommand" in {c[1] for c in commands}) and any(s[2] == "Idle" for s in states)
    proc = subprocess.run([sys.executable, "-m", "cotwin", "history", "list", "--db", postgres],
                          capture_output=True, text=True)
    assert proc.returncode == 0 and "twin  done" in proc.stdout and "82 samples" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "cotwin", "history", "export", "7", "--db", postgres, "-o",
                           str(tmp_path / "x.csv")], capture_output=True, text=True)
    assert proc.returncode == 1 and "no run 7" in proc.stderr and "Traceback" not in proc.stderr
    assert database_url("postgresql://u@h/db").startswith("postgresql+psycopg://")


def test_rtde_field_mapping_agrees_with_the_logs_own_tcp_poses(recorded):
    """The RTDE endpoint's field mapping (UR joint angles -> p-model joints) checked against the recorded
    log's columns: through our kinematics, the robot's reported TCP must sit at one fixed point of the
    flange frame over the whole run (a wrong offset or sign would make it wander), and the replay
    endpoint reads exactly what the mapping gives."""
    import numpy as np

    from conftest import EXAMPLES
    from cotwin.mapping.profile import read_profile
    from cotwin.mapping.replay import ReplayEndpoint, read_rtde_log
    from cotwin.mapping.rtde import read_rtde
    from cotwin.mapping.urrtde import fields_to_state
    from cotwin.pmodel import ik

    tree = load(EXAMPLES / "ur5e" / "cotwin.toml").models.tree
    arm = ik.arm_joints(tree, ik.find_tool(tree))
    flange = next(j.child for j in tree.joints if j.name == arm[-1])
    log = read_rtde(recorded)
    ur = read_profile(EXAMPLES / "ur5e" / "ur.profile.toml", len(arm))
    replay = ReplayEndpoint(tree, read_rtde_log(recorded, arm, ur), offset=0.0)
    in_flange = []
    for i in range(0, len(log.data), 7):
        row = dict(zip(log.columns, log.data[i]))
        q, qd = fields_to_state(row, arm, ur)
        tcp_ur = np.array([row[f"actual_TCP_pose_{k}"] for k in range(3)])
        tcp = np.array([-tcp_ur[0], -tcp_ur[1], tcp_ur[2], 1.0])  # the UR base frame turned by pi about z
        in_flange.append((np.linalg.inv(tree.forward(q)[flange]) @ tcp)[:3])
        replay.time = row["timestamp"]
        assert all(replay.joint_positions()[j] == pytest.approx(v, abs=1e-12) for j, v in q.items())
    spread = np.ptp(np.array(in_flange), axis=0)
    # one rigid tool point, to 6 mm: a real arm's kinematics differ from the nominal model by millimetres;
    # a wrong joint offset or sign would move the point by tens of centimetres
    assert np.all(spread < 0.006), spread


def test_the_runs_history_is_read_through_the_live_twins_public_accessors(tmp_path):
    """A fleet's host and the CLI read the run's history id, its store's problem and a stop request through
    LiveTwin.run_id, .history_problem and .stop_requested (they read its private _history and _stop)."""
    from conftest import EXAMPLES
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.analysis.fleet.host import _history_problem

    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    live = LiveTwin(system, tmp_path, pt=SimulatedEndpoint(PlatformSimulator(system.models.tree)), end=1.0)
    assert (live.run_id, live.history_problem, live.stop_requested) == (None, None, False)  # no store opened yet
    result = live.run()
    assert live.run_id == result.run_id == list_runs(result.history_url)[-1]["id"]
    assert live.history_problem is None is result.history_problem and _history_problem(live) is None
    live.stop()
    assert live.stop_requested


def test_nothing_outside_the_live_runtime_reads_a_live_twins_private_state():
    """`live._history` and `live._stop` were read by cotwin.twin.analysis.fleet.host and cotwin.cli.live: a live
    twin's state is read through its public accessors (the test above), so that the runtime may change its own."""
    import ast

    src = Path(__file__).resolve().parents[1] / "src" / "cotwin"
    runtime = src / "twin" / "live" / "runtime.py"
    found = []
    for path in sorted(src.rglob("*.py")):
        if path == runtime:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                base = node.value
                named = base.id if isinstance(base, ast.Name) else base.attr if isinstance(base, ast.Attribute) else ""
                if named == "live":
                    found.append(f"{path.relative_to(src)}:{node.lineno}: {ast.unparse(node)}")
    assert not found, found
