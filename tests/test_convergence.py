"""Convergence ([convergence]): the DT resynced to its PT's measured state, and the payload the DT does not
know estimated from the PT's joint torques, against the perturbed OPC UA plant."""

from __future__ import annotations

from pathlib import Path

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import retimed
from cotwin.mapping.motion import Segment
from cotwin.mapping.perturbed import PerturbedEndpoint
from cotwin.pmodel.perturbation import Perturbation
from cotwin.twin.project import load_project
from cotwin.twin.assembly.run import load

pytest.importorskip("asyncua")
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ur5e"
PAYLOAD = 0.5  # kg at the plant's tool, unknown to the DT
# the cell's controller also lags its commands (300 ms): a state the DT drifts from, which a resync removes
PLANT = Perturbation(payload=PAYLOAD, latency_ms=300, noise={"effort": 0.05, "position": 1e-4}, seed=3)


def project(folder: Path, convergence: str, end: float = 8.0) -> Path:
    """The UR5e experiment's models and plan, a deviation check that expects the DT in step (lag 1), and
    `convergence` as the [convergence] table's body."""
    path = folder / "cotwin.toml"
    path.write_text(f'[models]\ndmodel = "{EXAMPLE / "arm.rst"}"\npmodel = "{EXAMPLE / "ur5e.pm"}"\n'
                    f'mapping = "{EXAMPLE / "mapping.pm"}"\n[scenario]\nplan = "{EXAMPLE / "plan.csv"}"\n'
                    f"[cosim]\nstep = 0.1\nend = {end}\n[deviation]\nlag_steps = 1\n[convergence]\n{convergence}\n")
    return path


def test_bad_convergence_keys_are_each_reported_at_their_line(tmp_path):
    path = project(tmp_path, 'resync = "sometimes"\nestimate = "mass"\npayload_std = -1\nrest = 0.1\n')
    with pytest.raises(CotwinError) as err:
        load_project(path)
    found = {f.location.line: f.message for f in err.value.findings}
    lines = path.read_text().splitlines()
    for key, words in (("resync", '"never", "on-alarm" or "every N steps"'), ("estimate", "must be one of"),
                       ("payload_std", "positive"), ("rest", "unknown key 'rest'")):
        line = next(n for n, text in enumerate(lines, 1) if text.startswith(f"{key} ="))
        assert words in found.get(line, ""), (key, found)
    with pytest.raises(CotwinError, match="every N steps takes N in 1"):
        load_project(project(tmp_path, 'resync = "every 0 steps"'))
    assert load_project(project(tmp_path, 'resync = "every 5 steps"')).convergence.every == 5


def test_a_resynced_move_continues_from_the_measured_state():
    move = Segment({"a": 0.0, "b": 1.0}, {"a": 1.0, "b": -1.0}, t0=0.0, duration=2.0)
    behind = move.at(0.6)  # the PT is where the DT's set-point was 0.4 s ago
    later = retimed(move, behind, now=1.0)
    assert later.goal == move.goal and later.duration == move.duration
    assert later.at(1.0) == pytest.approx(behind, abs=1e-9)
    assert later.t0 == pytest.approx(0.4, abs=1e-9)
    waiting = Segment({"a": 0.0}, {"a": 1.0}, t0=5.0, duration=1.0)  # not begun on either side: kept
    assert retimed(waiting, {"a": 0.0}, now=1.0) is waiting


@pytest.fixture(scope="module")
def against_plant(tmp_path_factory):
    """One 8 s live twin per resync setting, each against its own perturbed plant over OPC UA (payload
    estimated in both): resync -> (result, history rows of corrections)."""
    from cotwin.mapping.opcua import OPCUAEndpoint
    from cotwin.twin.services.history import read_run
    from cotwin.twin.services.plant import Plant
    from cotwin.twin.live.runtime import LiveTwin

    out = {}
    for resync in ("never", "on-alarm"):
        folder = tmp_path_factory.mktemp(resync)
        system = load(project(folder, f'resync = "{resync}"\nestimate = "payload"'))
        plant = Plant(PerturbedEndpoint.build(system.models.tree, system.models.scene, PLANT), "opc.tcp://127.0.0.1:0")
        plant.start()
        try:
            with OPCUAEndpoint(system.models.tree, plant.url, timeout=5, reset=True) as pt:
                twin = LiveTwin(system, folder / "out", pt=pt)
                result = twin.run()
        finally:
            plant.stop()
        assert not plant.running
        rows = read_run(result.history_url, result.run_id)["corrections"]
        out[resync] = (result, rows, twin)
    return out


