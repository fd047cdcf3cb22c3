"""Long commands show progress on stderr: a line every COTWIN_PROGRESS_SECONDS in a log (0: every
update), a bar on a terminal; `cotwin run` and a twin say how far the run is."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

from cotwin.cli.progress import ProgressReport, interval

ROOT = Path(__file__).resolve().parents[1]


def test_a_log_gets_a_line_per_interval_and_none_when_off(monkeypatch):
    monkeypatch.setenv("COTWIN_PROGRESS_SECONDS", "0")
    stream = io.StringIO()
    with ProgressReport("sweeping", "what-ifs", stream=stream, terminal=False) as progress:
        for k in range(1, 4):
            progress(k, 3, "detail")
    lines = stream.getvalue().splitlines()
    assert [line.split(" [")[0] for line in lines] == [f"sweeping: {k}/3 what-ifs ({p}%), detail"
                                                      for k, p in ((1, 33), (2, 67), (3, 100))]
    monkeypatch.setenv("COTWIN_PROGRESS_SECONDS", "3600")
    stream = io.StringIO()
    with ProgressReport("x", stream=stream, terminal=False) as progress:
        for k in range(100):
            progress(k)
    assert stream.getvalue() == ""  # nothing within the first hour
    monkeypatch.setenv("COTWIN_PROGRESS_SECONDS", "off")
    assert interval() is None


def test_a_terminal_gets_a_bar_that_is_gone_at_the_end():
    stream = io.StringIO()
    with ProgressReport("verifying", "states", stream=stream, terminal=True) as progress:
        progress(5, None, "limit 10")
    assert "verifying" in stream.getvalue()


def test_cotwin_run_reports_its_steps(tmp_path):
    env = dict(os.environ, COTWIN_PROGRESS_SECONDS="0")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(ROOT / "examples" / "ur5e" / "cotwin.toml"),
                           "-o", str(tmp_path), "--end", "1"], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "co-simulating: 10/10 steps (100%)" in proc.stderr
