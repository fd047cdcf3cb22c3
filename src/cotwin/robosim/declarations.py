"""Declarations common to d-models, p-models and mappings: variables, types, functions, imports."""

from __future__ import annotations

from dataclasses import dataclass, field

from .syntax import Expr, Location, QName, TypeRef


@dataclass(frozen=True)
class Import:
    name: QName
    wildcard: bool
    loc: Location


@dataclass(frozen=True)
class VarDecl:
    """A `var` or `const` (or, in devices, an `input`/`output`/`local` port)."""

    name: str
    type: TypeRef
    init: Expr | None
    kind: str  # var | const | input | output | local
    loc: Location

    @property
    def is_const(self) -> bool:
        return self.kind == "const"


@dataclass(frozen=True)
class Param:
    name: str
    type: TypeRef
    loc: Location


@dataclass(frozen=True)
class EventDecl:
    name: str
    type: TypeRef | None
    loc: Location
    broadcast: bool = False  # RoboChart's `_broadcast event`


@dataclass(frozen=True)
class OperationSig:
    name: str
    params: tuple[Param, ...]
    loc: Location
    terminates: bool = False  # `op(...) [terminates]`


@dataclass(frozen=True)
class ClockDecl:
    name: str
    loc: Location


@dataclass(frozen=True)
class PrimitiveDecl:
    """`type T`: an abstract given type."""

    name: str
    loc: Location


@dataclass(frozen=True)
class RecordDecl:
    name: str
    fields: tuple[Param, ...]
    loc: Location

    def field(self, name: str) -> Param | None:
        return next((f for f in self.fields if f.name == name), None)


@dataclass(frozen=True)
class EnumLiteral:
    name: str
    params: tuple[TypeRef, ...]
    loc: Location


@dataclass(frozen=True)
class EnumDecl:
    name: str
    literals: tuple[EnumLiteral, ...]
    loc: Location

    def literal(self, name: str) -> EnumLiteral | None:
        return next((lit for lit in self.literals if lit.name == name), None)


@dataclass(frozen=True)
class FunctionDecl:
    name: str
    params: tuple[Param, ...]
    result: TypeRef
    preconditions: tuple[Expr, ...]
    postconditions: tuple[Expr, ...]
    loc: Location


TypeDecl = PrimitiveDecl | RecordDecl | EnumDecl


@dataclass
class SourceFile:
    """One parsed file: its package, imports and top-level elements in source order."""

    path: str
    notation: str  # "rst" | "rct" | "pm"
    package: QName | None = None
    imports: list[Import] = field(default_factory=list)
    elements: list[object] = field(default_factory=list)
    siblings: list["SourceFile"] = field(default_factory=list)  # further `package` blocks of a .pm file

    def of_kind(self, cls) -> list:
        return [e for e in self.elements if isinstance(e, cls)]

    @property
    def namespace(self) -> tuple[str, ...]:
        """The package this file's elements belong to (() for a file without `package`)."""
        return self.package.parts if self.package is not None else ()
