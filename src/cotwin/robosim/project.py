"""A project: all the model files read together, plus the built-in library, with one symbol table.

Names are looked up per kind (a p-model, a part and an actuator may all be called `Gripper`). Every
element of the project's own files is visible in every file, as in a RoboTool project; library
elements only where a file imports them, and a project element shadows a library one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Iterable

from ..diagnostics import CotwinError, Diagnostics, Finding, Location, Severity
from .declarations import EnumDecl, FunctionDecl, Import, PrimitiveDecl, RecordDecl, SourceFile
from .dmodel_elements import Controller, Interface, Module, OperationDef, RoboticPlatform, StateMachine
from .parser import notation_of, parse_file, parse_text
from .pmodel_elements import Device, Mapping, PModel
from .syntax import QName

#: element class -> symbol kind
KIND_OF = {
    PrimitiveDecl: "type", RecordDecl: "type", EnumDecl: "type", Interface: "interface",
    FunctionDecl: "function", Module: "module", Controller: "controller", StateMachine: "stm",
    OperationDef: "operation", RoboticPlatform: "platform", PModel: "pmodel", Mapping: "mapping",
}
KIND_WORD = {
    "type": "type", "interface": "interface", "function": "function", "module": "module",
    "controller": "controller", "stm": "state machine", "operation": "operation",
    "platform": "robotic platform", "pmodel": "p-model", "mapping": "mapping", "sensor": "sensor",
    "actuator": "actuator", "joint": "joint",
}


def kind_of(element: object) -> str | None:
    if isinstance(element, Device):
        return element.kind
    return KIND_OF.get(type(element))


@dataclass
class Package:
    """A library package such as `physmod::joints`."""

    name: tuple[str, ...]
    source: SourceFile


@dataclass
class Project:
    files: list[SourceFile]
    packages: dict[tuple[str, ...], Package] = field(default_factory=dict)
    table: dict[str, dict[str, object]] = field(default_factory=dict)

    # ---- queries ----
    def elements(self, cls) -> list:
        return [e for f in self.files for e in f.elements if isinstance(e, cls)]

    def file_of(self, element: object) -> SourceFile | None:
        for f in self.files:
            if any(e is element for e in f.elements):
                return f
        return None

    def lookup(self, kind: str, name: QName | str, source: SourceFile | None = None):
        """The element of `kind` called `name`, as seen from `source` (for its imports)."""
        parts = name.parts if isinstance(name, QName) else tuple(name.split("::"))
        if len(parts) == 1 and parts[0] in self.table.get(kind, {}):
            return self.table[kind][parts[0]]
        if len(parts) > 1:
            package = self.packages.get(parts[:-1])
            if package is not None:
                return _find(package.source, kind, parts[-1])
            # a project file may declare `package p`; allow p::Name
            hit = self.table.get(kind, {}).get(parts[-1])
            if hit is not None:
                owner = self.file_of(hit)
                if owner is not None and owner.package is not None and owner.package.parts == parts[:-1]:
                    return hit
            return None
        for imp in source.imports if source is not None else ():
            found = self._from_import(imp, kind, parts[0])
            if found is not None:
                return found
        return None

    def _from_import(self, imp: Import, kind: str, name: str):
        if imp.wildcard:
            package = self.packages.get(imp.name.parts)
            return _find(package.source, kind, name) if package else None
        if imp.name.last != name:
            return None
        package = self.packages.get(imp.name.parts[:-1])
        return _find(package.source, kind, name) if package else None

    def visible_functions(self, source: SourceFile | None) -> dict[str, FunctionDecl]:
        """Functions callable from `source`: the project's and the imported library ones."""
        out: dict[str, FunctionDecl] = {}
        for imp in source.imports if source is not None else ():
            if imp.wildcard and imp.name.parts in self.packages:
                for fn in self.packages[imp.name.parts].source.of_kind(FunctionDecl):
                    out.setdefault(fn.name, fn)
            elif not imp.wildcard and imp.name.parts[:-1] in self.packages:
                fn = _find(self.packages[imp.name.parts[:-1]].source, "function", imp.name.last)
                if fn is not None:
                    out.setdefault(fn.name, fn)
        out.update(self.table.get("function", {}))
        return out


