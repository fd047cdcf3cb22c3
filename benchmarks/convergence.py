"""Convergence against the perturbed OPC UA plant (payload 0.5 kg unknown to the DT, commands taking effect
300 ms late, noisy encoders and torques): the DT's position deviation RMSE with resync = "on-alarm" against
"never" in the same run (20 s, the UR5e experiment's plan), and the payload estimate against the truth.
Writes convergence.png beside the bench record: |PT - DT| per step of both runs with the resyncs marked,
and the estimate with its 3-sigma band against the truth.

    python benchmarks/convergence.py [END_S]
"""

from __future__ import annotations

import csv
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.mapping.opcua import OPCUAEndpoint  # noqa: E402
from cotwin.mapping.perturbed import PerturbedEndpoint  # noqa: E402
from cotwin.pmodel.perturbation import Perturbation  # noqa: E402
from cotwin.twin.services.plant import Plant  # noqa: E402
from cotwin.twin.assembly.run import load  # noqa: E402
from cotwin.twin.live.runtime import LiveTwin  # noqa: E402
from figures import figure, goal  # noqa: E402

EXAMPLE = ROOT / "examples" / "ur5e"
PAYLOAD = 0.5
PLANT = Perturbation(payload=PAYLOAD, latency_ms=300, noise={"effort": 0.05, "position": 1e-4}, seed=3)
JOINTS = [f"q{i}" for i in range(6)]


def project(folder: Path, resync: str, end: float) -> Path:
    path = folder / "cotwin.toml"
    path.write_text(f'[models]\ndmodel = "{EXAMPLE / "arm.rst"}"\npmodel = "{EXAMPLE / "ur5e.pm"}"\n'
                    f'mapping = "{EXAMPLE / "mapping.pm"}"\n[scenario]\nplan = "{EXAMPLE / "plan.csv"}"\n'
                    f"[cosim]\nstep = 0.1\nend = {end}\n[deviation]\nlag_steps = 1\n"
                    f'[convergence]\nresync = "{resync}"\nestimate = "payload"\n')
    return path


def run(folder: Path, resync: str, end: float):
    system = load(project(folder, resync, end))
    plant = Plant(PerturbedEndpoint.build(system.models.tree, system.models.scene, PLANT), "opc.tcp://127.0.0.1:0")
    plant.start()
    try:
        with OPCUAEndpoint(system.models.tree, plant.url, timeout=10, reset=True) as pt:
            twin = LiveTwin(system, folder / "out", pt=pt)
            started = time.perf_counter()
            result = twin.run()
            return result, twin, time.perf_counter() - started
    finally:
        plant.stop()


def deviation_trace(out: Path) -> tuple[list[float], list[float]]:
    """(time, largest |PT - DT| over the joints) per step, from the two sides' outputs.csv."""
    sides = [list(csv.DictReader(open(out / side / "outputs.csv"))) for side in ("pt", "dt")]
    times, worst = [], []
    for p, d in zip(*sides):
        times.append(float(p["time"]))
        worst.append(max(abs(float(p[f"{{mapping}}.mapping.{q}"]) - float(d[f"{{mapping}}.mapping.{q}"])) for q in JOINTS))
    return times, worst


def rmse(result) -> float:
    values = [result.deviation["variables"][q]["rmse"] for q in JOINTS]
    return sum(values) / len(values)


def main() -> int:
    end = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    record = os.environ.get("COTWIN_BENCH_JSON")
    folder_out = Path(record).parent if record else ROOT / "out" / "bench"
    folder_out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="cotwin-converge-") as tmp:
        runs = {}
        for resync in ("never", "on-alarm"):
            (Path(tmp) / resync).mkdir()
            runs[resync] = run(Path(tmp) / resync, resync, end)
        (never, _, wall_never), (alarm, twin, wall_alarm) = runs["never"], runs["on-alarm"]
        traces = {name: deviation_trace(Path(tmp) / name / "out") for name in runs}
    a, b = rmse(alarm), rmse(never)
    print(f"DT position RMSE (mean over 6 joints): on-alarm {a:.4f} rad, never {b:.4f} rad ({b / a:.1f}x lower); "
          f"{alarm.convergence['resyncs']} resyncs, {alarm.deviation['alarms']} alarms against {never.deviation['alarms']}")
    figure("convergence: DT position RMSE, resync on-alarm", a, "rad", "resync never", b,
           resyncs=alarm.convergence["resyncs"], end_s=end)
    figure("convergence: live twin wall time, resync on-alarm", wall_alarm, "s", "resync never", wall_never)
    print(goal("convergence: RMSE on-alarm / never", a / b, 0.5, at_most=True))
    payload = alarm.convergence["payload"]
    error = abs(payload["estimate"] - PAYLOAD)
    print(f"payload estimate {payload['estimate']:.4f} kg +- {payload['std']:.4f} kg (truth {PAYLOAD} kg, error "
          f"{error:.4f} kg = {error / payload['std']:.1f} sigma) from {payload['samples']} rest samples; applied "
          f"{payload['applied']:.4f} kg")
    figure("convergence: payload estimate", payload["estimate"], "kg", "truth", PAYLOAD, std=payload["std"],
           samples=payload["samples"])
    print(goal("convergence: payload error", error, 0.02, at_most=True, unit=" kg"))
    draw(folder_out / "convergence.png", traces, alarm.convergence["corrections"], twin.convergence.trace, end)
    print(f"figure: {folder_out / 'convergence.png'}")
    return 0


def draw(path: Path, traces: dict, corrections: list[dict], estimates: list, end: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for (name, (t, worst)), colour in zip(traces.items(), ("#c92a2a", "#1f6feb")):
        top.plot(t, worst, color=colour, label=f'resync = "{name}"')
    for e in corrections:
        if e["kind"] == "resync":
            top.axvline(e["time"], color="#2b8a3e", alpha=0.25, lw=0.8)
    top.set_ylabel("largest |PT - DT| over joints (rad)")
    top.set_title("DT against the perturbed OPC UA plant (payload 0.5 kg, latency 300 ms); green: resyncs")
    top.legend()
    if estimates:
        t, m, s = zip(*estimates)
        bottom.plot(t, m, color="#1f6feb", label="estimate")
        bottom.fill_between(t, [x - 3 * y for x, y in zip(m, s)], [x + 3 * y for x, y in zip(m, s)],
                            color="#1f6feb", alpha=0.2, label="3 sigma")
    bottom.axhline(PAYLOAD, color="black", ls="--", label="truth")
    for e in corrections:
        if e["kind"] == "payload":
            bottom.axvline(e["time"], color="#2b8a3e", alpha=0.5, lw=0.8)
    bottom.set_ylim(0.3, 0.7)
    bottom.set_xlim(0, end)
    bottom.set_xlabel("time (s)")
    bottom.set_ylabel("payload (kg)")
    bottom.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
