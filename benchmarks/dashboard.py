"""The live dashboard's cost and reach, with its peer (the same twin without a dashboard) measured in the
same run:
- real-time factor of the PT+DT live twin and of one twin without pacing, dashboard off vs on (no
  client; a consuming websocket client; a stalled client that never reads; Debian's headless Chromium
  showing the page), interleaved and repeated, median ratio on/off (goal: the dashboard costs < 5 %);
  wall-clock ratios move with whatever else the (2-core) machine runs, so the direct cost is printed
  too: the feed's time in the twin's thread per step and the server thread's CPU, against the twin's CPU;
- page load on loopback: navigation to the page built, and to the first 3D frame (goal: < 1 s);
- a 100 Hz stream (step 0.01 s, paced): samples the page received and drew vs samples the twin made,
  and whether the paced twin kept to real time.
"""

from __future__ import annotations

import asyncio
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.mapping.endpoint import SimulatedEndpoint  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from cotwin.twin.services.dashboard import Dashboard  # noqa: E402
from cotwin.twin.assembly.run import load, run_twin  # noqa: E402
from cotwin.twin.live.runtime import LiveTwin  # noqa: E402
from figures import figure, goal  # noqa: E402

CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"]
PROJECT = ROOT / "examples" / "ur5e" / "cotwin.toml"


class Reader:
    """A websocket client on its own thread: consuming every message, or (stalled) connecting with a
    one-message buffer and never reading, so the server's sends back up."""

    def __init__(self, url: str, stalled: bool = False):
        self.url = url.replace("http", "ws") + "ws"
        self.stalled = stalled
        self.messages = 0
        self.connected = threading.Event()
        self.done = threading.Event()
        self.ws = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        self.connected.wait(10)

    def _run(self) -> None:
        from websockets.sync.client import connect

        try:
            with connect(self.url, max_queue=1 if self.stalled else 64) as ws:
                self.ws = ws
                self.connected.set()
                if self.stalled:
                    self.done.wait()
                    return
                for _ in ws:
                    self.messages += 1
        except Exception:  # noqa: BLE001 - closed by the server at the end
            pass

    def close(self) -> None:
        self.done.set()
        if self.ws is not None:
            self.ws.close()
        self.thread.join(5)


def browser():
    if not CHROMIUM.is_file():
        return None, None
    from playwright.sync_api import sync_playwright

    p = sync_playwright().start()
    return p, p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)


def server_cpu(dash: Dashboard | None) -> float:
    """CPU seconds the dashboard's server thread has used (asked on its own event loop)."""
    if dash is None:
        return 0.0

    async def now() -> float:
        return time.thread_time()

    return asyncio.run_coroutine_threadsafe(now(), dash._server.servers[0].get_loop()).result(5)


def one_run(kind: str, variant: str, step: float, end: float, chromium) -> dict:
    """One unpaced run (`twin`: PT+DT lockstep; `run`: one twin) with the dashboard `variant` (off |
    server | client | stalled | browser): its real-time factor, the CPU seconds per simulated second of
    the twin's thread and of the server's thread, and the time the feed took in the twin's thread."""
    system = load(PROJECT)
    with tempfile.TemporaryDirectory() as tmp:
        dash = None
        reader = page = None
        capture = [0.0]
        if variant != "off":
            dash = Dashboard(system, port=0, mode=kind).start()
            original = dash.feed._capture

            def timed(t, original=original):
                started = time.perf_counter()
                original(t)
                capture[0] += time.perf_counter() - started

            dash.feed._capture = timed
            if variant in ("client", "stalled"):
                reader = Reader(dash.url, stalled=variant == "stalled")
            if variant == "browser":
                page = chromium.new_page(viewport={"width": 1400, "height": 900})
                page.goto(dash.url)
                page.wait_for_selector("body[data-ready=true]")
        observers = [dash.feed] if dash else []
        server = server_cpu(dash)
        twin_cpu = time.thread_time()
        try:
            if kind == "twin":
                pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
                result = LiveTwin(system, tmp, pt=pt, step=step, end=end, realtime=False, observers=observers).run().pt
            else:
                result = run_twin(system, tmp, step=step, end=end, realtime=False, observers=observers, plot=False).result
            twin_cpu = time.thread_time() - twin_cpu
            server = server_cpu(dash) - server
        finally:
            if page is not None:
                page.close()
            if reader is not None:
                reader.close()
            if dash is not None:
                dash.stop()
        return {"rtf": result.real_time_factor, "twin": twin_cpu / end, "server": server / end,
                "capture": capture[0] / max(result.steps, 1), "step": result.wall_seconds / max(result.steps, 1)}


