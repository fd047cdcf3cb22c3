"""A process that ran Python FMUs exits cleanly: pythonfmu's exit-time use-after-free is not reached.

pythonfmu's export library frees its interpreter guard twice at process exit when it could not be unloaded
(valgrind: "Invalid read ... finalizePythonInterpreter ... free'd in __run_exit_handlers"); glibc sometimes
aborts on it ("corrupted double-linked list", exit -6) after every row was written, which failed a CI run of
`cotwin simulate`. cotwin.cosim.pythonfmu_exit releases the guard from an atexit hook. Memcheck sees the
invalid access on every run, where the abort itself is a matter of heap layout, so the test runs under it.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from conftest import EXAMPLES
from cotwin.cosim.pythonfmu_exit import SYMBOL
from cotwin.twin.assembly.build import build
from cotwin.twin.assembly.run import load

SCRIPT = """
import sys
from cotwin.cosim.units import FMUUnit
units = [FMUUnit(name, f"{sys.argv[1]}/{name}.fmu") for name in ("mapping", "controller")]
for unit in units:
    unit.instantiate(0.0)
    unit.initialize()
for unit in units:
    unit.step(0.0, 0.01)
for unit in units:
    unit.terminate()  # removes the extraction folder: the hook must still find the library
print("ran")
"""


@pytest.fixture(scope="module")
def python_fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("twin")
    build(load(EXAMPLES / "ur5e" / "cotwin.toml"), out)
    return out


def test_the_exit_hook_finds_the_pythonfmu_library_of_a_freed_unit(python_fmus):
    """After a unit is freed and its folder removed, its library is still mapped and still found by name;
    the hook releases its guard (a count, so a hook that found nothing would fail here). In a process of its
    own: releasing the guards changes the process's native pythonfmu state."""
    code = SCRIPT + """
from cotwin.cosim.pythonfmu_exit import loaded_libraries, release_guards
print("mapped", sum(path.endswith("CotwinUnit.so") for path in loaded_libraries()))
print("released", release_guards())
"""
    proc = subprocess.run([sys.executable, "-c", code, str(python_fmus)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    said = dict(line.split() for line in proc.stdout.splitlines() if line.startswith(("mapped", "released")))
    assert int(said["mapped"]) >= 1 and int(said["released"]) == int(said["mapped"]), proc.stdout


def _valgrind() -> str | None:
    """valgrind's path; in CI (CI set) its absence is a failure, not a skip: .ci/run installs it."""
    found = shutil.which("valgrind")
    if found is None and os.environ.get("CI"):
        pytest.fail("valgrind is not installed, and CI must run this test (.ci/run installs it: apt-get install valgrind)")
    return found


def test_python_fmus_run_in_process_exit_without_an_invalid_access(python_fmus):
    """Two Python FMUs run and freed in one process: memcheck reports no invalid access in pythonfmu's exit
    path (the defect: without the hook, one 'Invalid read' in finalizePythonInterpreter on every run)."""
    valgrind = _valgrind()
    if valgrind is None:
        pytest.skip("valgrind is not installed (apt-get install -y valgrind; .ci/run installs it)")
    proc = subprocess.run([valgrind, "--error-limit=no", sys.executable, "-c", SCRIPT, str(python_fmus)],
                          capture_output=True, text=True, env={"PYTHONMALLOC": "malloc", "PATH": "/usr/bin:/bin"},
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "ran" in proc.stdout
    invalid = [block for block in proc.stderr.split("==\n") if "Invalid" in block and SYMBOL in block]
    assert invalid == [], invalid[0][-3000:]
