"""The bound on cotwin's cache (cotwin.cache): least recently used rebuildable entries evicted when cotwin writes a
new one over COTWIN_CACHE_MAX_MB, never one in use by a running process; an entry removed while another process
wants it is built again, without an error."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from cotwin import cache, cbuild
from cache_entries import HOUR, entry
from cotwin.files import MiB


@pytest.fixture
def root(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv("COTWIN_CACHE", str(folder))
    monkeypatch.delenv("COTWIN_CACHE_MAX_MB", raising=False)
    return folder


# ---- the bound -----------------------------------------------------------------------------------

def test_the_bound_evicts_the_least_recently_used_and_keeps_the_newest(root):
    old = [entry(root, "native", n, 300 * 1024, age=HOUR * (10 - n)) for n in range(3)]  # n = 0 the oldest
    fmu = entry(root, "fmu", 1, 300 * 1024, age=HOUR * 20)  # the oldest of all
    ik = entry(root, "ik", 1, 300 * 1024, age=HOUR * 30)  # older still, but not rebuildable
    new = entry(root, "binaries", 1, 300 * 1024, age=0)
    removed = cache.evict(root, cap=1 * MiB, keep=new)  # 6 x 300 KiB: three go
    assert sorted(e.path for e in removed) == sorted([fmu, old[0], old[1]])
    assert not fmu.exists() and not old[0].exists() and not old[1].exists()
    assert old[2].is_file() and ik.is_file() and new.is_file()


def test_an_entry_used_recently_is_evicted_after_an_older_one(root):
    first, second = entry(root, "binaries", 1, 600 * 1024, age=2 * HOUR), entry(root, "binaries", 2, 600 * 1024, age=HOUR)
    cache.touch(first)  # copied out by a build just now
    os.utime(first, (time.time() - 2 * cache.FRESH,) * 2)
    assert [e.path for e in cache.evict(root, cap=1 * MiB)] == [second]


def test_writing_a_new_library_bounds_the_cache(root, monkeypatch):
    """The bound runs when cotwin writes an entry: an edited model per day left a library per edit, without end."""
    if cbuild.compiler() is None:
        pytest.skip("no C compiler")
    stale = [entry(root, "native", n, 1 * MiB, age=HOUR * (n + 1)) for n in range(3)]
    monkeypatch.setenv("COTWIN_CACHE_MAX_MB", "1.5")
    assert cbuild.compile_library(f"int cotwin_bound(void) {{ return {time.time_ns() % 1000}; }}\n", "bound")
    assert [p.exists() for p in stale] == [True, False, False]  # the two least recently used went: 1 MiB and the new one left
    assert len(list((root / "native").glob("bound-*.so"))) == 1


def test_an_entry_in_use_by_another_process_or_fresh_is_never_evicted(root):
    used = entry(root, "fmu", 1, 1000, age=5 * HOUR)
    fresh = entry(root, "native", 2, 1000, age=1)
    idle = entry(root, "native", 3, 1000, age=HOUR)
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        from cotwin.cache import hold
        held = hold({str(used)!r})
        print("held" if held else "not held", flush=True)
        sys.stdin.read()
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        os.utime(used, (time.time() - 5 * HOUR,) * 2)  # its hold marked it used: made old again
        assert [e.path for e in cache.evict(root, cap=0)] == [idle]
        assert used.is_dir() and fresh.is_file()
        cleared = cache.clear(root)  # --clear keeps it too
        assert used.is_dir() and [e.path for e in cleared.kept] == [used]
    finally:
        holder.communicate("", timeout=30)
    assert [e.path for e in cache.evict(root, cap=0)] == [used]  # its process ended


@pytest.mark.parametrize("setting", ["missing", "a file", "read-only"])
def test_the_bound_never_fails(root, monkeypatch, setting):
    """The cache is an optimisation: a cache removed meanwhile, a file, or one that cannot be written is no error."""
    if setting == "a file":
        root.write_text("x")
    elif setting == "read-only":  # chmod does not stop root: the refusal made by hand
        entry(root, "native", 1, 1000)

        def refused(*args, **kwargs):
            raise PermissionError(13, "Permission denied")

        monkeypatch.setattr(os, "unlink", refused)
    monkeypatch.setenv("COTWIN_CACHE_MAX_MB", "0")
    cache.bound()
    monkeypatch.setenv("COTWIN_CACHE_MAX_MB", "lots")  # a wrong value: the default
    cache.bound()
    assert cache.read_cap({"COTWIN_CACHE_MAX_MB": "lots"})[0] == 512 * MiB


# ---- an entry removed while another process wants it ---------------------------------------------

@pytest.mark.skipif(cbuild.compiler() is None, reason="no C compiler")
def test_a_library_removed_between_being_found_and_loaded_is_built_again(root, monkeypatch):
    source = f"int cotwin_again(void) {{ return {time.time_ns() % 1000 + 1}; }}\n"
    expected = cbuild.compile_library(source, "again").cotwin_again()
    kept = next(root.glob("native/again-*.so"))
    cbuild._LOADED.pop(kept).release()  # as another process would: found in the cache, not yet held
    real = cache.hold
    evicted = []

    def removed_first(path):  # another process's eviction comes between finding the file and holding it
        if not evicted:
            evicted.append(path)
            os.unlink(path)
        return real(path)

    monkeypatch.setattr(cbuild, "hold", removed_first)
    assert cbuild.compile_library(source, "again").cotwin_again() == expected
    assert evicted == [kept] and kept.is_file()  # built again, and kept


@pytest.mark.skipif(cbuild.compiler() is None, reason="no C compiler")
def test_an_extracted_fmu_is_kept_while_run_and_one_being_removed_is_extracted_again(root, tmp_path):
    """A twin runs for days on an FMU extracted once: the bound must not remove it under the run. An FMU found
    in the cache while an eviction removes it (its exclusive lock) is extracted again, and runs."""
    import fcntl

    from conftest import EXAMPLES
    from cotwin.cosim.units import FMUUnit
    from cotwin.dmodel.fmu import build_fmu
    from cotwin.dmodel.program import build_program
    from cotwin.robosim.check import load_checked

    fmu = build_fmu(build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"])), tmp_path / "arm.fmu")
    running = FMUUnit("a", fmu)
    running.instantiate(0.0)
    try:
        folder = Path(running.folder)
        assert folder.parent == root / "fmu"
        os.utime(folder, (time.time() - HOUR,) * 2)
        assert folder not in [e.path for e in cache.evict(root, cap=0)]
        running.initialize()
        running.step(0.0, 1.0)
    finally:
        running.terminate()
    fd = os.open(folder, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)  # an eviction of it under way
    try:
        late = FMUUnit("b", fmu)
        late.instantiate(0.0)
        assert Path(late.folder) != folder and Path(late.folder, "modelDescription.xml").is_file()
        late.initialize()
        late.step(0.0, 1.0)
        late.terminate()
    finally:
        os.close(fd)
    assert folder in [e.path for e in cache.evict(root, cap=0, now=time.time() + HOUR)]  # no run holds it now


@pytest.mark.skipif(cbuild.compiler() is None, reason="no C compiler")
def test_processes_loading_libraries_while_the_cache_is_cleared_never_fail(root):
    """Two processes build and load libraries while this one clears the cache over and over: each library is
    loaded (from the cache, or built again), and nothing fails."""
    script = textwrap.dedent("""
        import sys
        from cotwin import cbuild
        for i in range(6):
            source = f"int cotwin_v{i}(void) {{ return {i} + %s; }}\\n"
            assert getattr(cbuild.compile_library(source, "race"), f"cotwin_v{i}")() == i + %s
        print("ok")
        """)
    workers = [subprocess.Popen([sys.executable, "-c", script % (w, w)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True) for w in range(2)]
    clears = 0
    while any(w.poll() is None for w in workers):
        try:
            cache.clear(root)
        except Exception as err:  # noqa: BLE001 - the clearing side may not fail either
            pytest.fail(f"clear failed: {err}")
        clears += 1
    for w in workers:
        out, err = w.communicate(timeout=120)
        assert w.returncode == 0 and out.strip() == "ok" and "Traceback" not in err, err
    assert clears > 1
