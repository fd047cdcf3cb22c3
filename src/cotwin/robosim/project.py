"""A project: all the model files read together, plus the built-in library, with one symbol table.

Names are resolved as RoboTool's scope providers resolve them (RoboChartScopeProvider over Xtext's
ImportedNamespaceAwareLocalScopeProvider; docs/robosim-notation.md, section 1): every top-level
element has a qualified name, its file's `package` followed by its own name, and a name is resolved
in the file where it is *written* (a type in an interface of another file is that file's business).
A simple name resolves, in order, to an element of that file itself, an element of a file without a
package (those are visible everywhere), an element its imports bring in (`import P::*`,
`import P::N`); a qualified name `P::N` resolves directly (and relative to the imports). Names are
looked up per kind (a p-model, a part and an actuator may all be called `Gripper`).

What RoboTool does with the rest is recorded as findings (`Project.scope_findings`): two imports that
bring different elements of one name make it ambiguous, which RoboTool reports as an unresolved
reference (an error); an element of another file of the same package, which RoboTool does not resolve
without an import, is read with a warning; two elements with one qualified name are RoboTool's
"more than one element with name" warning, and the first one (in file order) is used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Iterable

from ..diagnostics import CotwinError, Diagnostics, Finding, Location, Severity
from .declarations import EnumDecl, FunctionDecl, Import, PrimitiveDecl, RecordDecl, SourceFile
from .dmodel_elements import (
    Controller, ForeignComponent, Interface, Module, OperationDef, RoboticPlatform, StateMachine,
)
from .functions import SUBSTITUTE_PACKAGES
from .parser import notation_of, parse_file, parse_text
from .pmodel_elements import AnnotationTemplate, BodyDecl, Device, Fragment, LinkDecl, Mapping, PModel
from .readings import Readings
from .syntax import QName

#: element class -> symbol kind
KIND_OF = {
    PrimitiveDecl: "type", RecordDecl: "type", EnumDecl: "type", Interface: "interface",
    FunctionDecl: "function", Module: "module", Controller: "controller", StateMachine: "stm",
    OperationDef: "operation", RoboticPlatform: "platform", PModel: "pmodel", Mapping: "mapping",
    LinkDecl: "link", BodyDecl: "body", Fragment: "fragment", AnnotationTemplate: "annotation",
    ForeignComponent: "foreign",
}
KIND_WORD = {
    "type": "type", "interface": "interface", "function": "function", "module": "module",
    "controller": "controller", "stm": "state machine", "operation": "operation",
    "platform": "robotic platform", "pmodel": "p-model", "mapping": "mapping", "sensor": "sensor",
    "actuator": "actuator", "joint": "joint", "link": "link", "body": "body", "fragment": "fragment",
    "annotation": "annotation template", "foreign": "component",
}


def kind_of(element: object) -> str | None:
    if isinstance(element, Device):
        return element.kind
    return KIND_OF.get(type(element))


@dataclass
class Package:
    """A library package such as `physmod::joints` or `set_toolkit`."""

    name: tuple[str, ...]
    source: SourceFile


@dataclass
class Project:
    files: list[SourceFile]
    packages: dict[tuple[str, ...], Package] = field(default_factory=dict)
    #: kind -> qualified name -> element (the project's files and the library packages)
    symbols: dict[str, dict[tuple[str, ...], object]] = field(default_factory=dict)
    #: element id -> the file declaring it
    owners: dict[int, SourceFile] = field(default_factory=dict)
    #: package names declared by the project's files
    namespaces: set[tuple[str, ...]] = field(default_factory=set)
    #: types and readings the checker recorded (filled by check_project)
    readings: Readings = field(default_factory=Readings)
    #: what name resolution found beside the element (ambiguities, RoboTool's unresolved names): findings
    #: by (place, message), reported by check_project
    scope_findings: dict[tuple, Finding] = field(default_factory=dict)
    #: path -> (first line, package block) of every file, for the scope a name is written in
    _blocks: dict[str, list[tuple[int, SourceFile]]] = field(default_factory=dict)
    _ambiguous: set = field(default_factory=set)
    #: id(file) -> (kind, name) -> its own element (the first of that name in the file)
    _own: dict[int, dict[tuple[str, str], object]] = field(default_factory=dict)

    # ---- queries ----
    def elements(self, cls) -> list:
        return [e for f in self.files for e in f.elements if isinstance(e, cls)]

    def file_of(self, element: object) -> SourceFile | None:
        return self.owners.get(id(element))

    def qualified_name(self, element: object) -> tuple[str, ...]:
        owner = self.file_of(element)
        return (owner.namespace if owner is not None else ()) + (element.name,)

    def source_at(self, loc: Location | None) -> SourceFile | None:
        """The file (the `package` block of a .pm file) where `loc` is written, if it is one of the
        project's or the library's."""
        if loc is None or not self._blocks:
            return None
        blocks = self._blocks.get(loc.path)
        if not blocks:
            return None
        found = blocks[0][1]
        for line, block in blocks:
            if line <= loc.line:
                found = block
        return found

    def lookup(self, kind: str, name: QName | str, source: SourceFile | None = None):
        """The element of `kind` called `name`, as RoboTool resolves it where the name is written (its
        location's file), else as seen from `source`; None when unknown or ambiguous."""
        parts = name.parts if isinstance(name, QName) else tuple(name.split("::"))
        loc = name.loc if isinstance(name, QName) else None
        source = self.source_at(loc) or source
        table = self.symbols.get(kind, {})
        if len(parts) > 1:
            hit = table.get(parts)
            if hit is not None:
                return hit
            for prefix in self._import_prefixes(source):  # `import P::*` then `Q::N` is P::Q::N
                hit = table.get(prefix + parts)
                if hit is not None:
                    return hit
            return None
        if source is None:
            return table.get(parts)
        mine = self._own.get(id(source), {}).get((kind, parts[0]))
        if mine is not None:
            return mine  # the file's own element
        bare = table.get(parts)  # files without a package are visible everywhere
        if bare is not None:
            return bare
        own = source.namespace + parts
        hit = table.get(own) if source.namespace else None
        imported = self._imported(kind, parts, source, loc)
        if imported is not None or (loc is not None and (loc, kind) in self._ambiguous):
            return imported
        if hit is not None:  # another file of the same package: RoboTool needs an import for it
            if loc is not None and loc.line > 0:
                owner = self.file_of(hit)
                self._note(Finding(loc, Severity.WARNING,
                                   f"'{parts[0]}' is the {KIND_WORD.get(kind, kind)} {'::'.join(own)} of another file "
                                   f"({owner.path if owner else '?'}): RoboTool resolves a name of the same package "
                                   f"in another file only when it is imported or qualified (import "
                                   f"{'::'.join(source.namespace)}::*); cotwin reads it"))
            return hit
        return None

    def ambiguous(self, kind: str, name: QName) -> bool:
        """Whether `name` was found ambiguous (already reported: callers need not call it unknown)."""
        return (name.loc, kind) in self._ambiguous

    def _imported(self, kind: str, parts: tuple[str, ...], source: SourceFile, loc: Location | None):
        """The element the file's imports bring for a simple name; two imports bringing different ones
        make it ambiguous (RoboTool: an unresolved reference), reported once per place."""
        table = self.symbols.get(kind, {})
        found: list[tuple[object, Import]] = []
        for imp in source.imports:
            if imp.wildcard:
                hit = table.get(imp.name.parts + parts)
            elif imp.name.last == parts[0]:
                hit = table.get(imp.name.parts)
            else:
                hit = None
            if hit is not None and all(hit is not other for other, _ in found):
                found.append((hit, imp))
        if len(found) > 1:
            if loc is not None and loc.line > 0:
                self._ambiguous.add((loc, kind))
                names = ", ".join(f"{'::'.join(self.qualified_name(e))} (import {imp.name}"
                                  f"{'::*' if imp.wildcard else ''}, line {imp.loc.line})" for e, imp in found)
                self._note(Finding(loc, Severity.ERROR,
                                   f"'{parts[0]}' is ambiguous: the imports bring {names}; RoboTool resolves "
                                   "it to none of them (an unresolved reference): qualify it"))
            return None
        return found[0][0] if found else None

    def _import_prefixes(self, source: SourceFile | None) -> list[tuple[str, ...]]:
        if source is None:
            return []
        return [source.namespace] + [imp.name.parts for imp in source.imports if imp.wildcard]

    def _note(self, finding: Finding) -> None:
        self.scope_findings.setdefault((finding.location, finding.message), finding)

    def elsewhere(self, kind: str, name: QName | str) -> list[str]:
        """Qualified names of elements of `kind` with this simple name, for 'did you mean' hints."""
        last = name.last if isinstance(name, QName) else name.split("::")[-1]
        return sorted("::".join(q) for q in self.symbols.get(kind, {}) if q[-1] == last and len(q) > 1)

    def visible_functions(self, source: SourceFile | None) -> dict[str, FunctionDecl]:
        """Functions callable by simple name from `source`: its package's, package-less files',
        and the imported ones (the first of these shadows the others)."""
        out: dict[str, FunctionDecl] = {}
        table = self.symbols.get("function", {})
        own = source.namespace if source is not None else ()
        for imp in reversed(source.imports if source is not None else []):
            for q, fn in table.items():
                if (imp.wildcard and q[:-1] == imp.name.parts) or (not imp.wildcard and q == imp.name.parts):
                    out[q[-1]] = fn
        for q, fn in table.items():
            if len(q) == 1 and q[0] not in out:
                out[q[0]] = fn
        for q, fn in table.items():
            if q[:-1] == own:
                out[q[-1]] = fn
        return out


# ---- library --------------------------------------------------------------------------------

_LIBRARY_CACHE: dict[tuple[str, ...], Package] | None = None


def library_packages() -> dict[tuple[str, ...], Package]:
    """The built-in packages (`physmod::joints`, `set_toolkit`, `Mathematics`, ...), parsed once; a
    package is named after its path under library/ (`physmod/joints.pm` is `physmod::joints`)."""
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
            source.package = QName(name)  # named after its path, whatever it declares
            packages[name] = Package(name, source)
            for block in source.siblings:  # further `package` blocks of a .pm file, under their own names
                packages.setdefault(block.package.parts, Package(block.package.parts, block))
        _LIBRARY_CACHE = packages
    return _LIBRARY_CACHE


def _library_files(root) -> Iterable[Path]:
    return [p for p in Path(str(root)).rglob("*") if p.is_file() and notation_of(p)]


# ---- loading --------------------------------------------------------------------------------


def model_files(paths: Iterable[str | Path]) -> tuple[list[Path], list[Finding]]:
    """Expand folders into their .rst, .rct and .pm files (sorted), reporting paths that do not exist."""
    files: list[Path] = []
    findings: list[Finding] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.is_file() and notation_of(p))
            if not found:
                findings.append(Finding(Location(str(path), 1, 1), Severity.ERROR,
                                        "no .rst, .rct or .pm files in folder"))
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            findings.append(Finding(Location(str(path), 1, 1), Severity.ERROR, "not a regular file (a FIFO, a device?)"
                                    if path.exists() else "no such file or folder"))
    unique = list(dict.fromkeys(files))
    return unique, findings


