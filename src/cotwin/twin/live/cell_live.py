"""A live twin of a cell of several robots (`cotwin twin` on a project with [[robots]]).

The PT is the cell's plant: the same robots in a world perturbed as the project's `[plant]` table says
(payload at each robot's tool, friction and damping on each robot's joints: cotwin.pmodel.perturbation
perturbed_world), each robot seen through the plant's latency and noise (cotwin.mapping.perturbed); the
DT is the nominal cell. Both are the cell's co-simulation (cotwin.twin.assembly.cell), the
same commands played into each, stepped in lockstep on one clock: step k of the PT, then of the DT, then
the observers look at both. The services are a live twin's own (cotwin.twin.live.live_observers):
- deviation per robot: one DeviationCheck per robot over its monitored variables (its q<i>, ...), its
  alarms naming the robot (`twin`) and the variable scoped by it (`ROBOT.q0`);
- history: HistoryRecording, one run in the history store (DIR/history.sqlite unless [history] url), its
  samples every logged column of both sides, each robot's d-model state changes as machine
  `ROBOT.Machine` and its commands as `ROBOT.port`, the alarms;
- real-time pacing (Pacing), after the caller's observers.
Results: DIR/pt/outputs.csv, DIR/dt/outputs.csv, DIR/deviation.json (a report per robot).

Commands come from the cell's plan (its ROBOT.port columns) or, with `[scenario] rabbitmq`, from the broker
routed per robot (TO_COSIM.ROBOT): one bridge and command stream per robot feed both sides, so each command
reaches the robot's PT and DT in the same step, and only the PT echoes (cotwin.twin.live.runtime.paired_sources).
Observers get what a live twin's get (cotwin.twin.assembly.observing; the page's feed is
cotwin.twin.services.dashboard.feed.CellFeed). Not yet: a PT over OPC UA (a plant server of the whole
cell), the what-if forks.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from pathlib import Path

from ...cosim.algorithm import algorithm as make_algorithm
from ...cosim.execution import Execution, RunResult, step_count
from ...cosim.observers import CSVWriter
from ...diagnostics import CotwinError, Finding, Severity
from ...files import write_text
from ..assembly.observing import TwinObserver
from ..assembly.cell import CELL_MAPPING, CellOutcomes, CellSystem
from ..services.deviation import DeviationMonitor
from ..project import check_timing
from ..assembly.system import MAPPING
from .live_observers import DeviationCheck, HistoryRecording, Pacing
from .lockstep import lockstep
from .runtime import paired_sources

SIDES = ("pt", "dt")


@dataclass(frozen=True)
class CellSide:
    execution: Execution


@dataclass
class CellAlarms:
    """Every robot's deviation alarms, in the order they were raised (what a live twin's observers read as
    its monitor's `events`)."""

    events: list[dict] = field(default_factory=list)


@dataclass
class CellTwin:
    """What a cell twin's observers are given, as a live twin's are: the cell (`system`), the sides, the
    alarms, the step, the end, where the run is (`steps`, `time`) and why it did not finish (`message`)."""

    system: CellSystem
    end: float
    step_size: float
    sides: dict[str, CellSide]
    monitor: CellAlarms
    watchers: list[TwinObserver] = field(default_factory=list)
    convergence: None = None
    steps: int = 0
    time: float = 0.0
    message: str | None = None

    @property
    def cell(self) -> CellSystem:
        return self.system

    def alarm(self, event: dict) -> None:
        """A robot's monitor raised or cleared an alarm: kept, and told to every observer."""
        self.monitor.events.append(event)
        for observer in self.watchers:
            observer.twin_alarm(self, event)


@dataclass
class CellTwinResult:
    pt: RunResult
    dt: RunResult
    deviation: dict  # robot -> its DeviationMonitor report
    out: Path
    history_url: str
    run_id: int | None
    outcomes: dict[str, CellOutcomes] = field(default_factory=dict)  # side -> per-robot outcomes
    alarms: list[dict] = field(default_factory=list)
    stopped: bool = False  # asked to stop (`stop`) before its end: the steps so far, kept as a finished run's
    history_problem: str | None = None  # why the run's history is incomplete (its store failed), if it is

    @property
    def alarm_count(self) -> int:
        return sum(report["alarms"] for report in self.deviation.values())


def deviation_check(spec, robot, alarm) -> DeviationCheck:
    """Robot `robot`'s deviation check over its ports of the cell's mapping: [deviation] variables of its own
    (ROBOT.variable, checked by the cell), else every variable it logs; its alarms name it and go to `alarm`."""
    dev = spec.deviation
    variables = [robot.scoped(v) for v in robot.system.log[MAPPING.name]] if dev.variables is None else \
        [v for v in dev.variables if v.startswith(robot.name + ".")]
    monitor = DeviationMonitor(variables, dev.absolute, dev.relative, dev.lag_steps, dev.debounce_steps,
                               publish=alarm, twin=robot.name)
    return DeviationCheck(monitor, variables, unit=CELL_MAPPING.name)


