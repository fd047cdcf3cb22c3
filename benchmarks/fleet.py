"""Fleets (cotwin fleet): how many UR5e twins (step 0.1 s, PT a replayed log, DT in MuJoCo) this machine keeps
at real time, every twin in one process against Ray with 2 workers (two actor processes sharing the twins),
and the fleet's throughput at full speed (unpaced) on both, measured in the same run.

A fleet "keeps real time" when every twin ends within LAG_LIMIT of the wall clock (a late first step, e.g.
the first inverse kinematics, may be caught up; a twin that cannot keep up falls further behind each step,
and the supervisor reports it, never slowing it further). Counts are tried doubling from 1,
then bisected; the PT replays ../shared/data/ur5e/rtde_run1.csv, or a generated log when it is absent.
Goal: Ray with 2 workers keeps at least as many twins at real time as one process (two cores against one)."""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.twin.analysis.fleet.spec import read_fleet  # noqa: E402
from cotwin.twin.analysis.fleet.supervisor import Fleet  # noqa: E402
from figures import figure, goal, shown  # noqa: E402

PROJECT = ROOT / "examples" / "ur5e" / "replay.toml"
SHARED_LOG = ROOT.parent / "shared" / "data" / "ur5e" / "rtde_run1.csv"
LAG_LIMIT = 0.2  # s: two steps behind the wall clock
PACED_END = 6.0  # s simulated in a paced trial
FULL_END = 60.0  # s simulated per twin at full speed (long enough that start-up, an actor process each, is not the figure)
FULL_TWINS = 8
MAX_TWINS = 64


def generated_log(path: Path, span: float = 30.0) -> Path:
    """A UR5e RTDE log at rest 1 s, then moving smoothly (10 Hz), for machines without ../shared."""
    header = "timestamp " + " ".join(f"actual_q_{k}" for k in range(6)) + " " + " ".join(f"actual_qd_{k}" for k in range(6))
    home = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
    lines = [header]
    for n in range(int(span * 10) + 1):
        t, s = n / 10, max(0.0, n / 10 - 1.0)
        q = [h + 0.3 * math.sin(0.5 * s) * (1 if k % 2 else -1) for k, h in enumerate(home)]
        qd = [0.15 * math.cos(0.5 * s) * (1 if k % 2 else -1) * (s > 0) for k in range(6)]
        lines.append(f"{t:.3f} " + " ".join(f"{v:.6f}" for v in q + qd))
    path.write_text("\n".join(lines) + "\n")
    return path


def fleet_file(folder: Path, log: Path, twins: int, end: float, realtime: bool, workers: int) -> Path:
    text = f"[fleet]\ncheckpoint_every = 50\nmax_restarts = 0\nworkers = {workers}\n\n"
    for k in range(twins):
        text += (f'[[twin]]\nname = "arm-{k}"\nproject = "{PROJECT}"\npt_log = "{log}"\nend = {end}\n'
                 f"realtime = {str(realtime).lower()}\n\n")
    path = folder / f"fleet-{twins}-{workers}-{realtime}.toml"
    path.write_text(text)
    return path


def run(folder: Path, log: Path, twins: int, end: float, realtime: bool, ray: str | None, workers: int) -> tuple[dict, float]:
    spec = read_fleet(fleet_file(folder, log, twins, end, realtime, workers))
    out = folder / f"out-{twins}-{ray}-{workers}-{realtime}-{time.monotonic_ns()}"
    t0 = time.perf_counter()
    summary = Fleet(spec, out, ray=ray).run()
    return summary, time.perf_counter() - t0


def keeps_real_time(summary: dict) -> tuple[bool, float]:
    twins = summary["twins"]
    worst = max((t.get("lag") or 0.0) for t in twins)
    return all(t["state"] == "done" for t in twins) and worst <= LAG_LIMIT, worst


