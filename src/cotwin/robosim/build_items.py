"""Item tags shared by the parse-tree builders: block contents arrive as a flat list of item objects,
and containers sort them by type. These small classes tag items that have no model class of their own."""

from __future__ import annotations

import re
from dataclasses import dataclass

from lark import Token

from ..diagnostics import Location


class _Group(tuple):
    """Several declarations from one `var a: T, b: U` line; flattened into the container."""


class _Params(tuple):
    pass


class _Args(tuple):
    pass


@dataclass(frozen=True)
class _Tagged:
    tag: str
    value: object
    loc: Location


def _flatten(items) -> list:
    out = []
    for item in items:
        if isinstance(item, _Group):
            out.extend(item)
        else:
            out.append(item)
    return out


def _of(items, cls) -> tuple:
    return tuple(i for i in items if isinstance(i, cls))


def _tagged(items, tag: str) -> list[_Tagged]:
    return [i for i in items if isinstance(i, _Tagged) and i.tag == tag]


#: the escapes of Xtext's STRING terminal (its STRINGValueConverter): \b \t \n \f \r \" \' \\ and \uXXXX
_ESCAPE = re.compile(r"\\(u[0-9a-fA-F]{4}|[btnfr\"'\\])")
_ESCAPED = {"b": "\b", "t": "\t", "n": "\n", "f": "\f", "r": "\r"}


def _string(token: Token) -> str:
    """The text of a string literal: quotes removed, Xtext's escapes decoded (any other backslash is kept)."""
    return _ESCAPE.sub(lambda m: chr(int(m[1][1:], 16)) if m[1][0] == "u" else _ESCAPED.get(m[1], m[1]),
                       str(token)[1:-1])


def _ident(token: Token) -> str:
    text = str(token)
    return text[1:] if text.startswith("^") else text
