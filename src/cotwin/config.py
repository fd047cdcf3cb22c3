"""Strictly read TOML configuration (projects, scenarios, calibrations): every problem is a finding at
the file, line and column of the offending key, all reported together.

`tomllib` gives values without positions, so `TomlFile` scans the text once for where each table and
key is written (headers, `key =` lines, dotted keys, keys of inline tables) and a `Schema` checks
values by declared kind: a string is never read as a Boolean (`realtime = "no"` is an error, not
true), numbers must be finite, unknown keys are reported with the known ones.
"""

from __future__ import annotations

import difflib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from .diagnostics import CotwinError, Finding, Location, Severity
from .files import read_text

_HEADER = re.compile(r'^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?')
_KEY = r'(?:[A-Za-z0-9_-]+|"[^"\n]*"|\'[^\'\n]*\')'
_ASSIGN = re.compile(rf'^\s*({_KEY}(?:\s*\.\s*{_KEY})*)\s*=')
_INLINE_KEY = re.compile(rf'[{{,]\s*({_KEY})\s*=')
_DECODE_AT = re.compile(r"\(at line (\d+), column (\d+)\)")


def _keys(text: str) -> tuple[str, ...]:
    parts = re.findall(_KEY, text)
    return tuple(p[1:-1] if p[:1] in "\"'" else p for p in parts)


class TomlFile:
    """A TOML file's data and where each key path was written."""

    def __init__(self, path: str | Path, what: str = "file"):
        self.path = Path(path)
        self.text = read_text(self.path, what)  # capped, UTF-8, a byte order mark dropped; errors located
        try:
            self.data: dict = tomllib.loads(self.text)
        except tomllib.TOMLDecodeError as err:
            message = str(err)
            at = _DECODE_AT.search(message)
            line, column = (int(at.group(1)), int(at.group(2))) if at else (1, 1)
            if not at and "end of document" in message:  # where the document ends
                line, column = self.text.count("\n") + 1, len(self.text.rsplit("\n", 1)[-1]) + 1
            raise self.error(f"bad TOML: {_DECODE_AT.sub('', message).strip()}", line, column) from None
        except RecursionError:  # arrays or inline tables nested thousands deep
            lines = self.text.splitlines() or [""]
            line = max(range(len(lines)), key=lambda n: lines[n].count("[") + lines[n].count("{")) + 1
            raise self.error(f"the {what} nests arrays or tables too deeply to read", line) from None
        self.where: dict[tuple, tuple[int, int]] = {}
        self._scan()

    def _scan(self) -> None:
        table: tuple = ()
        arrays: dict[tuple, int] = {}
        for number, line in enumerate(self.text.splitlines(), start=1):
            header = _HEADER.match(line)
            if header and not _ASSIGN.match(line):
                name = _keys(header.group(2))
                if header.group(1) == "[[":
                    arrays[name] = arrays.get(name, -1) + 1
                    table = name + (arrays[name],)
                else:
                    table = name
                for n in range(1, len(table) + 1):  # [a.b.c] (or [[a]]) also writes a, a.b
                    self.where.setdefault(table[:n], (number, header.start(1) + 1))
                continue
            assign = _ASSIGN.match(line)
            if assign:
                key = table + _keys(assign.group(1))
                for n in range(len(table) + 1, len(key) + 1):  # a.b.c = 1 also writes a, a.b
                    self.where.setdefault(key[:n], (number, assign.start(1) + 1))
                for inner in _INLINE_KEY.finditer(line, assign.end()):
                    self.where.setdefault(key + _keys(inner.group(1)), (number, inner.start(1) + 1))

    def location(self, key: tuple = ()) -> Location:
        """Where `key` (a path of table names, array indices and keys) was written, or its nearest
        written parent; the file's start when nothing of it was written."""
        for n in range(len(key), 0, -1):
            if key[:n] in self.where:
                return Location(str(self.path), *self.where[key[:n]])
        return Location(str(self.path), 1, 1)

    def error(self, message: str, line: int = 1, column: int = 1) -> CotwinError:
        return CotwinError([Finding(Location(str(self.path), line, column), Severity.ERROR, message)])


