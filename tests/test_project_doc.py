"""docs/project.md is the project schema's reference, generated from it: the page and the schema agree,
and every key of every section is on it with its type and default."""

from __future__ import annotations

from pathlib import Path

from cotwin.settings import default_text, kind_text, leaves
from cotwin.twin.project.doc import DOC, main, project_reference
from cotwin.twin.project.sections import ProjectSettings

ROOT = Path(__file__).resolve().parents[1]


def test_the_page_is_what_the_schema_generates():
    assert DOC == ROOT / "docs" / "project.md"
    assert DOC.read_text(encoding="utf-8") == project_reference(), \
        "docs/project.md differs from the schema: run python -m cotwin.twin.project.doc"


def test_every_key_is_on_the_page_with_its_type_and_default():
    text = project_reference()
    for path, spec in leaves(ProjectSettings).items():
        if len(path) == 1:
            assert f"`[{path[0]}]`" in text or f"`[[{path[0]}]]`" in text, path  # a table, or a list of them
        else:
            assert f"| `{path[-1]}` | {kind_text(spec)} | {default_text(spec)} |" in text, path


def test_check_mode_reports_a_stale_page(tmp_path):
    stale = tmp_path / "project.md"
    stale.write_text(project_reference().replace("| `step` |", "| `stride` |"))
    assert main(["--check", str(stale)]) == 1
    assert main(["--check", str(DOC)]) == 0
