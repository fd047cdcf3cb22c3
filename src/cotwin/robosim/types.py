"""Semantic types of RoboSim values and the resolution of written type references to them."""

from __future__ import annotations

from dataclasses import dataclass

from ..diagnostics import Diagnostics
from . import syntax as s
from .declarations import EnumDecl, PrimitiveDecl, RecordDecl, SourceFile
from .pmodel_elements import Device


@dataclass(frozen=True)
class PrimTy:
    name: str  # int | nat | real | boolean | string | unknown

    def __str__(self) -> str:
        return self.name


INT, NAT, REAL, BOOL, STRING = PrimTy("int"), PrimTy("nat"), PrimTy("real"), PrimTy("boolean"), PrimTy("string")
UNKNOWN = PrimTy("unknown")  # after an error: compatible with everything, so errors do not cascade
PRIMITIVES = {"int": INT, "nat": NAT, "real": REAL, "boolean": BOOL, "string": STRING}


@dataclass(frozen=True)
class EnumTy:
    decl: EnumDecl

    def __str__(self) -> str:
        return self.decl.name


@dataclass(frozen=True)
class RecordTy:
    decl: RecordDecl

    def __str__(self) -> str:
        return self.decl.name


@dataclass(frozen=True)
class AbstractTy:
    decl: PrimitiveDecl

    def __str__(self) -> str:
        return self.decl.name


@dataclass(frozen=True)
class VectorTy:
    element: "Ty"
    size: int | None

    def __str__(self) -> str:
        return f"vector({self.element}, {self.size if self.size is not None else '?'})"


@dataclass(frozen=True)
class CollectionTy:
    kind: str  # Set | Seq
    element: "Ty"

    def __str__(self) -> str:
        return f"{self.kind}({self.element})"


@dataclass(frozen=True)
class MatrixTy:
    element: "Ty"
    rows: int | None
    columns: int | None

    def __str__(self) -> str:
        def size(n):
            return n if n is not None else "?"
        return f"matrix({self.element}, {size(self.rows)}, {size(self.columns)})"


@dataclass(frozen=True)
class TypeVar:
    """`?X`: a type parameter of a generic function."""

    name: str

    def __str__(self) -> str:
        return "?" + self.name


@dataclass(frozen=True)
class TupleTy:
    items: tuple["Ty", ...]

    def __str__(self) -> str:
        return "(" + " * ".join(str(i) for i in self.items) + ")"


@dataclass(frozen=True)
class FuncTy:
    params: tuple["Ty", ...]
    result: "Ty"

    def __str__(self) -> str:
        return f"({', '.join(str(p) for p in self.params)}) -> {self.result}"


@dataclass(frozen=True)
class DeviceTy:
    """A sensor or actuator instance in a p-model; its ports are reached with `.port`."""

    device: Device

    def __str__(self) -> str:
        return f"{self.device.kind} {self.device.name}"


Ty = PrimTy | EnumTy | RecordTy | AbstractTy | VectorTy | CollectionTy | MatrixTy | TupleTy | FuncTy | DeviceTy | TypeVar

NUMERIC = (INT, NAT, REAL)
#: physmod's built-in types, known in p-model files: `LINK`, a link of the model (a joint's `const parent: LINK`)
PHYSMOD_TYPES = {"LINK": AbstractTy(PrimitiveDecl("LINK", s.NOWHERE))}


def is_numeric(ty: Ty) -> bool:
    return ty in NUMERIC or ty == UNKNOWN


def assignable(target: Ty, value: Ty) -> bool:
    """Can a value of type `value` be stored where `target` is expected (int widens to real)?"""
    if target == UNKNOWN or value == UNKNOWN or target == value:
        return True
    if isinstance(target, TypeVar) or isinstance(value, TypeVar):
        return True
    if target == REAL and value in (INT, NAT):
        return True
    if target == INT and value == NAT:
        return True
    if isinstance(target, VectorTy) and isinstance(value, (VectorTy, TupleTy)):
        items = value.items if isinstance(value, TupleTy) else None
        size = len(items) if items is not None else value.size
        if target.size is not None and size is not None and target.size != size:
            return False
        elements = items if items is not None else (value.element,)
        return all(assignable(target.element, e) for e in elements)
    if isinstance(target, MatrixTy) and isinstance(value, MatrixTy):
        return (_same_size(target.rows, value.rows) and _same_size(target.columns, value.columns)
                and assignable(target.element, value.element))
    if isinstance(target, CollectionTy) and isinstance(value, CollectionTy):
        return target.kind == value.kind and assignable(target.element, value.element)
    if isinstance(target, TupleTy) and isinstance(value, TupleTy):
        return len(target.items) == len(value.items) and all(
            assignable(a, b) for a, b in zip(target.items, value.items))
    if isinstance(target, FuncTy) and isinstance(value, FuncTy):
        return len(target.params) == len(value.params) and assignable(target.result, value.result)
    return False


