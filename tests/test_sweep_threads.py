"""A sweep on threads of one process (`cotwin sweep --threads N`): each thread steps its own forks, the native
loop outside the GIL; the answers are those of one thread, in the plans' order, and an interrupt keeps the
what-ifs answered."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import EXAMPLES, cotwin_in_process, interrupted_sweep
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


def test_a_loaded_twin_is_swept_as_it_is_not_loaded_again(tmp_path, monkeypatch):
    """run_sweep given a TwinSystem (as predict takes one) answers as given the project file, on one thread and on
    threads, without reading the project again (it parsed the models anew at every sweep)."""
    twin = load(PROJECT)
    plans = grid(twin.models.program, "moveDiscreteCommand", {"target_X": [8, 15], "target_Y": [10], "target_Z": [0]})
    by_file = run_sweep(PROJECT, plans, horizon=3.0, workers=1, artefacts=tmp_path)
    from cotwin.twin.assembly import run as assembly_run

    def no_load(*args, **kwargs):
        raise AssertionError("the project was loaded again")

    monkeypatch.setattr(assembly_run, "load", no_load)
    assert run_sweep(twin, plans, horizon=3.0, workers=1, artefacts=tmp_path) == by_file
    assert run_sweep(twin, plans, horizon=3.0, threads=2, artefacts=tmp_path) == by_file


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
    _, rest, _, _ = interrupted_sweep(PROJECT, tmp_path, "--threads", "2")
    assert "Traceback" not in rest


def test_threads_read_the_fmus_model_description_one_at_a_time(tmp_path, monkeypatch):
    """FMPy validates a model description with libxml2's schema parser, which threads reading at once corrupted
    (every later what-if of the sweep then failed: 'cannot read dmodel.fmu: Internal error:
    xmlSchemaPValAttrNodeValue, the given type is not a built-in type'): the threads' forks read theirs in turn."""
    import threading

    from cotwin.cosim import units

    reading, most, lock = [0], [0], threading.Lock()
    plain = units.read_model_description

    def watched(*args, **kwargs):
        with lock:
            reading[0] += 1
            most[0] = max(most[0], reading[0])
        try:
            time.sleep(0.2)  # long enough for the other threads' forks to come to theirs
            return plain(*args, **kwargs)
        finally:
            with lock:
                reading[0] -= 1

    monkeypatch.setattr(units, "read_model_description", watched)
    plans = grid(load(PROJECT).models.program, "moveDiscreteCommand", {"target_X": [0, 1, 2], "target_Y": [0], "target_Z": [0]})
    rows = run_sweep(PROJECT, plans, horizon=2.0, threads=3, artefacts=tmp_path)
    assert not [r for r in rows if r.get("error")] and most[0] == 1, (most[0], rows)


def test_an_interrupt_while_the_threads_start_keeps_the_sweep_not_a_bug(tmp_path, monkeypatch):
    """Ctrl-C as the threads were started (Thread.start waits for each) joined one never started: 'internal error:
    RuntimeError: cannot join thread before it is started' instead of the interrupted sweep."""
    import threading

    from cotwin.twin.analysis import sweep
    from cotwin.twin.analysis.sweep import SweepInterrupted

    plain = threading.Thread.start

    def start(thread):
        if thread.name == "cotwin-sweep-0":
            os.kill(os.getpid(), signal.SIGINT)  # as the first thread starts, before the second has
        plain(thread)

    monkeypatch.setattr(sweep.threading.Thread, "start", start)
    plans = grid(load(PROJECT).models.program, "moveDiscreteCommand", {"target_X": [0, 1, 2], "target_Y": [0], "target_Z": [0]})
    with pytest.raises(SweepInterrupted) as caught:
        run_sweep(PROJECT, plans, horizon=2.0, threads=3, artefacts=tmp_path)
    assert caught.value.total == 3 and caught.value.running == 0


def test_a_second_interrupt_ends_the_process_without_finalising_under_the_threads(tmp_path):
    """A second Ctrl-C does not wait for the what-ifs in hand: the partial answers are written and the process ends
    at once, without the interpreter's exit (which, under a thread still in the native loop or a compile, crashed:
    SIGSEGV instead of exit 130). The what-ifs here hold a thread in C (outside the GIL) for 20 s each. The sweep's
    scratch folder, which those threads hold, is removed all the same before the process ends."""
    script = tmp_path / "held.py"
    script.write_text(
        "import atexit, ctypes, sys, threading, time\n"
        "from cotwin.twin.analysis import sweep\n"
        "plain = sweep._run\n"
        "def held(plan, *args, **kwargs):\n"
        "    if plan[0].values[1][1] != 0:  # the first what-if answers at once, the others stay in C\n"
        "        held = time.monotonic() + 20\n"
        "        while time.monotonic() < held:  # a signal ends one sleep early, not the hold\n"
        "            ctypes.CDLL(None).usleep(100_000)\n"
        "    return plain(plan, *args, **kwargs)\n"
        "sweep._run = held\n"
        "atexit.register(lambda: print('FINALISED', file=sys.stderr))\n"
        "from cotwin.cli import entry\n"
        "sys.argv = ['cotwin', *sys.argv[1:]]\n"
        "entry()\n")
    import cotwin

    out = tmp_path / "sweep.csv"
    here = str(Path(cotwin.__file__).resolve().parents[1])  # this cotwin, whatever PYTHONPATH says from another folder
    scratch = tmp_path / "tmp"  # where the sweep makes its scratch folder (and Python its other temporary files)
    scratch.mkdir()
    env = {**os.environ, "COTWIN_PROGRESS_SECONDS": "0", "PYTHONPATH": here, "TMPDIR": str(scratch)}
    proc = subprocess.Popen([sys.executable, str(script), "sweep", str(PROJECT), "--event", "moveDiscreteCommand",
                             "--arg", "target_X=0..3", "--arg", "target_Y=0", "--arg", "target_Z=0", "-o", str(out),
                             "--threads", "2", "--horizon", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    seen = ""
    while "sweeping: 1/4 " not in seen:  # the first answered, both threads now held
        line = proc.stderr.readline()
        assert line, seen
        seen += line
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.5)
    interrupted = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=60)
    assert proc.returncode == 130 and time.monotonic() - interrupted < 5.0, seen + rest
    assert "error: interrupted after 1 of 4 what-ifs; the 1 answered are in" in rest
    assert len((tmp_path / "sweep.partial.csv").read_text().splitlines()) == 2
    assert "FINALISED" not in rest and "Traceback" not in rest, rest
    assert list(scratch.glob("cotwin-sweep-*")) == []


def test_an_interrupt_waits_for_every_threads_whatif_in_hand(tmp_path, monkeypatch):
    """On Python 3.11 a Thread.join interrupted by Ctrl-C marks the thread it waited for ended though it runs on
    (bpo-45274's fix): the interrupted sweep waited for the other threads only, and returned (and the process exited)
    with that one inside its what-if."""
    import threading

    from cotwin.twin.analysis import sweep
    from cotwin.twin.analysis.sweep import SweepInterrupted

    plain, lock, in_hand = sweep._run, threading.Lock(), [0]

    def held(plan, *args, **kwargs):
        with lock:
            if in_hand[0] == 0 and not held.signalled:
                held.signalled = True
                threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT)).start()
            in_hand[0] += 1
        try:
            time.sleep(3.0 if threading.current_thread().name == "cotwin-sweep-0" else 1.0)
            return plain(plan, *args, **kwargs)
        finally:
            with lock:
                in_hand[0] -= 1

    held.signalled = False
    monkeypatch.setattr(sweep, "_run", held)
    plans = grid(load(PROJECT).models.program, "moveDiscreteCommand", {"target_X": [0, 1, 2, 3], "target_Y": [0], "target_Z": [0]})
    with pytest.raises(SweepInterrupted) as caught:
        run_sweep(PROJECT, plans, horizon=2.0, threads=2, artefacts=tmp_path)
    assert in_hand[0] == 0 and caught.value.running == 0 and len(caught.value.rows) == 2