# ---- schemas ------------------------------------------------------------------------------------

def is_number(v) -> bool:
    """A finite TOML number (not a Boolean); an integer too large for any float is none."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:
        return False



@dataclass(frozen=True)
class Key:
    """One key of a table: its kind, whether it must be given, its default and an extra check.

    Kinds: "str", "bool", "int", "number", "positive" (number > 0), "nonnegative", "list[str]",
    "list", "table" (checked by `table`), "any". `choices` restricts a string; `check(value)` returns
    a message when the value is wrong.
    """

    kind: str
    default: Any = None
    required: bool = False
    choices: tuple = ()
    table: "Schema | None" = None
    check: Callable[[Any], str | None] | None = None


_KINDS: dict[str, tuple[Callable[[Any], bool], str]] = {
    "str": (lambda v: isinstance(v, str), "a string"),
    "bool": (lambda v: isinstance(v, bool), "true or false (a TOML Boolean, not a string)"),
    "int": (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer"),
    "number": (is_number, "a finite number"),
    "positive": (lambda v: is_number(v) and v > 0, "a positive number"),
    "nonnegative": (lambda v: is_number(v) and v >= 0, "a number >= 0"),
    "list[str]": (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a list of strings"),
    "list": (lambda v: isinstance(v, list), "a list"),
    "table": (lambda v: isinstance(v, dict), "a table"),
    "any": (lambda v: True, "anything"),
}


@dataclass
class Schema:
    """The keys a table may hold (`open` tables also take keys they do not list, checked by `values`)."""

    keys: dict[str, Key] = field(default_factory=dict)
    open: bool = False
    values: Key | None = None

    def read(self, data: dict, file: TomlFile, at: tuple = (), problems: list[Finding] | None = None) -> dict:
        """The table's values with defaults filled in; problems are appended, not raised."""
        problems = [] if problems is None else problems
        name = table_name(at)
        out: dict = {}
        for key, value in data.items():
            spec = self.keys.get(key) or (self.values if self.open else None)
            where = at + (key,)
            if spec is None:
                problems.append(Finding(file.location(where), Severity.ERROR, unknown_key(key, self.keys, name)))
                continue
            out[key] = _value(spec, value, file, where, problems, key_name(where))
        for key, spec in self.keys.items():
            if key not in data:
                if spec.required:
                    problems.append(Finding(file.location(at), Severity.ERROR, f"{name} needs '{key}'"))
                    out[key] = spec.default
                elif spec.kind == "table" and spec.table is not None:
                    out[key] = None if spec.default is None else spec.table.read(
                        dict(spec.default), file, at + (key,), problems)
                else:
                    out[key] = spec.default
        return out


def unknown_key(key: str, known, name: str) -> str:
    """The message for a key a table does not take, naming the nearest known key when one is close."""
    near = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    hint = f"; did you mean '{near[0]}'?" if near else ""
    return f"unknown key '{key}' in {name}{hint} (known: {', '.join(known) or 'none'})"


def did_you_mean(value, known) -> str:
    """"; did you mean 'X'?" naming the valid value closest to a wrong one (a typo: "jacobii", "opcau",
    "on_alarm"), or "" when none is close or the value is not a string."""
    if not isinstance(value, str):
        return ""
    choices = [str(k) for k in known]
    folded = {c.lower().replace("_", "-"): c for c in choices}  # "Free", "on_alarm", "target_x": case and dash
    near = [folded[key] for key in [value.lower().replace("_", "-")] if key in folded] or \
        difflib.get_close_matches(value, choices, n=1, cutoff=0.6) or \
        difflib.get_close_matches(value.lower().replace("_", "-"), choices, n=1, cutoff=0.6)
    return f"; did you mean '{near[0]}'?" if near else ""