def overhead(chromium, repeats: int = 5) -> None:
    variants = ["off", "server", "client", "stalled"] + (["browser"] if chromium else [])
    for kind, step, end in (("twin", 0.01, 6.0), ("twin", 0.1, 20.0), ("run", 0.01, 10.0)):
        one_run(kind, "off", step, min(end, 2.0), chromium)  # warm caches (FMU build, imports)
        runs: dict[str, list[dict]] = {v: [] for v in variants}
        for _ in range(repeats):
            for v in variants:  # interleaved, so drift of the machine's load hits all alike
                runs[v].append(one_run(kind, v, step, end, chromium))

        def med(v, key):
            return statistics.median(r[key] for r in runs[v])

        base = med("off", "rtf")
        label = "PT+DT live twin" if kind == "twin" else "one twin (cotwin run)"
        print(f"{label}, step {step:g} s ({1 / step:.0f} Hz samples), {end:g} s, no pacing, median of {repeats}:")
        for v in variants:
            line = (f"  dashboard {v:<8} real-time factor {med(v, 'rtf'):6.1f}x  ratio to off {med(v, 'rtf') / base:5.3f} "
                    f"(cost {100 * (1 - med(v, 'rtf') / base):+5.1f} %)")
            figure(f"{label}, step {step:g} s, dashboard {v}: real-time factor", med(v, "rtf"), "x",
                   peer="dashboard off", peer_value=base)
            if v != "off":
                direct = (med(v, "capture") * end / step + med(v, "server") * end) / (med(v, "twin") * end)
                figure(f"{label}, step {step:g} s, dashboard {v}: direct cost", 100 * direct, "% of the twin's CPU")
                line += (f"; feed {1e6 * med(v, 'capture'):4.1f} us of a {1e6 * med(v, 'step'):6.0f} us step, "
                         f"server thread {1000 * med(v, 'server'):5.1f} ms CPU per simulated s: direct cost "
                         f"{100 * direct:4.1f} % of the twin's CPU "
                         f"({goal(f'dashboard {v} direct cost, {label}, step {step:g} s', 100 * direct, 5.0, at_most=True, unit=' %')})")
            print(line)


def page_load(chromium, loads: int = 5) -> None:
    system = load(PROJECT)
    with Dashboard(system, port=0, mode="run") as dash:
        ready, first3d = [], []
        for _ in range(loads):
            page = chromium.new_page(viewport={"width": 1400, "height": 900})
            page.goto(dash.url)
            page.wait_for_function("window.cotwin.robot && window.cotwin.robot.frames > 0")
            ready.append(page.evaluate("window.cotwin.readyAt"))
            first3d.append(page.evaluate("window.cotwin.robot.firstFrameAt"))
            page.close()
    figure("page load: first 3D frame, median", statistics.median(first3d), "ms", page_built_ms=statistics.median(ready),
           loads=loads)
    print(f"page load on loopback over {loads} loads (ms from navigation start): page built median "
          f"{statistics.median(ready):.0f} (max {max(ready):.0f}), first 3D frame median {statistics.median(first3d):.0f} "
          f"(max {max(first3d):.0f}); {goal('page load to the first 3D frame, median', statistics.median(first3d), 1000, at_most=True, unit=' ms')} (< 1000)")


def stream(chromium, step: float = 0.01, end: float = 10.0) -> None:
    """A paced live twin at 100 Hz with the page open: what the page got and drew."""
    system = load(PROJECT)
    with tempfile.TemporaryDirectory() as tmp, Dashboard(system, port=0, mode="twin") as dash:
        page = chromium.new_page(viewport={"width": 1400, "height": 900})
        page.goto(dash.url)
        page.wait_for_selector("body[data-ready=true]")
        frames0 = page.evaluate("[window.cotwin.live.plot.frames, window.cotwin.robot ? window.cotwin.robot.frames : 0]")
        pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
        started = time.perf_counter()
        result = LiveTwin(system, tmp, pt=pt, step=step, end=end, realtime=True, observers=[dash.feed]).run()
        wall = time.perf_counter() - started
        time.sleep(0.3)
        got = page.evaluate("({samples: window.cotwin.samples, skipped: window.cotwin.skipped, "
                            "plot: window.cotwin.live.plot.frames, robot: window.cotwin.robot ? window.cotwin.robot.frames : 0})")
        page.close()
        made = dash.feed.samples.count
    print(f"100 Hz stream (step {step:g} s, paced, {end:g} s, PT+DT): the twin made {made} samples in {wall:.2f} s "
          f"(real-time factor {result.pt.real_time_factor:.3f}); the page received {got['samples']} "
          f"({100 * got['samples'] / made:.1f} %), skipped {got['skipped']}, drew {got['plot'] - frames0[0]} plot frames "
          f"and {got['robot'] - frames0[1]} 3D frames ({(got['plot'] - frames0[0]) / wall:.1f} and "
          f"{(got['robot'] - frames0[1]) / wall:.1f} per s)")


def main() -> None:
    p, chromium = browser()
    try:
        if chromium is None:
            print(f"no Debian chromium at {CHROMIUM}: browser figures not measured")
            goal("page load to the first 3D frame (no chromium)", None, 1000, at_most=True, unit=" ms")
        else:
            page_load(chromium)
            stream(chromium)
        overhead(chromium)
    finally:
        if chromium is not None:
            chromium.close()
            p.stop()


if __name__ == "__main__":
    main()
