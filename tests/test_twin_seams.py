"""The twin runtime's seams (issue 20): an endpoint kind registered from outside the core and named by a
project, the live twin's observers (started, each step, alarms, ended), and the background-service base
every threaded service uses (a failure on its thread reaches the caller; one never ready is a clear
timeout)."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.service import BackgroundService
from cotwin.twin.assembly.endpoints import EndpointKind, endpoint_kinds, register_endpoint
from cotwin.twin.assembly.observing import TwinObserver
from cotwin.twin.assembly.run import load
from cotwin.twin.live.runtime import LiveTwin

ROOT = Path(__file__).resolve().parents[1]
UR5E = ROOT / "examples" / "ur5e"


def project_with_pt(folder: Path, pt: str) -> Path:
    """The UR5e example's project (its files by absolute path) with this [pt] table."""
    text = (UR5E / "cotwin.toml").read_text()
    for name in ("arm.rst", "ur5e.pm", "mapping.pm", "plan.csv", "ur.profile.toml"):
        text = text.replace(f'"{name}"', json.dumps(str(UR5E / name)))
    path = folder / "custom.toml"
    path.write_text(text + f"\n{pt}\n")
    return path


class CountingEndpoint(SimulatedEndpoint):
    """A PT kind no core module knows: the embedded simulator, counting its steps and closing."""

    made: list["CountingEndpoint"] = []

    def __init__(self, system, settings):
        super().__init__(PlatformSimulator(system.models.tree, system.models.scene))
        self.queue = settings.queue
        self.advanced = 0
        self.closed = False
        CountingEndpoint.made.append(self)

    def advance(self, dt: float) -> None:
        self.advanced += 1
        super().advance(dt)

    def close(self) -> None:
        self.closed = True


class Recorder(TwinObserver):
    """Every callback a live twin makes, in order."""

    def __init__(self):
        self.calls: list[tuple] = []

    def twin_started(self, twin) -> None:
        self.calls.append(("started", twin.steps, twin.time))

    def twin_step(self, twin, k: int, t: float) -> None:
        self.calls.append(("step", k, round(t, 9)))

    def twin_alarm(self, twin, event: dict) -> None:
        self.calls.append(("alarm", event["state"], event["variable"]))

    def twin_ended(self, twin, status: str) -> None:
        self.calls.append(("ended", status, twin.message))


def test_an_endpoint_kind_registered_outside_the_core_is_used_by_a_project_and_observers_see_the_run(tmp_path):
    register_endpoint(EndpointKind("counting-sim", CountingEndpoint, ("pt",), "a test's PT"))
    try:
        project = project_with_pt(tmp_path, '[pt]\nendpoint = "counting-sim"\nqueue = "robot.7"')
        system = load(project)
        recorder = Recorder()
        CountingEndpoint.made.clear()
        result = LiveTwin(system, tmp_path / "out", end=1.0, observers=[recorder]).run()
    finally:
        from cotwin.twin.assembly import endpoints

        endpoints._KINDS.pop("counting-sim", None)
    assert "counting-sim" not in endpoint_kinds()
    made = CountingEndpoint.made
    assert len(made) == 1 and made[0].queue == "robot.7"  # built from the project's [pt] table
    assert made[0].advanced == 10 and made[0].closed  # stepped as the PT, closed when the run ended
    assert result.pt.steps == result.dt.steps == 10
    assert json.loads((tmp_path / "out" / "deviation.json").read_text())["pt"] == "counting-sim"
    calls = recorder.calls
    assert calls[0] == ("started", 0, 0.0)
    assert [c for c in calls if c[0] == "step"] == [("step", k, round(0.1 * k, 9)) for k in range(1, 11)]
    assert calls[-1] == ("ended", "done", None)


def test_a_registered_kind_says_which_pt_keys_it_takes(tmp_path):
    register_endpoint(EndpointKind("queue-only", CountingEndpoint, ("pt",), "a test's PT", keys=("queue",)))
    try:
        project = project_with_pt(tmp_path, '[pt]\nendpoint = "queue-only"\nqueue = "q"\nurl = "opc.tcp://h:1"')
        system = load(project)
        with pytest.raises(CotwinError) as err:
            LiveTwin(system, tmp_path / "out", end=1.0).run()
    finally:
        from cotwin.twin.assembly import endpoints

        endpoints._KINDS.pop("queue-only", None)
    (finding,) = err.value.findings
    assert finding.message == "[pt] url does not apply to endpoint 'queue-only' (it takes queue)"
    assert finding.location.line == project.read_text().splitlines().index('url = "opc.tcp://h:1"') + 1
    assert not (tmp_path / "out" / "dmodel.fmu").exists()  # said before the d-model was built


def test_an_unknown_endpoint_kind_is_a_located_error_listing_the_known_ones(tmp_path):
    system = load(project_with_pt(tmp_path, '[pt]\nendpoint = "carrier-pigeon"'))
    with pytest.raises(CotwinError) as err:
        LiveTwin(system, tmp_path / "out", end=1.0).run()
    finding = err.value.findings[0]
    assert finding.location.path.endswith("custom.toml") and finding.location.line > 1
    assert "'carrier-pigeon'" in finding.message
    for known in ("broker", "opcua", "replay", "rtde"):
        assert known in finding.message
    assert not (tmp_path / "out" / "dmodel.fmu").exists()  # said before the d-model was built


