"""The live twin (`cotwin twin`): a physical twin (PT) and a digital twin (DT) co-simulated in lockstep.

Both are the same TwinSystem (same d-model FMU, same mapping) instantiated twice, differing only in
their platform endpoint, as in the paper's Fig. 15. One clock steps both: step k of the PT, then
step k of the DT, then the services look at both. Commands come from one source: a scenario (each
side plays the same commands) or one RabbitMQ bridge and command stream shared by both sides, so
every command reaches both in the same step exactly once; only the PT's unit echoes on `from_cosim`.

After every step the twin tells its observers (cotwin.twin.assembly.observing): first its own services
(cotwin.twin.live.live_observers: deviation checking, history, alarms published on the broker, what-if
requests, [convergence]), then the caller's (e.g. the dashboard's live feed), then the real-time pacer
the co-simulation uses too. The loop itself only steps both sides. Results:
DIR/pt/outputs.csv and DIR/dt/outputs.csv (Maestro format), DIR/deviation.json, DIR/figure.png and
the history store (DIR/history.sqlite unless the project names a database).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ...cosim.algorithm import algorithm as make_algorithm
from ...cosim.execution import Execution, RunResult, ended_early, saved_execution, step_count, uninterrupted
from ...cosim.observers import CSVWriter, StateFile
from ...config import did_you_mean
from ...diagnostics import CotwinError, Finding, Severity
from ..project import check_timing
from ..assembly.build import ARTEFACTS, dmodel_fmu, folder_lock
from ..services.deviation import DeviationMonitor
from ..assembly.endpoints import check_endpoints, make_endpoint
from .live_observers import AlarmPublisher, DeviationCheck, HistoryRecording, Pacing, WhatIfPolling
from .lockstep import lockstep
from ..assembly.observing import TwinObserver
from ..assembly.system import MAPPING, RABBITMQ, TwinSystem
from ..assembly.outcomes import CommandLedger, saturated_joints
from ..assembly.waits import WaitWatch

log = logging.getLogger("cotwin.twin")


def pt_endpoint(system: TwinSystem):
    """The physical twin's platform, from the project's [pt] table (its kind from cotwin.twin.assembly.endpoints)."""
    return make_endpoint(system, "pt")


def paired_sources(system: TwinSystem, name: str, cancelled: Callable[[], bool]):
    """The PT's and the DT's command sources of one robot, and the broker bridge they share (None when the
    commands come from a plan): from RabbitMQ, one bridge and one command stream feed both, so every command
    reaches both sides in the same step exactly once, and only the PT's unit echoes on `from_cosim`."""
    if system.source is not RABBITMQ:
        return system.source_unit(), system.source_unit(), None
    from ..assembly.rabbitmq import (CommandStream, RabbitMQBridge, announcer, origin, port_arguments, port_scalars,
                                     port_types)

    settings, program = system.spec.rabbitmq, system.models.program
    bridge = RabbitMQBridge(settings, name)  # started by the PT's unit when it initialises
    stream = CommandStream(port_types(program, system.source_ports), system.command_events, bridge.receive,
                           settings.maxage_ms / 1000, settings.timeout_s, scalars=port_scalars(program),
                           cancelled=cancelled, max_skew=settings.max_skew_s, arguments=port_arguments(program),
                           origin=origin(settings), announce=announcer(bridge, settings))
    return system.source_unit(bridge, stream, echo=True), system.source_unit(bridge, stream, echo=False), bridge


@dataclass
class Side:
    """One of the two co-simulations of a live twin."""

    name: str  # pt | dt
    execution: Execution
    writer: CSVWriter
    units: dict[str, object]
    watch: object = None  # cotwin.twin.assembly.waits.WaitWatch: blocked waits of this side's d-model
    ledger: object = None  # cotwin.twin.assembly.outcomes.CommandLedger: what became of every command on this side
    saturated: list = field(default_factory=list)  # (joint, limit): at their effort limit at the end (Summary.saturated)

    @property
    def endpoint(self):
        """This side's platform endpoint (the PT's, the DT's), as its mapping unit drives it."""
        return self.units["mapping"].mapping.endpoint

    def summary(self):
        from ..assembly.outcomes import not_applied

        return self.ledger.summary(self.watch.found, not_applied(self.units.get("source")), self.saturated)

    def values(self, unit: str, names: list[str]) -> dict[str, float]:
        values = self.execution.values
        return {n: values.get((unit, n)) for n in names}


