"""Typed settings: frozen dataclasses whose fields carry their TOML kind, default and meaning, read from
a `TomlFile` with every problem located, written back as TOML and documented, all from one declaration.

A field is `name: type = setting("meaning", Key(kind, default, ...))` (a `cotwin.config.Key`), a nested
table `setting("meaning", section=Cls)`, a list of tables `setting("meaning", items=Cls)`. `read` walks
the dataclasses: unknown keys are reported with a "did you mean", wrong values at their key, required
keys missing at their table, all together; `tables` gives what `cotwin.config.dumps` writes; `reference`
gives a Markdown table of every key.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from .config import Key, TomlFile, _value, key_name, shown, table_name, unknown_key
from .diagnostics import Finding, Severity


@dataclass(frozen=True)
class Setting:
    """What a field of a settings dataclass is in its TOML table."""

    meaning: str
    key: Key = Key("any")
    section: type | None = None  # a nested table read as this dataclass
    items: type | None = None  # a list of tables, each read as this dataclass
    optional: bool = False  # a nested table that is None when absent (else its defaults)
    path: bool = False  # a file name, relative to the file that names it


def setting(meaning: str, key: Key | None = None, *, section: type | None = None, items: type | None = None,
            optional: bool = False, path: bool = False) -> Any:
    """A dataclass field declared with its TOML key (kind, default, check) and meaning."""
    spec = Setting(meaning, key or Key("table" if section else "list" if items else "any"), section, items,
                   optional, path)
    meta = {"setting": spec}
    if section is not None and not (optional or spec.key.required):
        return dataclasses.field(default_factory=section, metadata=meta)
    if section is not None or items is not None:
        return dataclasses.field(default=None if section is not None else (), metadata=meta)
    default = freeze(spec.key.default)
    if isinstance(default, dict):
        return dataclasses.field(default_factory=lambda: dict(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def settings_of(cls: type) -> dict[str, Setting]:
    """A settings dataclass's keys in declaration order."""
    return {f.name: f.metadata["setting"] for f in dataclasses.fields(cls) if "setting" in f.metadata}


def freeze(value):
    """A TOML value with its lists made tuples (settings are immutable; tables stay dicts)."""
    if isinstance(value, list):
        return tuple(freeze(v) for v in value)
    return value


