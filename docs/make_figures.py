"""Remake the README's figure, docs/run.png: the paper's UR5e experiment as `make demo` co-simulates it
(`cotwin run examples/ur5e/cotwin.toml`, the figure it writes beside outputs.csv).

    .venv/bin/python docs/make_figures.py
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="cotwin-figures-") as out:
        subprocess.run([sys.executable, "-m", "cotwin", "run", str(ROOT / "examples" / "ur5e" / "cotwin.toml"), "-o", out],
                       check=True)
        shutil.copyfile(Path(out) / "figure.png", ROOT / "docs" / "run.png")
    print(ROOT / "docs" / "run.png")


if __name__ == "__main__":
    main()
