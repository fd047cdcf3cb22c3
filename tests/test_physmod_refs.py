"""RoboTool's own p-models read by `cotwin check`: its physmod library and its metamodel-coverage models
(inputs and expected files), at least 95% accepted, every refusal listed with its reason.

The files are RoboTool's (UoY-RoboStar/robotool-meta-physmod), not this repository's: fetch them to a
folder outside it, keeping their relative paths (lib/physmod/..., metamodelCoverage/...): for instance
`scripts/fetch-physmod-refs.sh /work/refs/physmod`; then point COTWIN_PHYSMOD_REFS at that folder. Each
file is checked with the other model files of its folder (a coverage case) and, like a RoboTool workspace,
with the files declaring packages it imports from elsewhere in the tree. The `.txt` expected files are
RoboTool's generator messages, not models: they are counted apart.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import mujoco
import pytest

from cotwin.diagnostics import Diagnostics, Severity
from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.tree import build_tree
from cotwin.robosim.check import check_project
from cotwin.robosim.pmodel_elements import PModel
from cotwin.robosim.project import library_packages, load_project

REFS = os.environ.get("COTWIN_PHYSMOD_REFS")
pytestmark = pytest.mark.skipif(not REFS, reason="COTWIN_PHYSMOD_REFS is not set: RoboTool's physmod models are "
                                "not part of this repository (see this file's docstring)")
PACKAGE = re.compile(r"^\s*package\s+([\w:]+)", re.MULTILINE)
IMPORT = re.compile(r"^\s*import\s+([\w:]+?)(?:::\*)?\s*$", re.MULTILINE)


def _workspace(root: Path) -> dict[str, list[Path]]:
    declared: dict[str, list[Path]] = {}
    for path in sorted(root.rglob("*.pm")):
        if "expected" in path.parts:
            continue
        for name in PACKAGE.findall(path.read_text(encoding="utf-8", errors="replace")):
            declared.setdefault(name, []).append(path)
    return declared


def _group(path: Path, declared: dict[str, list[Path]]) -> list[Path]:
    group = sorted(path.parent.glob("*.pm"))
    library = {"::".join(k) for k in library_packages()}
    own = {name for p in group for name in PACKAGE.findall(p.read_text(encoding="utf-8", errors="replace"))}
    for p in list(group):
        for name in IMPORT.findall(p.read_text(encoding="utf-8", errors="replace")):
            package = name if name in declared else name.rsplit("::", 1)[0]
            if package not in own and package not in library:
                group.extend(q for q in declared.get(package, []) if q not in group)
    return group


def _check(path: Path, declared) -> tuple[list, object]:
    diag = Diagnostics()
    project = load_project(_group(path, declared), diag)
    check_project(project, diag)
    errors = [f for f in diag.findings if f.severity is Severity.ERROR and Path(f.location.path) == path]
    return errors, project


def test_robotool_models_are_accepted():
    root = Path(REFS)
    declared = _workspace(root)
    library_packages()  # built once per process: not part of a model's check time (printed; benchmarks/pmodel_check.py)
    models = sorted(root.rglob("*.pm"))
    messages = sorted(root.rglob("*.txt"))
    assert models, f"no .pm files under {root}"
    refused, slowest, exported = {}, 0.0, 0
    for path in models:
        start = time.perf_counter()
        errors, project = _check(path, declared)
        slowest = max(slowest, time.perf_counter() - start)
        if errors:
            refused[path.relative_to(root)] = errors[0]
            continue
        source = next(s for s in project.files if Path(s.path) == path)
        for pmodel in [e for f in (source, *source.siblings) for e in f.elements if isinstance(e, PModel)]:
            mujoco.MjModel.from_xml_string(to_mjcf(build_tree(project, pmodel.name)))  # every tree loads
            exported += 1
    accepted = len(models) - len(refused)
    report = [f"{accepted}/{len(models)} p-model files accepted ({100 * accepted / len(models):.1f}%), "
              f"{exported} p-models exported to MJCF and loaded by MuJoCo; {len(messages)} .txt expected files are "
              f"generator messages, not models; slowest check {slowest:.2f} s"]
    report += [f"  refused {path}: {finding}" for path, finding in refused.items()]
    print("\n".join(report))
    assert accepted >= 0.95 * len(models), "\n".join(report)
