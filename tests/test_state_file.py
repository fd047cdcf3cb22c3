"""The run's state file (StateFile): made when the run starts, so that a place it cannot be written fails the run
before its first step (it failed after the last, the run's work done and its state lost), and written whole at
the end, the previous state left as it was by a run that does not save one, with no temporary file beside it."""

from __future__ import annotations

import pytest

from cotwin.cosim.algorithm import Jacobi
from cotwin.cosim.execution import Execution, saved_execution
from cotwin.cosim.observers import StateFile
from cotwin.cosim.system import System
from cotwin.cosim.units import Port, PythonUnit
from cotwin.diagnostics import CotwinError


class Counter(PythonUnit):
    """Counts its steps; fails at `fail_at` when given; cannot save its state with `saves` false."""

    def __init__(self, fail_at: float | None = None, saves: bool = True):
        super().__init__("{c}.c", [Port("n", "Integer", "output")])
        self.values.update(n=0)
        self.fail_at, self.saves, self.steps = fail_at, saves, 0

    def step(self, t: float, h: float) -> None:
        if self.fail_at is not None and t >= self.fail_at:
            raise CotwinError("the counter breaks")
        self.steps += 1
        self.values["n"] = self.steps

    def get_state(self) -> bytes:
        if not self.saves:
            raise CotwinError("this counter cannot save its state")
        return super().get_state()


def execution(unit: Counter, path) -> tuple[Execution, StateFile]:
    saver = StateFile(path)
    return Execution(System.of([unit], [], log={unit.name: ["n"]}), Jacobi(), 0.01, observers=[saver]), saver


def strays(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".part"))


def test_a_state_path_that_cannot_be_written_fails_the_run_before_its_first_step(tmp_path):
    (tmp_path / "state").mkdir()
    unit = Counter()
    run, _ = execution(unit, tmp_path / "state")
    with pytest.raises(CotwinError, match=r"state: error: is a folder: cannot write a file there"):
        run.run(1.0)
    assert unit.steps == 0 and strays(tmp_path) == []


def test_a_run_that_ends_well_replaces_the_state_and_leaves_no_temporary_file(tmp_path):
    (tmp_path / "state").write_bytes(b"an earlier run's state")
    unit = Counter()
    run, saver = execution(unit, tmp_path / "state")
    run.run(0.5)
    saved = saved_execution((tmp_path / "state").read_bytes())
    assert saved["steps"] == unit.steps == 50 and saved["values"][(unit.name, "n")] == 50
    assert saver.skipped is None and strays(tmp_path) == []


@pytest.mark.parametrize("fail_at, saves", [(0.2, True), (None, False)])
def test_a_run_that_saves_no_state_leaves_the_earlier_one_as_it_was(tmp_path, fail_at, saves):
    """A run that failed, and a system that cannot save its state (noted in `skipped`): the earlier state file
    is untouched and the file made for this run's is removed."""
    (tmp_path / "state").write_bytes(b"an earlier run's state")
    run, saver = execution(Counter(fail_at, saves), tmp_path / "state")
    if fail_at is not None:
        with pytest.raises(CotwinError, match="the counter breaks"):
            run.run(0.5)
    else:
        run.run(0.5)
        assert saver.skipped == "this counter cannot save its state"
    assert (tmp_path / "state").read_bytes() == b"an earlier run's state" and strays(tmp_path) == []
