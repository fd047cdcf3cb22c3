"""Running a fleet: its twins on hosts (Ray actors, or this process), watched by a supervisor that restarts
a failed twin from its last saved state and says so (logged, and recorded in the fleet's store).

Each twin's folder is DIR/NAME (a restart's DIR/NAME/restart-K: the rows of the attempt that failed stay
where they were written); every attempt records its run in the one history store, and `fleet_twins`
(cotwin.twin.analysis.fleet.record) names the twin and attempt of each run, with every failure and restart. A
twin whose writes the store refuses or loses goes on running (its outputs are whole); the fleet says so, names
it in its summary and records it ('history incomplete').
"""

from __future__ import annotations

import hashlib
import json
import logging
import threading
import time as wallclock
from dataclasses import dataclass, field
from pathlib import Path

from ....diagnostics import CotwinError
from ....files import write_text
from .host import TwinHost, TwinJob
from .spec import FleetSpec, TwinEntry, twin_project

log = logging.getLogger("cotwin.fleet")
POLL_SECONDS = 0.25
STATUS_TIMEOUT = 30.0  # s a host may take to answer a status call before it counts as dead


class HostDied(Exception):
    """A host (a Ray actor's process) ended: every twin on it failed with it."""


class LocalHosts:
    """Hosts in this process (no Ray): the twins share its interpreter, each in a thread."""

    where = "this process"

    def new(self):
        return TwinHost()

    def start(self, host, job: TwinJob, resume) -> int:
        return host.start(job, resume)

    def status(self, host) -> list[dict]:
        return host.status()

    def stop(self, host) -> None:
        host.stop()

    def close(self) -> None:
        pass


class RayHosts:
    """Hosts as Ray actors (one process each) on a local Ray started here on 127.0.0.1 ("auto"), or on a
    cluster by address. A host that dies (killed, out of memory) is reported as HostDied."""

    def __init__(self, address: str, cpus: int | None = None):
        try:
            import ray
        except ImportError:
            raise CotwinError("fleets on Ray need the ray extra: pip install 'cotwin[ray]' (or run the fleet in "
                              "this process: --ray off)") from None
        self.ray = ray
        self.started_here = not ray.is_initialized()
        if self.started_here:
            try:
                if address == "auto":
                    ray.init(address="local", _node_ip_address="127.0.0.1", include_dashboard=False, num_cpus=cpus,
                             logging_level="ERROR", log_to_driver=False, configure_logging=False)
                else:
                    from ..sweep import _reachable

                    _reachable(address)
                    ray.init(address=address, logging_level="ERROR", log_to_driver=False, configure_logging=False)
            except (ConnectionError, RuntimeError, ValueError) as err:
                from ..sweep import join_hint

                raise CotwinError(f"cannot start or join Ray at {address!r}: {err}{join_hint(address, err)}") from None
        self.where = "a local Ray on 127.0.0.1" if address == "auto" else f"the Ray cluster at {address}"
        self.actor = ray.remote(num_cpus=0, max_concurrency=64, max_restarts=0)(TwinHost)

    def new(self):
        return self.actor.remote()

    def start(self, host, job: TwinJob, resume) -> int:
        return self._get(host.start.remote(job, resume))

    def status(self, host) -> list[dict]:
        return self._get(host.status.remote())

    def _get(self, ref):
        try:
            return self.ray.get(ref, timeout=STATUS_TIMEOUT)
        except (self.ray.exceptions.RayActorError, self.ray.exceptions.GetTimeoutError) as err:
            raise HostDied(str(err).splitlines()[0][:200] if str(err) else type(err).__name__) from None

    def stop(self, host) -> None:
        try:
            self._get(host.stop.remote())
        except HostDied:
            pass

    def close(self) -> None:
        if self.started_here:
            self.ray.shutdown()


@dataclass
class TwinRecord:
    """What the supervisor knows of one twin."""

    entry: TwinEntry
    host: object = None
    attempt: int = 0
    restarts: int = 0
    status: dict = field(default_factory=dict)
    checkpoint: dict | None = None
    checkpoint_time: float | None = None
    failures: list[dict] = field(default_factory=list)
    restart_at: float | None = None  # monotonic time a pending restart is due
    final: bool = False
    history_problems: list[dict] = field(default_factory=list)  # per attempt: why its run's history is incomplete

    @property
    def state(self) -> str:
        if self.restart_at is not None:
            return "restarting"
        return self.status.get("state", "starting")