def thaw(value):
    """A settings value as TOML data: tuples back to lists, nested settings to tables."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return tables(value)
    if isinstance(value, tuple):
        return [thaw(v) for v in value]
    if isinstance(value, dict):
        return {k: thaw(v) for k, v in value.items()}
    return value


def read(cls: type, data: dict, file: TomlFile, at: tuple = (), problems: list[Finding] | None = None):
    """`data` (the table at `at` in `file`) as a `cls`; every problem is appended to `problems`."""
    problems = [] if problems is None else problems
    keys = settings_of(cls)
    name = table_name(at)
    values: dict[str, Any] = {}
    for key, value in data.items():
        where = at + (key,)
        spec = keys.get(key)
        if spec is None:
            problems.append(Finding(file.location(where), Severity.ERROR, unknown_key(key, keys, name)))
        elif spec.section is not None:
            if isinstance(value, dict):
                values[key] = read(spec.section, value, file, where, problems)
            else:
                problems.append(Finding(file.location(where), Severity.ERROR,
                                        f"{key_name(where)} must be a table, got {shown(value)}"))
        elif spec.items is not None:
            values[key] = _items(spec.items, value, file, where, problems)
        else:
            values[key] = freeze(_value(spec.key, value, file, where, problems, key_name(where)))
    for key, spec in keys.items():
        if key not in data and spec.key.required:
            problems.append(Finding(file.location(at), Severity.ERROR, f"{name} needs '{key}'"))
    return cls(**values)


def _items(cls: type, value, file: TomlFile, where: tuple, problems: list[Finding]) -> tuple:
    if not isinstance(value, list):
        problems.append(Finding(file.location(where), Severity.ERROR,
                                f"{key_name(where)} must be a list of tables, got {shown(value)}"))
        return ()
    out = []
    for i, item in enumerate(value):
        if not isinstance(item, dict):
            problems.append(Finding(file.location(where + (i,)), Severity.ERROR,
                                    f"each {table_name(where)} must be a table, got {shown(item)}"))
            continue
        out.append(read(cls, item, file, where + (i,), problems))
    return tuple(out)


def tables(value) -> dict:
    """The keys of a settings value that differ from their defaults, as TOML data (what reads back equal)."""
    out: dict = {}
    for f in dataclasses.fields(value):
        spec = f.metadata.get("setting")
        if spec is None:
            continue
        v = getattr(value, f.name)
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        if v is None or (v == default and not spec.key.required):
            continue
        v = thaw(v)
        if spec.section is not None and not v and not spec.optional:
            continue  # a table left at its defaults
        out[f.name] = v
    return out


def replace_path(value, path: tuple, new):
    """`value` with the setting at `path` (a tuple of field names) replaced by `new`."""
    if len(path) == 1:
        return dataclasses.replace(value, **{path[0]: new})
    return dataclasses.replace(value, **{path[0]: replace_path(getattr(value, path[0]), path[1:], new)})


def leaves(cls: type, at: tuple = ()) -> dict[tuple, Setting]:
    """Every key of `cls` and of its nested tables, by path (lists of tables are one key)."""
    out: dict[tuple, Setting] = {}
    for name, spec in settings_of(cls).items():
        out[at + (name,)] = spec
        if spec.section is not None:
            out.update(leaves(spec.section, at + (name,)))
    return out


# ---- reference ----------------------------------------------------------------------------------

KIND_WORDS = {"str": "string", "bool": "Boolean", "int": "integer", "number": "number", "positive": "number > 0",
              "nonnegative": "number >= 0", "list[str]": "list of strings", "list": "list", "table": "table",
              "any": "value"}


def kind_text(spec: Setting) -> str:
    """A key's type as the reference shows it."""
    if spec.items is not None:
        return "list of tables"
    if spec.section is not None:
        return "table"
    text = KIND_WORDS[spec.key.kind]
    if spec.key.choices:
        text = " \\| ".join(f'`"{c}"`' for c in spec.key.choices)
    return text + (" (file)" if spec.path else "")


def default_text(spec: Setting) -> str:
    if spec.key.required:
        return "required"
    if spec.section is not None or spec.items is not None:
        return "absent" if spec.optional or spec.items is not None else "(its keys' defaults)"
    value = spec.key.default
    if value is None or value in ({}, []):
        return "none" if value is None else f"`{thaw(value)}`".replace("{}", "{ }")
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, str):
        return f'`"{value}"`'
    return f"`{value!r}`"


def reference(cls: type, at: tuple = (), level: int = 2) -> list[str]:
    """Markdown: one heading per table of `cls` (nested tables and lists of tables after it), one row per
    key with its type, default and meaning."""
    lines: list[str] = []
    for name, spec in settings_of(cls).items():
        table = spec.section or spec.items
        path = ".".join(at + (name,))
        if table is None:
            if not at and spec.key.kind == "table":  # a top-level table read elsewhere
                lines += ["", f"{'#' * level} `[{path}]`", "", spec.meaning]
            continue
        header = f"[[{path}]]" if spec.items is not None else f"[{path}]"
        first = (table.__doc__ or "").strip().split("\n\n")[0]  # the docstring's first paragraph, however wrapped
        doc = " ".join(line.strip() for line in first.splitlines())
        about = f"{spec.meaning} {doc}" if not at and doc else doc or spec.meaning
        lines += ["", f"{'#' * level} `{header}`", "", about]
        if spec.key.required:
            lines[-1] += " Required."
        rows = [(k, s) for k, s in settings_of(table).items()]
        if rows:
            lines += ["", "| key | type | default | meaning |", "|---|---|---|---|"]
            lines += [f"| `{k}` | {kind_text(s)} | {default_text(s)} | {s.meaning.replace('|', chr(92) + '|')} |"
                      for k, s in rows]
        lines += reference(table, at + (name,), level + 1 if level < 4 else level)
    return lines