def test_the_threads_fork_their_sweeps_twin_whatever_another_sweep_loads_meanwhile(tmp_path, monkeypatch):
    """The threads took the twin to fork from the module's _SYSTEM when they started: another sweep of the process
    loading its project meanwhile made them answer that project's what-ifs (here one whose d-model divides by X)."""
    import shutil
    import threading

    from cotwin.twin.analysis import sweep

    other = tmp_path / "dividing"
    shutil.copytree(EXAMPLES / "ur5e", other)
    arm = other / "arm.rst"
    arm.write_text(arm.read_text().replace("var margs: MovementArgs", "var margs: MovementArgs\n\tvar k: int")
                   .replace("state Requested { entry $movediscrete(", "state Requested { entry k = 10 / margs.target_X; $movediscrete("))
    meanwhile = (load(other / "cotwin.toml", reader=sweep.READER), str(tmp_path / "other"))
    from cotwin.twin.assembly.build import dmodel_fmu

    dmodel_fmu(meanwhile[0], meanwhile[1])
    monkeypatch.setattr(sweep, "_SYSTEM", sweep._SYSTEM)  # put back after the test
    plain = threading.Thread.start

    def start(thread):
        if thread.name == "cotwin-sweep-1":
            sweep._SYSTEM = meanwhile  # as another sweep of this process would, loading its project
        plain(thread)

    monkeypatch.setattr(sweep.threading.Thread, "start", start)
    plans = grid(load(PROJECT).models.program, "moveDiscreteCommand", {"target_X": [0], "target_Y": [0, 1, 2, 3], "target_Z": [0]})
    rows = run_sweep(PROJECT, plans, horizon=2.0, threads=2, artefacts=tmp_path / "mine")
    assert not [r for r in rows if r.get("error")], rows