class Fleet:
    """A fleet being run (see module doc); `overview()` is what the fleet page shows."""

    def __init__(self, spec: FleetSpec, out: str | Path, ray: str | None = "auto", history: str | None = None,
                 cc: str = "cc", say=None):
        from ...services.history import database_url

        self.spec = spec
        self.out = Path(out)
        self.ray = ray
        self.history = database_url(history or spec.history, self.out)
        self.cc = cc
        self._say = say  # the command's voice (restarts, give-ups); without one, the "cotwin.fleet" logger
        self.twins = {e.name: TwinRecord(e) for e in spec.twins}
        self.hosts: list = []
        self.backend = None
        self.recorder = None
        self.started = wallclock.time()
        self._lock = threading.Lock()
        self._stop = False

    # ---- running ----
    def run(self) -> dict:
        """Run every twin to its end (or give it up), restarting failed ones; the fleet's summary."""
        from .record import FleetRecorder

        self.out.mkdir(parents=True, exist_ok=True)
        builds = self._build()
        self.recorder = FleetRecorder(self.history, self.spec.name,
                                      on_error=lambda problem: self._tell(logging.WARNING, f"{problem}; the fleet goes on"))
        self.backend = LocalHosts() if self.ray is None else RayHosts(self.ray, None)
        try:
            shared = self.backend.new() if self.spec.workers else None
            pool = [shared] + [self.backend.new() for _ in range(self.spec.workers - 1)] if shared is not None else []
            for k, record in enumerate(self.twins.values()):
                record.host = pool[k % len(pool)] if pool else self.backend.new()
                self._start(record, builds, None)
            while not self._stop and not all(r.final for r in self.twins.values()):
                self._poll(builds)
                wallclock.sleep(POLL_SECONDS)
            if self._stop:
                for record in self.twins.values():
                    if record.host is not None and not record.final:
                        self.backend.stop(record.host)
                deadline = wallclock.monotonic() + 30
                while not all(r.final for r in self.twins.values()) and wallclock.monotonic() < deadline:
                    self._poll(builds, restart=False)
                    wallclock.sleep(POLL_SECONDS)
        finally:
            self.backend.close()
            summary = self.summary()
            write_text(self.out / "fleet.json", json.dumps(summary, indent=1) + "\n")
            self.recorder.close()
        return summary

    def stop(self) -> None:
        """End every twin after its current step (from a signal handler)."""
        self._stop = True

    @property
    def stop_requested(self) -> bool:
        """Whether `stop()` was asked: every twin ends after its step under way (the command line stops at once on
        a second interrupt), as LiveTwin.stop_requested says it of one twin."""
        return self._stop

    def _build(self) -> dict[str, str]:
        """The d-model FMU of each project, built once into DIR/.build/<digest> for its twins to copy. Every
        project's models are read first and all their problems reported together, each naming the twins
        of that project (not one project's, then the next's once it is fixed)."""
        from dataclasses import replace

        from ...assembly.build import dmodel_fmu
        from ...assembly.run import load

        systems, problems = {}, []
        for entry in self.spec.twins:
            if entry.project in systems:
                continue
            try:
                systems[entry.project] = load(twin_project(entry))
            except CotwinError as err:
                systems[entry.project] = None
                names = [repr(t.name) for t in self.spec.twins if t.project == entry.project]
                said = f"twin{'s' if len(names) > 1 else ''} {', '.join(names)} ({self.spec.path})"
                problems += [replace(f, message=f"{said}: {f.message}") for f in err.findings]
        if problems:
            raise CotwinError(problems)
        builds: dict[str, str] = {}
        for project, system in systems.items():
            folder = self.out / ".build" / hashlib.sha256(project.encode()).hexdigest()[:16]
            folder.mkdir(parents=True, exist_ok=True)
            dmodel_fmu(system, folder, self.cc)
            builds[project] = str(folder)
        return builds

    def _job(self, record: TwinRecord, builds: dict[str, str]) -> TwinJob:
        entry = record.entry
        folder = self.out / entry.name
        if record.attempt:
            folder = folder / f"restart-{record.attempt}"
        spec = twin_project(entry)
        key = f"{spec.deviation.routing_key}.{entry.name}"
        alarms = self.spec.alarms or (spec.rabbitmq.url if spec.rabbitmq else None)
        return TwinJob(entry, str(folder), self.history, alarms, self.spec.checkpoint_every, record.attempt,
                       builds.get(entry.project), key)

    def _start(self, record: TwinRecord, builds: dict[str, str], resume) -> None:
        job = self._job(record, builds)
        record.status = {"name": record.entry.name, "state": "starting", "attempt": record.attempt}
        try:
            self.backend.start(record.host, job, resume)
        except HostDied as err:
            self._failed(record, f"its host did not start: {err}")

    def _poll(self, builds: dict[str, str], restart: bool = True) -> None:
        by_host: dict[int, list[TwinRecord]] = {}
        for record in self.twins.values():
            if not record.final and record.restart_at is None:
                by_host.setdefault(id(record.host), []).append(record)
        for records in by_host.values():
            host = records[0].host
            try:
                statuses = {s["name"]: s for s in self.backend.status(host)}
            except HostDied as err:
                for record in records:
                    self._failed(record, f"its process ended ({err})")
                continue
            for record in records:
                status = statuses.get(record.entry.name)
                if status is None:
                    continue
                if "checkpoint" in status:
                    record.checkpoint, record.checkpoint_time = status.pop("checkpoint"), status["checkpoint_time"]
                if status.get("run_id") is not None and status.get("run_id") != record.status.get("run_id"):
                    self.recorder.event(record.entry.name, record.attempt, status["run_id"], "started",
                                        status.get("time"), f"in {status.get('out')}")
                with self._lock:
                    record.status = status
                if status.get("history_problem"):
                    self._history_failed(record, status["history_problem"])
                if status["state"] == "failed":
                    self._failed(record, status.get("message") or "failed")
                elif status["state"] in ("done", "stopped"):
                    record.final = True
                    self.recorder.event(record.entry.name, record.attempt, status.get("run_id"), status["state"],
                                        status.get("time"), None)
        if not restart:
            return
        now = wallclock.monotonic()
        for record in self.twins.values():
            if record.restart_at is not None and now >= record.restart_at and not self._stop:
                record.restart_at = None
                record.attempt += 1
                record.restarts += 1
                if self.ray is not None and not self.spec.workers:
                    record.host = self.backend.new()  # one actor per twin: a fresh one
                elif self.ray is not None:
                    record.host = self._live_host(record)
                self._start(record, builds, record.checkpoint)

    def _live_host(self, record: TwinRecord):
        """The record's host if it still answers, else a new one (for the twins that shared a dead host)."""
        try:
            self.backend.status(record.host)
            return record.host
        except HostDied:
            host = self.backend.new()
            for other in self.twins.values():
                if other.host is record.host:
                    other.host = host
            return host

    def _tell(self, level: int, said: str) -> None:
        """Say it in the command's voice, or log it where there is none: once (a logger with no handler of its
        own prints to stderr too, which printed each restart twice)."""
        if self._say is not None:
            self._say(said)
        else:
            log.log(level, said)

    def _failed(self, record: TwinRecord, message: str) -> None:
        name, t = record.entry.name, record.status.get("time")
        record.failures.append({"attempt": record.attempt, "time": t, "message": message})
        self.recorder.event(name, record.attempt, record.status.get("run_id"), "failed", t, message)
        if record.restarts >= self.spec.max_restarts or self._stop:
            record.final = True
            record.status = {**record.status, "state": "failed", "message": message}
            said = (f"twin {name} failed at t = {t if t is not None else 0:g} s: {message}; given up after "
                    f"{record.restarts} restart(s)")
            self._tell(logging.ERROR, said)
            self.recorder.event(name, record.attempt, record.status.get("run_id"), "given up", t, message)
            return
        record.restart_at = wallclock.monotonic() + self.spec.restart_delay
        saving = record.status.get("saving")
        where = (f"from its state saved at t = {record.checkpoint_time:g} s" if record.checkpoint is not None
                 else f"afresh (its states cannot be saved: {saving})" if saving else "afresh (no saved state yet)")
        said = (f"twin {name} failed at t = {t if t is not None else 0:g} s: {message}; restarting it {where} "
                f"(restart {record.restarts + 1} of at most {self.spec.max_restarts})")
        self._tell(logging.WARNING, said)
        self.recorder.event(name, record.attempt, record.status.get("run_id"), "restarting", record.checkpoint_time,
                            said)

    def _history_failed(self, record: TwinRecord, problem: str) -> None:
        """The twin's store refuses or lost its writes: said once per attempt (the twin goes on, as its recorder
        lets it) and recorded, and kept up to date for the summary (more records are lost as it runs)."""
        with self._lock:
            known = next((p for p in record.history_problems if p["attempt"] == record.attempt), None)
            if known is not None:
                known["message"] = problem
                return
            record.history_problems.append({"attempt": record.attempt, "message": problem})
        self._tell(logging.WARNING, f"twin {record.entry.name}: {problem}; the twin goes on running")
        self.recorder.event(record.entry.name, record.attempt, record.status.get("run_id"), "history incomplete",
                            record.status.get("time"), problem)

    # ---- what is shown ----
    def overview(self) -> dict:
        """Every twin's state, time, pace, deviation and alarms, and the fleet's (the page's JSON)."""
        with self._lock:
            twins = []
            for record in self.twins.values():
                s = dict(record.status)
                s.pop("checkpoint", None)
                s.update(name=record.entry.name, state=record.state, restarts=record.restarts,
                         failures=list(record.failures), checkpoint_time=record.checkpoint_time,
                         behind=_behind(s), history_problems=[dict(p) for p in record.history_problems])
                twins.append(s)
        return {"fleet": self.spec.name, "file": str(self.spec.path), "hosts": self.backend.where if self.backend else None,
                "history": _redacted(self.history), "started": self.started, "twins": twins,
                "events_problem": self.recorder.problem() if self.recorder is not None else None}

    def summary(self) -> dict:
        return self.overview()


def _behind(status: dict) -> bool:
    """Whether a twin paced to the wall clock has fallen behind it (more than a step's worth): reported,
    since a live twin is never slowed further to hide it."""
    return bool(status.get("realtime") and (status.get("lag") or 0.0) > 0.2)


def _redacted(url: str) -> str:
    from ...services.history import redacted

    return redacted(url)
