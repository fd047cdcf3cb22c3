"""A cell whose robots are placed in one another (both bases at the scene's origin): `cotwin run` says so,
located at the project, instead of reporting an ordinary collision at the first step and refusing every move."""

from __future__ import annotations

from click.testing import CliRunner

from conftest import EXAMPLES
from cotwin.cli import main

CELL = EXAMPLES / "flexcell2"


def project(folder, xyz: str) -> str:
    text = f"""[models]
dmodel = "{EXAMPLES / 'ur5e' / 'arm.rst'}"
[[robots]]
name = "ur5e"
pmodel = "{EXAMPLES / 'ur5e' / 'ur5e.pm'}"
mapping = "{CELL / 'ur5e_mapping.pm'}"
[[robots]]
name = "panda"
pmodel = "{CELL / 'panda.pm'}"
mapping = "{CELL / 'panda_mapping.pm'}"
calibration = "{CELL / 'panda_cell.toml'}"
xyz = {xyz}
rpy = [0.0, 0.0, -2.575]
[scenario]
plan = "{CELL / 'apart.csv'}"
[platform]
scene = "flexcell"
[cosim]
step = 0.1
end = 0.3
"""
    path = folder / "cell.toml"
    path.write_text(text)
    return str(path)


def test_robots_placed_in_one_another_are_told_at_the_project(tmp_path):
    path = project(tmp_path, "[0.0, 0.0, 0.0]")
    result = CliRunner().invoke(main, ["run", path, "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert f"{path}:1:1: warning: ur5e and panda touch from the start" in result.output, result.output


def test_robots_apart_are_not_told(tmp_path):
    path = project(tmp_path, "[1.0, 0.65, 0.0]")
    result = CliRunner().invoke(main, ["run", path, "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "touch from the start" not in result.output, result.output
