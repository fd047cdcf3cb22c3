"""The live twin's clock: its sides stepped in lockstep, its observers told after every step.

One loop for a single robot's twin (cotwin.twin.live.runtime.LiveTwin) and a cell's
(cotwin.twin.live.cell_live): step k of every side in order (the PT first), then `twin_step(twin, k, t)` to
every observer (cotwin.twin.assembly.observing), until the last step or a stop request, asked before each
step. Building the sides, initialising them and ending the run stay with each runtime.
"""

from __future__ import annotations

from typing import Callable, Sequence


def lockstep(twin, executions: Sequence, total: int, observers: Sequence, stopped: Callable[[], bool]) -> str:
    """Step `executions` together from `twin.steps` to `total`, keeping `twin.steps` and `twin.time` (the first
    side's clock) and telling `observers` of each step; "done", or "stopped" when `stopped()` ended it first.
    Observers are told `twin_started(twin)` before the first step."""
    for observer in observers:
        observer.twin_started(twin)
    first = executions[0]
    while twin.steps < total:
        if stopped():
            return "stopped"
        for execution in executions:
            execution.step()
        twin.steps += 1
        twin.time = first.time
        for observer in observers:
            observer.twin_step(twin, twin.steps, twin.time)
    return "done"
