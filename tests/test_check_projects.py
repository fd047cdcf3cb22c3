"""`cotwin check` of a project file: the models its twin is made of, each robot's own set for a cell of
several robots (a cell's folder holds two mappings and two p-models, one set per robot, which checked as
one set name each other's robot as unknown)."""

from __future__ import annotations

import shutil

from click.testing import CliRunner

from conftest import EXAMPLES
from cotwin.cli import main

CELL = EXAMPLES / "flexcell2"


def check(*args: str):
    return CliRunner().invoke(main, ["check", *args])


def test_a_cell_project_checks_each_robots_models_apart():
    result = check(str(CELL / "cotwin.toml"))
    assert result.exit_code == 0, result.output
    for name in ("arm.rst", "ur5e.pm", "ur5e_mapping.pm", "panda.pm", "panda_mapping.pm"):
        assert sum(line.split(":")[0].endswith(name) for line in result.output.splitlines() if ": ok (" in line) == 1, \
            (name, result.output)


def test_a_cell_folder_checks_each_robots_models_apart():
    result = check(str(CELL))
    assert result.exit_code == 0, result.output
    for name in ("ur5e.pm", "ur5e_mapping.pm", "panda.pm", "panda_mapping.pm"):
        assert sum(line.split(":")[0].endswith(name) for line in result.output.splitlines() if ": ok (" in line) == 1, \
            (name, result.output)


def test_a_single_robot_folder_still_checks_as_one_set():
    result = check(str(EXAMPLES / "ur5e"))
    assert result.exit_code == 0, result.output
    assert "cotwin.toml" not in result.output
    assert any(line.split(":")[0].endswith("mapping.pm") for line in result.output.splitlines()), result.output


def test_an_error_in_one_robots_mapping_is_located_in_it(tmp_path):
    cell = tmp_path / "cell"
    shutil.copytree(CELL, cell, ignore=shutil.ignore_patterns("meshes"))
    (cell / "meshes").symlink_to(CELL / "meshes")
    shutil.copytree(EXAMPLES / "ur5e", tmp_path / "ur5e")
    mapping = cell / "panda_mapping.pm"
    mapping.write_text(mapping.read_text() + "\nfunction broken(): real { return nowhere }\n")
    result = check(str(cell / "cotwin.toml"))
    assert result.exit_code == 1
    errors = [line for line in result.output.splitlines() if ": error: " in line]
    assert errors and all(line.startswith(str(mapping)) for line in errors), result.output


def test_a_single_robot_project_checks_its_three_models():
    result = check(str(EXAMPLES / "ur5e" / "cotwin.toml"))
    assert result.exit_code == 0, result.output
    assert [line.split(":")[0].rsplit("/", 1)[-1] for line in result.output.splitlines() if ": ok (" in line] == \
        ["arm.rst", "ur5e.pm", "mapping.pm"]


def test_a_broken_project_file_is_reported_at_its_keys(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[models]\ndmodel = "nope.rst"\n')
    result = check(str(bad))
    assert result.exit_code == 1 and f"{bad}:2:1: error: [models] dmodel: no file" in result.output


def test_a_project_whose_plan_cotwin_run_refuses_does_not_check_ok(tmp_path):
    """`cotwin check PROJECT.toml` said ok for a project whose plan `cotwin run` rejects (an unknown robot's
    column, an unknown port): the project is checked against its models as a run checks it, its plan's
    problems located."""
    for example, column in ((CELL, "kuka.moveDiscreteCommand"), (EXAMPLES / "ur5e", "fly")):
        folder = tmp_path / example.name
        shutil.copytree(example, folder, symlinks=True)
        plan = folder / ("plan.csv" if example.name == "ur5e" else "apart.csv")
        for toml in folder.glob("*.toml"):
            toml.write_text(toml.read_text().replace("../ur5e/", f"{EXAMPLES}/ur5e/"))
        lines = plan.read_text().splitlines()
        plan.write_text("\n".join([lines[0] + f",{column}"] + [line + ",1" for line in lines[1:]]) + "\n")
        result = check(str(folder / "cotwin.toml"))
        assert result.exit_code == 1, result.output
        assert f"{plan}:1:{len(lines[0]) + 2}: error: " in result.output and column in result.output
