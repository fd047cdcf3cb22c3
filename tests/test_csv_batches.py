"""The CSV writer formats its rows in batches: the bytes are those of Maestro's spelling row by row
(format_value), whatever the values, and a run that fails keeps every row it produced."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cotwin.cosim.algorithm import Jacobi
from cotwin.cosim.execution import Execution
from cotwin.cosim.observers import CSVWriter, format_value
from cotwin.cosim.system import System
from cotwin.cosim.units import Port, PythonUnit
from cotwin.diagnostics import CotwinError

PORTS = [Port("r", "Real", "output"), Port("i", "Integer", "output"), Port("b", "Boolean", "output")]


class Wave(PythonUnit):
    """Reals of every kind (tiny, huge, negative, inf), integers, Booleans; numpy scalars and None in some
    steps; fails at `fail_at` when given."""

    def __init__(self, fail_at: float | None = None):
        super().__init__("{w}.w", PORTS)
        self.fail_at = fail_at
        self.values.update(r=0.0, i=0, b=False)

    def step(self, t: float, h: float) -> None:
        if self.fail_at is not None and t >= self.fail_at:
            raise CotwinError("the wave breaks")
        k = round(t / h)
        r = [1e-300 * k, -k / 3, 1e300 * k, math.inf, 0.1 * k][k % 5]
        self.values.update(r=np.float64(r) if k % 7 == 3 else r, i=None if k % 11 == 5 else k * 1000003,
                           b=bool(k % 2))


def expected(rows: list[tuple]) -> str:
    return "".join(f"{t!r}," + ",".join(format_value(v) for v in values) + "\n" for t, *values in rows)


def run(tmp_path, batch: int, fail_at=None):
    unit, seen = Wave(fail_at), []

    class Record(CSVWriter):
        def step_complete(self, execution):
            seen.append((round(execution.time, 12), *(unit.values[p.name] for p in PORTS)))
            super().step_complete(execution)

    writer = Record(tmp_path / "out.csv", batch=batch)
    execution = Execution(System.of([unit], [], log={unit.name: ["r", "i", "b"]}), Jacobi(), 0.001, observers=[writer])
    return execution, writer, seen


@pytest.mark.parametrize("batch", [1, 7, 256, 100000])
def test_rows_formatted_in_batches_are_the_bytes_of_row_by_row_formatting(tmp_path, batch):
    execution, writer, seen = run(tmp_path, batch)
    execution.run(1.0)
    lines = (tmp_path / "out.csv").read_text().splitlines(keepends=True)
    assert lines[0] == "time,{w}.w.r,{w}.w.i,{w}.w.b\n"
    assert "".join(lines[2:]) == expected(seen)
    assert writer.rows == len(seen) + 1 == 1001


def test_a_failed_run_keeps_every_row_it_produced_though_not_yet_formatted(tmp_path):
    execution, writer, seen = run(tmp_path, batch=100000, fail_at=0.5)
    with pytest.raises(CotwinError, match="the wave breaks"):
        execution.run(1.0)
    text = (tmp_path / "out.partial.csv").read_text()
    assert text.splitlines(keepends=True)[2:] == expected(seen).splitlines(keepends=True)
    assert len(seen) == 500 and "the 501 row(s) computed are in" in writer.kept()


def test_a_run_that_ends_well_removes_an_earlier_failed_runs_rows_and_a_folder_in_the_way_is_said_first(tmp_path):
    """After a failed run left out.partial.csv, a run into the same place that ends well replaces it (the old
    partial rows stayed beside the new result); a folder where the result goes is refused before any step,
    naming it (the run was computed, then failed at a temporary name)."""
    failed, _, _ = run(tmp_path, batch=7, fail_at=0.2)
    with pytest.raises(CotwinError):
        failed.run(1.0)
    assert (tmp_path / "out.partial.csv").is_file()
    execution, _, _ = run(tmp_path, batch=7)
    execution.run(0.5)
    assert (tmp_path / "out.csv").is_file() and not (tmp_path / "out.partial.csv").exists()
    (tmp_path / "out.csv").unlink()
    (tmp_path / "out.csv").mkdir()
    blocked, _, seen = run(tmp_path, batch=7)
    with pytest.raises(CotwinError, match=r"out\.csv is a folder"):
        blocked.run(0.5)
    assert seen == []


class PlainWave(Wave):
    """Plain numbers only (floats of every kind, ints, Booleans: what FMU ports hold), so that every batch of
    rows is spelt in C (cotwin.cosim.rowtext) rather than by repr."""

    def step(self, t: float, h: float) -> None:
        k = round(t / h)
        self.values.update(r=[1e-300 * k, -k / 3, 1e300 * k, math.inf, 0.1 * k, -0.0, math.nan][k % 7],
                           i=(k * 1000003) * (-1) ** k, b=bool(k % 2))


@pytest.mark.parametrize("batch", [1, 7, 256])
def test_plain_rows_spelt_in_c_are_the_bytes_of_row_by_row_formatting(tmp_path, batch):
    unit, seen = PlainWave(), []

    class Record(CSVWriter):
        def step_complete(self, execution):
            seen.append((round(execution.time, 12), *(unit.values[p.name] for p in PORTS)))
            super().step_complete(execution)

    execution = Execution(System.of([unit], [], log={unit.name: ["r", "i", "b"]}), Jacobi(), 0.001,
                          observers=[Record(tmp_path / "out.csv", batch=batch)])
    execution.run(1.0)
    lines = (tmp_path / "out.csv").read_text().splitlines(keepends=True)
    assert "".join(lines[2:]) == expected(seen)
