"""How model names appear in the generated C, shared by the C generator and the FMI wrapper.

Every name that comes from the model is prefixed `x_` and lives inside a struct (the model's
inputs, calls, outputs, a machine's state, a record), so that any legal RoboSim name compiles:
`int`, `NAN`, `EOF`, `errno`, `main` become `x_int`, `x_NAN`, ... and cannot collide with a C
keyword, a libc macro or another generated name (the generator's own members never start `x_`).
"""

from __future__ import annotations


def ident(name: str) -> str:
    """A model identifier as a C identifier (inside a struct)."""
    return "x_" + name


def field_path(path: tuple[str, ...]) -> str:
    """`.x_a.x_b` for the record field path (a, b)."""
    return "".join("." + ident(f) for f in path)


def in_flag(event: str) -> str:
    return f"M->in.{ident(event)}.on"


def in_value(event: str) -> str:
    return f"M->in.{ident(event)}.v"


def out_flag(event: str) -> str:
    return f"M->out.{ident(event)}.on"


def out_value(event: str) -> str:
    return f"M->out.{ident(event)}.v"


def call_flag(operation: str) -> str:
    return f"M->call.{ident(operation)}.on"


def call_arg(operation: str, param: str) -> str:
    return f"M->call.{ident(operation)}.{ident(param)}"


def parameter(machine: int, name: str) -> str:
    """The C lvalue of an FMU parameter: a machine's constant, or the module's random seed."""
    if machine < 0:
        return "M->seed"
    return f"M->m{machine}.par.{ident(name)}"


def c_string(text: str) -> str:
    """A C string literal for any text (paths, names)."""
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif ord(ch) < 32 or ord(ch) > 126:
            out.append("".join(f"\\{b:03o}" for b in ch.encode("utf-8")))
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def c_comment(text: str) -> str:
    """Text safe inside a /* */ comment."""
    return text.replace("*/", "* /").replace("/*", "/ *")