def run_cell_twin(cell: CellSystem, out: str | Path, step: float | None = None, end: float | None = None,
                  algorithm: str | None = None, realtime: bool | None = None, history_url: str | None = None,
                  cc: str = "cc", observers: tuple[TwinObserver, ...] | list[TwinObserver] = (),
                  stop: threading.Event | None = None) -> CellTwinResult:
    """Run the cell's PT (its perturbed plant) and DT in lockstep into `out` (see the module doc).
    `observers` are told as a live twin's are (cotwin.twin.assembly.observing): started, each step, each alarm,
    ended. `stop`, once set, ends the run after the step under way, its results kept as a finished run's."""
    from ...pmodel.perturbation import Perturbation
    from ..assembly.build import dmodel_fmu, folder_lock
    from ..assembly.build import ARTEFACTS
    from ..services.history import HistoryRecorder, database_url, sqlite_path

    spec = cell.spec
    if spec.pt is not None:
        raise CotwinError([Finding(spec.location("pt"), Severity.ERROR, "[pt]: a cell of several robots is twinned "
                                   "with its own perturbed plant ([plant]) as its PT; another PT is not done yet")])
    plant = spec.plant or Perturbation()
    out = Path(out)
    step = spec.step if step is None else step
    end = spec.end if end is None else end
    check_timing(spec, step, end)
    steps = step_count(end, step)
    out.mkdir(parents=True, exist_ok=True)
    url = database_url(history_url or spec.history_url, out)
    store = sqlite_path(url)
    writes = [f"{side}/{name}" for side in SIDES for name in ("outputs.csv", "outputs.partial.csv", "outputs.csv.part")]
    with folder_lock(out, [*writes, "deviation.json", *ARTEFACTS, *([store] if store else [])], spec.inputs):
        fmu = dmodel_fmu(cell.robots[0].system, out, cc)
        outcomes = {side: CellOutcomes(cell) for side in SIDES}
        executions: dict[str, Execution] = {}
        bridges: list = []
        running = CellTwin(cell, end, step, {}, CellAlarms())
        cancelled = stop.is_set if stop is not None else (lambda: False)  # also ends the wait for first commands
        paced = spec.realtime if realtime is None else realtime
        history = None
        try:  # from the first thing built: whatever was built is closed if a later part fails
            paired = {r.name: paired_sources(r.system, f"cotwin cell twin ({r.name})", cancelled)
                      for r in cell.robots if r.system.source is not None}
            bridges += [bridge for *_, bridge in paired.values() if bridge is not None]
            worlds = {"pt": cell.world(plant), "dt": cell.world()}
            for k, side in enumerate(SIDES):
                chain = [CSVWriter(out / side / "outputs.csv"), outcomes[side]]
                cosim = cell.instantiate(fmu, worlds[side], plant if side == "pt" else None,
                                         {name: pair[k] for name, pair in paired.items()})
                executions[side] = Execution(cosim, make_algorithm(algorithm or spec.algorithm), step, 0.0, chain)
                running.sides[side] = CellSide(executions[side])
            checks = {r.name: deviation_check(spec, r, running.alarm) for r in cell.robots}
            for bridge in bridges:  # every robot says it is ready before any waits for its first commands
                bridge.start()
            for execution in executions.values():
                execution.initialize()
            columns = {side: [f"{u}.{v}" for u, v in e.system.observed()] for side, e in executions.items()}
            history = HistoryRecorder(url, str(spec.path), "twin", step, executions["pt"].algorithm.name, columns)
            running.watchers = [*checks.values(), HistoryRecording(history), *observers, *([Pacing()] if paced else [])]
            status = lockstep(running, [executions[side] for side in SIDES], steps, running.watchers, cancelled)
            results = {}
            for side, execution in executions.items():
                execution.close()
                results[side] = execution.result()
        except BaseException as err:
            for execution in executions.values():
                execution.close(err)
            for bridge in bridges:
                bridge.close()
            running.message = str(err) or type(err).__name__
            if history is not None and not running.watchers:
                history.close("failed", running.message)
            for observer in running.watchers or observers:
                observer.twin_ended(running, "failed")
            raise
        for bridge in bridges:
            bridge.close()
        for observer in running.watchers:
            observer.twin_ended(running, status)
        deviation = {name: check.report for name, check in checks.items()}
        write_text(out / "deviation.json", json.dumps(deviation, indent=2) + "\n")
        alarms = running.monitor.events
        return CellTwinResult(results["pt"], results["dt"], deviation, out, url, history.run_id, outcomes, alarms,
                              status == "stopped", history.problem)
