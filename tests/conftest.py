"""Shared fixtures: where the paper's published models are, and our own examples."""

from __future__ import annotations

from pathlib import Path

import pytest

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


@pytest.fixture(scope="session")
def postgres_server():
    _service(5432, "PostgreSQL", "pg_ctlcluster --skip-systemctl-redirect $(ls /etc/postgresql) main start")