def nearest_first(value: str, known, shown: int = 5) -> str:
    """The `shown` names of `known` closest to `value` (difflib's ratio, the nearest first), then "... and N more":
    a short list where the whole one would bury the answer (a p-model's forty readings); "none" if none."""
    choices = sorted(dict.fromkeys(str(k) for k in known))
    if not choices:
        return "none"
    near = difflib.get_close_matches(str(value), choices, n=shown, cutoff=0)
    rest = len(choices) - len(near)
    return ", ".join(near) + (f", ... and {rest} more" if rest else "")


def table_name(at: tuple) -> str:
    """`[scenario.rabbitmq]`, `[[command]] 2`, or `the file` for the top level."""
    if not at:
        return "the file"
    names = [str(a) for a in at if not isinstance(a, int)]
    index = [a for a in at if isinstance(a, int)]
    if index:
        return f"[[{'.'.join(names)}]] {index[-1] + 1}"
    return f"[{'.'.join(names)}]"


def key_name(where: tuple) -> str:
    return f"{table_name(where[:-1])} {where[-1]}" if len(where) > 1 else f"'{where[0]}'"


def shown(value, limit: int = 80) -> str:
    """A value as a message quotes it: its repr, cut short (a hostile file's value may be megabytes)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit - 15]}... ({len(text)} characters)"


def _value(spec: Key, value, file: TomlFile, where: tuple, problems: list[Finding], name: str):
    test, words = _KINDS[spec.kind]
    if spec.kind == "bool" and not isinstance(value, str):
        words = "true or false (a TOML Boolean)"  # "not a string" would mislead about 1 or 0
    if not test(value):
        problems.append(Finding(file.location(where), Severity.ERROR, f"{name} must be {words}, got {shown(value)}"))
        return spec.default
    if spec.choices and value not in spec.choices:
        problems.append(Finding(file.location(where), Severity.ERROR,
                                f"{name} must be one of {', '.join(map(repr, spec.choices))}, got {shown(value)}"
                                f"{did_you_mean(value, spec.choices)}"))
        return spec.default
    if spec.kind == "table" and spec.table is not None:
        return spec.table.read(value, file, where, problems)
    if spec.check is not None:
        message = spec.check(value)
        if message:
            problems.append(Finding(file.location(where), Severity.ERROR, f"{name}: {message}"))
            return spec.default
    return value


def within(low: float, high: float, unit: str = "") -> Callable[[Any], str | None]:
    """A check that a number lies in [low, high] (what a setting can sensibly be, not just finite)."""
    def check(value) -> str | None:
        if low <= value <= high:
            return None
        return f"must be in [{low:g}, {high:g}]{f' {unit}' if unit else ''}, got {shown(value)}"
    return check


def unique(what: str, empty: bool = False) -> Callable[[Any], str | None]:
    """A check that a list of names is not empty (unless `empty`), holds no empty name and names nothing
    twice."""
    def check(value) -> str | None:
        if not value and not empty:
            return f"names no {what} (leave the key out for the default)"
        if any(not v for v in value):
            return f"an empty {what} name"
        twice = sorted({v for v in value if value.count(v) > 1})
        return f"names {', '.join(map(repr, twice))} more than once" if twice else None
    return check


def raise_problems(problems: list[Finding]) -> None:
    if any(p.severity is Severity.ERROR for p in problems):
        raise CotwinError(problems)


# ---- writing ------------------------------------------------------------------------------------

def dumps(tables: dict[str, dict], header: str = "") -> str:
    """TOML text of tables of strings, numbers, Booleans, lists and inline tables, deterministic; floats
    written as their shortest exact text, so that reading gives back the very same values."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    for table, values in tables.items():
        for item in values if isinstance(values, list) else [values]:  # a list: an array of tables ([[name]])
            if lines:
                lines.append("")
            lines.append(f"[[{table}]]" if isinstance(values, list) else f"[{table}]")
            lines.extend(f"{key} = {_toml_value(value)}" for key, value in item.items() if value is not None)
    return "\n".join(lines) + "\n"


def _toml_value(value) -> str:
    import json

    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items() if v is not None) + " }"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, float):
        return repr(value + 0.0)
    return json.dumps(value)
