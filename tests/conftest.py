"""Shared fixtures: where the paper's published models are, our own examples, the loopback services;
a fresh cotwin cache for the session; and, at the end of a run, the tests skipped grouped by cause."""

from __future__ import annotations

import contextlib
import fcntl
import os
import secrets
import random
import re
import shutil
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

import pytest

# The tests' Ray clusters are single nodes on 127.0.0.1 (on Linux, Ray otherwise registers its nodes at
# the machine's outward address), with token authentication, as `ray start` sets one up by default, which
# a driver joins only with RAY_AUTH_MODE=token (read once per process, so set before Ray is imported).
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
os.environ.setdefault("RAY_AUTH_MODE", "token")
# the tests' Ray heads and drivers share one token of this session (Ray also looks in ~/.ray/auth_token, which a
# fresh machine does not have and the tests should not write)
os.environ.setdefault("RAY_AUTH_TOKEN", secrets.token_hex(32))

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
SHARED = ROOT.parent / "shared" / "robosim"


@pytest.fixture
def published() -> Path:
    """The paper's models, read unchanged from ../shared (absent in a user's fresh clone)."""
    if not (SHARED / "ur5e" / "ur5e_gripper.rst").is_file():
        pytest.skip(f"the paper's published models are not at {SHARED} (only in the project workspace)")
    return SHARED


@pytest.fixture
def ur5e_example() -> Path:
    return EXAMPLES / "ur5e"


@pytest.fixture
def check_texts(tmp_path):
    """Write model texts into a fresh folder and check them as one project."""
    from cotwin.robosim.check import check_paths

    def run(files: dict[str, str]):
        for name, text in files.items():
            (tmp_path / name).write_text(text)
        return check_paths([tmp_path])

    return run


def one_machine(inputs: tuple[str, ...], body: str, outputs: tuple[str, ...] = ("report: int",)) -> str:
    """A d-model's text: state machine M in controller C in module Mod, taking the input events `inputs` and sending
    `outputs` (each "name" or "name: type"), each asynchronous at the platform; `body` is M's variables, states and
    transitions, which start at line 10 (where a test reads a finding's line)."""
    ins, outs = ([d.split(":")[0].strip() for d in decls] for decls in (inputs, outputs))
    events = " ".join(f"event {d}" for d in (*inputs, *outputs))
    return (f"interface Ev {{ {events} }}\n"
            "controller C { uses Ev sref m = M\n"
            f"\t{' '.join(f'connection C on {e} to m on {e}' for e in ins)} "
            f"{' '.join(f'connection m on {e} to C on {e}' for e in outs)} }}\n"
            "module Mod { robotic platform P { uses Ev } cref c = C\n"
            f"\t{' '.join(f'connection P on {e} to c on {e} (_async)' for e in ins)}\n"
            f"\t{' '.join(f'connection c on {e} to P on {e} (_async)' for e in outs)} }}\n"
            "stm M {\n"
            "\tinput context { uses Ev }\n"
            "\toutput context { uses Ev }\n"
            f"{body.lstrip(chr(10))}}}\n")


@pytest.fixture
def ur_rtde(monkeypatch):
    """ur-rtde's two client classes, standing in for a UR controller whose arm is at rest at zero; the control
    client keeps each moveJ's joints in `moves` (an RTDEEndpoint's `control.moves`)."""
    import types

    class Receive:
        def __init__(self, host):
            pass

        def getActualQ(self):
            return [0.0] * 6

        def getActualQd(self):
            return [0.0] * 6

    class Control:
        def __init__(self, host):
            self.moves = []

        def moveJ(self, q, speed, acceleration, asynchronous):
            self.moves.append(list(q))

    monkeypatch.setitem(sys.modules, "rtde_receive", types.SimpleNamespace(RTDEReceiveInterface=Receive))
    monkeypatch.setitem(sys.modules, "rtde_control", types.SimpleNamespace(RTDEControlInterface=Control))


def listening(port: int, host: str = "127.0.0.1") -> bool:
    import socket

    try:
        with socket.create_connection((host, port), timeout=1):
            return True
    except OSError:
        return False


def _service(port: int, name: str, start: str) -> None:
    import os

    if not listening(port):
        if os.environ.get("CI"):
            pytest.fail(f"{name} is not listening on 127.0.0.1:{port} (.ci/run should have started it)")
        pytest.skip(f"no {name} on 127.0.0.1:{port} (start it with: {start})")


@pytest.fixture(scope="session")
def broker():
    """RabbitMQ on loopback: a test that needs it skips, saying why, where it is not running (and fails
    under CI, whose .ci/run starts it)."""
    _service(5672, "RabbitMQ", "rabbitmq-server -detached")


