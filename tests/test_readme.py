"""The README is a front page: the two commands first, one table row per cotwin command, links that
resolve, figures that exist; `make demo` installs the runtime extras only, `make test` the test extras."""

from __future__ import annotations

import re
from pathlib import Path

from cotwin.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_the_two_commands_come_first():
    first_block = README.split("```sh", 1)[1].split("```", 1)[0]
    assert [line.split()[:2] for line in first_block.strip().splitlines()] == [["make", "demo"], ["make", "test"]]
    assert README.index("make demo") < README.index("## Commands")
    assert len(README.splitlines()) <= 150  # a page read in five minutes; reference material is in docs/


def test_the_command_table_has_one_row_per_command():
    table = README.split("## Commands", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in table.splitlines() if line.startswith("| `cotwin ")]
    named = [re.match(r"\| `cotwin ([a-z-]+)", row).group(1) for row in rows]
    assert sorted(named) == sorted(main.commands), "one row per command, no command without its row"
    assert len(named) == len(set(named))


def test_every_link_and_figure_of_the_readme_and_the_docs_resolves():
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)\)", page.read_text()):
            if "://" in target:
                continue
            assert (page.parent / target).exists(), f"{page.name}: {target}"
    assert (ROOT / "docs" / "run.png").is_file() and (ROOT / "docs" / "make_figures.py").is_file()


def test_make_demo_installs_the_runtime_extras_and_make_test_the_test_extras():
    makefile = (ROOT / "Makefile").read_text()
    rules = dict(re.findall(r"^([$()A-Za-z_-]+):[ \t]*([^\n]*)$", makefile, re.M))
    assert rules["demo"].split() == ["install-runtime"] and rules["test"].split() == ["install"]
    runtime = makefile.split("$(RUNTIME): pyproject.toml", 1)[1].split("\n\n", 1)[0]
    full = makefile.split("$(STAMP): $(RUNTIME)", 1)[1].split("\n\n", 1)[0]
    assert "'.[sim]'" in runtime and "test" not in runtime
    assert "'.[test]'" in full
