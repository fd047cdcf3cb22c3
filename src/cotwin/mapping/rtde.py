"""UR RTDE logs: space-separated, one header row of RTDE output fields (vectors expanded `_0`..`_5`),
one row per sample. Read strictly: a missing column, a short row or a cell that is not a finite number
is an error at its line and column."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..diagnostics import CotwinError, Finding, Location, Severity

MAX_LINE = 1 << 16


@dataclass
class RTDELog:
    path: str
    columns: list[str]
    data: np.ndarray  # (rows, columns)

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.columns.index(name)]

    def vector(self, field: str, n: int = 6) -> np.ndarray:
        return np.column_stack([self.column(f"{field}_{k}") for k in range(n)])

    @property
    def times(self) -> np.ndarray:
        return self.column("timestamp")

    @property
    def q(self) -> np.ndarray:
        return self.vector("actual_q")

    @property
    def qd(self) -> np.ndarray:
        return self.vector("actual_qd")


def read_rtde(path: str | Path, required=("timestamp", *(f"actual_q_{k}" for k in range(6)),
                                          *(f"actual_qd_{k}" for k in range(6)))) -> RTDELog:
    path = Path(path)
    problems: list[Finding] = []

    def problem(line: int, column: int, message: str) -> None:
        problems.append(Finding(Location(str(path), line, column), Severity.ERROR, message))

    try:
        raw = path.read_bytes()
    except OSError as err:
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR,
                                   f"cannot read the log: {err.strerror or err}")]) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        line = raw[:err.start].count(b"\n") + 1
        raise CotwinError([Finding(Location(str(path), line, 1), Severity.ERROR, "the log is not UTF-8 text")]) from None
    lines = text.splitlines()
    if not lines:
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR, "the log is empty")])
    header = lines[0].split()
    missing = [c for c in required if c not in header]
    if missing:
        problem(1, 1, f"the log has no column(s) {', '.join(missing)} (an RTDE log with actual_q_0..5 and "
                      "actual_qd_0..5 is needed)")
        raise CotwinError(problems)
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        if len(line) > MAX_LINE:
            problem(number, 1, f"a line longer than {MAX_LINE} characters")
            continue
        cells = line.split()
        if len(cells) != len(header):
            problem(number, 1, f"{len(cells)} values for {len(header)} columns")
            continue
        row, column = [], 1
        for k, cell in enumerate(cells):
            column = line.index(cell, column - 1) + 1
            try:
                value = float(cell)
                if not math.isfinite(value):
                    raise ValueError
            except ValueError:
                problem(number, column, f"column '{header[k]}': '{cell[:40]}' is not a finite number")
                break
            row.append(value)
            column += len(cell)
        else:
            rows.append(row)
        if len(problems) >= 20:
            break
    if problems:
        raise CotwinError(problems)
    if len(rows) < 2:
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR, "the log has fewer than two samples")])
    data = np.array(rows)
    times = data[:, header.index("timestamp")]
    back = np.nonzero(np.diff(times) <= 0)[0]
    if len(back):
        raise CotwinError([Finding(Location(str(path), int(back[0]) + 3, 1), Severity.ERROR,
                                   "timestamps must increase")])
    return RTDELog(str(path), header, data)