@contextlib.contextmanager
def machine_lock(name: str):
    """Held by one test process of this machine at a time (`make test` runs its files on pytest-xdist's
    workers): for what is one per machine, e.g. Ray, whose `ray stop --force` ends every cluster here."""
    with open(Path(tempfile.gettempdir()) / f"cotwin-tests-{name}.lock", "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(held, fcntl.LOCK_UN)


@pytest.fixture
def ray_alone():
    """This test's Ray cluster is the only one on the machine while it runs (see machine_lock)."""
    with machine_lock("ray"):
        yield


@pytest.fixture(scope="session")
def postgres_server():
    _service(5432, "PostgreSQL", "pg_ctlcluster --skip-systemctl-redirect $(ls /etc/postgresql) main start")


@pytest.fixture
def postgres_database(postgres_server):
    """A fresh database on the loopback PostgreSQL, dropped afterwards: (its URL, its name)."""
    import uuid

    import psycopg

    name = f"cotwin_test_{uuid.uuid4().hex[:8]}"
    with psycopg.connect("host=127.0.0.1 user=postgres dbname=postgres", autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    yield f"postgresql://postgres@127.0.0.1:5432/{name}", name
    with psycopg.connect("host=127.0.0.1 user=postgres dbname=postgres", autocommit=True) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


# ---- one fresh cache per test session -------------------------------------------------------------
# cotwin caches IK solutions in $COTWIN_CACHE (else ~/.cache/cotwin): tests that shared the user's cache
# depended on what earlier runs had solved. Every test session gets its own, empty, inherited by the
# commands the tests run; tests of the cache itself point it elsewhere.
_SESSION_CACHE = os.environ.get("COTWIN_TEST_SESSION_CACHE") or tempfile.mkdtemp(prefix="cotwin-test-cache-")
os.environ["COTWIN_TEST_SESSION_CACHE"] = os.environ["COTWIN_CACHE"] = _SESSION_CACHE  # once, however imported

# ---- one seed for every random test case of the session, printed in the header ----------------------
FUZZ_SEED = int(os.environ.get("COTWIN_FUZZ_SEED") or random.SystemRandom().randrange(2 ** 32))
os.environ["COTWIN_FUZZ_SEED"] = str(FUZZ_SEED)


def pytest_report_header(config) -> str:
    return (f"fuzz seed: {FUZZ_SEED} (COTWIN_FUZZ_SEED={FUZZ_SEED} repeats this run's random cases); "
            f"IK cache: {_SESSION_CACHE}")


def pytest_unconfigure(config) -> None:
    if not hasattr(config, "workerinput"):  # under pytest-xdist the workers share it: the controller removes it
        shutil.rmtree(_SESSION_CACHE, ignore_errors=True)


# ---- the longest test files first -------------------------------------------------------------------
# `make test` hands whole files to pytest-xdist's workers in collection order (--no-loadscope-reorder: not by
# their numbers of tests): a long file handed out last ran alone while the other worker idled (two minutes of a
# 15-minute suite). These, measured the longest (tens of seconds to two minutes each: a C compiler per random
# model, valgrind, a fleet of 8 twins), go first; every other file keeps its place, the tests in a file theirs.
LONGEST_FIRST = ("test_dmodel_random.py", "test_pythonfmu_exit.py", "test_fleet.py", "test_cli_e2e.py",
                 "test_testgen.py", "test_flexcell2.py", "test_frontend_fuzz.py", "test_whatif.py", "test_native.py")


def pytest_collection_modifyitems(config, items) -> None:
    """On pytest-xdist's workers only (each collects, all alike; the controller does not): a run on one process
    keeps the order it always had, files as collected. A worker is told by its config, as in pytest_unconfigure,
    not by PYTEST_XDIST_WORKER, which a pytest the tests start (test_session) inherits."""
    if not hasattr(config, "workerinput"):
        return
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest as collected


# ---- why tests skipped, grouped by cause -------------------------------------------------------------
_CAUSES = [  # (pattern in a skip reason, the cause it is counted under; None: the reason is its own cause)
    (r"COTWIN_[A-Z_]+ is not set", None),  # reference data a variable names (it may mention ../shared)
    (r"RabbitMQ", "RabbitMQ is not running on 127.0.0.1:5672"),
    (r"PostgreSQL", "PostgreSQL is not running on 127.0.0.1:5432"),
    (r"chromium", "Debian's chromium is not at /usr/bin/chromium"),
    (r"shared|published|recorded|only in the project workspace", "../shared (the paper's models and the UR5e's log) is not beside the clone"),
]


def skip_cause(reason: str) -> str:
    reason = reason.removeprefix("Skipped: ")
    for pattern, cause in _CAUSES:
        if re.search(pattern, reason, re.IGNORECASE):
            return cause or reason
    return reason


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """How many tests skipped and why, grouped by cause (a user's machine without the services or
    ../shared skips their tests: said here, at the very end, not only in -ra's per-test lines)."""
    yield
    if exitstatus not in (0, 5):  # -q shows no header: a failing run names its random cases here
        terminalreporter.line(f"fuzz seed: {FUZZ_SEED} (COTWIN_FUZZ_SEED={FUZZ_SEED} repeats this run's random cases)")
    skipped = terminalreporter.stats.get("skipped", [])
    if not skipped:
        return
    causes = Counter()
    for report in skipped:
        longrepr = report.longrepr
        reason = longrepr[2] if isinstance(longrepr, tuple) and len(longrepr) == 3 else str(longrepr)
        causes[skip_cause(reason)] += 1
    terminalreporter.section(f"{len(skipped)} test(s) skipped, by cause")
    for cause, n in causes.most_common():
        terminalreporter.line(f"{n:5d}  {cause}")


# ---- each d-model compiled once per session -----------------------------------------------------------
# cotwin keeps every d-model it compiles in its cache, by the sources and the compiler
# (cotwin.dmodel.fmu.compile_binary); the session's COTWIN_CACHE above makes that one cache for the whole run,
# in this process and the commands it starts.


# ---- `cotwin` in this process ----------------------------------------------------------------------------
# A `python -m cotwin` subprocess spends 1-2 s importing before it does anything. A test about what a command
# says or writes, not about the process (signals, exit on a dead peer, environment), runs the same entry point
# here: `cotwin.cli.entry`, with its error reporting and exit codes, its output captured as a subprocess's is.
def cotwin_in_process(*args, cwd=None, env: dict[str, str] | None = None):
    """Run `cotwin ARGS` through its entry point in this process; a CompletedProcess-like result. `env`:
    variables set for the command's duration only (the rest of os.environ is the test's, as a subprocess's)."""
    import contextlib
    import signal
    import subprocess
    import sys

    from click.testing import CliRunner

    from cotwin.cli import entry

    argv = ["cotwin", *map(str, args)]
    code = 0
    sigterm = signal.getsignal(signal.SIGTERM)  # entry() installs its own: put pytest's back
    import inspect

    separate = {"mix_stderr": False} if "mix_stderr" in inspect.signature(CliRunner).parameters else {}  # click 8.1
    with CliRunner(**separate).isolation(env=env) as streams, contextlib.chdir(cwd or os.getcwd()):
        out, err = streams[0], streams[1]
        saved, sys.argv = sys.argv, argv
        try:
            entry()
        except SystemExit as stop:
            code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
        finally:
            sys.argv = saved
            signal.signal(signal.SIGTERM, sigterm)
        sys.stdout.flush()
        sys.stderr.flush()
        stdout, stderr = out.getvalue().decode(), err.getvalue().decode()
    return subprocess.CompletedProcess(argv, code, stdout, stderr)


def interrupted_sweep(project: Path, tmp_path: Path, *options: str) -> tuple[subprocess.Popen, str, float, list[int]]:
    """`cotwin sweep` of 192 holes with `options` (--workers N, --threads N) sent Ctrl-C once some what-ifs are
    answered; checks the interrupted sweep's exit, message and partial CSV (the answers kept, not the output) and
    gives the process, its stderr after the interrupt, the seconds it took to end and its children then."""
    import signal
    import time

    out = tmp_path / "sweep.csv"
    env = {**os.environ, "COTWIN_PROGRESS_SECONDS": "0.2"}
    proc = subprocess.Popen([sys.executable, "-m", "cotwin", "sweep", str(project), "--event", "moveDiscreteCommand",
                             "--arg", "target_X=0..15", "--arg", "target_Y=0..11", "--arg", "target_Z=0", "-o", str(out),
                             "--horizon", "5", "--physics-step", "0.0002", *options],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    seen = ""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:  # until some what-ifs are answered
        line = proc.stderr.readline()
        seen += line
        if not line or line.startswith("sweeping: ") and not line.startswith("sweeping: 0/"):
            break
    children = [int(pid) for pid in Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()]
    interrupted = time.monotonic()
    proc.send_signal(signal.SIGINT)
    rest = proc.communicate(timeout=120)[1]
    waited = time.monotonic() - interrupted
    partial = tmp_path / "sweep.partial.csv"
    assert proc.returncode == 130, seen + rest
    rows = partial.read_text().splitlines()
    assert f"error: interrupted after {len(rows) - 1} of 192 what-ifs; the {len(rows) - 1} answered are in {partial}" \
        in rest and len(rows) > 1 and not out.exists()
    assert len(rows) - 1 < 150 and waited < 8.0, f"{len(rows) - 1} answered, {waited:.1f} s after the interrupt"
    return proc, rest, waited, children