def _rmse(result) -> float:
    """The mean over the joints of the raw PT - DT position RMSE (rad)."""
    values = [v["rmse"] for name, v in result.deviation["variables"].items() if name.startswith("q") and
              not name.startswith("qd")]
    return sum(values) / len(values)


def test_resync_on_alarm_keeps_the_dt_closer_to_the_perturbed_plant(against_plant):
    never, _, _ = against_plant["never"]
    on_alarm, rows, _ = against_plant["on-alarm"]
    assert never.deviation["convergence"]["resyncs"] == 0 and never.deviation["alarms"] > 0
    resyncs = [e for e in on_alarm.convergence["corrections"] if e["kind"] == "resync"]
    assert resyncs and all(e["reason"].startswith("alarm: ") for e in resyncs)
    assert max(e["size"] for e in resyncs) > 0.05  # rad: the DT had drifted beyond the alarm threshold
    assert _rmse(on_alarm) < 0.5 * _rmse(never), (_rmse(on_alarm), _rmse(never))
    stored = [r for r in rows if r["kind"] == "resync"]  # each resync is in the history, with its reason and size
    assert [(r["time"], r["reason"]) for r in stored] == [(e["time"], e["reason"]) for e in resyncs]
    assert [r["size"] for r in stored] == pytest.approx([e["size"] for e in resyncs])


def test_the_payload_is_estimated_from_the_plants_torques_and_applied_to_the_dt(against_plant):
    result, rows, twin = against_plant["never"]
    payload = result.deviation["convergence"]["payload"]
    error = abs(payload["estimate"] - PAYLOAD)
    assert error < 0.01 and error < 3 * payload["std"], payload  # kg: 2 % of the truth, within its uncertainty
    assert payload["std"] < 0.01 and payload["samples"] > 20
    assert abs(payload["applied"] - payload["estimate"]) <= 2 * payload["std"] + 1e-9
    estimator = twin.convergence.estimator  # the DT's payload body carries what was applied
    assert estimator.model.body_mass[estimator.body] == pytest.approx(payload["applied"])
    from cotwin.twin.assembly.convergence import summary

    assert f"payload {payload['estimate']:.4g} +- " in summary(result.convergence)  # what `cotwin twin` prints
    applied = [r for r in rows if r["kind"] == "payload"]
    assert applied and applied[-1]["size"] == pytest.approx(payload["applied"] - sum(r["size"] for r in applied[:-1]))


def test_every_n_steps_resyncs_on_schedule_and_marks_the_page(tmp_path):
    from cotwin.twin.services.dashboard.feed import DashboardFeed
    from cotwin.twin.live.runtime import LiveTwin

    system = load(project(tmp_path, 'resync = "every 10 steps"', end=3.0))
    pt = PerturbedEndpoint.build(system.models.tree, system.models.scene, PLANT)
    feed = DashboardFeed(system)
    result = LiveTwin(system, tmp_path / "out", pt=pt, observers=[feed]).run()
    times = [e["time"] for e in result.convergence["corrections"]]
    assert times == pytest.approx([1.0, 2.0, 3.0])
    marks = [e for e in feed.events if e["kind"] == "correction"]
    assert [e["correction"] for e in marks] == ["resync"] * 3 and [e["time"] for e in marks] == pytest.approx(times)


def test_the_page_marks_each_resync_on_its_plot(tmp_path):
    """The dashboard of a resyncing twin draws a marker per correction (a page opened after the run gets them
    from the feed's event ring), and lists them in the run's history."""
    chromium = Path("/usr/bin/chromium")
    if not chromium.is_file():
        pytest.skip(f"no Debian chromium at {chromium}")
    from playwright.sync_api import sync_playwright

    from cotwin.twin.services.dashboard import Dashboard
    from cotwin.twin.services.history import database_url
    from cotwin.twin.live.runtime import LiveTwin

    system = load(project(tmp_path, 'resync = "every 10 steps"', end=2.0))
    pt = PerturbedEndpoint.build(system.models.tree, system.models.scene, PLANT)
    with Dashboard(system, port=0, mode="twin", history_url=database_url(None, tmp_path / "out")) as dash:
        LiveTwin(system, tmp_path / "out", pt=pt, observers=[dash.feed]).run()
        dash.finish("done")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(chromium),
                                        args=["--headless", "--no-sandbox", "--disable-gpu"])
            try:
                page = browser.new_page()
                page.goto(dash.url)
                page.wait_for_selector("#alarms li.correction", timeout=15_000)
                markers = page.evaluate("window.cotwin.live.plot.markers.filter((m) => m.color)")
                assert [(m["time"], m["label"]) for m in markers] == [(1.0, "resync"), (2.0, "resync")]
                assert page.locator("#alarms li.correction").count() == 2
                page.click('header nav button[data-tab="history"]')  # and the run's history shows them too
                page.wait_for_selector("#runs tbody tr", timeout=5_000)
                page.click("#runs tbody tr")
                page.wait_for_selector("#run-alarms li.correction", timeout=5_000)
                assert page.locator("#run-alarms li.correction").count() == 2
                assert "every 10 steps" in page.inner_text("#run-alarms")
            finally:
                browser.close()



