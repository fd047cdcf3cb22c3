"""What-if and sweeps: one what-if from a live state (wall time; peer: a straight run of the same
simulated span, both warm: FMU built, IK solutions cached, each the best of three after an untimed
one), and every hole of the plate at Z = 0 (384 what-ifs) on one process, on a local pool and on a
local Ray cluster, with the speed-up over one process (the IK cache filled first, for every runner)."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.twin.assembly.run import load, run_twin  # noqa: E402
from cotwin.twin.analysis.sweep import grid, run_sweep  # noqa: E402
from cotwin.twin.services.whatif import predict  # noqa: E402
from figures import figure  # noqa: E402

PROJECT = ROOT / "examples" / "ur5e" / "cotwin.toml"


def one_whatif(repeats: int = 3) -> None:
    system = load(PROJECT)
    with tempfile.TemporaryDirectory() as tmp:
        run_twin(system, tmp, plot=False)  # builds the FMU, fills the IK cache, leaves the state at t = 20 s
        state = (Path(tmp) / "state").read_bytes()
        forks, straights = [], []
        for k in range(repeats + 1):  # the first of each is untimed (warm-up)
            t0 = time.perf_counter()
            prediction = predict(system, system.commands, state, horizon=25.0, artefacts=tmp)
            forks.append(time.perf_counter() - t0)
            span = prediction.end - prediction.start
            t0 = time.perf_counter()
            run_twin(system, Path(tmp) / "straight", end=span, plot=False)
            straights.append(time.perf_counter() - t0)
    fork, straight = min(forks[1:]), min(straights[1:])
    figure("what-if of the paper's plan from t = 20 s", fork, "s", peer=f"straight run of the same {span:.1f} s",
           peer_value=straight, simulated_s=span)
    print(f"what-if of the paper's plan from the state at t = 20 s, warm: {fork:.2f} s for {span:.1f} s simulated "
          f"({span / fork:.0f}x real time); peer, a straight run of the same {span:.1f} s, warm: {straight:.2f} s "
          f"(what-if/straight = {fork / straight:.2f})")


def stop_ray(temp: str) -> None:
    """End the Ray head started with --temp-dir=temp by its processes' ids (`ray stop` would end every
    Ray cluster on the machine, other users' too): the processes whose command line names temp."""
    import signal

    def ours() -> list[int]:
        pids = []
        for entry in Path("/proc").iterdir():
            try:
                if entry.name.isdigit() and temp.encode() in (entry / "cmdline").read_bytes():
                    pids.append(int(entry.name))
            except OSError:
                continue
        return pids

    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in ours():
            try:
                os.kill(pid, sig)
            except OSError:
                pass
        deadline = time.monotonic() + 15
        while ours() and time.monotonic() < deadline:
            time.sleep(0.2)


def holes(z: int = 0) -> None:
    system = load(PROJECT)
    plans = grid(system.models.program, "moveDiscreteCommand",
                 {"target_X": list(range(16)), "target_Y": list(range(24)), "target_Z": [z]})
    timings = {}
    workers = os.cpu_count() or 2
    # untimed: fills the IK cache (~/.cache/cotwin or $COTWIN_CACHE) so that every runner finds it alike;
    # on a fresh machine the first runner timed would otherwise solve every hole's IK for the others
    run_sweep(PROJECT, plans, horizon=8.0, workers=workers)
    t0 = time.perf_counter()
    one = run_sweep(PROJECT, plans, horizon=8.0, workers=1)
    timings["one process"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pool = run_sweep(PROJECT, plans, horizon=8.0, workers=workers)
    timings[f"local pool ({workers})"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    threaded = run_sweep(PROJECT, plans, horizon=8.0, threads=workers)
    timings[f"one process, {workers} threads"] = time.perf_counter() - t0
    try:
        import ray  # noqa: F401
    except ImportError:
        ray_result = None
    else:
        with tempfile.TemporaryDirectory(prefix="ray", dir="/tmp") as temp:
            import socket

            with socket.socket() as s:  # a free port, not a fixed one another user's Ray may hold
                s.bind(("127.0.0.1", 0))
                port = str(s.getsockname()[1])
            exe = str(Path(sys.executable).parent / "ray")
            subprocess.run([exe, "start", "--head", f"--port={port}", f"--num-cpus={workers}", "--include-dashboard=false",
                            "--disable-usage-stats", f"--temp-dir={temp}", "--node-ip-address=127.0.0.1"],
                           capture_output=True, check=True, timeout=180)
            try:
                t0 = time.perf_counter()
                ray_result = run_sweep(PROJECT, plans, horizon=8.0, ray=f"127.0.0.1:{port}")
                timings[f"Ray ({workers} CPUs)"] = time.perf_counter() - t0
            finally:
                stop_ray(temp)
    feasible = sum(1 for r in one if r["feasible"])
    times = sorted(r["time_to_done"] for r in one if r["feasible"] and r["time_to_done"] is not None)
    print(f"sweep of the 384 holes at Z = {z}: {feasible} reachable (time to reach from home: median "
          f"{times[len(times) // 2]:.1f} s, max {times[-1]:.1f} s); answers equal on every runner: "
          f"{pool == one and threaded == one and (ray_result is None or ray_result == one)}")
    base = timings["one process"]
    for name, seconds in timings.items():
        figure(f"sweep of 384 holes: {name}", seconds, "s", peer="one process", peer_value=base)
    print("  " + "; ".join(f"{name}: {seconds:.1f} s (speed-up {base / seconds:.2f})" for name, seconds in timings.items()))


if __name__ == "__main__":
    one_whatif()
    holes()