def _project_root(file: Path, top: Path) -> Path:
    """The folder holding the RoboTool (Eclipse) project of `file`: its nearest ancestor, up to
    `top`, with a `.project` file; otherwise the file's own folder."""
    folder = file.parent
    while True:
        if (folder / ".project").is_file():
            return folder
        if folder == top or folder.parent == folder:
            return file.parent
        folder = folder.parent


def project_groups(paths: Iterable[str | Path]) -> tuple[list[list[Path]], list[Finding]]:
    """Group model files into projects: the files named directly form one project; under a folder,
    every RoboTool project (a folder with a `.project` file, with all its subfolders) and every
    other folder holding model files forms its own (so `check arm1 arm2` checks two projects)."""
    loose: list[Path] = []
    groups: dict[Path, list[Path]] = {}
    findings: list[Finding] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            files, found = model_files([path])
            findings.extend(found)
            for f in files:
                groups.setdefault(_project_root(f, path), []).append(f)
        else:
            files, found = model_files([path])
            findings.extend(found)
            loose.extend(files)
    out = [list(dict.fromkeys(loose))] if loose else []
    out.extend(groups[k] for k in sorted(groups))
    return out, findings


def _index(project: Project, source: SourceFile, namespace: tuple[str, ...], diag: Diagnostics | None) -> None:
    own = project._own.setdefault(id(source), {})
    for element in source.elements:
        kind = kind_of(element)
        project.owners[id(element)] = source
        if kind is None:
            continue
        own.setdefault((kind, element.name), element)
        names = project.symbols.setdefault(kind, {})
        qualified = namespace + (element.name,)
        first = names.get(qualified)
        if first is not None:
            if diag is not None:  # RoboTool's validators warn (UniqueQualifiedName); the first is used
                diag.warning(element.loc, f"duplicate {KIND_WORD[kind]} '{'::'.join(qualified)}' (first declared at "
                                          f"{first.loc}; RoboTool warns too): the first one is used")
            continue
        names[qualified] = element