def test_a_saved_state_carries_the_payload_applied_to_the_dt(tmp_path):
    """A what-if fork of a DT that was given an estimated payload restores that payload with its state."""
    from cotwin.cosim.state import pack, unpack
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.twin.assembly.convergence import PayloadEstimator, effort_sensors, payload_simulator

    system = load(project(tmp_path, 'estimate = "payload"'))
    tree, scene = system.models.tree, system.models.scene
    dt = SimulatedEndpoint(payload_simulator(tree, scene))
    estimator = PayloadEstimator(dt.sim, effort_sensors(tree))
    estimator.apply(0.42)
    saved = unpack(pack("platform", dt.snapshot()), "platform")
    fork = SimulatedEndpoint(payload_simulator(tree, scene))
    fork.restore(saved)
    body = fork.sim.model.body(estimator.body)
    assert float(fork.sim.model.body_mass[body.id]) == 0.42
    assert fork.sim.changed_bodies() == dt.sim.changed_bodies()
    saved["bodies"] = {"no_such_body": [1.0, 0.0, 0.0, 0.0]}
    with pytest.raises(CotwinError, match="changes a body 'no_such_body' that this model does not have"):
        fork.restore(saved)


def test_estimating_the_payload_from_a_replayed_log_is_refused_at_its_key(tmp_path):
    from cotwin.twin.live.runtime import LiveTwin

    log = EXAMPLE.parents[1].parent / "shared" / "data" / "ur5e" / "rtde_run1.csv"
    if not log.is_file():
        pytest.skip(f"../shared is absent ({log})")
    path = project(tmp_path, 'resync = "on-alarm"\nestimate = "payload"')
    path.write_text(path.read_text() + f'[pt]\nendpoint = "replay"\nlog = "{log}"\n')
    system = load(path)
    with pytest.raises(CotwinError, match="needs a PT reporting joint torques") as err:
        LiveTwin(system, tmp_path / "out").run()
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if text.startswith("estimate ="))
    assert err.value.findings[0].location.line == line
    assert not (tmp_path / "out" / "history.sqlite").exists()  # refused before anything was built or recorded


def test_a_brick_both_twins_carry_is_not_taken_for_the_payload(tmp_path):
    """Picking a brick up: its weight is in the PT's torques and in the DT's, so it cancels (the DT's own
    torques are the reference); only the payload the DT does not know is estimated."""
    from cotwin.twin.live.runtime import LiveTwin

    path = tmp_path / "cotwin.toml"
    path.write_text(f'[models]\ndmodel = "{EXAMPLE / "arm.rst"}"\npmodel = "{EXAMPLE / "ur5e.pm"}"\n'
                    f'mapping = "{EXAMPLE / "mapping.pm"}"\n[scenario]\ncommands = "{EXAMPLE / "pick_place.toml"}"\n'
                    '[scene]\nbricks = [[8, 10]]\n[cosim]\nstep = 0.05\nend = 14.0\nalgorithm = "gauss-seidel"\n'
                    '[convergence]\nestimate = "payload"\n')
    system = load(path)
    pt = PerturbedEndpoint.build(system.models.tree, system.models.scene, Perturbation(payload=PAYLOAD))
    twin = LiveTwin(system, tmp_path / "out", pt=pt)
    result = twin.run()
    grasped = [m for t, m, _ in twin.convergence.trace if t > 12.0]  # the brick lifted at 11 s
    assert grasped and all(abs(m - PAYLOAD) < 0.01 for m in grasped), grasped[-5:]
    assert abs(result.convergence["payload"]["applied"] - PAYLOAD) < 0.01


def test_a_dt_behind_the_broker_cannot_be_corrected(tmp_path):
    from cotwin.twin.live.runtime import LiveTwin

    path = project(tmp_path, 'resync = "on-alarm"')
    path.write_text(path.read_text().replace("[cosim]", '[platform]\nendpoint = "broker"\n[cosim]'))
    with pytest.raises(CotwinError, match=r"not a robot behind the broker") as err:
        LiveTwin(load(path), tmp_path / "out").run()
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if text == "[convergence]")
    assert err.value.findings[0].location.line == line
