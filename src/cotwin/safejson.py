"""One JSON reader for every message cotwin takes from outside: broker commands and echoes, what-if
requests and answers, the page's requests, the robot link, records read back from the history store.

A message is read as a hostile peer may write it, with one policy everywhere: at most `limit` bytes;
UTF-8 without lone surrogates (text that cannot be written back to a log, a CSV or a database);
nested at most MAX_DEPTH deep; a number of at most MAX_NUMBER characters that is finite (no NaN or
Infinity, which JSON lacks, and no 1e999, which reads as infinity); an object naming no key twice
(which of the two values is meant?). Anything else raises `Refused` (a ValueError) saying what and
where, never a RecursionError, an OverflowError or a silently chosen value.
"""

from __future__ import annotations

import json
import math
import re

MAX_DEPTH = 32  # a what-if request, the deepest message, is 4 deep: {plan: [{args: {...}}]}
MAX_NUMBER = 40  # characters of a number: a double needs at most 24, an int64 20
_SURROGATE = re.compile("[\ud800-\udfff]")
_ESCAPED_SURROGATE = re.compile(r"\\u[dD][89a-fA-F]")


class Refused(ValueError):
    """A message that is not the JSON cotwin reads; the text says why (and where, when JSON says). `token` is the
    text refused (a number, a constant, a key given twice: its `nth` occurrence), for a file's reader to locate."""

    def __init__(self, message: str, token: str | None = None, nth: int = 1):
        super().__init__(message)
        self.token, self.nth = token, nth


_TOKENS = re.compile(r'"(?:[^"\\]|\\.)*"|-?Infinity|NaN|-?[0-9][0-9.eE+-]*|[^"\-0-9IN]+|.', re.S)


def position(text: str, token: str, nth: int = 1) -> tuple[int, int] | None:
    """Line and column (from 1) of the nth occurrence of `token` as a whole JSON token of `text` (a string, a
    number, a constant; not a part of a string), or None."""
    seen = 0
    for match in _TOKENS.finditer(text):
        if match.group() == token:
            seen += 1
            if seen == nth:
                line = text.count("\n", 0, match.start()) + 1
                return line, match.start() - (text.rfind("\n", 0, match.start()) + 1) + 1
    return None


def loads(body: bytes | bytearray | str, limit: int, depth: int = MAX_DEPTH):
    """The JSON value of `body` under the module's policy, or Refused saying why not."""
    if len(body) > limit:
        raise Refused(f"{len(body)} bytes, more than the {limit} accepted")
    if isinstance(body, (bytes, bytearray)):
        try:
            text = bytes(body).decode("utf-8")
        except UnicodeDecodeError as err:
            raise Refused(f"not UTF-8 (byte 0x{body[err.start]:02x} at {err.start})") from None
    elif isinstance(body, str):
        text = body
    else:
        raise Refused(f"expected bytes or text, got {type(body).__name__}")
    try:
        value = decode(text)
    except json.JSONDecodeError as err:
        raise Refused(f"not JSON: {err.msg} at line {err.lineno} column {err.colno}") from None
    except RecursionError:
        raise Refused(f"nested too deeply (at most {depth} levels)") from None
    if text.count("[") + text.count("{") > depth or _ESCAPED_SURROGATE.search(text):  # else none is too deep
        _check(value, depth)
    return value


def decode(text: str):
    """`json.loads` under the policy on numbers and keys (Refused); a JSONDecodeError or RecursionError is left
    to the caller, for a file's reader to locate (cotwin.cosim.multimodel)."""
    return json.loads(text, parse_int=_integer, parse_float=_real, parse_constant=_constant, object_pairs_hook=_object)


def loads_object(body: bytes | bytearray | str, limit: int, depth: int = MAX_DEPTH) -> dict:
    """`loads`, for messages that must be a JSON object."""
    value = loads(body, limit, depth)
    if not isinstance(value, dict):
        raise Refused(f"expected a JSON object, got {_kind(value)}")
    return value


def _integer(text: str) -> int:
    if len(text) > MAX_NUMBER:
        raise Refused(f"a number of {len(text)} digits ({text[:12]}...; at most {MAX_NUMBER} characters)", text)
    return int(text)


def _real(text: str) -> float:
    if len(text) > MAX_NUMBER:
        raise Refused(f"a number of {len(text)} characters ({text[:12]}...; at most {MAX_NUMBER})", text)
    value = float(text)
    if not math.isfinite(value):
        raise Refused(f"the number {text} is beyond the range of a double", text)
    return value


def _constant(name: str):
    raise Refused(f"{name} is not a JSON number", name)


def _object(pairs: list[tuple[str, object]]) -> dict:
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set[str] = set()
        twice = next(k for k, _ in pairs if k in seen or seen.add(k))
        raise Refused(f"the key {_show(twice)} appears twice: which value is meant?", json.dumps(twice), 2)
    return out


def _check(value, limit: int) -> None:
    """Depth and text of a parsed value, without recursion (a value within Python's limit may still be
    deeper than ours). Only called where a quick look at the text finds something that may be wrong."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > limit:
            raise Refused(f"nested too deeply (at most {limit} levels)")
        if type(item) is dict:
            for key in item:
                _text(key)
        for member in (item.values() if type(item) is dict else item):
            kind = type(member)
            if kind is str:
                _text(member)
            elif kind is dict or kind is list:
                stack.append((member, depth + 1))


def _text(text: str) -> None:
    if not text.isascii() and _SURROGATE.search(text):
        raise Refused(f"the text {_show(text)} holds a lone surrogate (\\u{ord(_SURROGATE.search(text)[0]):04x}), "
                      "which is not Unicode text")


def _kind(value) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a Boolean", type(None): "null"}.get(
        type(value), "a number")


def _show(text: str, limit: int = 40) -> str:
    shown = repr(text[:limit])
    return shown if len(text) <= limit else shown + "..."
