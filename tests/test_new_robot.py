"""docs/new-robot.md as a user follows it: the blocks marked `<!-- tested -->` run in order, as one shell
script, in an empty folder beside a cotwin clone's examples; the Panda imported from its URDF then runs
the paper's d-model in its own cell and completes every move of its plan."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from conftest import ROOT

PAGE = ROOT / "docs" / "new-robot.md"
MARK = "<!-- tested -->"


def marked_blocks(text: str) -> list[str]:
    """The ```sh blocks that follow a line `<!-- tested -->` (other blocks are for reading only)."""
    return re.findall(r"^" + re.escape(MARK) + r"\n```sh\n(.*?)^```$", text, re.MULTILINE | re.DOTALL)


def test_the_page_marks_every_step_from_import_to_run():
    blocks = marked_blocks(PAGE.read_text())
    script = "\n".join(blocks)
    assert len(blocks) == 6 and PAGE.read_text().count(f"\n{MARK}\n") == 6
    for step in ("cotwin import-urdf", "mapping.pm", "cell.toml", "cotwin.toml", "cotwin check", "cotwin run"):
        assert step in script, step


def test_the_tutorial_runs_to_a_twin_that_completes_its_moves(tmp_path):
    script = "set -euo pipefail\n" + "\n".join(marked_blocks(PAGE.read_text()))
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "COTWIN_CLONE": str(ROOT)}  # as the page says: a folder of one's own, the clone named
    proc = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    assert "mycell/panda.pm: p-model panda: 13 links, 7 revolute, 2 prismatic" in proc.stdout
    assert "mycell/mapping.pm: ok" in proc.stdout
    assert "commands: 4, 4 completed" in proc.stdout, proc.stdout[-3000:]
    assert (tmp_path / "mycell" / "out" / "outputs.csv").is_file()
