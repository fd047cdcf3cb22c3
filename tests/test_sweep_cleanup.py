"""A sweep's scratch folder (the d-model FMU its workers share, when no `artefacts` folder is given) is removed
however the sweep ends, the what-ifs answered kept; and a threaded sweep says when it asks for many more threads
than the machine has CPUs, or than its memory holds at what a fork was measured to take."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import shutil
import time
from pathlib import Path

import pytest

from conftest import EXAMPLES
from cotwin.twin.analysis import sweep, thread_budget
from cotwin.twin.analysis.sweep import SweepInterrupted, grid, run_sweep
from cotwin.twin.analysis.thread_budget import MB, thread_warnings
from cotwin.twin.assembly.run import load

PROJECT = EXAMPLES / "ur5e" / "cotwin.toml"


@pytest.fixture
def scratch_root(tmp_path, monkeypatch):
    """The folder a sweep's scratch folder is made in (tempfile's; other temporary files are made there too)."""
    root = tmp_path / "tmp"
    root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(root))
    return root


def _plans(n: int):
    return grid(load(PROJECT).models.program, "moveDiscreteCommand",
                {"target_X": list(range(n)), "target_Y": [0], "target_Z": [0]})


def _interrupted(**options) -> SweepInterrupted:
    """The SweepInterrupted a sweep of the UR5e's project ends with (a bare KeyboardInterrupt, its answers lost,
    fails the test rather than ending pytest's session)."""
    try:
        run_sweep(PROJECT, **options)
    except SweepInterrupted as err:
        return err
    except KeyboardInterrupt:
        pytest.fail("the sweep ended with a bare KeyboardInterrupt: the answers so far lost")
    pytest.fail("the sweep was not interrupted")


def _sweep_threads_end(timeout: float = 120.0) -> None:
    """Wait for the threads a sweep left running (a second interrupt does not wait for them)."""
    for thread in [t for t in threading.enumerate() if t.name.startswith("cotwin-sweep-")]:
        thread.join(timeout)


def test_a_second_interrupt_leaves_no_scratch_folder_behind_the_threads_it_did_not_wait_for(scratch_root, monkeypatch):
    """Ctrl-C twice: the sweep ended at once and removed its scratch folder while a thread was still in its what-if,
    which then set up its fork and built the d-model FMU again in a folder made anew, left behind for good."""
    plain, first = sweep._run, threading.Event()

    def held(plan, *args, **kwargs):
        if threading.current_thread().name == "cotwin-sweep-0":  # answers at once
            row = plain(plan, *args, **kwargs)
            first.set()
            return row
        first.wait()
        threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()
        threading.Timer(0.6, os.kill, (os.getpid(), signal.SIGINT)).start()
        time.sleep(1.5)  # still in its first what-if (its fork not set up yet) as the sweep ends
        return plain(plan, *args, **kwargs)

    monkeypatch.setattr(sweep, "_run", held)
    caught = _interrupted(plans=_plans(4), horizon=1.0, threads=2)
    assert caught.running == 1 and len(caught.rows) >= 1  # the answers so far are kept
    assert list(scratch_root.glob("cotwin-sweep-*"))  # held by the thread still in its what-if
    _sweep_threads_end()
    assert list(scratch_root.glob("cotwin-sweep-*")) == []


def test_an_interrupt_as_the_scratch_folder_is_removed_keeps_the_answers_and_removes_it_all(scratch_root, monkeypatch):
    """A Ctrl-C reaching the sweep's clean-up stopped the removal (part of the folder left) and turned the finished
    sweep into a bare KeyboardInterrupt: every answer lost."""
    plain, calls = shutil.rmtree, []

    def interrupted(path, *args, **kwargs):
        if Path(path).name.startswith("cotwin-sweep-"):
            calls.append(path)
            if len(calls) == 1:
                raise KeyboardInterrupt  # as Ctrl-C would, before anything is removed
        return plain(path, *args, **kwargs)

    monkeypatch.setattr(shutil, "rmtree", interrupted)
    caught = _interrupted(plans=_plans(2), horizon=1.0, workers=1)
    assert len(caught.rows) == caught.total == 2 and len(calls) == 2
    assert list(scratch_root.glob("cotwin-sweep-*")) == []


