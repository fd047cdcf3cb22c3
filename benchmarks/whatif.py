"""What-if and sweeps: one what-if from a live state (wall time, peer: the same plan in a straight run),
and every hole of the plate at Z = 0 (384 what-ifs) on one process, on a local pool and on a local
Ray cluster, with the speed-up over one process."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.twin.run import load, run_twin  # noqa: E402
from cotwin.twin.sweep import grid, run_sweep  # noqa: E402
from cotwin.twin.whatif import predict  # noqa: E402

PROJECT = ROOT / "examples" / "ur5e" / "cotwin.toml"


def one_whatif() -> None:
    system = load(PROJECT)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run_twin(system, tmp, plot=False)
        straight = time.perf_counter() - t0
        state = (Path(tmp) / "state").read_bytes()
        t0 = time.perf_counter()
        prediction = predict(system, system.commands, state, horizon=25.0, artefacts=tmp)
        fork = time.perf_counter() - t0
    print(f"what-if of the paper's plan from the state at t = 20 s: {fork:.2f} s for {prediction.end - prediction.start:.1f} s "
          f"simulated ({(prediction.end - prediction.start) / fork:.0f}x real time); straight run of 20 s: {straight:.2f} s")


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
    try:
        import ray  # noqa: F401
    except ImportError:
        ray_result = None
    else:
        with tempfile.TemporaryDirectory(prefix="ray", dir="/tmp") as temp:
            port = "38127"
            exe = str(Path(sys.executable).parent / "ray")
            subprocess.run([exe, "start", "--head", f"--port={port}", f"--num-cpus={workers}", "--include-dashboard=false",
                            "--disable-usage-stats", f"--temp-dir={temp}", "--node-ip-address=127.0.0.1"],
                           capture_output=True, check=True, timeout=180)
            try:
                t0 = time.perf_counter()
                ray_result = run_sweep(PROJECT, plans, horizon=8.0, ray=f"127.0.0.1:{port}")
                timings[f"Ray ({workers} CPUs)"] = time.perf_counter() - t0
            finally:
                subprocess.run([exe, "stop", "--force"], capture_output=True, timeout=120)
    feasible = sum(1 for r in one if r["feasible"])
    times = sorted(r["time_to_done"] for r in one if r["feasible"] and r["time_to_done"] is not None)
    print(f"sweep of the 384 holes at Z = {z}: {feasible} reachable (time to reach from home: median "
          f"{times[len(times) // 2]:.1f} s, max {times[-1]:.1f} s); answers equal on every runner: "
          f"{pool == one and (ray_result is None or ray_result == one)}")
    base = timings["one process"]
    print("  " + "; ".join(f"{name}: {seconds:.1f} s (speed-up {base / seconds:.2f})" for name, seconds in timings.items()))


if __name__ == "__main__":
    one_whatif()
    holes()
