"""Run every benchmark in this folder, in one process each; a failing one is reported and the rest still run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

failed = []
for script in sorted(HERE.glob("*.py")):
    if script.name == "run.py":
        continue
    print(f"== {script.stem}", flush=True)
    if subprocess.run([sys.executable, str(script)]).returncode != 0:
        failed.append(script.stem)
if failed:
    print(f"benchmarks that failed: {', '.join(failed)}", file=sys.stderr)
    sys.exit(1)