def capacity(folder: Path, log: Path, ray: str | None, workers: int, label: str) -> int:
    """The most twins kept at real time: doubling, then bisecting between the last kept and the first lost."""
    kept, lost = 0, None
    n = 1
    while n <= MAX_TWINS:
        summary, _ = run(folder, log, n, PACED_END, True, ray, workers)
        ok, worst = keeps_real_time(summary)
        print(f"  {label}: {n} twin(s) paced, lag at the end {worst:.3f} s -> {'kept' if ok else 'lost'}", flush=True)
        if not ok:
            lost = n
            break
        kept, n = n, n * 2
    while lost is not None and lost - kept > 1:
        n = (kept + lost) // 2
        summary, _ = run(folder, log, n, PACED_END, True, ray, workers)
        ok, worst = keeps_real_time(summary)
        print(f"  {label}: {n} twin(s) paced, lag at the end {worst:.3f} s -> {'kept' if ok else 'lost'}", flush=True)
        kept, lost = (n, lost) if ok else (kept, n)
    return kept


def throughput(folder: Path, log: Path, ray: str | None, workers: int) -> tuple[float | None, float | None]:
    """(simulated twin-seconds per wall second over the whole run, start-up included; the same while stepping,
    the sum of the twins' real-time factors) of FULL_TWINS unpaced twins; None when a twin did not finish."""
    summary, wall = run(folder, log, FULL_TWINS, FULL_END, False, ray, workers)
    done = [t for t in summary["twins"] if t["state"] == "done"]
    if len(done) < FULL_TWINS:
        print(f"  {FULL_TWINS - len(done)} twin(s) did not finish: " +
              "; ".join(f"{t['name']}: {t.get('message')}" for t in summary["twins"] if t["state"] != "done")[:600])
        return None, None
    return FULL_TWINS * FULL_END / wall, sum(t["real_time_factor"] or 0.0 for t in done)


def main() -> None:
    import logging

    import ray

    logging.getLogger("cotwin.twin").setLevel(logging.ERROR)  # each twin's deviation alarms: not this figure's

    with tempfile.TemporaryDirectory(prefix="cotwin-bench-fleet-") as tmp:
        folder = Path(tmp)
        log = SHARED_LOG if SHARED_LOG.is_file() else generated_log(folder / "run.csv")
        print(f"PT: {'the real UR5e log ' + str(SHARED_LOG) if log == SHARED_LOG else 'a generated log (../shared absent)'}")
        one = capacity(folder, log, None, 0, "one process")
        one_full, one_stepping = throughput(folder, log, None, 0)
        ray.init(address="local", _node_ip_address="127.0.0.1", include_dashboard=False, num_cpus=2,
                 logging_level="ERROR", log_to_driver=False, configure_logging=False)
        try:
            two = capacity(folder, log, "auto", 2, "Ray, 2 workers")
            two_full, two_stepping = throughput(folder, log, "auto", 2)
        finally:
            ray.shutdown()
    figure("UR5e twins kept at real time, Ray with 2 workers", two, "twins", peer="one process", peer_value=one,
           lag_limit_s=LAG_LIMIT, simulated_s=PACED_END)
    figure(f"fleet throughput at full speed, {FULL_TWINS} twins, Ray with 2 workers", two_full, "twin-s/s",
           peer="one process", peer_value=one_full, stepping_two=two_stepping, stepping_one=one_stepping)
    print(f"UR5e twins (step 0.1 s, replayed PT, MuJoCo DT) kept at real time (lag <= {LAG_LIMIT} s): one process "
          f"{one}, Ray with 2 workers {two} ({goal('twins at real time, Ray 2 workers against one process', two - one, 0, unit=' twins')})")
    ratio = two_full / one_full if two_full and one_full else None
    print(f"fleet of {FULL_TWINS} at full speed, {FULL_END:g} s each (start-up included): one process "
          f"{shown(one_full)} twin-s/s (stepping {shown(one_stepping)}), Ray with 2 workers {shown(two_full)} twin-s/s "
          f"(stepping {shown(two_stepping)}), ratio {shown(ratio, '.2f')} "
          f"({goal('fleet throughput, Ray 2 workers over one process', ratio, 1.2, unit='x')})")

if __name__ == "__main__":
    main()
