"""The history store read by the live twin's page: memory of 8 concurrent GETs of a long run, each in a
fresh process, beside its peer measured in the same run:
- peer: each request reads the whole run (`read_run` without bounds, what the page's server did), then
  thins it to the page's 4000 points per side;
- page: 8 concurrent GETs of /api/history/RUN from the dashboard served in that process (samples
  chosen by the database, at most 4000 per side; at most 2 reads at once).
Goal: the page's peak memory growth under 100 MiB for a run of 200 000 samples (its peer's grows with
the run). Also the time of one GET against one whole-run read.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = 100_000  # per side: 200 000 in the run
COLUMNS = [f"{{mapping}}.mapping.q{i}" for i in range(6)] + [f"{{mapping}}.mapping.qd{i}" for i in range(6)] + \
          [f"{{dmodel}}.dmodel.x{i}" for i in range(18)]  # 30, about what the UR5e twin logs per side
GOAL_MIB = 100.0

MAKE = r"""
import json, sys, random
import sqlalchemy as sa
sys.path.insert(0, sys.argv[3])
from cotwin.twin.services.history import HistoryRecorder, samples
url, n = sys.argv[1], int(sys.argv[2])
columns = json.loads(sys.argv[4])
r = HistoryRecorder(url, "bench.toml", "twin", 0.01, "jacobi", {"pt": columns, "dt": columns})
rows = []
for side in ("pt", "dt"):
    for k in range(n):
        rows.append({"run": r.run_id, "side": side, "step": k, "time": k * 0.01, "wall": 0.0,
                     "values": json.dumps([random.random() for _ in columns])})
        if len(rows) == 20000:
            with r.engine.begin() as c:
                c.execute(samples.insert(), rows)
            rows = []
if rows:
    with r.engine.begin() as c:
        c.execute(samples.insert(), rows)
r.close()
print(r.run_id)
"""

MEASURE = r"""
import json, sys, threading, time, urllib.request
sys.path.insert(0, sys.argv[4])

def peak():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024

url, run, how = sys.argv[1], int(sys.argv[2]), sys.argv[3]
from cotwin.twin.services.dashboard import Dashboard
from cotwin.twin.services.dashboard.app import thin
from cotwin.twin.services.history import read_run
base = peak()
seconds = []
if how == "peer":
    def get():
        t = time.perf_counter()
        data = read_run(url, run)
        {side: thin(rows, 4000) for side, rows in data["samples"].items()}
        seconds.append(time.perf_counter() - t)
    threads = [threading.Thread(target=get) for _ in range(8)]
else:
    dash = Dashboard(None, port=0, mode="history", history_url=url).start()
    def get():
        t = time.perf_counter()
        with urllib.request.urlopen(dash.url + f"api/history/{run}", timeout=600) as r:
            body = json.loads(r.read())
        assert len(body["sides"]["dt"]["time"]) <= 4001 and body["counts"]["dt"] > 4000
        seconds.append(time.perf_counter() - t)
    threads = [threading.Thread(target=get) for _ in range(8)]
for t in threads:
    t.start()
for t in threads:
    t.join()
if how != "peer":
    dash.stop()
print(json.dumps({"growth": peak() - base, "seconds": max(seconds)}))
"""


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="cotwin-bench-history-") as tmp:
        url = f"sqlite:///{Path(tmp) / 'history.sqlite'}"
        started = time.perf_counter()
        run = subprocess.run([sys.executable, "-c", MAKE, url, str(SAMPLES), str(ROOT / "src"), json.dumps(COLUMNS)],
                             capture_output=True, text=True, check=True).stdout.strip()
        print(f"a run of {2 * SAMPLES} samples x {len(COLUMNS)} values written in {time.perf_counter() - started:.1f} s "
              f"({(Path(tmp) / 'history.sqlite').stat().st_size / 2**20:.0f} MiB)")
        found = {}
        for how in ("peer", "page"):
            proc = subprocess.run([sys.executable, "-c", MEASURE, url, run, how, str(ROOT / "src")],
                                  capture_output=True, text=True)
            if proc.returncode != 0:
                print(proc.stderr[-2000:], file=sys.stderr)
                return 1
            found[how] = json.loads(proc.stdout.strip().splitlines()[-1])
    peer, page = found["peer"], found["page"]
    print(f"8 concurrent reads of the run, peak memory growth of the process: whole-run reads {peer['growth']:.0f} MiB "
          f"(slowest {peer['seconds']:.1f} s), the page's bounded GETs {page['growth']:.0f} MiB "
          f"(slowest {page['seconds']:.1f} s); goal < {GOAL_MIB:g} MiB")
    if page["growth"] >= GOAL_MIB:
        print("history pages: missed the memory goal", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