def test_an_observer_hears_of_alarms_and_of_a_run_that_fails(tmp_path):
    from cotwin.mapping.perturbed import PerturbedEndpoint
    from cotwin.pmodel.perturbation import Perturbation

    system = load(UR5E / "cotwin.toml")
    pt = PerturbedEndpoint.build(system.models.tree, system.models.scene,
                                 Perturbation(payload=2.0, latency_ms=200, seed=3))
    recorder = Recorder()

    class Failing(TwinObserver):
        def twin_step(self, twin, k, t):
            if k == 70:
                raise CotwinError("observer gave up")

    with pytest.raises(CotwinError, match="observer gave up"):
        LiveTwin(system, tmp_path, pt=pt, end=8.0, observers=[recorder, Failing()]).run()
    alarms = [c for c in recorder.calls if c[0] == "alarm"]
    assert alarms and alarms[0][1] == "raised"  # the perturbed PT deviates before step 70
    assert recorder.calls[-1] == ("ended", "failed", "observer gave up")
    report = json.loads((tmp_path / "deviation.json").read_text())  # the deviation service ended too
    assert report["steps"] == 70 and sum(len(v["alarms"]) for v in report["variables"].values()) >= 1


class Failing(BackgroundService):
    def __init__(self, when: str):
        super().__init__("test service")
        self.when = when

    def serve(self) -> None:
        if self.when == "before":
            raise OSError("port taken")
        self.ready()
        self.stopping.wait(0.05)
        raise ValueError("the link broke")


class Sleepy(BackgroundService):
    def serve(self) -> None:
        self.stopping.wait()  # never says it is ready


def test_a_background_service_failing_on_its_thread_reports_it_to_the_caller():
    with pytest.raises(CotwinError, match="test service: OSError: port taken"):
        Failing("before").start(timeout=5)
    service = Failing("after").start(timeout=5)
    assert service.is_ready
    deadline = time.monotonic() + 5
    while service.running and time.monotonic() < deadline:
        time.sleep(0.01)
    with pytest.raises(CotwinError, match="test service: ValueError: the link broke"):
        service.check()
    assert service.stop()


def test_a_background_service_never_ready_is_a_clear_timeout_and_is_stopped():
    service = Sleepy("sleepy service")
    before = threading.active_count()
    started = time.monotonic()
    with pytest.raises(CotwinError, match=r"sleepy service did not become ready within 0.3 s"):
        service.start(timeout=0.3)
    assert 0.3 <= time.monotonic() - started < 3
    assert not service.started and threading.active_count() == before  # its thread was stopped and joined


PUBLISHED_TURTLEBOT = ROOT / "examples" / "turtlebot" / "published.toml"


def test_a_robot_profile_gives_the_scanner_a_p_model_leaves_out(tmp_path):
    from cotwin.mapping.profile import profile_rays
    from cotwin.pmodel.kinds import RAY_DEFAULTS

    if not (ROOT.parent / "shared" / "robosim" / "mobile" / "Turtlebot3_Burger.pm").is_file():
        pytest.skip("RoboTool's published TurtleBot is not in ../shared/robosim/mobile (only in the workspace)")
    system = load(PUBLISHED_TURTLEBOT)  # names turtlebot.profile.toml: the LDS-01
    (lidar,) = [s.ray for s in system.models.tree.sensors if s.ray is not None][:1]
    assert (lidar.samples, lidar.range_min, lidar.range_max, lidar.update_rate) == (360, 0.12, 3.5, 5.0)
    bare = tmp_path / "bare.profile.toml"
    bare.write_text('joint_offsets = []\n[lidar]\nrange_max = 8.0\n')
    rays = profile_rays(bare)  # what it leaves out comes from the generic default, not a robot's
    assert rays["lidar"].range_max == 8.0 and rays["lidar"].range_min == RAY_DEFAULTS["lidar"].range_min
    assert RAY_DEFAULTS["lidar"] != rays["lidar"] and "sonar" not in rays


def test_a_profile_scanner_table_is_checked_at_its_keys(tmp_path):
    from cotwin.mapping.profile import profile_rays, read_profile

    path = tmp_path / "bad.profile.toml"
    path.write_text('joint_offsets = []\n[lidar]\nsamples = 0\nrange_max = 3.5\nbeams = 4\n[sonar]\nrange_min = 5.0\n'
                    'range_max = 4.0\n')
    with pytest.raises(CotwinError) as err:
        profile_rays(path)
    said = [(f.location.line, f.message) for f in err.value.findings]
    assert (3, "[lidar] samples: must be a finite number (a whole number >= 1), got 0") in said
    assert (5, "[lidar] beams: unknown key (it takes samples, min_angle, max_angle, range_min, range_max, "
               "update_rate)") in said
    assert any(line == 6 and "range_min 5 m is not below range_max 4 m" in m for line, m in said)
    assert read_profile(path).name == "bad.profile.toml"  # the joints' convention reads past the scanner tables


def test_a_loop_thread_runs_coroutines_until_stopped_then_closes_its_loop():
    import asyncio

    from cotwin.service import LoopThread

    thread = LoopThread("test loop").start(timeout=5)

    async def double(x):
        await asyncio.sleep(0.01)
        return 2 * x

    assert asyncio.run_coroutine_threadsafe(double(21), thread.loop).result(5) == 42
    assert thread.stop(5) and thread.loop.is_closed() and not thread.started
