"""What conftest gives every test session: a cotwin cache of its own, and at the end the tests skipped
counted by cause."""

from __future__ import annotations

import os
from pathlib import Path

from cotwin.pmodel.ikcache import cache_dir


def test_the_session_has_a_cache_of_its_own():
    folder = cache_dir()
    assert folder is not None and folder != Path.home() / ".cache" / "cotwin"
    assert str(folder) == os.environ["COTWIN_CACHE"] and folder.name.startswith("cotwin-test-cache-")


def test_a_run_ends_with_its_skips_counted_by_cause(tmp_path):
    """conftest's summary: a user's `make test` says at the end how many tests skipped and why, one line
    per cause (the service, ../shared, or the reason itself), as seen in a session of its own."""
    import shutil
    import subprocess
    import sys

    from conftest import ROOT

    (tmp_path / "tests").mkdir()
    shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "tests" / "conftest.py")
    (tmp_path / "tests" / "test_some.py").write_text('''import pytest

@pytest.mark.parametrize("k", range(3))
def test_needs_the_broker(k):
    pytest.skip("no RabbitMQ on 127.0.0.1:5672 (start it with: rabbitmq-server -detached)")

def test_needs_shared():
    pytest.skip("the paper's published models are not at /x/shared/robosim (only in the project workspace)")

def test_other():
    pytest.skip("a reason of its own")

def test_runs():
    pass
''')
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "COTWIN_TEST_SESSION_CACHE")}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, env=env)
    lines = proc.stdout.splitlines()
    start = next(k for k, line in enumerate(lines) if "5 test(s) skipped, by cause" in line)
    assert [line.split(None, 1) for line in lines[start + 1:start + 4]] == [
        ["3", "RabbitMQ is not running on 127.0.0.1:5672"],
        ["1", "../shared (the paper's models and the UR5e's log) is not beside the clone"],
        ["1", "a reason of its own"]]
    assert lines[-1].startswith("1 passed, 5 skipped")  # the summary is the last thing before the totals