@pytest.mark.parametrize("second", [signal.SIGINT, signal.SIGTERM])
def test_a_second_interrupt_as_the_process_exits_prints_no_traceback(tmp_path, second):
    """Ctrl-C twice quickly: the second, reaching the interpreter's exit (an atexit hook, as pythonfmu_exit's is),
    printed 'Exception ignored in atexit callback' and a traceback; so did a SIGTERM there (a service manager's
    stop after a Ctrl-C), which cotwin takes as an interrupt."""
    import cotwin

    script = tmp_path / "exiting.py"
    script.write_text(
        "import atexit, sys, time\n"
        "def slow():\n"
        "    print('EXITING', file=sys.stderr, flush=True)\n"
        "    time.sleep(1.5)\n"
        "atexit.register(slow)\n"
        "from cotwin.cli import entry\n"
        "sys.argv = ['cotwin', *sys.argv[1:]]\n"
        "entry()\n")
    env = {**os.environ, "COTWIN_PROGRESS_SECONDS": "0", "PYTHONPATH": str(Path(cotwin.__file__).resolve().parents[1])}
    proc = subprocess.Popen([sys.executable, str(script), "sweep", str(PROJECT), "--event", "moveDiscreteCommand",
                             "--arg", "target_X=0..15", "--arg", "target_Y=0", "--arg", "target_Z=0", "--horizon", "2",
                             "--threads", "2", "-o", str(tmp_path / "sweep.csv")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    seen = ""
    for wanted, sent in (("sweeping: 0/", signal.SIGINT), ("EXITING", second)):
        while wanted not in seen:
            line = proc.stderr.readline()
            assert line, seen
            seen += line
        proc.send_signal(sent)
    _, rest = proc.communicate(timeout=60)
    assert proc.returncode == 130, seen + rest
    assert "Traceback" not in seen + rest and "Exception ignored" not in seen + rest, seen + rest


def test_options_that_would_be_ignored_are_refused_and_one_worker_goes_with_threads(tmp_path):
    """`--ray auto --workers 2` dropped --workers without a word; `--threads 2 --workers 1` (one process, as the
    API accepts it) was refused."""
    base = [sys.executable, "-m", "cotwin", "sweep", str(PROJECT), "--event", "moveDiscreteCommand", "--arg",
            "target_X=0", "--arg", "target_Y=3", "--arg", "target_Z=0", "--horizon", "1", "-o", str(tmp_path / "a.csv")]
    ray = subprocess.run([*base, "--ray", "auto", "--workers", "2"], capture_output=True, text=True, timeout=120)
    assert ray.returncode == 2 and "--workers sizes the local pool of processes" in ray.stderr, ray.stderr
    one = subprocess.run([*base, "--threads", "2", "--workers", "1"], capture_output=True, text=True, timeout=300)
    assert one.returncode == 0, one.stderr
    assert "1 what-ifs" in one.stdout


def test_the_summary_says_how_many_threads_or_processes_ran(tmp_path):
    """`--threads 1024` on 2 what-ifs said '(this process, 1024 threads)', 2 having run, and a sweep of one what-if,
    run in this process, said 'local pool' (found by the hostile probe): it says what ran."""
    base = ["sweep", PROJECT, "--event", "moveDiscreteCommand", "--arg", "target_Y=3", "--arg", "target_Z=0",
            "--horizon", "1", "-o", tmp_path / "a.csv"]
    two = cotwin_in_process(*base, "--arg", "target_X=0..1", "--threads", "1024")
    assert two.returncode == 0 and "2 what-ifs in" in two.stdout and "(this process, 2 threads)" in two.stdout, two.stdout
    one = cotwin_in_process(*base, "--arg", "target_X=0")
    assert one.returncode == 0 and "(this process)" in one.stdout, one.stdout