@dataclass
class LiveResult:
    pt: RunResult
    dt: RunResult
    deviation: dict
    out: Path
    history_url: str
    run_id: int | None
    sides: dict[str, Side] = field(default_factory=dict)
    alarms: list[dict] = field(default_factory=list)
    convergence: dict = field(default_factory=dict)  # [convergence]: its corrections and estimate
    history_problem: str | None = None  # why the run's history is incomplete (its store failed), if it is


class LiveTwin:
    """A PT and a DT of one TwinSystem in lockstep (see module doc). `observers` (cotwin.twin.assembly.observing.
    TwinObserver) get `twin_started(twin)` once both are initialised, `twin_step(twin, k, t)` after every
    step, `twin_alarm(twin, event)` for each deviation alarm and `twin_ended(twin, status)` at the end."""

    def __init__(self, system: TwinSystem, out: str | Path, pt=None, dt=None, step: float | None = None,
                 end: float | None = None, algorithm: str | None = None, realtime: bool | None = None,
                 history_url: str | None = None, alarms_url: str | None = None, observers=(), cc: str = "cc",
                 whatif_url: str | None = None, restart: bool = False, resume: dict[str, bytes] | None = None):
        spec = system.spec
        self.resume = resume  # side -> its saved execution state: go on from there (a fleet's restarted twin)
        self.restart = restart  # a failed step of a d-model FMU is retried in a new process from its last good state
        self.system = system
        self.out = Path(out)
        self.pt_endpoint, self.dt_endpoint = pt, dt
        self.step_size = spec.step if step is None else step
        self.end = spec.end if end is None else end
        check_timing(spec, self.step_size, self.end)
        self.algorithm = algorithm or spec.algorithm
        self.realtime = spec.realtime if realtime is None else realtime
        self.history_url = history_url if history_url is not None else spec.history_url
        self.alarms_url = alarms_url
        self.whatif_url = whatif_url  # a broker URL: answer what-if requests there (WhatIfService)
        self.whatif = None
        self.observers = list(observers)
        self.cc = cc
        self.sides: dict[str, Side] = {}
        self.steps = 0
        self.time = 0.0
        dev = spec.deviation
        self.variables = list(dev.variables) if dev.variables is not None else list(system.log[MAPPING.name])
        unknown = [v for v in self.variables if v not in system.models.monitored]
        if unknown:
            raise CotwinError([Finding(spec.location("deviation", "variables"), Severity.ERROR,
                                       f"[deviation] variables {', '.join(unknown)} are not monitored mapping "
                                       f"variables{did_you_mean(unknown[0], system.models.monitored)} "
                                       f"({', '.join(system.models.monitored) or 'none'})")])
        self.monitor = DeviationMonitor(self.variables, dev.absolute, dev.relative, dev.lag_steps, dev.debounce_steps,
                                        publish=self._alarm, twin=spec.path.stem)
        self._publisher = None
        self._history = None
        self._watchers: list[TwinObserver] = []  # the twin's services, then `observers`, then pacing (run())
        self.status: str | None = None  # done | stopped | failed, once the run is over
        self.message: str | None = None  # why it did not finish, if it says
        self.convergence = None  # cotwin.twin.assembly.convergence.Convergence, when the project has [convergence]
        self._bridge = None
        self._stop = False
        self.looping = False  # in the step loop: a stop request ends the run after the current step

    # ---- services ----
    def _alarm(self, event: dict) -> None:
        log.warning("deviation alarm %s: %s = %.4g at t = %.3f s (threshold %.4g)", event["state"], event["variable"],
                    event["deviation"], event["time"], event["threshold"])
        for o in self._watchers:
            o.twin_alarm(self, event)

    def stop(self) -> None:
        """Ask the run to end after the current step (from another thread, e.g. a signal handler)."""
        self._stop = True

    @property
    def stop_requested(self) -> bool:
        """Whether `stop()` was asked: the run ends (or ended) after the step under way, as "stopped"."""
        return self._stop

    # ---- the run's history (read by a fleet's host and the CLI while the run lasts and after) ----
    @property
    def run_id(self) -> int | None:
        """The history store's id of this run; None until `run()` has opened the store."""
        return self._history.run_id if self._history is not None else None

    @property
    def history_problem(self) -> str | None:
        """Why this run is not (wholly) recorded in the history store, if it is not: the recorder keeps the twin
        running when the store refuses or loses its writes and says so only here (None: recorded, or not started)."""
        return self._history.problem if self._history is not None else None

    # ---- building ----
    def _sources(self):
        pt, dt, self._bridge = paired_sources(self.system, "cotwin live twin", lambda: self._stop)
        return pt, dt

    def _side(self, name: str, fmu: Path, endpoint, source) -> Side:
        cosim = self.system.instantiate(fmu, endpoint, source=source, restart=self.restart)
        writer = CSVWriter(self.out / name / "outputs.csv")
        watch, ledger = WaitWatch(self.system, prefix=f"{name.upper()}: "), CommandLedger(self.system)
        observers = [writer, watch, ledger] + ([StateFile(self.out / "state")] if name == "dt" else [])  # where a what-if may start
        start = 0.0 if self.resume is None else saved_execution(self.resume[name])["time"]
        execution = Execution(cosim, make_algorithm(self.algorithm), self.step_size, start, observers)
        units = {u.role: cosim.units[u.name] for u in self.system.units}
        return Side(name, execution, writer, units, watch, ledger)

    # ---- running ----
    def run(self) -> LiveResult:
        from ..services.history import HistoryRecorder, database_url, sqlite_path
        from ..assembly.run import dt_endpoint

        spec = self.system.spec
        self.out.mkdir(parents=True, exist_ok=True)
        store = sqlite_path(database_url(self.history_url, self.out))
        writes = [f"{side}/{name}" for side in ("pt", "dt") for name in ("outputs.csv", "outputs.partial.csv",
                                                                          "outputs.csv.part")]
        writes += ["state", "deviation.json", "figure.png", *ARTEFACTS, *([store] if store else [])]
        with folder_lock(self.out, writes, spec.inputs):
            settings = spec.convergence
            if settings is not None and settings.active:  # checked against the models before anything is built
                from ..assembly.convergence import Convergence

                self.convergence = Convergence(settings, self.system)
            check_endpoints(self.system, *(side for side, given in (("pt", self.pt_endpoint), ("dt", self.dt_endpoint))
                                           if given is None))  # before the d-model is built
            fmu = dmodel_fmu(self.system, self.out, self.cc)
            pt_ep = self.pt_endpoint if self.pt_endpoint is not None else pt_endpoint(self.system)
            self._warn_if_outlasting(pt_ep)
            dt_ep = self.dt_endpoint if self.dt_endpoint is not None else dt_endpoint(self.system)
            pt_source, dt_source = self._sources()
            try:
                self.sides = {"pt": self._side("pt", fmu, pt_ep, pt_source), "dt": self._side("dt", fmu, dt_ep, dt_source)}
                url = database_url(self.history_url, self.out)
                columns = {n: [f"{u}.{v}" for u, v in s.execution.system.observed()] for n, s in self.sides.items()}
                self._history = HistoryRecorder(url, str(spec.path), "twin", self.step_size, self.algorithm, columns)
                self._publisher = self._alarm_publisher()
                if self.convergence is not None:
                    self.convergence.history = self._history
                if self.whatif_url is not None:
                    from ..services.whatif import WhatIfService

                    self.whatif = WhatIfService(self.whatif_url, spec.deviation.exchange, spec.path, self.out)
                self._watchers = self._services() + self.observers + ([Pacing()] if self.realtime else [])
                return self._loop(url)
            except (CotwinError, KeyboardInterrupt) as err:
                raise self._kept(err) from None
            finally:
                for side in self.sides.values():
                    side.execution.close()
                for endpoint in (pt_ep, dt_ep):  # sessions and threads of remote platforms
                    try:
                        endpoint.close()
                    except Exception:  # noqa: BLE001 - closing must not hide the run's outcome
                        pass
                if self._publisher is not None:
                    self._publisher.close()
                if self.whatif is not None:
                    self.whatif.close()
                if self._bridge is not None:
                    self._bridge.close()

    def _warn_if_outlasting(self, endpoint) -> None:
        """A replayed PT whose log ends before the run does holds its last sample: say so (a held pose would
        otherwise look like a robot at rest)."""
        ending = endpoint.ends()
        if ending is not None and ending[0] < self.end:
            log.warning("%s ends at t = %.3f s of the run, which goes on to %g s: its last sample holds from then on",
                        ending[1], ending[0], self.end)

    def _kept(self, err: CotwinError | KeyboardInterrupt) -> CotwinError:
        """The error of a run that failed or was interrupted, saying where the rows it computed are (each
        side's result file holds a header and the rows so far; the previous result is left untouched)."""
        said = "; ".join(f"{side.name.upper()}: {side.writer.kept()}" for side in self.sides.values()
                         if side.writer.rows) or "no rows computed"
        return ended_early(err, self.time, said)

    def _alarm_publisher(self):
        url = self.alarms_url or (self.system.spec.rabbitmq.url if self.system.spec.rabbitmq else None)
        if url is None:
            return None
        from ..assembly.rabbitmq import EventPublisher

        return EventPublisher(url, self.system.spec.deviation.exchange, "cotwin alarms")

    def _services(self) -> list[TwinObserver]:
        """The twin's own services as its observers (cotwin.twin.live.live_observers), in the order they look at a
        step: deviation (its alarms to all), history, alarms on the broker, what-if, [convergence] (the DT
        corrected before the caller's observers look at it)."""
        self.deviation = DeviationCheck(self.monitor, self.variables, self.out)
        services: list[TwinObserver] = [self.deviation, HistoryRecording(self._history)]
        if self._publisher is not None:
            services.append(AlarmPublisher(self._publisher, self.system.spec.deviation.routing_key))
        if self.whatif is not None:
            services.append(WhatIfPolling(self.whatif))
        if self.convergence is not None:
            services.append(self.convergence)
        return services

    def _loop(self, url: str) -> LiveResult:
        """Step both sides in lockstep and tell the observers (the services among them) of each step."""
        pt, dt = self.sides["pt"], self.sides["dt"]
        total = step_count(self.end, self.step_size)
        status, message = "failed", None
        try:
            if self.resume is not None:  # both sides from their saved states
                for side in (pt, dt):
                    side.execution.set_state(self.resume[side.name])
                self.steps, self.time = pt.execution.steps, pt.execution.time
            else:
                pt.execution.initialize()
                if dt.endpoint.placeable:  # the DT starts where the PT is
                    dt.endpoint.place(pt.endpoint.joint_positions())
                dt.execution.initialize()
            pt.execution.total_steps = dt.execution.total_steps = total
            self.looping = True  # a stop request from now on ends the run after the step under way
            status = lockstep(self, [pt.execution, dt.execution], total, self._watchers, lambda: self._stop)
            for side in (pt, dt):  # as a run's summary says them (cotwin.twin.assembly.run), before the platforms close
                side.saturated = saturated_joints(side.endpoint)
        except CotwinError as err:
            message = "; ".join(f.message for f in err.findings)
            raise
        except KeyboardInterrupt:
            status, message = "stopped", "interrupted"
            raise
        finally:
            error = None if status == "done" or (status == "stopped" and message is None) else \
                RuntimeError(message or "failed")
            self.status, self.message = status, message
            uninterrupted([*(lambda side=side: side.execution.close(error) for side in (pt, dt)),
                           *(lambda o=o: o.twin_ended(self, status) for o in self._watchers)])
        report = self.deviation.report
        result = LiveResult(pt.execution.result(), dt.execution.result(), report, self.out, url,
                            self.run_id, dict(self.sides), list(self.monitor.events), report.get("convergence", {}),
                            self.history_problem)
        if status in ("done", "stopped"):  # a run stopped as asked is kept as a finished run's, its figure too
            self._figure()
        return result

    def _figure(self) -> None:
        from ...plot import twin_figure

        from ..assembly.run import monitored_units

        units = {name: unit for name, (_, unit) in monitored_units(self.system).items()}
        twin_figure(self.out / "pt" / "outputs.csv", self.out / "dt" / "outputs.csv", self.monitor.events,
                    self.out / "figure.png", [f"{MAPPING.name}.{v}" for v in self.variables], units=units,
                    title=f"{self.system.models.program.module.name}: PT ({self.system.spec.pt.endpoint if self.system.spec.pt else 'custom'}) "
                          f"and DT, step {self.step_size:g} s, {self.algorithm}")

