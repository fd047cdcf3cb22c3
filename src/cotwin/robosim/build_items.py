"""Item tags shared by the parse-tree builders: block contents arrive as a flat list of item objects,
and containers sort them by type. These small classes tag items that have no model class of their own."""

from __future__ import annotations

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


def _ident(token: Token) -> str:
    text = str(token)
    return text[1:] if text.startswith("^") else text