def _index_blocks(project: Project, source: SourceFile) -> None:
    """Where each package block of a file starts (the first at line 1), for `Project.source_at`."""
    blocks = project._blocks.setdefault(source.path, [])
    if any(block is source for _, block in blocks):
        return
    line = source.package.loc.line if blocks and source.package is not None else 1
    blocks.append((line, source))
    blocks.sort(key=lambda b: b[0])


def build_project(sources: list[SourceFile], diag: Diagnostics) -> Project:
    """Index the files' elements per kind and qualified name, reporting duplicates and unknown imports."""
    project = Project(files=sources, packages=dict(library_packages()))
    own_pm = {s.namespace for s in sources if s.notation == "pm"}
    for package in project.packages.values():
        _index_blocks(project, package.source)
        if package.source.notation == "pm" and package.name in own_pm:
            continue  # the project's own copy of a p-model library package (RoboTool's files) replaces ours
        _index(project, package.source, package.name, None)
    for source in sources:
        project.namespaces.add(source.namespace)
        _index_blocks(project, source)
        _index(project, source, source.namespace, diag)
    known_packages = set(project.packages) | project.namespaces
    for source in sources:
        for imp in source.imports:
            if imp.wildcard:
                known = imp.name.parts in known_packages
            else:
                known = any(imp.name.parts in table for table in project.symbols.values())
            if not known:  # RoboTool does not check imports: the names used later are reported if unknown
                diag.warning(imp.loc, f"unknown import '{imp.name}{'::*' if imp.wildcard else ''}': nothing is imported")
            elif imp.name.parts[:1] in SUBSTITUTE_PACKAGES and imp.name.parts[:1] not in project.namespaces:
                diag.warning(imp.loc, f"package {imp.name.parts[0]} is not part of the project (RoboTool projects "
                                      f"import it without publishing it): cotwin uses its built-in "
                                      f"{imp.name.parts[0]} (abs, floor, ceil, sqrt, trigonometry, random)")
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
            sources.extend((source, *source.siblings))
    return build_project(sources, diag)
