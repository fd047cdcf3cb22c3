"""A process hosting twins of a fleet (a Ray actor, or the fleet's own process): each twin a LiveTwin in a
thread of its own, watched by a `TwinWatch` that keeps its saved state and its pace.

The host answers `status()` while its twins run (a Ray actor with threads: a status call is served beside
the running twins); the supervisor reads every twin's state, simulated time, real-time factor, lag and
alarms from it, and the latest saved state a restart goes on from.
"""

from __future__ import annotations

import logging
import os
import shutil
import threading
import time as wallclock
from dataclasses import dataclass
from pathlib import Path

from ....diagnostics import CotwinError
from ....service import BackgroundService
from ...assembly.observing import TwinObserver

log = logging.getLogger("cotwin.fleet")
# One twin of a host starts at a time: loading an FMU, FMPy changes the process's working directory to the
# FMU's binaries and back, so two loading at once leave the process in a folder deleted with an FMU.
_STARTING = threading.Lock()


@dataclass(frozen=True)
class TwinJob:
    """What a host needs to run one twin (plain data, sent to the process that runs it)."""

    entry: object  # spec.TwinEntry
    out: str  # the twin's folder for this attempt
    history: str  # the fleet's store (a SQLAlchemy URL)
    alarms: str | None  # the broker the twin's alarms go to
    checkpoint_every: int  # steps between saved states
    attempt: int = 0
    build: str | None = None  # a folder holding the d-model FMU built for this project (copied, not rebuilt)
    routing_key: str | None = None  # the twin's alarms' routing key (the project's, naming the twin)


class TwinWatch(TwinObserver):
    """A live twin's observer: its saved state every `every` steps (both sides), its real-time factor (the
    simulated time over the wall time it took since it started or resumed) and its lag behind the wall
    clock when it is paced to it (a twin that cannot keep real time is reported, never slowed further)."""

    def __init__(self, every: int, started=lambda: None):
        self.every = every
        self.started = started  # called once both sides are initialised
        self.checkpoint: dict[str, bytes] | None = None
        self.checkpoint_time: float | None = None
        self.checkpoint_step = 0
        self.saving: str | None = None  # why states cannot be saved, if they cannot
        self.time = 0.0
        self.begun: float | None = None
        self.wall0 = 0.0
        self.real_time_factor: float | None = None
        self.lag = 0.0
        self.worst_lag = 0.0
        self.realtime = False

    def twin_started(self, twin) -> None:
        self.begun, self.time, self.wall0 = twin.time, twin.time, wallclock.perf_counter()
        self.realtime = bool(twin.realtime)
        self.started()
        self._save(twin)

    def twin_step(self, twin, k: int, t: float) -> None:
        self.time = t
        wall = wallclock.perf_counter() - self.wall0
        simulated = t - (self.begun or 0.0)
        self.real_time_factor = simulated / wall if wall > 0 else None
        self.lag = max(0.0, wall - simulated)
        self.worst_lag = max(self.worst_lag, self.lag)
        if k % self.every == 0:
            self._save(twin)

    def _save(self, twin) -> None:
        if self.saving is not None:
            return
        try:
            states = {name: side.execution.get_state() for name, side in twin.sides.items()}
        except CotwinError as err:  # e.g. a remote PT cannot save its platform's state
            self.saving = "; ".join(f.message for f in err.findings)
            log.warning("%s: no saved states (a restart starts afresh): %s", twin.system.spec.path, self.saving)
            return
        self.checkpoint, self.checkpoint_time, self.checkpoint_step = states, twin.time, twin.steps


