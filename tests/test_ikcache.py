"""The IK solution cache (cotwin.pmodel.ikcache): a hit gives the stored solution without solving, a miss
solves and stores, a file of another solver (stale) or one that cannot be read (corrupt) is ignored and
rewritten."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from cotwin.pmodel.ikcache import SolutionCache, cache_dir

FINGERPRINT = "ab" * 32
SOLUTION = {"q": {"j1": 0.5, "j2": -1.25}, "position_error": 1e-9, "angle_error": 2e-9, "iterations": 7}


def test_a_miss_is_stored_and_found_again(tmp_path):
    cache = SolutionCache(FINGERPRINT, tmp_path)
    key = SolutionCache.key([0.1, 0.2, 0.3])
    assert cache.get(key) is None and cache.loaded == 0
    cache.put(key, SOLUTION)
    cache.save()
    data = json.loads(cache.path.read_text())
    assert data == {"fingerprint": FINGERPRINT, "solutions": {key: SOLUTION}}
    again = SolutionCache(FINGERPRINT, tmp_path)
    assert again.loaded == 1 and again.get(key) == SOLUTION
    assert list(tmp_path.rglob("*.part")) == []  # written whole, then renamed


def test_a_file_of_another_solver_is_ignored_and_replaced(tmp_path):
    stale = "ab" * 16 + "ff" * 16  # the same file name (the first 32 characters), another solver
    old = SolutionCache(stale, tmp_path)
    old.put("k", SOLUTION)
    old.save()
    cache = SolutionCache(FINGERPRINT, tmp_path)
    assert cache.path == old.path and cache.loaded == 0 and cache.get("k") is None
    cache.put("k2", SOLUTION)
    cache.save()
    assert json.loads(cache.path.read_text())["fingerprint"] == FINGERPRINT


@pytest.mark.parametrize("text", ['{"fingerprint": "ab', "", "[1, 2]", "\xff\xfe", '{"fingerprint": null}',
                                  '{"fingerprint": "%s", "solutions": [1]}' % FINGERPRINT,
                                  '{"fingerprint": "%s", "solutions": {"k": "q"}}' % FINGERPRINT,
                                  '{"fingerprint": "%s", "solutions": {"k": {"q": {"j1": "x"}}}}' % FINGERPRINT,
                                  '{"fingerprint": "%s", "solutions": {"k": {"q": {"j1": 1.0}, "position_error": 0,'
                                  ' "angle_error": 0, "iterations": 1, "extra": 2}}}' % FINGERPRINT])
def test_a_file_that_cannot_be_read_is_ignored_and_rewritten(tmp_path, text):
    path = SolutionCache(FINGERPRINT, tmp_path).path
    path.parent.mkdir(parents=True)
    path.write_bytes(text.encode("utf-8", "surrogateescape") if "\xff" not in text else b"\xff\xfe")
    cache = SolutionCache(FINGERPRINT, tmp_path)
    assert cache.get("k") is None and cache.loaded == 0
    cache.put("k", SOLUTION)
    cache.save()
    assert SolutionCache(FINGERPRINT, tmp_path).get("k") == SOLUTION


def test_the_mapping_uses_a_stored_solution_without_solving_and_solves_a_miss(tmp_path, monkeypatch):
    """Through the mapping's function registry, as a twin uses it: the first registry solves the hole
    and stores it; a second one (a later run) finds it without calling the solver; a corrupt entry
    or another target is solved again."""
    from conftest import EXAMPLES

    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.mapping.runtime import FunctionRegistry
    from cotwin.pmodel import ik
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.assembly.run import load

    monkeypatch.setenv("COTWIN_CACHE", str(tmp_path))
    models = load(EXAMPLES / "ur5e" / "cotwin.toml").models

    def registry():
        return FunctionRegistry(SimulatedEndpoint(PlatformSimulator(models.tree, models.scene)))

    first = registry()
    q = first.inverse_kinematics(0.3, 0.4, 0.05)
    first.stored.save()
    files = list((tmp_path / "ik").glob("*.json"))
    assert len(files) == 1 and first.stored.loaded == 0

    def unsolvable(self, target):
        raise AssertionError("solved again: the stored solution was not used")

    with monkeypatch.context() as m:
        m.setattr(ik.Solver, "branch", unsolvable)
        second = registry()
        assert second.stored.loaded == 1
        assert np.allclose(second.inverse_kinematics(0.3, 0.4, 0.05), q, atol=0)  # a hit: exactly the same
        with pytest.raises(AssertionError, match="solved again"):
            second.inverse_kinematics(0.3, 0.5, 0.05)  # a miss: solved
    data = json.loads(files[0].read_text())
    data["solutions"] = {k: {"q": "garbage"} for k in data["solutions"]}
    files[0].write_text(json.dumps(data))
    third = registry()  # a corrupt entry: solved again, not a crash
    assert np.allclose(third.inverse_kinematics(0.3, 0.4, 0.05), q, atol=1e-9)



def test_caches_of_one_file_saved_in_turn_keep_each_others_solutions(tmp_path):
    """A threaded sweep's forks each solve their holes into a cache of the same file: the last one saved wrote only
    its own (a cold 16-hole sweep on 4 threads left 4 of its 16 solutions, the others solved again next time)."""
    first, second = SolutionCache(FINGERPRINT, tmp_path), SolutionCache(FINGERPRINT, tmp_path)
    first.put("a", SOLUTION)
    second.put("b", SOLUTION)
    first.save()
    second.save()
    again = SolutionCache(FINGERPRINT, tmp_path)
    assert again.loaded == 2 and again.get("a") == again.get("b") == SOLUTION


def test_a_process_saving_the_file_meanwhile_keeps_its_solutions(tmp_path, monkeypatch):
    """A pool's workers end their chunks at once: another process saving between this one's reading the file and
    writing it lost its solutions (the lock of 407dcd5 held only this process's threads)."""
    import subprocess
    import sys

    from cotwin.pmodel import ikcache

    child = ("import sys; from cotwin.pmodel.ikcache import SolutionCache; from pathlib import Path; "
             f"c = SolutionCache({FINGERPRINT!r}, Path(sys.argv[1])); c.put('b', {SOLUTION!r}); "
             "print('ready', flush=True); c.save()")
    read = ikcache._stored
    other = []

    def meanwhile(path, fingerprint):  # this save has read the file: the other process saves now
        found = read(path, fingerprint)
        proc = subprocess.Popen([sys.executable, "-c", child, str(tmp_path)], stdout=subprocess.PIPE, text=True,
                                env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
        assert proc.stdout.readline().strip() == "ready"
        try:
            proc.wait(timeout=1.5)  # done at once unless it waits for this save
        except subprocess.TimeoutExpired:
            pass
        other.append(proc)
        return found

    first = SolutionCache(FINGERPRINT, tmp_path)
    first.put("a", SOLUTION)
    monkeypatch.setattr(ikcache, "_stored", meanwhile)
    first.save()
    monkeypatch.setattr(ikcache, "_stored", read)
    assert other[0].wait(timeout=60) == 0
    again = SolutionCache(FINGERPRINT, tmp_path)
    assert again.loaded == 2 and again.get("a") == again.get("b") == SOLUTION
