"""Portable artefacts and states: the same models give byte-identical artefacts (FMUs, GUIDs, generated
C, SDF/URDF/MJCF, multimodel) from any working directory and wherever the project lies, and a state
saved by one copy of a project restores into another copy from another working directory, through
`cotwin whatif --from` and `cotwin sweep --from` alike; a state of other models is refused naming
what differs."""

from __future__ import annotations

import os
import re
import shutil
import zipfile
from pathlib import Path

import pytest
from click.testing import CliRunner

from cotwin.cli import main


def _copy(where: Path) -> Path:
    from conftest import EXAMPLES

    shutil.copytree(EXAMPLES / "ur5e", where)
    return where


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file() and not p.name.startswith(".")}


@pytest.fixture(scope="module")
def copies(tmp_path_factory):
    root = tmp_path_factory.mktemp("portable")
    return _copy(root / "one" / "ur5e"), _copy(root / "elsewhere" / "deeper" / "ur5e")


def test_the_same_models_build_byte_identical_artefacts_from_any_folder_and_any_copy(copies, tmp_path, monkeypatch):
    from cotwin.twin.assembly.build import build
    from cotwin.twin.assembly.run import load

    one, other = copies
    builds = []
    for cwd, project in ((one, "cotwin.toml"), (one.parent.parent, "one/ur5e/cotwin.toml"),
                         (tmp_path, str(other / "cotwin.toml")), (other / "..", "ur5e/cotwin.toml")):
        monkeypatch.chdir(cwd)
        out = tmp_path / f"out{len(builds)}"
        build(load(project), out)
        builds.append(_files(out))
    assert set(builds[0]) >= {"dmodel.fmu", "mapping.fmu", "controller.fmu", "multimodel.json", "ur5e_scene.xml"}
    for other_build in builds[1:]:
        assert other_build == builds[0]
    with zipfile.ZipFile(tmp_path / "out0" / "dmodel.fmu") as zf:
        model_c = zf.read("sources/model.c").decode()
    assert '"arm.rst:' in model_c and str(one) not in model_c  # locations relative to the project


def test_locations_in_the_generated_c_are_relative_to_the_project(copies, monkeypatch):
    from cotwin.dmodel.fmu import fmu_sources
    from cotwin.twin.assembly.run import load

    one, _ = copies
    monkeypatch.chdir(one.parent)
    system = load("ur5e/cotwin.toml")
    relative = fmu_sources(system.models.program, one)
    default = fmu_sources(system.models.program)  # no project given: the folder of the model files
    assert relative == default
    assert '"arm.rst:' in relative["sources/model.c"]
    assert fmu_sources(system.models.program, one.parent)["sources/model.c"].count('"ur5e/arm.rst:') > 0


@pytest.fixture(scope="module")
def saved_state(copies, tmp_path_factory):
    """DIR/state of a run of the first copy, made from inside its folder."""
    one, _ = copies
    out = tmp_path_factory.mktemp("run")
    before = os.getcwd()
    os.chdir(one)
    try:
        result = CliRunner().invoke(main, ["run", "cotwin.toml", "-o", str(out)])
    finally:
        os.chdir(before)
    assert result.exit_code == 0, result.output
    return out / "state"


def test_a_state_restores_in_another_copy_from_another_folder_through_whatif_and_sweep(copies, saved_state, tmp_path,
                                                                                      monkeypatch):
    one, other = copies
    monkeypatch.chdir(other)  # the copy's own folder, the state given by an absolute path
    here = CliRunner().invoke(main, ["whatif", "cotwin.toml", "--plan", "plan.csv", "--from", str(saved_state)])
    assert here.exit_code == 0, here.output
    assert "forked at t = 20 s" in here.output
    monkeypatch.chdir(tmp_path)  # elsewhere: the project and the state by relative paths
    state = Path("state")
    shutil.copy(saved_state, state)
    there = CliRunner().invoke(main, ["whatif", os.path.relpath(other / "cotwin.toml"), "--plan",
                                      os.path.relpath(other / "plan.csv"), "--from", "state"])
    assert there.exit_code == 0, there.output
    def prediction(output: str) -> list[str]:  # the same prediction, wall time aside
        return [re.sub(r" in [0-9.]+ s\)", ")", line) for line in output.splitlines()]

    assert prediction(there.output) == prediction(here.output)
    swept = CliRunner().invoke(main, ["sweep", str(other / "cotwin.toml"), "--event", "moveDiscreteCommand",
                                      "--arg", "target_X=0..1", "--arg", "target_Y=23", "--arg", "target_Z=1",
                                      "--from", "state", "--workers", "1", "-o", "sweep.csv"])
    assert swept.exit_code == 0, swept.output
    rows = Path("sweep.csv").read_text().splitlines()
    assert len(rows) == 3 and all(",True,True," in row for row in rows[1:])


def test_a_state_of_other_models_is_refused_naming_the_file_that_changed(saved_state, tmp_path, monkeypatch):
    changed = _copy(tmp_path / "changed")
    (changed / "arm.rst").write_text((changed / "arm.rst").read_text() + "\n// one more line\n")
    monkeypatch.chdir(changed)
    run = CliRunner().invoke(main, ["whatif", "cotwin.toml", "--plan", "plan.csv", "--from", str(saved_state)])
    assert run.exit_code == 1
    said = str(run.exception)
    assert "saved from other models than these: arm.rst changed (sha256" in said
    assert "mapping.pm" not in said and "ur5e.pm" not in said  # only what differs