def test_a_second_interrupt_while_the_pool_stops_keeps_the_answers_and_removes_the_scratch_folder(scratch_root,
                                                                                                  monkeypatch):
    """Ctrl-C, then Ctrl-C again while the pool's workers were being stopped: a bare KeyboardInterrupt, the answers
    lost. Here the first interrupt comes once a chunk is answered, the second from the workers' stopping."""
    plain = sweep._stop

    def stopped_again(pool):
        plain(pool)
        raise KeyboardInterrupt

    def progress(done, total):
        if done:
            raise KeyboardInterrupt

    monkeypatch.setattr(sweep, "_stop", stopped_again)
    caught = _interrupted(plans=_plans(2), horizon=1.0, workers=2, progress=progress)
    assert len(caught.rows) >= 1 and caught.total == 2
    assert list(scratch_root.glob("cotwin-sweep-*")) == []


def test_a_failing_sweep_removes_its_scratch_folder(scratch_root, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("a thread's own failure")

    monkeypatch.setattr(sweep, "_forks", broken)
    with pytest.raises(RuntimeError, match="a thread's own failure"):
        run_sweep(PROJECT, _plans(2), horizon=1.0, threads=2)
    assert list(scratch_root.glob("cotwin-sweep-*")) == []


def test_threads_are_judged_against_the_cpus_and_the_memory_a_fork_takes():
    assert thread_warnings(4, 2, 10 * MB, 8000 * MB) == []  # twice the CPUs: no word
    [cpus] = thread_warnings(5, 2, 10 * MB, 8000 * MB)
    assert cpus.startswith("5 threads on 2 CPUs: ") and "no faster than with 2" in cpus
    [memory] = thread_warnings(3, 2, 100 * MB, 250 * MB)
    assert memory.startswith("3 threads need about 300 MB of memory, more than the 250 MB available: ")
    assert "about 100.0 MB" in memory and "about 2 threads fit" in memory
    assert thread_warnings(3, 2, None, 250 * MB) == thread_warnings(3, 2, 100 * MB, None) == []  # not known: not judged


def test_a_threaded_sweep_measures_a_fork_and_warns_where_its_threads_do_not_fit(tmp_path, monkeypatch):
    """The fork is measured on the process (what a second fork adds); the machine's figures are the test's."""
    monkeypatch.setattr(thread_budget, "usable_cpus", lambda: 1)
    measured = []
    plain = sweep.fork_footprint

    def footprint(*args, **kwargs):
        measured.append(plain(*args, **kwargs))
        return measured[-1]

    monkeypatch.setattr(sweep, "fork_footprint", footprint)
    monkeypatch.setattr(thread_budget, "available_memory", lambda: 1)  # no room at all
    said = []
    rows = run_sweep(PROJECT, _plans(3), horizon=1.0, threads=3, artefacts=tmp_path, warn=said.append)
    assert len(rows) == 3 and not [r for r in rows if r.get("error")]
    [per_thread] = measured
    assert per_thread is not None and 0 <= per_thread < 500 * MB  # a fork of the UR5e's twin: a few MB
    assert said[0].startswith("3 threads on 1 CPU: ")
    if per_thread:
        assert said[1].startswith(f"3 threads need about {3 * per_thread / MB:.0f} MB of memory, more than the 0 MB")
    said.clear()
    monkeypatch.setattr(thread_budget, "usable_cpus", lambda: 2)  # as many threads as CPUs: nothing measured
    run_sweep(PROJECT, _plans(2), horizon=1.0, threads=2, artefacts=tmp_path, warn=said.append)
    assert said == [] and len(measured) == 1


def test_the_cli_says_where_too_many_threads_were_asked_for(tmp_path):
    cpus = thread_budget.usable_cpus()
    many = 2 * cpus + 1
    proc = subprocess.run([sys.executable, "-m", "cotwin", "sweep", str(PROJECT), "--event", "moveDiscreteCommand",
                           "--arg", f"target_X=0..{many - 1}", "--arg", "target_Y=0", "--arg", "target_Z=0",
                           "--horizon", "1", "--threads", str(many), "-o", str(tmp_path / "a.csv")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert f"warning: --threads {many}: {many} threads on {cpus} CPU" in proc.stderr
    assert f"{many} what-ifs" in proc.stdout


def test_an_interrupted_pool_keeps_the_answers_of_its_chunks_in_hand(scratch_root):
    """Ctrl-C during a process-pool sweep kept only the chunks already collected: the chunks the workers had
    answered meanwhile, or half answered, were dropped (up to 64 what-ifs each). Here the interrupt comes 3 s
    after the first chunk is collected: the workers' answers of those 3 s are kept, each with its grid point."""
    def progress(done, total):
        if done:
            time.sleep(3)  # the workers answer on meanwhile
            raise KeyboardInterrupt

    plans = _plans(1024)  # chunks of 64 on 2 workers
    caught = _interrupted(plans=plans, horizon=1.0, workers=2, progress=progress)
    xs = [next(v for k, v in row.items() if k.endswith("target_X")) for row in caught.rows]
    assert len(xs) > 64 and caught.total == 1024
    assert xs == sorted(set(xs))  # in the plans' order, none twice
    assert list(scratch_root.glob("cotwin-sweep-*")) == []


_FOOTPRINT = """
import json, sys, tempfile
from cotwin.twin.analysis.sweep import _forks, fork_footprint
from cotwin.twin.assembly.run import load

system = load(sys.argv[1])
with tempfile.TemporaryDirectory() as tmp:
    with _forks(None, None, None, (system, tmp)) as forks:
        forks.predict([], horizon=system.spec.step)
        memos = [memo.full for memo in forks.memos]
    print(json.dumps([memos, fork_footprint((system, tmp), [], None, None)]))
"""


def _mujoco_without_headers(folder: Path) -> Path:
    """The installed MuJoCo package without its C headers (links to its files but include/), as pip can leave it:
    a model's digest cannot be made, so no simulator has a memo of held steps (cotwin.pmodel.memo.remembers)."""
    import mujoco

    package = folder / "mujoco"
    package.mkdir(parents=True)
    for entry in Path(mujoco.__file__).parent.iterdir():
        if entry.name != "include":
            (package / entry.name).symlink_to(entry)
    return folder


@pytest.mark.parametrize("headers", [True, False], ids=["memo", "no-memo"])
def test_a_forks_footprint_counts_a_memo_of_held_steps_only_where_the_fork_has_one(tmp_path, headers):
    """fork_footprint added a memo's budget (8 MB) to what a second fork was measured to take, also where the fork
    has no memo (here MuJoCo without its headers): a sweep judged such a fork at 20 times what it takes and warned
    that threads which fit would not. A fork with a memo counts what that memo takes once full."""
    import json

    import cotwin
    from cotwin.pmodel import memo

    src = str(Path(cotwin.__file__).parents[1])
    path = src if headers else os.pathsep.join([str(_mujoco_without_headers(tmp_path / "site")), src])
    proc = subprocess.run([sys.executable, "-c", _FOOTPRINT, str(PROJECT)], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": path}, timeout=300)
    assert proc.returncode == 0, proc.stderr
    memos, footprint = json.loads(proc.stdout.splitlines()[-1])
    if headers:
        assert len(memos) == 1 and 0 < memos[0] <= memo.BUDGET and footprint >= memos[0]
    else:
        assert memos == [] and footprint is not None and footprint < memo.BUDGET  # a few hundred KB
