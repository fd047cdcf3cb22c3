"""Findings (errors and warnings with a location) and the one exception type cotwin raises for bad input."""

from __future__ import annotations

import copyreg
from dataclasses import dataclass
from enum import Enum
from typing import Iterable



@dataclass(frozen=True, order=True)
class Location:
    """A position in a source file: 1-based line and column."""

    path: str
    line: int
    column: int

    def __str__(self) -> str:
        return f"{self.path}:{self.line}:{self.column}"


class Severity(str, Enum):
    ERROR = "error"
    WARNING = "warning"


@dataclass(frozen=True, order=True)
class Finding:
    location: Location
    severity: Severity
    message: str

    def __str__(self) -> str:
        if self.location.line > 0:
            return f"{self.location}: {self.severity.value}: {self.message}"
        if self.location.path.startswith("<"):  # no place to name: the message says what it is about
            return f"{self.severity.value}: {self.message}"
        return f"{self.location.path}: {self.severity.value}: {self.message}"


class PicklableError(Exception):
    """An exception that crosses process boundaries (a sweep's or a what-if's worker, a Ray task) intact.

    Pickle rebuilds an exception as `cls(*self.args)`; an __init__ taking other arguments than the
    message it passes on (e.g. unit, time, call, detail) then fails in the receiving process, and a
    process pool reports only that it broke. This one is rebuilt as `cls.__new__(cls, *args)` (its
    __init__ not called) with its attributes restored: pickle's NEWOBJ, which names the class itself.
    """

    def __reduce__(self):
        return copyreg.__newobj__, (type(self), *self.args), self.__dict__


class CotwinError(PicklableError):
    """Bad input: carries every finding, each with its location. Never a bare traceback."""

    def __init__(self, findings: Iterable[Finding | str] | str, ordered: bool = False):
        """Findings sorted by place; with `ordered`, in the order given (a cause, then what follows from it,
        such as where a run that failed kept its rows)."""
        if isinstance(findings, str):
            findings = [findings]
        given = [f if isinstance(f, Finding) else Finding(Location("<input>", 0, 0), Severity.ERROR, f) for f in findings]
        self.findings = given if ordered else sorted(given)
        super().__init__("\n".join(str(f) for f in self.findings))


class Interrupted(CotwinError):
    """A command or run stopped by an interrupt (Ctrl-C, or SIGTERM, which cotwin takes as one): its findings say
    what was kept; the command line exits 130 after reporting it."""


def placed(err: CotwinError, location: Location) -> CotwinError:
    """`err` with each finding that names no place put at `location` (what it is about: a file, an expression);
    of its class (an Interrupted stays one), its other attributes kept."""
    found = [f if not f.location.path.startswith("<") else Finding(location, f.severity, f.message) for f in err.findings]
    out = CotwinError.__new__(type(err))
    CotwinError.__init__(out, found)
    out.__dict__.update({k: v for k, v in err.__dict__.items() if k != "findings"})
    return out


class Diagnostics:
    """Collects findings so that all problems are reported together."""

    def __init__(self) -> None:
        self._findings: list[Finding] = []
        self._seen: set[Finding] = set()

    def error(self, loc: Location, message: str) -> None:
        self._add(Finding(loc, Severity.ERROR, message))

    def warning(self, loc: Location, message: str) -> None:
        self._add(Finding(loc, Severity.WARNING, message))

    def extend(self, findings: Iterable[Finding]) -> None:
        for f in findings:
            self._add(f)

    def _add(self, finding: Finding) -> None:
        if finding not in self._seen:
            self._seen.add(finding)
            self._findings.append(finding)

    @property
    def findings(self) -> list[Finding]:
        return sorted(self._findings)

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.severity is Severity.ERROR]

    @property
    def has_errors(self) -> bool:
        return any(f.severity is Severity.ERROR for f in self._findings)

    def raise_if_errors(self) -> None:
        if self.has_errors:
            raise CotwinError(self._findings)
