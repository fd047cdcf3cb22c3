"""A live twin of a cell of several robots (`cotwin twin` on a project with [[robots]]).

The PT is the cell's plant: the same robots in a world perturbed as the project's `[plant]` table says
(payload at each robot's tool, friction and damping on each robot's joints: cotwin.pmodel.perturbation
perturbed_world), each robot seen through the plant's latency and noise (cotwin.mapping.perturbed); the
DT is the nominal cell. Both are the cell's co-simulation (cotwin.twin.assembly.cell), the
same commands played into each, stepped in lockstep on one clock: step k of the PT, then of the DT, then
the services look at both:
- deviation per robot: one DeviationMonitor per robot over its monitored variables (its q<i>, ...), its
  alarms naming the robot (`twin`) and the variable scoped by it (`ROBOT.q0`);
- history: one run in the history store (DIR/history.sqlite unless [history] url), its samples every
  logged column of both sides, each robot's d-model state changes as machine `ROBOT.Machine`, the alarms.
Results: DIR/pt/outputs.csv, DIR/dt/outputs.csv, DIR/deviation.json (a report per robot).

Observers get `twin_started(twin)` and `twin_step(twin, k, t)` as a live twin's do (the page's feed,
cotwin.twin.services.dashboard.feed.CellFeed). Not yet: a PT over OPC UA (a plant server of the whole cell), the
what-if forks.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from ...cosim.algorithm import algorithm as make_algorithm
from ...cosim.execution import Execution, RunResult, step_count
from ...cosim.observers import CSVWriter, RealTimePacer
from ...diagnostics import CotwinError, Finding, Severity
from ...files import write_text
from ..assembly.observing import TwinObserver
from ..assembly.cell import CELL_MAPPING, CellOutcomes, CellSystem, dmodel_of
from ..services.deviation import DeviationMonitor
from ..project import check_timing
from ..assembly.system import MAPPING

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
    """What a cell twin's observers are given (`twin_started(twin)` once both sides are initialised, then
    `twin_step(twin, k, t)`), as a live twin's are: the sides, the alarms, the step and the end."""

    cell: CellSystem
    end: float
    step_size: float
    sides: dict[str, CellSide]
    monitor: CellAlarms
    convergence: None = None
    message: str | None = None  # why the run did not finish, when it did not


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

    @property
    def alarm_count(self) -> int:
        return sum(report["alarms"] for report in self.deviation.values())


def run_cell_twin(cell: CellSystem, out: str | Path, step: float | None = None, end: float | None = None,
                  algorithm: str | None = None, realtime: bool | None = None, history_url: str | None = None,
                  cc: str = "cc", observers: tuple[TwinObserver, ...] | list[TwinObserver] = ()) -> CellTwinResult:
    """Run the cell's PT (its perturbed plant) and DT in lockstep into `out` (see the module doc).
    `observers` are told as a live twin's are (cotwin.twin.assembly.observing): started, each step, each alarm,
    ended."""
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
        worlds = {"pt": cell.world(plant), "dt": cell.world()}
        outcomes = {side: CellOutcomes(cell) for side in SIDES}
        executions = {}
        for side in SIDES:
            chain = [CSVWriter(out / side / "outputs.csv"), outcomes[side]]
            if side == "pt" and (spec.realtime if realtime is None else realtime):
                chain.append(RealTimePacer())
            cosim = cell.instantiate(fmu, worlds[side], plant if side == "pt" else None)
            executions[side] = Execution(cosim, make_algorithm(algorithm or spec.algorithm), step, 0.0, chain)
        monitors = {r.name: DeviationMonitor([r.scoped(v) for v in spec.deviation.variables or
                                              r.system.log[MAPPING.name]],
                                             spec.deviation.absolute, spec.deviation.relative,
                                             spec.deviation.lag_steps, spec.deviation.debounce_steps, twin=r.name)
                    for r in cell.robots}
        history = None
        running = CellTwin(cell, end, step, {side: CellSide(e) for side, e in executions.items()}, CellAlarms())
        try:
            for execution in executions.values():
                execution.initialize()
            for observer in observers:
                observer.twin_started(running)
            columns = {side: [f"{u}.{v}" for u, v in e.system.observed()] for side, e in executions.items()}
            history = HistoryRecorder(url, str(spec.path), "twin", step, executions["pt"].algorithm.name, columns)
            readers = {side: e.reader(e.system.observed()) for side, e in executions.items()}
            watched = {r.name: [(CELL_MAPPING.name, v) for v in monitors[r.name].variables] for r in cell.robots}
            program = cell.program
            machines = [(m.name, program.state_port(m), program.leaf_names(m)) for m in program.machines]
            alarms = running.monitor.events
            for k in range(1, steps + 1):
                for execution in executions.values():
                    execution.step()
                t = executions["pt"].time
                for side, execution in executions.items():
                    history.record_sample(side, k, t, readers[side]())
                    values = execution.values
                    for robot in cell.robots:
                        for machine, port, leaves in machines:
                            state = values.get((dmodel_of(robot.name).name, port))
                            if isinstance(state, int) and not isinstance(state, bool):
                                history.record_state(side, k, t, f"{robot.name}.{machine}", state,
                                                     leaves[state] if 0 <= state < len(leaves) else "none")
                for robot in cell.robots:
                    pt = {v: executions["pt"].values.get((unit, v)) for unit, v in watched[robot.name]}
                    dt = {v: executions["dt"].values.get((unit, v)) for unit, v in watched[robot.name]}
                    for event in monitors[robot.name].observe(t, pt, dt):
                        alarms.append(event)
                        history.record_alarm(event)
                        for observer in observers:
                            observer.twin_alarm(running, event)
                for observer in observers:
                    observer.twin_step(running, k, t)
            results = {}
            for side, execution in executions.items():
                execution.close()
                results[side] = execution.result()
        except BaseException as err:
            for execution in executions.values():
                execution.close(err)
            if history is not None:
                history.close("failed", str(err) or type(err).__name__)
            running.message = str(err) or type(err).__name__
            for observer in observers:
                observer.twin_ended(running, "failed")
            raise
        history.close()
        for observer in observers:
            observer.twin_ended(running, "done")
        deviation = {name: monitor.report() for name, monitor in monitors.items()}
        write_text(out / "deviation.json", json.dumps(deviation, indent=2) + "\n")
        return CellTwinResult(results["pt"], results["dt"], deviation, out, url, history.run_id, outcomes, alarms)
