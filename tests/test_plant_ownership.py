"""Each plant owns its port and its credentials (a second plant on a busy port is refused naming the
first one's PID and touches nothing of it), a plant resets to the initial posture when a twin
connects if asked, and `cotwin twin --pt-url` points a project at another plant."""

from __future__ import annotations

import csv
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.listeners import port_owner
from cotwin.mapping.opcua import OPCUAEndpoint
from cotwin.mapping.opcua_auth import default_credentials_file
from cotwin.mapping.perturbed import PerturbedEndpoint
from cotwin.pmodel.perturbation import Perturbation
from cotwin.twin.services.plant import Plant
from cotwin.twin.assembly.run import load

pytest.importorskip("asyncua")
ROOT = Path(__file__).resolve().parents[1]
PROJECT = ROOT / "examples" / "ur5e" / "cotwin.toml"
COTWIN = str(Path(sys.executable).parent / "cotwin")


@pytest.fixture(scope="module")
def twin():
    return load(PROJECT)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def plant_on(twin, url: str, environ, **options) -> Plant:
    return Plant(PerturbedEndpoint.build(twin.models.tree, twin.models.scene, Perturbation()), url, environ=environ,
                 **options)


def test_the_owner_of_a_listening_port_is_found_from_proc():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        owner = port_owner(s.getsockname()[1])
        assert owner is not None and owner.pid == os.getpid() and "python" in owner.describe()
    assert port_owner(free_port()) is None


def test_a_second_plant_on_a_busy_port_is_refused_with_the_owners_pid_and_leaves_its_credentials(twin, tmp_path):
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    first = subprocess.Popen([COTWIN, "plant", str(PROJECT), "--opcua", url], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = first.stdout.readline()
        assert line.startswith(f"serving ur5e on {url}"), line + first.stderr.read()
        credentials = default_credentials_file(url, env)
        written = credentials.read_text()
        second = subprocess.run([COTWIN, "plant", str(PROJECT), "--opcua", url], capture_output=True, text=True,
                                env=env, timeout=120)
        assert second.returncode == 1, second.stderr
        assert f"port {url.rsplit(':', 1)[1]} on 127.0.0.1 is in use by process {first.pid} (" in second.stderr
        assert "cotwin plant" in second.stderr
        assert credentials.read_text() == written  # neither replaced nor removed
        with OPCUAEndpoint(twin.models.tree, url, timeout=5, environ=env) as endpoint:  # the first still drivable
            endpoint.start()
            endpoint.advance(0.1)
    finally:
        first.kill()
        first.wait(10)
        first.stdout.close()
        first.stderr.close()


def test_a_plant_in_this_process_on_a_busy_port_touches_no_credentials(twin, tmp_path):
    env = {"XDG_RUNTIME_DIR": str(tmp_path)}
    first = plant_on(twin, "opc.tcp://127.0.0.1:0", env).start()
    try:
        credentials = default_credentials_file(first.url, env)
        written = credentials.read_text()
        with pytest.raises(CotwinError, match=rf"in use by process {os.getpid()} "):
            plant_on(twin, first.url, env).start()
        assert credentials.read_text() == written
    finally:
        first.stop()
    assert not credentials.exists()  # the owner removes its own file


def _drive(twin, url: str, env) -> dict:
    """Connect as a twin does, move a joint for 1 s; the state it found on connecting."""
    with OPCUAEndpoint(twin.models.tree, url, timeout=5, environ=env) as endpoint:
        endpoint.start()
        found = {"time": endpoint.time, **endpoint.joint_positions()}
        endpoint.command({"M2": -0.8})
        endpoint.advance(1.0)
        assert endpoint.joint_positions()["shoulder_lift_joint"] < -0.3
        return found


@pytest.mark.parametrize("reset", [True, False])
def test_reset_on_connect_starts_every_twin_from_the_initial_posture(twin, tmp_path, reset):
    env = {"XDG_RUNTIME_DIR": str(tmp_path)}
    plant = plant_on(twin, "opc.tcp://127.0.0.1:0", env, reset_on_connect=reset).start()
    try:
        first = _drive(twin, plant.url, env)
        second = _drive(twin, plant.url, env)
    finally:
        plant.stop()
    assert first["time"] == 0.0 and first["shoulder_lift_joint"] == pytest.approx(0.0, abs=1e-6)
    if reset:
        assert second == first and plant.resets == 2
    else:  # the pose of the run before
        assert second["time"] == pytest.approx(1.0) and second["shoulder_lift_joint"] < -0.3


def test_the_reset_method_returns_to_the_initial_posture(twin, tmp_path):
    env = {"XDG_RUNTIME_DIR": str(tmp_path)}
    plant = plant_on(twin, "opc.tcp://127.0.0.1:0", env).start()
    try:
        with OPCUAEndpoint(twin.models.tree, plant.url, timeout=5, environ=env) as endpoint:
            endpoint.start()
            endpoint.command({"M1": 0.5})
            endpoint.advance(1.0)
            state = endpoint._take_state("Reset", endpoint.call("Reset"))
            assert state["time"] == 0.0 and state["joints"]["shoulder_pan_joint"] == pytest.approx(0.0, abs=1e-6)
    finally:
        plant.stop()


def test_twin_pt_url_overrides_the_projects_plant(twin, tmp_path):
    """The project's [pt] url names port 4840; --pt-url sends the twin to this plant instead."""
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path), "COTWIN_PROGRESS_SECONDS": "0"}
    project = ROOT / "examples" / "ur5e" / "twin.toml"
    plant = plant_on(twin, "opc.tcp://127.0.0.1:0", env).start()
    try:
        proc = subprocess.run([COTWIN, "twin", str(project), "-o", str(tmp_path / "out"), "--end", "1",
                               "--pt-url", plant.url], capture_output=True, text=True, env=env, timeout=300)
    finally:
        plant.stop()
    assert proc.returncode == 0, proc.stderr
    assert plant.calls > 10  # the twin stepped this plant
    assert "twin: 1/1 s (100%), step 10" in proc.stderr  # its progress
    rows = list(csv.DictReader(open(tmp_path / "out" / "pt" / "outputs.csv")))
    assert float(rows[-1]["time"]) == pytest.approx(1.0)


@pytest.mark.parametrize("url, message", [
    ("http://127.0.0.1:4840", "expected opc.tcp://HOST:PORT"),
    ("opc.tcp://127.0.0.1:0", "port 0 is not in 1..65535"),
])
def test_a_bad_pt_url_is_refused_at_the_option(tmp_path, url, message):
    proc = subprocess.run([COTWIN, "twin", str(ROOT / "examples" / "ur5e" / "twin.toml"), "-o", str(tmp_path),
                           "--pt-url", url], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--pt-url" in proc.stderr and message in proc.stderr, proc.stderr


def test_a_pt_url_nobody_listens_at_says_connection_refused(tmp_path):
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}  # no credentials file either
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    proc = subprocess.run([COTWIN, "twin", str(ROOT / "examples" / "ur5e" / "twin.toml"), "-o", str(tmp_path / "o"),
                           "--pt-url", url, "--end", "1"], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 1, proc.stderr
    assert f"the plant at {url} failed connect: connection refused (is the plant running?)" in proc.stderr
