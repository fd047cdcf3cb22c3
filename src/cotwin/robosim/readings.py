"""What the checker decided about a project's expressions, for the evaluators and the C generator.

The checker types every expression once and records here its type and the readings it chose where a
model is defective but still read (a vector indexed from 0, a call of an undeclared function, a
constant that is assigned): the interpreter, the C generator and the verifier then follow the same
reading instead of re-deriving it.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Readings:
    #: id(expression) -> its type (cotwin.robosim.types)
    types: dict[int, object] = field(default_factory=dict)
    #: id(IndexAccess) -> the index of the first element, where it is not 1 (a statement written 0-based)
    first_index: dict[int, int] = field(default_factory=dict)
    #: id(Call) -> the FunctionDecl it calls, where that is not the declaration its name resolves to
    call_targets: dict[int, object] = field(default_factory=dict)
    #: (path of the file, name) -> FunctionDecl synthesised for a call of an undeclared function
    implicit_functions: dict[tuple[str, str], object] = field(default_factory=dict)
    #: id(VarDecl) of constants a model assigns: they are read as variables
    assigned_constants: set[int] = field(default_factory=set)

    def type_of(self, expr):
        return self.types.get(id(expr))