class RunningTwin(BackgroundService):
    """One twin running in a thread of its host (cotwin.service: started at once; its failure is its state,
    the host goes on; `interrupt` asks its live twin to stop after the current step)."""

    def __init__(self, job: TwinJob, resume: dict[str, bytes] | None):
        BackgroundService.__init__(self, f"twin {job.entry.name}")
        self.job = job
        self.resume = resume
        self.watch = TwinWatch(job.checkpoint_every, self._started)
        self._starting = False
        self.state = "starting"
        self.message: str | None = None
        self.live = None
        self.page: str | None = None
        self.run_id: int | None = None
        self.end: float | None = None
        self.sent_checkpoint = -1  # the checkpoint step last handed to the supervisor

    def serve(self) -> None:
        self.ready()  # the host does not wait for the twin: its state says how it goes
        self._run()

    def interrupt(self) -> None:
        if self.live is not None:
            self.live.stop()

    def _run(self) -> None:
        from ...assembly.run import load
        from ...live.runtime import LiveTwin
        from .spec import twin_project

        job, dash = self.job, None
        _STARTING.acquire()
        self._starting = True
        try:
            spec = twin_project(job.entry)
            if job.routing_key is not None:
                from dataclasses import replace

                spec.deviation = replace(spec.deviation, routing_key=job.routing_key)
            self.end = spec.end
            system = load(spec)
            out = Path(job.out)
            out.mkdir(parents=True, exist_ok=True)
            if job.build is not None:  # the d-model FMU the fleet built once for this project
                for name in ("dmodel.fmu", "build.json"):
                    if (Path(job.build) / name).is_file() and not (out / name).exists():
                        shutil.copyfile(Path(job.build) / name, out / name)
            observers = [self.watch]
            if job.entry.dashboard is not None:
                from ...services.dashboard import Dashboard
                from ...services.dashboard.app import parse_address

                host, port = parse_address(job.entry.dashboard)
                dash = Dashboard(system, host, port, mode="twin", history_url=job.history).start()
                self.page = dash.url
                observers.append(dash.feed)
            self.live = LiveTwin(system, out, history_url=job.history, alarms_url=job.alarms, observers=observers,
                                 resume=self.resume)
            self.live.monitor.twin = job.entry.name  # alarms name the twin, not its project file
            self.state = "running"
            self.live.run()
            self.state = "stopped" if self.live.stop_requested else "done"
            if dash is not None:
                dash.finish(self.state)
        except BaseException as err:  # noqa: BLE001 - a twin's failure is its status, the host goes on
            self.state = "failed"
            if isinstance(err, CotwinError):
                self.message = "; ".join(str(f) if f.location.line > 0 else f.message for f in err.findings)
            else:
                self.message = f"{type(err).__name__}: {err}"
            if dash is not None:
                dash.finish("failed", self.message)
        finally:
            self._started()
            if self.live is not None and self.live.run_id is not None:
                self.run_id = self.live.run_id
            if dash is not None:
                dash.stop()

    def _started(self) -> None:
        """The twin runs (or ended before it could): the next twin of this host may start."""
        if self._starting:
            self._starting = False
            _STARTING.release()

    def status(self) -> dict:
        """What the supervisor and the overview show of this twin, with a saved state newer than the last
        one handed over."""
        w, live = self.watch, self.live
        monitor = live.monitor if live is not None else None
        if live is not None and live.run_id is not None:
            self.run_id = live.run_id
        out = {"name": self.job.entry.name, "attempt": self.job.attempt, "state": self.state, "message": self.message,
               "time": w.time, "end": self.end, "real_time_factor": w.real_time_factor, "lag": w.lag,
               "worst_lag": w.worst_lag, "realtime": w.realtime, "page": self.page, "run_id": self.run_id,
               "pid": os.getpid(), "alarms": len(monitor.events) if monitor is not None else 0,
               "deviating": sorted(monitor.active) if monitor is not None else [],
               "deviation": _worst(monitor), "checkpoint_time": w.checkpoint_time, "saving": w.saving,
               "out": self.job.out, "history_problem": _history_problem(live)}
        if w.checkpoint is not None and w.checkpoint_step != self.sent_checkpoint:
            out["checkpoint"] = w.checkpoint
            self.sent_checkpoint = w.checkpoint_step
        return out


def _history_problem(live) -> str | None:
    """Why the twin's run is not (wholly) recorded in the fleet's store, if it is not: its recorder keeps the twin
    running when the store refuses or loses its writes, and says so only by its `problem`."""
    return live.history_problem if live is not None else None


def _worst(monitor) -> float | None:
    """The largest deviation between PT and DT at the latest step, over the monitored variables."""
    if monitor is None:
        return None
    found = []
    for track in list(monitor.tracks.values()):
        try:
            found.append(abs(track.pt[-1] - track.dt[-1]))
        except IndexError:  # nothing observed yet
            pass
    return max(found) if found else None


class TwinHost:
    """Runs twins in threads of this process (as a Ray actor: `ray.remote(TwinHost)`)."""

    def __init__(self):
        self.twins: dict[str, RunningTwin] = {}

    def start(self, job: TwinJob, resume: dict[str, bytes] | None = None) -> int:
        running = RunningTwin(job, resume)
        self.twins[job.entry.name] = running
        running.start()
        return os.getpid()

    def status(self) -> list[dict]:
        return [t.status() for t in list(self.twins.values())]

    def stop(self) -> None:
        for t in self.twins.values():
            t.interrupt()

    def pid(self) -> int:
        return os.getpid()

    def wait(self, timeout: float) -> bool:
        """Whether every twin of this host has ended (waiting at most `timeout` s)."""
        deadline = wallclock.monotonic() + timeout
        for t in self.twins.values():
            t.wait(max(0.0, deadline - wallclock.monotonic()))
        return all(t.wait(0) for t in self.twins.values())
