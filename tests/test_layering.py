"""Data flows one way (models -> generated artefacts -> co-simulation -> twin): every module of cotwin
imports only from its own layer or those below it. The order is LAYERS, in one place; an import of a
higher layer (at module level or inside a function) fails here, naming the file and line."""

from __future__ import annotations

import ast
from pathlib import Path

from cotwin.twin import PARTS

SRC = Path(__file__).resolve().parents[1] / "src" / "cotwin"
ORDER = list(PARTS)  # the parts of cotwin.twin, lowest first

# Lowest first. A name is a subpackage of cotwin or a module at its top level.
LAYERS: list[tuple[str, ...]] = [
    ("__init__", "diagnostics", "files", "config", "settings", "safejson", "logcap", "listeners", "plot",
     "service", "cache", "cbuild", "memo", "interrupts"),
    ("robosim",),
    ("plaindata",),  # checks of saved plain data against robosim values, used by every layer that saves state
    ("dmodel",),
    ("pmodel",),
    ("mapping",),
    ("cosim",),
    ("twin",),
    ("cli", "launch", "__main__"),
]


def layer_of(name: str) -> int:
    for n, names in enumerate(LAYERS):
        if name in names:
            return n
    raise AssertionError(f"cotwin.{name} is in no layer: add it to LAYERS in {__file__}")


def part_of(path: Path, root: Path = SRC) -> str:
    """The layer name of a module file: its subpackage, or itself at the top level."""
    rel = path.relative_to(root).parts
    return rel[0] if len(rel) > 1 else path.stem


def imported(path: Path, root: Path = SRC) -> list[tuple[int, list[str]]]:
    """(line, the dotted name imported, as a list starting with 'cotwin') for every import of cotwin in
    `path`, at module level or inside a function."""
    package = [root.name, *path.relative_to(root).parent.parts]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name.split(".")) for a in node.names if a.name.split(".")[0] == root.name]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
            elif (node.module or "").split(".")[0] == root.name:
                base = []
            else:
                continue
            module = base + (node.module.split(".") if node.module else [])
            out += [(node.lineno, module + [a.name]) for a in node.names]
    return out


def _part(root: Path, name: list[str]) -> str:
    """The top-level part of cotwin a dotted name is in: a subpackage or module, else cotwin/__init__.py."""
    top = name[1] if len(name) > 1 else "__init__"
    known = (root / top).is_dir() or (root / f"{top}.py").is_file() or any(top in names for names in LAYERS)
    return top if known else "__init__"


def _twin_part(name: list[str]) -> str | None:
    """The part of cotwin.twin (PARTS) a dotted name inside it is in."""
    if len(name) < 3 or name[1] != "twin" or name[2] in ("PARTS", "__init__"):
        return None
    if name[2] in PARTS:  # each part is a subpackage of cotwin.twin
        return name[2]
    for part, modules in PARTS.items():
        if name[2] in modules:
            return part
    raise AssertionError(f"cotwin.twin.{name[2]} is in no part: add it to PARTS in cotwin/twin/__init__.py")


def upward_imports(root: Path = SRC) -> list[str]:
    found = []
    for path in sorted(root.rglob("*.py")):
        part = part_of(path, root)
        own = layer_of(part)
        here = [root.name, *path.relative_to(root).with_suffix("").parts]
        for line, name in imported(path, root):
            other = _part(root, name)
            if other != part and layer_of(other) > own:
                found.append(f"{path.relative_to(root.parent)}:{line}: {part} imports cotwin.{other}, "
                             "a layer above it")
            if part == "twin" and _twin_part(here) and _twin_part(name) and \
                    ORDER.index(_twin_part(name)) > ORDER.index(_twin_part(here)):
                found.append(f"{path.relative_to(root.parent)}:{line}: cotwin.twin's {_twin_part(here)} part "
                             f"imports {'.'.join(name[:3])}, of its {_twin_part(name)} part above it")
    return found


def test_no_module_imports_a_layer_above_its_own():
    assert upward_imports() == []


def test_an_upward_import_is_found_with_its_place(tmp_path):
    fake = tmp_path / "cotwin"
    (fake / "mapping").mkdir(parents=True)
    (fake / "mapping" / "unit.py").write_text("import math\n\ndef f():\n    from ..cosim.units import Port\n")
    (fake / "dmodel").mkdir()
    (fake / "dmodel" / "runner.py").write_text("from cotwin.twin import project\nfrom ..robosim import values\n")
    assert upward_imports(fake) == [
        "cotwin/dmodel/runner.py:1: dmodel imports cotwin.twin, a layer above it",
        "cotwin/mapping/unit.py:4: mapping imports cotwin.cosim, a layer above it"]


def test_every_part_of_cotwin_has_a_layer():
    for path in SRC.rglob("*.py"):
        layer_of(part_of(path))
        _twin_part([SRC.name, *path.relative_to(SRC).with_suffix("").parts])


def test_a_twin_part_importing_a_later_one_is_found(tmp_path):
    fake = tmp_path / "cotwin"
    (fake / "twin" / "project").mkdir(parents=True)
    (fake / "twin" / "assembly").mkdir()
    (fake / "twin" / "project" / "load.py").write_text("from ..live.runtime import LiveTwin\nfrom .sections import SECTIONS\n")
    (fake / "twin" / "assembly" / "system.py").write_text("def f():\n    from cotwin.twin.services.history import History\n")
    assert upward_imports(fake) == [
        "cotwin/twin/assembly/system.py:2: cotwin.twin's assembly part imports cotwin.twin.services, of its services "
        "part above it",
        "cotwin/twin/project/load.py:1: cotwin.twin's project part imports cotwin.twin.live, of its live part above it"]
