"""Functions: which declaration a call reaches, and what (if anything) computes its value.

A function is executable when the built-in library implements it (Mathematics, physmod::math, the
set and sequence toolkits) or when a postcondition defines its result (`postcondition result == e`).
A function declared with neither is uninterpreted: RoboTool accepts it, and cotwin executes its
calls by drawing a value of its result type from a seedable pseudo-random source (an uninterpreted
function denotes an arbitrary value; the source makes one choice, reproducibly).
"""

from __future__ import annotations

from . import syntax as s
from .declarations import FunctionDecl
from .operators import BUILTIN_PACKAGES

#: library packages cotwin offers in place of a package RoboTool projects import but do not publish
SUBSTITUTE_PACKAGES = {("Mathematics",)}


def definition(fn: FunctionDecl) -> s.Expr | None:
    """The `e` of a `postcondition result == e` (or `e == result`), if the function has one."""
    for post in fn.postconditions:
        if isinstance(post, s.Binary) and post.op == "==":
            if _is_result(post.left):
                return post.right
            if _is_result(post.right):
                return post.left
    return None


def _is_result(e) -> bool:
    return isinstance(e, s.Name) and e.name.parts == ("result",)


def package_of(project, fn: FunctionDecl) -> tuple[str, ...] | None:
    owner = project.file_of(fn)
    return owner.namespace if owner is not None else None


def builtin(project, fn: FunctionDecl):
    """The Python implementation of a library function, None if it has none; "random" for the
    pseudo-random draws of Mathematics::random."""
    package = package_of(project, fn)
    table = BUILTIN_PACKAGES.get(package) if package is not None else None
    if table is None or fn.name not in table:
        return None
    return table[fn.name] if table[fn.name] is not None else "random"


def is_builtin(project, fn: FunctionDecl) -> bool:
    package = package_of(project, fn)
    return package is not None and fn.name in BUILTIN_PACKAGES.get(package, {})


def substitute(project, name: str, arity: int) -> FunctionDecl | None:
    """A built-in function a defective call may be read as: same name, this many parameters."""
    for package in sorted(SUBSTITUTE_PACKAGES) + [("physmod", "math")]:
        fn = project.symbols.get("function", {}).get(package + (name,))
        if fn is not None and len(fn.params) == arity and builtin(project, fn) is not None:
            return fn
    return None


def in_library(project, fn: FunctionDecl) -> bool:
    owner = project.file_of(fn)
    return owner is not None and owner.path.startswith("<library>")


def target(project, call: s.Call, source) -> FunctionDecl | None:
    """The declaration a call runs: the checker's reading if it recorded one, else the declaration
    its name resolves to from `source`, else a function synthesised for an undeclared name."""
    readings = getattr(project, "readings", None)
    if readings is not None and id(call) in readings.call_targets:
        return readings.call_targets[id(call)]
    if not isinstance(call.function, s.Name):
        return None
    fn = project.lookup("function", call.function.name, source)
    if fn is None and readings is not None and source is not None:
        fn = readings.implicit_functions.get((source.path, call.function.name.last))
    return fn
