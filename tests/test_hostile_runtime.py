"""Hostile input to the twin's run time and its recorded data: RTDE logs that lie, replay offsets past a
log's end, project paths gone missing, Ctrl-C while waiting for the broker, runs failing midway, broker
messages from another time or in a flood. Each must end in a located error or a logged refusal, never a
traceback, a hang or a silently wrong result, and keep what was already computed."""

from __future__ import annotations

import csv
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import EXAMPLES, ROOT
from cotwin.diagnostics import CotwinError
from cotwin.mapping import rtde

RUN1 = ROOT.parent / "shared" / "data" / "ur5e" / "rtde_run1.csv"


def cotwin(*args, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture
def run1() -> tuple[list[str], list[list[str]]]:
    """The recorded UR5e run's header and rows, to mutate."""
    if not RUN1.is_file():
        pytest.skip(f"the recorded UR5e run is not at {RUN1} (only in the project workspace)")
    lines = RUN1.read_text().splitlines()
    return lines[0].split(), [line.split() for line in lines[1:]]


def _write(path: Path, header: list[str], rows: list[list[str]]) -> Path:
    path.write_text("\n".join([" ".join(header), *(" ".join(r) for r in rows)]) + "\n")
    return path


def _error(path: Path) -> str:
    with pytest.raises(CotwinError) as err:
        rtde.read_rtde(path)
    return str(err.value)


MUTATIONS = {  # name: (how a row set is spoilt, what the error says, the line it is at)
    "nan": (lambda h, r: r[5].__setitem__(h.index("actual_q_0"), "nan"), "'nan' is not a finite number", 7),
    "inf": (lambda h, r: r[5].__setitem__(h.index("actual_q_2"), "-inf"), "'-inf' is not a finite number", 7),
    "huge angle": (lambda h, r: r[5].__setitem__(h.index("actual_q_0"), "1e300"), "beyond any UR arm's", 7),
    "huge speed": (lambda h, r: r[9].__setitem__(h.index("actual_qd_4"), "-4e4"), "beyond any UR arm's", 11),
    "backwards": (lambda h, r: r[10].__setitem__(0, r[8][0]), "timestamps must increase", 12),
    "repeated": (lambda h, r: r[10].__setitem__(0, r[9][0]), "timestamps must increase", 12),
    "jump": (lambda h, r: r[-1].__setitem__(0, "1e300"), "a jump of 1e+300 s", 242),
    "ragged": (lambda h, r: r[7].pop(), "117 values for 118 columns", 9),
}


@pytest.mark.parametrize("name", MUTATIONS)
def test_impossible_rtde_values_are_located_errors(run1, tmp_path, name):
    header, rows = run1
    spoil, message, line = MUTATIONS[name]
    spoil(header, rows)
    log = _write(tmp_path / "log.csv", header, rows)
    error = _error(log)
    assert error.startswith(f"{log}:{line}:") and message in error


def test_broken_rtde_files_are_located_errors(run1, tmp_path):
    header, rows = run1
    cases = {
        "header only": (" ".join(header) + "\n", ":1:1: error: the log has 0 sample(s)"),
        "missing column": (" ".join(h for h in header if h != "actual_q_3") + "\n", "no column(s) actual_q_3"),
        "binary": (None, "not UTF-8 text"),
    }
    for name, (text, message) in cases.items():
        path = tmp_path / f"{name}.csv"
        if text is None:
            path.write_bytes(" ".join(header).encode() + b"\n" + bytes(range(128, 256)) * 10)
        else:
            path.write_text(text)
        assert message in _error(path), name
    big = tmp_path / "big.csv"  # sparse: the size says enough, nothing is read
    with big.open("wb") as f:
        f.truncate(rtde.MAX_BYTES + 1)
    started = time.monotonic()
    assert "MiB, over the 512 MiB cotwin reads" in _error(big) and time.monotonic() - started < 1.0


@pytest.fixture
def copied(tmp_path) -> Path:
    """The UR5e example copied elsewhere: replay.toml's relative [pt] log now points nowhere."""
    shutil.copytree(EXAMPLES / "ur5e", tmp_path / "ur5e")
    return tmp_path / "ur5e"


def test_a_replay_offset_outside_the_log_is_refused_naming_it_and_the_duration(run1, copied):
    from cotwin.twin.project import load_project
    from cotwin.twin.run import load
    from cotwin.twin.runtime import pt_endpoint

    toml = copied / "replay.toml"
    text = toml.read_text().replace('log = "../../../shared/data/ur5e/rtde_run1.csv"', f'log = "{RUN1}"')
    for offset in (9000.0, 0.0):  # past the end; before the start (the controller's clock starts at 5037.7 s)
        toml.write_text(text.replace("[pt]", f"[pt]\noffset = {offset}"))
        with pytest.raises(CotwinError) as err:
            pt_endpoint(load(load_project(toml)))
        assert (f"[pt] offset: the replay offset {offset} s is outside the log {RUN1}, whose time runs from "
                "5037.71 to 5061.71 s (24 s long)") in str(err.value)
    toml.write_text(text.replace("[pt]", "[pt]\noffset = 5040.0"))
    assert pt_endpoint(load(load_project(toml))).recording_time() == 5040.0


def test_pt_log_replaces_the_projects_missing_log_and_calibrate_names_the_key(run1, copied, tmp_path):
    toml = copied / "replay.toml"
    header, rows = run1
    rows[5][header.index("actual_q_1")] = "1e300"
    bad = _write(tmp_path / "bad.csv", header, rows)
    proc = cotwin("twin", toml, "-o", tmp_path / "out", "--end", "0.5", "--pt-log", bad)
    assert proc.returncode == 1 and proc.stderr.startswith(f"{bad}:7:") and "Traceback" not in proc.stderr
    proc = cotwin("twin", toml, "-o", tmp_path / "out", "--end", "0.5", "--pt-log", RUN1)
    assert proc.returncode == 0, proc.stderr
    assert len(list(csv.reader(open(tmp_path / "out" / "pt" / "outputs.csv")))) == 7
    proc = cotwin("calibrate", toml, "--check", RUN1)  # no --pt-log: the project's [pt] log is needed
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert f"{toml}:17:1: error: [pt] log: no file {copied}/../../../shared/data/ur5e/rtde_run1.csv" in proc.stderr