def _same_size(a: int | None, b: int | None) -> bool:
    return a is None or b is None or a == b


def join(a: Ty, b: Ty) -> Ty:
    """The type of a value that is either an a or a b (for branches and collection elements)."""
    if assignable(a, b):
        return b if a == UNKNOWN else a
    if assignable(b, a):
        return b
    return UNKNOWN


def comparable(a: Ty, b: Ty) -> bool:
    return assignable(a, b) or assignable(b, a)


class TypeResolver:
    """Resolves written types against a project, as seen from one file."""

    def __init__(self, project, source: SourceFile | None, diag: Diagnostics, constant=None):
        self.project = project
        self.source = source
        self.diag = diag
        self.constant = constant  # evaluates a size expression to an int, or None

    def resolve(self, ref: s.TypeRef | None) -> Ty:
        if ref is None:
            return UNKNOWN
        if isinstance(ref, s.NamedType):
            return self.named(ref.name)
        if isinstance(ref, s.VectorType):
            return VectorTy(self.resolve(ref.element), self._size(ref.size))
        if isinstance(ref, s.MatrixType):
            return MatrixTy(self.resolve(ref.element), self._size(ref.rows), self._size(ref.columns))
        if isinstance(ref, s.CollectionType):
            return CollectionTy(ref.kind, self.resolve(ref.element))
        if isinstance(ref, s.ProductType):
            return TupleTy(tuple(self.resolve(i) for i in ref.items))
        if isinstance(ref, s.FunctionType):
            return FuncTy((self.resolve(ref.argument),), self.resolve(ref.result))
        return UNKNOWN  # pragma: no cover

    def named(self, name: s.QName, report: bool = True) -> Ty:
        if len(name.parts) == 1 and name.last in PRIMITIVES:
            return PRIMITIVES[name.last]
        if len(name.parts) == 2 and name.parts[0] == "core" and name.last in PRIMITIVES:
            return PRIMITIVES[name.last]
        if len(name.parts) == 1 and name.last.startswith("?"):
            return TypeVar(name.last[1:])
        decl = self.project.lookup("type", name, self.source)
        if decl is None and len(name.parts) == 1 and name.last in PHYSMOD_TYPES and self._in_pmodel(name):
            return PHYSMOD_TYPES[name.last]
        if isinstance(decl, EnumDecl):
            return EnumTy(decl)
        if isinstance(decl, RecordDecl):
            return RecordTy(decl)
        if isinstance(decl, PrimitiveDecl):
            return AbstractTy(decl)
        if report and not self.project.ambiguous("type", name):  # an ambiguity is reported where found
            hint = self.project.elsewhere("type", name)
            extra = f" (there is {', '.join(hint)}: import its package or qualify the name)" if hint else ""
            self.diag.error(name.loc, f"unknown type '{name}'{extra}")
        return UNKNOWN

    def _in_pmodel(self, name: s.QName) -> bool:
        """Whether `name` is written in a p-model file (where physmod's types are known)."""
        return name.loc.path.endswith(".pm") or (self.source is not None and self.source.notation == "pm")

    def _size(self, expr: s.Expr) -> int | None:
        if isinstance(expr, s.Literal) and isinstance(expr.value, int):
            return expr.value
        if self.constant is not None:
            value = self.constant(expr)
            if isinstance(value, int):
                return value
        return None

    def declared(self, var) -> tuple[Ty, s.Expr | None]:
        """A variable's type and initial value, accepting `var x : E::lit` (an enumeration literal in
        type position, as a published mapping writes) as type E with initial value E::lit, with a warning."""
        ref = var.type
        if isinstance(ref, s.NamedType) and len(ref.name.parts) >= 2:
            enum_name = s.QName(ref.name.parts[:-1], ref.name.loc)
            decl = self.project.lookup("type", enum_name, self.source)
            if isinstance(decl, EnumDecl) and decl.literal(ref.name.last) is not None:
                if self.project.lookup("type", ref.name, self.source) is None:
                    self.diag.warning(
                        ref.loc,
                        f"'{ref.name}' is an enumeration literal, not a type: read as type "
                        f"'{decl.name}' with initial value {ref.name}",
                    )
                    init = var.init if var.init is not None else s.Name(ref.name, ref.loc)
                    return EnumTy(decl), init
        return self.resolve(ref), var.init
