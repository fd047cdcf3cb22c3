"""[outcomes]: an event named in two roles is an error at its key (it was judged infeasible in silence)."""
import shutil
from pathlib import Path

from click.testing import CliRunner

from cotwin.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ur5e"


def test_an_event_in_two_outcome_roles_is_an_error_at_the_later_key(tmp_path):
    shutil.copytree(EXAMPLE, tmp_path / "ur5e")
    project = tmp_path / "ur5e" / "cotwin.toml"
    text = project.read_text() + '\n[outcomes]\ninfeasible = ["moveCompleted"]\nfeasible = ["moveCompleted"]\n'
    project.write_text(text)
    result = CliRunner().invoke(main, ["check", str(project)])
    line = text.splitlines().index('feasible = ["moveCompleted"]') + 1
    assert result.exit_code != 0, result.output
    assert f"cotwin.toml:{line}:" in result.output, result.output
    assert "moveCompleted is already named in [outcomes] infeasible" in result.output, result.output