def _find(source: SourceFile, kind: str, name: str):
    return next((e for e in source.elements if kind_of(e) == kind and getattr(e, "name", None) == name), None)


# ---- library --------------------------------------------------------------------------------

_LIBRARY_CACHE: dict[tuple[str, ...], Package] | None = None


def library_packages() -> dict[tuple[str, ...], Package]:
    """The built-in packages (`physmod::joints`, `physmod::math`, ...), parsed once."""
    global _LIBRARY_CACHE
    if _LIBRARY_CACHE is None:
        root = resources.files("cotwin.robosim") / "library"
        packages: dict[tuple[str, ...], Package] = {}
        for path in sorted(_library_files(root)):
            rel = path.relative_to(Path(str(root)))
            name = tuple(rel.with_suffix("").parts)
            source, findings = parse_text(path.read_text(encoding="utf-8"), f"<library>/{rel.as_posix()}")
            if source is None:  # pragma: no cover - the library is ours and tested
                raise CotwinError(findings)
            packages[name] = Package(name, source)
        _LIBRARY_CACHE = packages
    return _LIBRARY_CACHE


def _library_files(root) -> Iterable[Path]:
    return [p for p in Path(str(root)).rglob("*.pm")]


# ---- loading --------------------------------------------------------------------------------


def model_files(paths: Iterable[str | Path]) -> tuple[list[Path], list[Finding]]:
    """Expand folders into their .rst and .pm files (sorted), reporting paths that do not exist."""
    files: list[Path] = []
    findings: list[Finding] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.is_file() and notation_of(p))
            if not found:
                findings.append(Finding(Location(str(path), 1, 1), Severity.ERROR, "no .rst or .pm files in folder"))
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            findings.append(Finding(Location(str(path), 1, 1), Severity.ERROR, "no such file or folder"))
    unique = list(dict.fromkeys(files))
    return unique, findings


def project_groups(paths: Iterable[str | Path]) -> tuple[list[list[Path]], list[Finding]]:
    """Group model files into projects: the files named directly form one project, and every folder
    holding model files forms its own (so `check ur5e ur3e` checks two independent projects)."""
    loose: list[Path] = []
    groups: dict[Path, list[Path]] = {}
    findings: list[Finding] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            files, found = model_files([path])
            findings.extend(found)
            for f in files:
                groups.setdefault(f.parent, []).append(f)
        else:
            files, found = model_files([path])
            findings.extend(found)
            loose.extend(files)
    out = [list(dict.fromkeys(loose))] if loose else []
    out.extend(groups[k] for k in sorted(groups))
    return out, findings


def build_project(sources: list[SourceFile], diag: Diagnostics) -> Project:
    """Index the files' elements per kind, reporting duplicates and unknown imports."""
    project = Project(files=sources, packages=dict(library_packages()))
    for source in sources:
        for element in source.elements:
            kind = kind_of(element)
            if kind is None:
                continue
            names = project.table.setdefault(kind, {})
            first = names.get(element.name)
            if first is not None:
                diag.error(element.loc, f"duplicate {KIND_WORD[kind]} '{element.name}' (first declared at {first.loc})")
                continue
            names[element.name] = element
        for imp in source.imports:
            if imp.wildcard:
                known = imp.name.parts in project.packages
            else:
                package = project.packages.get(imp.name.parts[:-1])
                known = package is not None and any(
                    getattr(e, "name", None) == imp.name.last for e in package.source.elements
                )
            if not known:
                diag.error(imp.loc, f"unknown import '{imp.name}{'::*' if imp.wildcard else ''}'")
    return project


def load_project(paths: Iterable[str | Path], diag: Diagnostics) -> Project:
    """Parse every model file under `paths` and index them; syntax errors go to `diag`."""
    files, findings = model_files(paths)
    diag.extend(findings)
    sources = []
    for path in files:
        source, file_findings = parse_file(path)
        diag.extend(file_findings)
        if source is not None:
            sources.append(source)
    return build_project(sources, diag)
