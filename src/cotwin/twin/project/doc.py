"""docs/project.md generated from the project schema (`cotwin.twin.project.sections`): every table and key with
its type, default and meaning, in the file's order. `python -m cotwin.twin.project.doc [OUT]` rewrites it
(default docs/project.md beside the package's repository); `--check` exits 1 when it differs."""

from __future__ import annotations

import sys
from pathlib import Path

from ...settings import reference
from .sections import READ_ONLY_BY, ProjectSettings

INTRO = """# The project file (`cotwin.toml`)

A twin project names the three models and says how they run: where commands come from, the platform, the
co-simulation and, for a live twin, the physical twin, deviation checking and history. Every problem in
it is reported at its key's line and column, all together; an unknown key is refused with the nearest
known one. Paths are relative to the project file. Tables left out take their keys' defaults.

This page is generated from the schema (`cotwin.twin.project.sections`) by `python -m cotwin.twin.project.doc`
(which rewrites docs/project.md; `--check` only compares);
`tests/test_project_doc.py` fails when the two differ. Read a project with
`cotwin.twin.project.load_project`; `TwinProject.with_overrides(step=..., pt_url=...)` gives a changed
copy (a change is named SECTION_KEY, or by a key only one section has) and `TwinProject.to_toml()` writes
one back. A new table is a frozen dataclass whose fields are `cotwin.settings.setting(meaning, Key(...))`
and one entry in `cotwin.twin.project.sections.SECTIONS` (then regenerate this page).

A minimal project:

```toml
[models]
dmodel = "arm.rst"
pmodel = "robot.pm"
mapping = "mapping.pm"

[scenario]
plan = "plan.csv"

[cosim]
step = 0.1
end = 20.0
```
"""


def read_only_by() -> str:
    """Which tables only some commands read (READ_ONLY_BY); another command warns that it ignores them."""
    rows = "\n".join(f"- `[{section}]`: {', '.join(f'`{r}`' for r in readers)}"
                     for section, readers in READ_ONLY_BY.items())
    return ("\nEvery command that runs a project reads its models, scenario, platform and co-simulation tables; "
            "these tables\nare read only by the commands listed (`cotwin run`, `cotwin whatif`, `cotwin sweep` and "
            "`cotwin test`,\ngiven a project holding one, warn at the table that they ignore it, and do not look for the "
            "files it names,\nsuch as a `[pt]` recording):\n\n" + rows + "\n")


def project_reference() -> str:
    """The Markdown text of docs/project.md."""
    return INTRO + read_only_by() + "\n".join(reference(ProjectSettings)) + "\n"


DOC = Path(__file__).resolve().parents[4] / "docs" / "project.md"


def main(argv: list[str]) -> int:
    check = "--check" in argv
    names = [a for a in argv if a != "--check"]
    out = Path(names[0]) if names else DOC
    text = project_reference()
    if check:
        same = out.is_file() and out.read_text(encoding="utf-8") == text
        if not same:
            print(f"{out} differs from the schema: run python -m cotwin.twin.project.doc", file=sys.stderr)
        return 0 if same else 1
    out.write_text(text, encoding="utf-8")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
