"""A sweep on threads of one process (`cotwin sweep --threads N`): each thread steps its own forks, the native
loop outside the GIL; the answers are those of one thread, in the plans' order, and an interrupt keeps the
what-ifs answered."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import EXAMPLES
from cotwin.diagnostics import CotwinError
from cotwin.twin.analysis.sweep import grid, run_sweep
from cotwin.twin.assembly.run import load

PROJECT = EXAMPLES / "ur5e" / "cotwin.toml"


def test_threads_give_the_answers_of_one_thread_in_the_plans_order(tmp_path):
    """Holes near and out of reach, in an order whose what-ifs take different times (threads finish out of order)."""
    plans = grid(load(PROJECT).models.program, "moveDiscreteCommand",
                 {"target_X": [0, 8, 15, 3], "target_Y": [10, 0], "target_Z": [0, 1]})
    one = run_sweep(PROJECT, plans, horizon=4.0, workers=1, artefacts=tmp_path)
    three = run_sweep(PROJECT, plans, horizon=4.0, threads=3, artefacts=tmp_path)
    assert three == one
    assert len({(r["MovementArgs_target_X"], r["MovementArgs_target_Y"], r["MovementArgs_target_Z"]) for r in three}) == 16
    assert {r["feasible"] for r in one} == {True, False}  # both kinds of answer, not 16 alike


def test_threads_are_one_process_not_with_a_pool_or_ray():
    plans = grid(load(PROJECT).models.program, "moveDiscreteCommand", {"target_X": [0], "target_Y": [0], "target_Z": [0]})
    with pytest.raises(CotwinError, match="threads run the what-ifs in this process: not with a pool"):
        run_sweep(PROJECT, plans, threads=2, workers=2)
    with pytest.raises(CotwinError, match="not with a pool of processes"):
        run_sweep(PROJECT, plans, threads=2, ray="auto")
    with pytest.raises(CotwinError, match="one thread or more, not 0"):
        run_sweep(PROJECT, plans, threads=0)
    proc = subprocess.run([sys.executable, "-m", "cotwin", "sweep", str(PROJECT), "--event", "moveDiscreteCommand",
                           "--arg", "target_X=0", "--threads", "2", "--workers", "2", "-o", "x.csv"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--threads runs the what-ifs in this process: not with --workers" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_an_interrupted_threaded_sweep_keeps_its_answers_and_stops_at_once(tmp_path):
    out = tmp_path / "sweep.csv"
    env = {**os.environ, "COTWIN_PROGRESS_SECONDS": "0.2"}
    proc = subprocess.Popen([sys.executable, "-m", "cotwin", "sweep", str(PROJECT), "--event", "moveDiscreteCommand",
                             "--arg", "target_X=0..15", "--arg", "target_Y=0..11", "--arg", "target_Z=0", "-o", str(out),
                             "--threads", "2", "--horizon", "5", "--physics-step", "0.0002"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    seen = ""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:  # until some what-ifs are answered
        line = proc.stderr.readline()
        seen += line
        if not line or line.startswith("sweeping: ") and not line.startswith("sweeping: 0/"):
            break
    interrupted = time.monotonic()
    proc.send_signal(signal.SIGINT)
    stdout, rest = proc.communicate(timeout=120)
    waited = time.monotonic() - interrupted
    partial = tmp_path / "sweep.partial.csv"
    assert proc.returncode == 130, seen + rest
    rows = partial.read_text().splitlines()
    assert f"error: interrupted after {len(rows) - 1} of 192 what-ifs; the {len(rows) - 1} answered are in {partial}" \
        in rest and len(rows) > 1 and not out.exists()
    assert len(rows) - 1 < 150 and waited < 8.0, f"{len(rows) - 1} answered, {waited:.1f} s after the interrupt"
    assert "Traceback" not in rest


def test_threads_read_fmu_model_descriptions_one_at_a_time(tmp_path, monkeypatch):
    """A new user's sweep on 2 threads failed every what-if at random: 'cannot read .../dmodel.fmu: Internal error:
    xmlSchemaPValAttrNodeValue, the given type is not a built-in type' (FMPy builds an XML Schema at every read and
    libxml2 sets its built-in types up on first use without a lock). Reads of a model description never overlap."""
    import threading

    from cotwin.cosim import units

    inside, most = [0], [0]
    guard = threading.Lock()

    def reading(path, *args, **kwargs):
        with guard:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        time.sleep(0.05)
        with guard:
            inside[0] -= 1
        raise ValueError("not read")

    monkeypatch.setattr(units, "read_model_description", reading)
    fmu = tmp_path / "x.fmu"
    fmu.write_bytes(b"")
    said = []

    def read():
        try:
            units.read_fmu("u", fmu)
        except CotwinError as err:
            said.append(str(err))

    threads = [threading.Thread(target=read) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert most[0] == 1 and len(said) == 4 and all("cannot read" in s for s in said)
