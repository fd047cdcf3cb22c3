"""examples/ur3e: the paper's d-model on a UR3e in a plate within its reach, made only of project files:
`cotwin run` completes every move of its plan (our own p-model, and the paper's published one where
../shared is here), and `cotwin twin` runs against its perturbed plant over OPC UA (a short span)."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import EXAMPLES, SHARED, cotwin_in_process  # `cotwin run`: what it prints, in this process
from test_cli_e2e import clean, cotwin, free_port, stop

PUBLISHED = SHARED / "ur3e" / "ur3e_gripper.pm"


@pytest.fixture
def project(tmp_path) -> Path:
    """examples/ur3e and the d-model it reuses (../ur5e/arm.rst) copied as a user's clone holds them."""
    shutil.copytree(EXAMPLES / "ur3e", tmp_path / "examples" / "ur3e")
    (tmp_path / "examples" / "ur5e").mkdir()
    shutil.copy(EXAMPLES / "ur5e" / "arm.rst", tmp_path / "examples" / "ur5e" / "arm.rst")
    (tmp_path / "elsewhere").mkdir()
    return tmp_path / "examples" / "ur3e"


def completed(stdout: str) -> tuple[int, int]:
    found = re.search(r"commands: (\d+), (\d+) completed", stdout)
    assert found, stdout
    return int(found.group(1)), int(found.group(2))


def test_run_completes_every_move_on_its_own_plate(project):
    proc = cotwin_in_process("run", project / "cotwin.toml", "-o", project / "out", cwd=project.parent.parent / "elsewhere")
    assert proc.returncode == 0 and clean(proc), proc.stderr[-2000:]
    assert completed(proc.stdout) == (4, 4), proc.stdout


@pytest.mark.xfail(strict=True, reason="open: on the paper's published ur3e_gripper.pm the wrist links meet this "
                   "example's plate (MuJoCo contacts of wrist_1_link and wrist_2_link with the plate, the joints then at "
                   "their 1000 N m effort limit), at any Z_TABLE tried from 0.02 to 0.2 m: the mapping's collision event "
                   "stops the moves, which the ledger counted as completed until it knew stopping events; our ur3e.pm "
                   "(the same names) completes them all")
def test_run_on_the_published_ur3e_completes_every_move():
    if not PUBLISHED.is_file():
        pytest.skip(f"the paper's published UR3e is not at {PUBLISHED} (only in the project workspace)")
    project = EXAMPLES / "ur3e" / "published.toml"
    out = Path(os.environ.get("TMPDIR", "/tmp")) / f"cotwin-ur3e-published-{os.getpid()}"
    proc = cotwin_in_process("run", project, "-o", out, cwd=EXAMPLES.parent)
    shutil.rmtree(out, ignore_errors=True)
    assert proc.returncode == 0 and clean(proc), proc.stderr[-2000:]
    assert completed(proc.stdout) == (4, 4), proc.stdout


def test_the_plate_is_the_mappings_small_grid_within_reach(project):
    from cotwin.twin.assembly.run import load

    cell = load(project / "cotwin.toml").models.scene
    assert (cell.xmax, cell.ymax, cell.hole_dist) == (7, 7, 0.04)
    x0, x1, y0, y1 = cell.extent()
    assert max(abs(x0), abs(x1), abs(y0), abs(y1)) < 0.45  # the UR3e reaches about 0.5 m


def test_twin_runs_against_its_perturbed_plant(project, tmp_path):
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    toml = project / "twin.toml"
    toml.write_text(re.sub(r'url = "opc\.tcp://[^"]*"', f'url = "{url}"', toml.read_text()))
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    plant = subprocess.Popen([sys.executable, "-m", "cotwin", "plant", str(toml), "--opcua", url],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = plant.stdout.readline()
        assert line.startswith(f"serving ur3e_gripper on {url}"), line + plant.stderr.read()
        proc = cotwin("twin", toml, "-o", tmp_path / "live", "--end", "4", "--realtime", cwd=tmp_path / "elsewhere",
                      env=env)
    finally:
        stop(plant, signal.SIGTERM)
    assert proc.returncode == 0 and clean(proc), proc.stderr[-3000:]
    out = proc.stdout + proc.stderr
    assert "PT and DT, 40 steps each" in out, out[-2000:]
    assert re.search(r"PT: commands: 1, 1 completed", out) and re.search(r"DT: commands: 1, 1 completed", out), out


def test_a_move_stopped_by_a_collision_is_no_completion_and_strict_fails(project):
    """The probe's finding: with its targets 20 mm above the plate the UR3e's wrist meets the plate on the
    corner holes, the mapping reports `collision`, the d-model stops and returns to rest; the run said
    '4 completed' (back at rest) and --strict exited 0, where the same robot as a cell said 2. Now such a
    command is 'stopped by collision at t', and --strict fails."""
    mapping = project / "mapping.pm"
    mapping.write_text(re.sub(r"const Z_TABLE: real = [0-9.]+", "const Z_TABLE: real = 0.020", mapping.read_text()))
    proc = cotwin_in_process("run", project / "cotwin.toml", "-o", project / "out", "--strict")
    assert proc.returncode == 3, proc.stdout + proc.stderr[-2000:]
    assert re.search(r"commands: 4, 2 completed, 2 stopped", proc.stdout), proc.stdout
    assert "moveDiscreteCommand(MovementArgs_target_X=0, MovementArgs_target_Y=7, MovementArgs_target_Z=1): " \
           "stopped by collision at t = 2.2 s" in proc.stdout
