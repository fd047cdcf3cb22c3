"""RoboTool's own p-models, read by cotwin and compared with RoboTool's expected outputs.

The files are RoboTool's physmod library and its T3 integration test data (UoY-RoboStar/robotool-meta-physmod,
copied unchanged to ../shared/refs/robotool-physmod: its README and T3/README say what each folder is); they
are not this repository's, and a user's clone has no ../shared, so these tests skip there, saying why.
COTWIN_PHYSMOD_REFS points at another copy with the same layout.

What is compared (RoboTool's expected outputs are its equation generator's, eqnComp, not SDF):
- every input and expected p-model is read; the few refused are listed with RoboTool's own reason;
- each Default metamodel-coverage input and RoboTool's rewriting of it (expected/*.pm, references made local)
  give the same kinematic tree;
- where RoboTool's generator message (expected/*.txt) is a validation error of the model, cotwin reports
  it too; where it is a limitation of the generator (an SKO requirement, a crash), cotwin reads the model;
- the robot examples' expected equations give each link's mass, inertia and geometry and each joint's
  axis (the SKO, Featherstone and CGA formulations): cotwin's tree of the input has the same.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from cotwin.diagnostics import Diagnostics, Severity
from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.tree import build_tree
from cotwin.robosim import syntax as s
from cotwin.robosim.check import check_project
from cotwin.robosim.consteval import try_evaluate
from cotwin.robosim.pmodel_elements import PModel
from cotwin.robosim.project import library_packages, load_project

ROOT = Path(__file__).resolve().parents[1]
REFS = Path(os.environ.get("COTWIN_PHYSMOD_REFS") or ROOT.parent / "shared" / "refs" / "robotool-physmod")
T3 = REFS / "T3"
pytestmark = pytest.mark.skipif(not T3.is_dir(), reason=f"RoboTool's physmod test data is not at {REFS} (it lives "
                                "in ../shared, beside the repository, which a user's clone does not have)")
PACKAGE = re.compile(r"^\s*package\s+([\w:]+)", re.MULTILINE)
IMPORT = re.compile(r"^\s*import\s+([\w:]+?)(?:::\*)?\s*$", re.MULTILINE)

#: the files cotwin refuses, each for a reason RoboTool gives too (its own expected output says so) or because
#: RoboTool's generator wrote it malformed
#: coverage models RoboTool's rewriting changes (so cotwin keeps its reading of the model; the notation page
#: says why): FixedConnection_Part's `link linkA fixed to linkB in TLB` is lost when RoboTool flattens the parts
REWRITTEN_WRONG = ["FixedConnection_Part"]

REFUSED = {
    "metamodelCoverage/SKO/Inertial/TwoBodiesPlusInertia.pm":
        "RoboTool's rule L2 (expected/TwoBodiesPlusInertia.txt: 'ERROR L2: The link realisation Tip contains "
        "inertial information and one or more of its bodies also contain inertial information')",
    "metamodelCoverage/SKO/Index/expected/Index.pm": "written malformed by RoboTool ('geom_11index i')",
    "metamodelCoverage/SKO/Link_Relation/expected/Link_Relation.pm": "written malformed by RoboTool ('geom_11local body')",
    "metamodelCoverage/SKO/DerivativeExp/expected/DerivativeExp.pm":
        "two variables 'theta' in one p-model: RoboTool's solver added 'InOut theta : vector(real, 2)' to the "
        "model's 'local theta : real' (its expected/DerivativeExp.txt: java.lang.NullPointerException)",
    "metamodelCoverage/SKO/IBCondition/expected/IBCondition.pm":
        "two variables 'theta' in one p-model: RoboTool's solver added 'InOut theta : vector(real, 2)' to the "
        "model's 'local theta : real' (its expected/IBCondition.txt: java.lang.NullPointerException)",
    "metamodelCoverage/SKO/IntegralExp/expected/IntegralExp.pm":
        "two variables 'theta' in one p-model: RoboTool's solver added 'InOut theta : vector(real, 2)' to the "
        "model's 'local theta : real' (its expected/IntegralExp.txt: java.lang.NullPointerException)",
}


def _read(path: Path) -> str:
    return path.read_text(encoding="utf-8", errors="replace")


def _declared() -> dict[str, list[Path]]:
    out: dict[str, list[Path]] = {}
    for path in sorted(REFS.rglob("*.pm")):
        if "expected" not in path.parts:
            for name in PACKAGE.findall(_read(path)):
                out.setdefault(name, []).append(path)
    return out


def _load(path: Path, declared):
    """The file as a RoboTool workspace loads it for a test: with the files declaring what it imports."""
    files = [path]
    library = {"::".join(k) for k in library_packages()}
    for name in IMPORT.findall(_read(path)):
        package = name if name in declared else name.rsplit("::", 1)[0]
        if package not in library:
            files.extend(q for q in declared.get(package, []) if q not in files)
    diag = Diagnostics()
    project = load_project(files, diag)
    check_project(project, diag)
    return project, [f for f in diag.findings if f.severity is Severity.ERROR and Path(f.location.path) == path]


def _pmodels(project, path: Path) -> list[PModel]:
    return [e for f in project.files if Path(f.path) == path for e in f.elements if isinstance(e, PModel)]


def _trees(project, path: Path) -> dict:
    used = {p.pmodel.last for pm in project.elements(PModel) for p in pm.parts}
    return {pm.name: build_tree(project, "::".join(project.qualified_name(pm)))
            for pm in _pmodels(project, path) if pm.name not in used}


def test_every_robotool_pmodel_is_read_and_exports():
    declared = _declared()
    files = sorted(p for p in REFS.rglob("*.pm"))
    assert len(files) > 200, f"only {len(files)} .pm files under {REFS}"
    refused, exported = {}, 0
    for path in files:
        project, errors = _load(path, declared)
        if errors:
            refused[path.relative_to(T3).as_posix() if T3 in path.parents else path.name] = errors[0]
            continue
        for tree in _trees(project, path).values():
            mujoco.MjModel.from_xml_string(to_mjcf(tree))  # every tree loads in MuJoCo
            exported += 1
    print(f"{len(files) - len(refused)}/{len(files)} RoboTool p-model files read, {exported} p-models exported")
    assert set(refused) == set(REFUSED), "\n".join(f"{k}: {v}" for k, v in refused.items())
    assert "RoboTool's rule L2" in refused["metamodelCoverage/SKO/Inertial/TwoBodiesPlusInertia.pm"].message


def _shape(tree):
    """What a kinematic tree says, rounded, without names (RoboTool's rewriting flattens parts as `P_L`):
    links (mass, pose), geometry (kind, size), joints (kind, axis, and which links they join)."""
    index = {l.name: k for k, l in enumerate(sorted(tree.links, key=lambda l: tuple(np.round(l.pose.ravel(), 3))))}
    links = sorted((round(l.mass, 6), tuple(np.round(l.pose[:3, :].ravel(), 3) + 0.0)) for l in tree.links)
    geoms = sorted((g.kind, tuple(sorted((k, round(v, 6)) for k, v in g.size.items()))) for l in tree.links
                   for g in l.geoms)
    joints = sorted((j.kind, tuple(np.round(j.axis, 6) + 0.0), index[j.parent], index[j.child])
                    for j in (*tree.joints, *tree.loops))
    return links, geoms, joints


def test_default_coverage_inputs_read_as_robotool_rewrites_them():
    """RoboTool's generator rewrites each Default coverage model (references made local, index moved, the
    instantiation of a local joint dropped): cotwin reads the rewriting as the model itself."""
    declared = _declared()
    compared, differ = 0, []
    for expected in sorted((T3 / "metamodelCoverage" / "Default").glob("*/expected/*.pm")):
        model = expected.parent.parent / expected.name
        if not model.is_file():
            continue
        theirs, errors = _load(expected, declared)
        ours, own_errors = _load(model, declared)
        assert not errors and not own_errors, (errors, own_errors)
        a, b = _trees(ours, model), _trees(theirs, expected)
        assert set(a) <= set(b), expected  # RoboTool's rewriting may leave a part's p-model unused
        for name in a:
            mine, rewritten = _shape(a[name]), _shape(b[name])
            # a joint RoboTool made local from a library reference loses the definition telling how it moves:
            # compare joints by their ends only there
            if mine[:2] != rewritten[:2] or sorted(j[2:] for j in mine[2]) != sorted(j[2:] for j in rewritten[2]):
                differ.append(expected.parent.parent.name)
            compared += 1
    assert differ == REWRITTEN_WRONG, differ
    assert compared >= 40


def test_robotool_generator_messages():
    """The generator's messages (expected/*.txt): a validation error of the model is cotwin's too; an SKO
    requirement or a crash of the generator is not about the model, which cotwin reads."""
    declared = _declared()
    validation = model_errors = 0
    for message_file in sorted(T3.rglob("expected/*.txt")):
        text = _read(message_file)
        model = message_file.parent.parent / (message_file.stem + ".pm")
        if not model.is_file():
            continue
        _, errors = _load(model, declared)
        if text.startswith("ERROR L2"):
            assert any("RoboTool's rule L2" in e.message for e in errors), model
            validation += 1
        else:
            assert not errors, f"{model}: RoboTool says '{text[:80]}', cotwin refuses: {errors[0]}"
            model_errors += 1
    assert validation == 1 and model_errors >= 100


def _const(expr):
    value = try_evaluate(expr, None, None) if expr is not None else None
    return value


def _expected_links(pmodel: PModel) -> dict[str, dict]:
    """Per link of an eqnComp output: the mass `m_k`, inertia `I_C_k` and geometry `Geom(| geomType, geomVal |)`
    RoboTool's generator computed for it (from the link's bodies)."""
    out = {}
    for link in pmodel.links:
        found = {}
        for var in link.variables:
            if re.fullmatch(r"m_\d+", var.name) and var.init is not None:
                found["mass"] = float(_const(var.init))
            elif re.fullmatch(r"I_C_\d+", var.name) and var.init is not None:
                found["inertia"] = np.array(_const(var.init), dtype=float)
            elif isinstance(var.init, s.RecordExpr) and var.init.record.last == "Geom":
                fields = {f: _const(e) for f, e, _ in var.init.fields}
                found["geom"] = (fields.get("geomType"), tuple(float(v) for v in fields.get("geomVal") or ()))
        out[link.name] = found
    return out


def _expected_axes(pmodel: PModel) -> dict[str, np.ndarray]:
    """Per joint of an eqnComp output: its axis, from its motion subspace (SKO `H`, Featherstone `S`) or CGA's
    `axis_rot`."""
    out = {}
    for link in pmodel.links:
        for joint in link.joints:
            ports = {p.name: p for p in (joint.local.ports if joint.local else ())}
            for name in ("H", "S", "axis_rot"):
                if name in ports and ports[name].init is not None:
                    value = np.array(_const(ports[name].init), dtype=float).ravel()
                    out[joint.name] = value[:3]
                    break
    return out


GEOM_SIZE = {"box": ("length", "width", "height"), "cylinder": ("radius", "length"), "sphere": ("radius",)}


def test_robot_examples_have_robotools_masses_inertias_geometry_and_axes():
    declared = _declared()
    compared = {"mass": 0, "inertia": 0, "geom": 0, "axis": 0}
    for expected in sorted((T3 / "RobotExamples").glob("*/*/expected/*.pm")):
        [model] = sorted((expected.parent.parent / "input").glob("*.pm"))
        theirs, errors = _load(expected, declared)
        ours, own_errors = _load(model, declared)
        assert not errors and not own_errors
        [pm] = _pmodels(theirs, expected)
        [tree] = _trees(ours, model).values()
        for name, found in _expected_links(pm).items():
            link = tree.link(name)
            if "mass" in found:
                assert link.mass == pytest.approx(found["mass"], rel=1e-6), (expected, name)
                compared["mass"] += 1
            if "inertia" in found:
                R = link.com[:3, :3]
                inertia = link.inertia if link.written_inertia is None else link.written_inertia  # the model's
                assert R @ inertia @ R.T == pytest.approx(found["inertia"].reshape(3, 3), abs=1e-6), (expected, name)
                compared["inertia"] += 1
            if "geom" in found:
                kind, values = found["geom"]
                [geom] = link.geoms
                assert geom.kind == kind and [geom.size[k] for k in GEOM_SIZE[kind]] == pytest.approx(values, rel=1e-6)
                compared["geom"] += 1
        for name, axis in _expected_axes(pm).items():
            joint = next(j for j in tree.joints if j.name == name)
            assert joint.axis == pytest.approx(axis / np.linalg.norm(axis)), (expected, name)
            compared["axis"] += 1
    print(compared)
    assert all(n >= 4 for n in compared.values()), compared
