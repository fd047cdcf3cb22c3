"""Run the benchmarks (`make bench`), one process per module, and judge their goals.

Each module prints its figures beside their peers and records them (benchmarks/figures.py). This runner
tees the text to OUT/bench.txt and writes every module's figures and goals to OUT/bench.json (OUT:
out/bench, or -o DIR), then exits non-zero naming each goal missed and each module that failed. A
module that fails is reported and the rest still run. To add a benchmark: a module in this folder
that records with figures.figure()/goal(), and its name in MODULES.

    python benchmarks/run.py [-o DIR] [MODULE ...]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

# In the order they run: cheap front-end figures first, the long live and dashboard runs last.
MODULES = [
    "frontend",      # parse and check, against Lark's bare parse
    "pmodel_check",  # p-models in RoboTool's notation: under a second each
    "dmodel",        # d-model FMU step through FMI calls, against the interpreter
    "mapping",       # compiled mapping expressions, against the interpreting evaluator
    "pmodel",        # the scene's physics, against the robot alone
    "twin",          # the 20 s experiment's real-time factors; the master against libcosim, like for like
    "fused",         # where a step's time goes; the twin's speed as a share of physics alone (issue 23)
    "whatif",        # one what-if against the same span run straight; sweeps on one process, a pool, Ray
    "live",          # command latency through RabbitMQ; PT+DT lockstep against one twin
    "opcua",         # OPC UA Advance against the embedded endpoint and the broker
    "calibration",   # the fit against one replay
    "turtlebot",     # the TurtleBot3's random walks
    "dashboard",     # the dashboard's cost against the same twin without it; page load
    "convergence",   # a DT resynced on alarm against never, the payload estimate against the truth (OPC UA plant)
]
HELPERS = {"run", "figures", "fmicalls"}  # imported by the modules, not run


def machine() -> dict:
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {"cpus": os.cpu_count(), "load_average": load, "python": platform.python_version(),
            "platform": platform.platform(), "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("modules", nargs="*", help=f"modules to run (default: all: {' '.join(MODULES)})")
    parser.add_argument("-o", "--output", default=str(HERE.parent / "out" / "bench"), help="folder for bench.txt and bench.json")
    args = parser.parse_args()
    unknown = [m for m in args.modules if m not in MODULES]
    if unknown:
        parser.error(f"no benchmark module {', '.join(unknown)} (known: {', '.join(MODULES)})")
    unlisted = sorted(p.stem for p in HERE.glob("*.py") if p.stem not in MODULES and p.stem not in HELPERS)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    text = open(out / "bench.txt", "w")

    def say(line: str, stream=sys.stdout) -> None:
        print(line, file=stream, flush=True)
        text.write(line + "\n")
        text.flush()

    if unlisted:
        say(f"warning: benchmarks/{', '.join(unlisted)}.py not in run.py's MODULES: not run", sys.stderr)
    results = {"machine": machine(), "modules": {}}
    for name in args.modules or MODULES:
        say(f"== {name}")
        record = out / f"{name}.json"
        record.unlink(missing_ok=True)
        started = time.perf_counter()
        proc = subprocess.Popen([sys.executable, str(HERE / f"{name}.py")], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, env={**os.environ, "COTWIN_BENCH_JSON": str(record)})
        for line in proc.stdout:
            say(line.rstrip("\n"))
        proc.wait()
        data, returncode = {"figures": [], "goals": []}, proc.returncode
        try:
            if record.is_file():
                data = json.loads(record.read_text())
        except ValueError as err:
            say(f"{name}: its figures could not be read ({err}): counted as failed", sys.stderr)
            returncode = returncode or 1
        record.unlink(missing_ok=True)
        results["modules"][name] = {"returncode": returncode, "seconds": time.perf_counter() - started, **data}
    results["machine"]["load_average_after"] = machine()["load_average"]
    failed = [n for n, r in results["modules"].items() if r["returncode"] != 0]
    missed = [f"{n}: {g['name']} = {g['value']} (goal {g['comparison']} {g['target']}{g['unit']})"
              for n, r in results["modules"].items() for g in r["goals"] if not g["met"]]
    results.update(failed=failed, missed=missed)
    (out / "bench.json").write_text(json.dumps(results, indent=1))
    say(f"figures: {out / 'bench.json'}; text: {out / 'bench.txt'}")
    for line in missed:
        say(f"goal missed: {line}", sys.stderr)
    if failed:
        say(f"benchmarks that failed: {', '.join(failed)}", sys.stderr)
    met = sum(g["met"] for r in results["modules"].values() for g in r["goals"])
    say(f"{met} goal(s) met, {len(missed)} missed, {len(failed)} module(s) failed")
    return 1 if missed or failed else 0


if __name__ == "__main__":
    sys.exit(main())
