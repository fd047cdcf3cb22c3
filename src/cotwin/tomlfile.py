"""TOML files whose errors name the place: a parsed document that can say where a key was written.

tomllib gives no positions for values, so a key is located by scanning the text for its table header
and its `key =` line (good enough for the flat, hand-written files cotwin reads); a parse error
carries the line and column tomllib reports.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

from .diagnostics import CotwinError, Diagnostics, Finding, Location, Severity

_HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-\"']+)\s*=")


class TomlDocument:
    """A TOML file read whole: `data` is the parsed dict; `where(table, key)` its location."""

    def __init__(self, path: str | Path, text: str | None = None):
        self.path = Path(path)
        if text is None:
            try:
                text = self.path.read_text()
            except (OSError, UnicodeDecodeError) as err:
                raise CotwinError([Finding(Location(str(self.path), 1, 1), Severity.ERROR,
                                           f"cannot read {self.path}: {err}")]) from None
        self.text = text
        try:
            self.data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            message = err.args[0] if err.args else str(err)
            line = getattr(err, "lineno", None) or _line_of(message)
            column = getattr(err, "colno", None) or _column_of(message)
            if line is None and "end of document" in message:
                line, column = text.count("\n") + 1, len(text.rsplit("\n", 1)[-1]) + 1
            line, column = line or 1, column or 1
            raise CotwinError([Finding(Location(str(self.path), line, column), Severity.ERROR,
                                       f"bad TOML: {message}")]) from None
        self.diag = Diagnostics()

    def where(self, table: str | None = None, key: str | None = None) -> Location:
        """The line of `key` inside `[table]` (or of the table header, or line 1 if not found)."""
        current, header_line = "", None
        for number, line in enumerate(self.text.splitlines(), start=1):
            match = _HEADER.match(line)
            if match:
                current = match.group(1).strip()
                if table is not None and current == table:
                    header_line = number
                    if key is None:
                        return Location(str(self.path), number, 1)
                continue
            if key is not None and (table or "") == current:
                m = _KEY.match(line)
                if m and m.group(1).strip("\"'") == key:
                    return Location(str(self.path), number, line.index(m.group(1)) + 1)
        return Location(str(self.path), header_line or 1, 1)

    def error(self, table: str | None, key: str | None, message: str) -> None:
        self.diag.error(self.where(table, key), message)

    def table(self, name: str, known: set[str], required: bool = False) -> dict:
        """A top-level table, reporting unknown keys (a typo would otherwise be silently ignored)."""
        value = self.data.get(name)
        if value is None:
            if required:
                self.error(None, None, f"missing table [{name}]")
            return {}
        if not isinstance(value, dict):
            self.error(None, name, f"'{name}' must be a table")
            return {}
        for key in value:
            if key not in known:
                self.error(name, key, f"unknown key '{key}' in [{name}] (known: {', '.join(sorted(known))})")
        return value

    def number(self, table: str, values: dict, key: str, default: float | None = None, positive: bool = False):
        if key not in values:
            if default is None:
                self.error(table, None, f"[{table}] needs '{key}'")
            return default
        value = values[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.error(table, key, f"[{table}] {key} must be a finite number, got {value!r}")
            return default
        if positive and value <= 0:
            self.error(table, key, f"[{table}] {key} must be positive, got {value!r}")
            return default
        return float(value)

    def vector(self, table: str, values: dict, key: str, length: int, default=None):
        if key not in values:
            return default
        value = values[key]
        if not (isinstance(value, list) and len(value) == length and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
            self.error(table, key, f"[{table}] {key} must be a list of {length} finite numbers, got {value!r}")
            return default
        return tuple(float(v) for v in value)

    def finish(self) -> None:
        self.diag.raise_if_errors()


def dumps(tables: dict[str, dict], header: str = "") -> str:
    """TOML text for tables of strings, numbers, lists and one level of inline tables (deterministic)."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    for table, values in tables.items():
        if lines:
            lines.append("")
        lines.append(f"[{table}]")
        for key, value in values.items():
            lines.append(f"{key} = {_value(value)}")
    return "\n".join(lines) + "\n"


def _value(value) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, float):
        return repr(value + 0.0)  # shortest text that reads back to the same float
    return json.dumps(value)


def _line_of(message: str) -> int | None:
    m = re.search(r"line (\d+)", message)
    return int(m.group(1)) if m else None


def _column_of(message: str) -> int | None:
    m = re.search(r"column (\d+)", message)
    return int(m.group(1)) if m else None
