"""Sweeps: many what-ifs in parallel, on a local process pool (default), on threads of this process, or on Ray.

A sweep is a list of plans (each a what-if from the same state); `grid` builds the common one: one
command per combination of argument values ("which holes can the arm reach, and how fast?"). Every
worker loads the project once and shares the d-model FMU built in `artefacts`; answers come back in the
order of the plans and are the same whichever runs them (what-ifs are deterministic). Threads share the loaded
twin and pay no start-up; they run side by side because the native loop, where a what-if spends most of its time,
runs without the GIL (each thread steps its own forks); a crash inside an FMU ends the whole process, which a
process pool would have reported per what-if.
"""

from __future__ import annotations

import itertools
import logging
import math
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import nullcontext
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from ...config import did_you_mean
from ...diagnostics import CotwinError, Interrupted
from ..assembly.scenario import Command, scalar_value

if TYPE_CHECKING:
    from ..assembly.system import TwinSystem
from .scratch import ScratchFolder

_SYSTEM = None  # the worker's TwinSystem, loaded once per process
MAX_PLANS = 100_000  # what-ifs of one sweep: a grid larger than this is a mistake, not a sweep
ERROR = "error"  # the column of a failed what-if's error
DIED = ("the worker process running this what-if (or another of its batch) died: killed by a signal (e.g. a crash "
        "inside an FMU) or out of memory")


def grid(program, event: str, ranges: dict[str, list], at: float = 0.5) -> list[list[Command]]:
    """One plan per combination of `ranges` (argument -> values): `event` with those arguments at `at` s."""
    events = {ev.name: ev for ev in program.inputs}
    if event not in events:
        raise CotwinError(f"unknown event {event!r}{did_you_mean(event, events)} (known: {', '.join(events)})")
    from ..assembly.scenario import argument_keys

    fields = argument_keys(events[event])  # by port (as plans and what-ifs name them) or by field name
    ports = [port for port, _ in events[event].value_ports]
    unknown = [k for k in ranges if k not in fields]
    if unknown:
        raise CotwinError(f"event {event} has no argument {', '.join(unknown)}{did_you_mean(unknown[0], fields)} "
                          f"(has {', '.join(ports) or 'none'}, or by field name "
                          f"{', '.join(k for k in fields if k not in ports) or 'none'})")
    twice = [port for port in ports if sum(fields[k][0] == port for k in ranges) > 1]
    if twice:
        raise CotwinError(f"argument {', '.join(twice)} is given twice (by its port and by its field name)")
    names = list(ranges)
    empty = [n for n in names if not len(ranges[n])]
    if empty:
        raise CotwinError(f"argument {', '.join(empty)}: no values to sweep (an empty range)")
    count = math.prod(len(ranges[n]) for n in names)
    if count > MAX_PLANS:
        sizes = " x ".join(f"{len(ranges[n])} {n}" for n in names)
        raise CotwinError(f"a grid of {sizes} is {count} what-ifs, more than {MAX_PLANS}")
    plans = []
    for combo in itertools.product(*(ranges[n] for n in names)):
        values = [(event, True)]
        for name, value in zip(names, combo):
            port, sc = fields[name]
            try:
                values.append((port, scalar_value(value, sc)))
            except ValueError as err:
                raise CotwinError(f"argument {name}: {value!r} {err}") from None
        plans.append([Command(at, tuple(values), "sweep")])
    return plans


def unswept(program, event: str, ranges: dict[str, list]) -> list[str]:
    """The ports of `event`'s arguments that `ranges` gives no values (by port or field name): every what-if of
    the grid sends their start value, which no row of the sweep shows."""
    from ..assembly.scenario import argument_keys

    ev = next((e for e in program.inputs if e.name == event), None)
    if ev is None:
        return []
    fields = argument_keys(ev)
    given = {fields[k][0] for k in ranges if k in fields}
    return [port for port, _ in ev.value_ports if port not in given]


def summary(prediction) -> dict:
    """One row of a sweep: per command its arguments, feasibility, acceptance and time to be done."""
    done = prediction.completion_time  # a step count times the step: 26.400000000000002 written as 26.4, as outputs.csv does
    out = {"completion_time": None if done is None else round(done, 12), "collisions": len(prediction.collisions)}
    for k, c in enumerate(prediction.commands):
        prefix = "" if len(prediction.commands) == 1 else f"c{k}_"
        out.update({f"{prefix}{name}": value for name, value in c.args.items()})
        out[f"{prefix}feasible"] = c.feasible
        out[f"{prefix}accepted"] = c.accepted
        # done only when completed (the ledger's verdict): an infeasible or stopped move the d-model came back to
        # rest from has a return time, not a time to be done (its row's completion_time is empty too)
        out[f"{prefix}time_to_done"] = round(c.done - c.time, 9) if c.verdict == "completed" else None
    return out


def tally(rows: list[dict]) -> str:
    """What a sweep's answers came to: how many commands completed (back at rest and not answered infeasible, as
    the ledger judges them) and, where the mapping answers feasibility (an event named feasible*, infeasible*,
    ...), how many were feasible and infeasible. A d-model without feasibility answers is not said to have had
    none feasible; an infeasible command the d-model came back to rest from is not said to have completed."""
    commands = [(r.get(k[:-len("time_to_done")] + "feasible"), v) for r in rows if ERROR not in r
                for k, v in r.items() if k.endswith("time_to_done")]
    completed = sum(1 for feasible, done in commands if done is not None and feasible is not False)
    said = [feasible for feasible, _ in commands if feasible is not None]
    out = f"{completed} completed"
    return out + (f", {sum(1 for v in said if v)} feasible, {sum(1 for v in said if not v)} infeasible" if said else "")


def point(plan: list[Command]) -> dict:
    """A plan's arguments, named as `summary` names them: the grid point a what-if answers."""
    out = {}
    for k, command in enumerate(plan):
        prefix = "" if len(plan) == 1 else f"c{k}_"
        out.update({f"{prefix}{port}": value for port, value in command.values[1:]})
    return out


def failed(plan: list[Command], err: BaseException) -> dict:
    """The row of a what-if that ended with an error: its grid point and the error, as text (a worker's
    exception never has to cross a process boundary; a bug of cotwin's says so, with its traceback)."""
    if isinstance(err, CotwinError):
        return {**point(plan), ERROR: "\n".join(f.message if f.location.path.startswith("<") else str(f)
                                                for f in err.findings)}
    import traceback

    where = "".join(traceback.format_exception(err)[-3:]).strip()
    return {**point(plan), ERROR: f"internal error: {type(err).__name__}: {err} (a cotwin bug)\n{where}"}


class SweepInterrupted(Interrupted):
    """A sweep stopped by an interrupt: `rows` are the what-ifs answered by then (each with its grid point),
    kept for the caller to write rather than lost with the others."""

    def __init__(self, rows: list[dict], total: int, running: int = 0):
        super().__init__(f"interrupted after {len(rows)} of {total} what-ifs")
        self.rows, self.total = rows, total
        self.running = running  # threads of a threaded sweep still in their what-if (a second interrupt did not wait)


def failures(rows: list[dict]) -> list[tuple[int, dict]]:
    """(index, row) of the what-ifs that failed."""
    return [(k, r) for k, r in enumerate(rows) if r.get(ERROR)]


READER = "cotwin sweep"  # as READ_ONLY_BY names it: a sweep's what-ifs read no [pt]


def _load(project: str, artefacts: str | None) -> None:
    global _SYSTEM
    from ..assembly.run import load

    _SYSTEM = (load(project, reader=READER), artefacts)


def _run(plan: list[Command], state: bytes | None, horizon: float, step: float | None, forks=None,
         physics: float | None = None) -> dict:
    """One what-if's row; on `forks` (cotwin.twin.services.whatif.Forks: one fork restored plan after plan) when given."""
    from ..services.whatif import predict

    system, artefacts = _SYSTEM
    try:
        if forks is not None:
            return summary(forks.predict(plan, horizon=horizon, decimate=10**9))
        return summary(predict(system, plan, state, horizon=horizon, step=step, artefacts=artefacts, decimate=10**9,
                               physics_step=physics))
    except Exception as err:  # noqa: BLE001 - one what-if's failure is its row, the sweep goes on
        return failed(plan, err)


def _forks(state: bytes | None, step: float | None, physics: float | None = None, loaded: tuple | None = None):
    """Forks of the loaded twin (`loaded`, else the worker's) at `state` for a run of what-ifs (closed by the caller
    when they are done)."""
    from ..services.whatif import Forks

    system, artefacts = loaded or _SYSTEM
    return Forks(system, state, step=step, artefacts=artefacts, physics_step=physics)


_STOP = None  # a pool worker's: the sweep's event set when it is interrupted (see _pool_load)


def _pool_load(project: str, artefacts: str | None, stop) -> None:
    """A pool worker's start: deaf to Ctrl-C (the terminal's interrupt reaches the whole process group, and a
    worker cut in the middle of its chunk lost the answers of that chunk's plans already run); the sweep stops
    its workers' chunks through `stop` instead, keeping what they answered."""
    import signal

    global _STOP
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _STOP = stop
    _load(project, artefacts)


def _run_chunk(plans: list[list[Command]], state: bytes | None, horizon: float, step: float | None,
               physics: float | None = None) -> list[dict]:
    """The rows of a chunk's plans, in order; fewer (the first ones) when the sweep is stopped meanwhile."""
    rows: list[dict] = []
    if _STOP is not None and _STOP.is_set():
        return rows
    with _forks(state, step, physics) as forks:
        for plan in plans:
            rows.append(_run(plan, state, horizon, step, forks))
            if _STOP is not None and _STOP.is_set():
                break
    return rows


def _ray_run(project: str, artefacts: str | None, plan, state, horizon, step, physics=None) -> dict:
    if _SYSTEM is None or str(_SYSTEM[0].spec.path) != str(Path(project)):
        try:
            _load(project, artefacts)
        except Exception as err:  # noqa: BLE001 - the project does not load on this node: say so per what-if
            return failed(plan, err)
    return _run(plan, state, horizon, step, physics=physics)


def sweep_shape(threads: int, workers: int | None, plans: int) -> tuple[int, int]:
    """The threads and the processes a sweep of `plans` what-ifs runs on: no more of either than what-ifs."""
    return min(threads, plans), max(1, min(workers or os.cpu_count() or 1, plans))


def run_sweep(project: "str | Path | TwinSystem", plans: list[list[Command]], state: bytes | None = None, horizon: float = 30.0,
              step: float | None = None, workers: int | None = None, ray: str | None = None,
              artefacts: str | Path | None = None, progress=None, physics_step: float | None = None,
              threads: int = 1, warn: Callable[[str], None] | None = None) -> list[dict]:
    """Run every plan as a what-if; `ray` is a Ray address ("auto" joins the local cluster) or None
    for a local process pool of `workers` processes (default: one per CPU; 1 runs in this process), or, with
    `threads` > 1, `threads` what-ifs at once in this process (see the module doc).

    One row per plan, in the plans' order: `summary` of its prediction, or (a what-if that failed) its
    grid point and the error in the ERROR column (`failures` lists them). `progress(done, total)` is
    called as what-ifs finish. `physics_step`: the what-ifs' physics steps (s; None: cotwin's 1 ms; see
    cotwin.twin.services.whatif.physics_timing). `project` may be a twin already loaded (a TwinSystem, as
    `predict` takes): what-ifs in this process use it as it is, a pool's processes and Ray load its project file.
    `warn(message)` is told what is unwise about the threads asked
    for (cotwin.twin.analysis.thread_budget; default: the cotwin.twin logger's warning). Without `artefacts`, the
    d-model FMU is built in a scratch folder removed however the sweep ends (cotwin.twin.analysis.scratch)."""
    if threads < 1:
        raise CotwinError(f"a sweep runs on one thread or more, not {threads}")
    if threads > 1 and (ray is not None or workers not in (None, 1)):
        raise CotwinError("threads run the what-ifs in this process: not with a pool of processes (workers) or Ray")
    if threads > 1:
        workers = 1
    if state is not None:  # its format and times checked once here, before any worker reads it
        from ...cosim.execution import saved_execution

        saved_execution(state)
    from ..assembly.system import TwinSystem

    loaded = project if isinstance(project, TwinSystem) else None
    project = str(Path(loaded.spec.path if loaded is not None else project).resolve())
    report = progress or (lambda done, total: None)
    warn = warn or logging.getLogger("cotwin.twin").warning
    scratch = ScratchFolder("cotwin-sweep-") if artefacts is None else None
    try:
        rows = _sweep(project, plans, state, horizon, step, workers, ray, scratch.path if scratch else artefacts,
                      report, physics_step, threads, warn, scratch, loaded)
    except BaseException:
        if scratch is not None:
            scratch.close()  # an interrupt meanwhile is not raised: the exception under way says how the sweep ended
        raise
    if scratch is not None and scratch.close():  # interrupted as it was cleaned up: the answers are all there
        raise SweepInterrupted(rows, len(plans))
    return rows


def _sweep(project: str, plans: list[list[Command]], state: bytes | None, horizon: float, step: float | None,
           workers: int | None, ray: str | None, artefacts: str | Path, report, physics_step: float | None,
           threads: int, warn: Callable[[str], None], scratch: ScratchFolder | None,
           loaded: "TwinSystem | None" = None) -> list[dict]:
    """run_sweep's work, its FMU built in `artefacts` (`scratch`'s path when the sweep made one), on the twin
    `loaded` when given, else on `project` loaded here."""
    from ..assembly.build import dmodel_fmu
    from ..assembly.run import load

    system = loaded if loaded is not None else load(project, reader=READER)
    fmi = 2
    if state is not None:  # a state of other models fails every what-if alike: said once, before any runs
        from ...cosim.execution import check_models, saved_execution
        from ..assembly.clocked import saved_clock

        saved = saved_execution(state)
        check_models(saved["models"], system.models.digests)
        fmi = 2 if saved_clock(saved) is None else 3  # the d-model the state was saved from, forked as it ran
    from ..services.whatif import check_horizon, physics_timing

    check_horizon(horizon, system.spec.step if step is None else step)  # said once, not by every what-if
    physics_step = physics_timing(system.spec.step if step is None else step, physics_step)  # once, not per what-if
    dmodel_fmu(system, artefacts, fmi=fmi)  # built once, before the workers share it
    artefacts = str(artefacts)
    if ray is not None:
        return _on_ray(project, plans, state, horizon, step, ray, artefacts, report, physics_step)
    threads, workers = sweep_shape(threads, workers, len(plans))
    rows: list[dict] = []
    if workers == 1:
        global _SYSTEM
        _SYSTEM = (system, artefacts)  # the project loaded above (loading it again costed a parse)
    if threads > 1:  # on one worker: this process
        try:
            for message in _thread_warnings(_SYSTEM, plans[0], state, step, physics_step, threads):
                warn(message)
        except KeyboardInterrupt:
            raise SweepInterrupted([], len(plans)) from None
        report(0, len(plans))
        return _threaded(_SYSTEM, plans, state, horizon, step, physics_step, threads, report,
                         scratch.use if scratch is not None else nullcontext)
    report(0, len(plans))
    if workers == 1:
        try:
            with _forks(state, step, physics_step) as forks:
                for plan in plans:
                    rows.append(_run(plan, state, horizon, step, forks))
                    report(len(rows), len(plans))
        except KeyboardInterrupt:
            raise SweepInterrupted(rows, len(plans)) from None
        return rows
    size = max(1, min(len(plans) // (workers * 8), 64))  # small chunks: progress and balance
    chunks = [plans[k:k + size] for k in range(0, len(plans), size)]
    answers: dict[int, list[dict]] = {}
    context = get_context("spawn")
    stop = context.Event()  # set on an interrupt: each worker ends its chunk after the what-if in hand
    pool = ProcessPoolExecutor(workers, mp_context=context, initializer=_pool_load,
                               initargs=(project, artefacts, stop))
    futures: dict = {}
    try:
        for k, chunk in enumerate(chunks):
            futures[pool.submit(_run_chunk, chunk, state, horizon, step, physics_step)] = k
        done = 0
        for future in as_completed(futures):
            k = futures[future]
            try:
                answers[k] = future.result()
            except BrokenProcessPool:  # a worker died (a signal, out of memory): its what-ifs say so
                answers[k] = [{**point(plan), ERROR: DIED} for plan in chunks[k]]
            done += len(answers[k])
            report(done, len(plans))
    except KeyboardInterrupt:  # the answers so far are kept (in the plans' order), not lost
        try:
            _collect_stopped(pool, stop, futures, answers)
        except KeyboardInterrupt:  # a second interrupt: the chunks in hand not waited for
            pass
        try:
            _stop(pool)
        except KeyboardInterrupt:  # a second interrupt as the workers are stopped: the answers all the same
            pass
        raise SweepInterrupted([row for k in sorted(answers) for row in answers[k]], len(plans)) from None
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown()
    return [row for k in range(len(chunks)) for row in answers[k]]


def _thread_warnings(loaded: tuple, plan: list[Command], state: bytes | None, step: float | None,
                     physics: float | None, threads: int) -> list[str]:
    """What is unwise about `threads` threads here (cotwin.twin.analysis.thread_budget): more than the CPUs by far,
    or more forks than the memory holds; a fork is measured only for more threads than CPUs (fewer are sized as a
    pool of one process per CPU would be, and the measure costs two forks' set-up)."""
    from .thread_budget import available_memory, thread_warnings, usable_cpus

    cpus = usable_cpus()
    per_thread = fork_footprint(loaded, plan, state, step, physics) if threads > cpus else None
    return thread_warnings(threads, cpus, per_thread, available_memory())


def fork_footprint(loaded: tuple, plan: list[Command], state: bytes | None, step: float | None,
                   physics: float | None = None) -> int | None:
    """Bytes one more thread's forks take: how much this process's resident memory grew while a second fork of
    `loaded` was set up (a what-if of `plan` one step long), the first set up before so that what the process
    loads once (the FMU's library, MuJoCo's first model) is not counted, and, where the fork has a memo of held
    steps (not every simulator can: cotwin.pmodel.simulator.remember_held_steps), what it takes once full (untouched
    after one step). None where it cannot be told (no /proc/self/statm, or the what-if fails: its error is the
    sweep's to say)."""
    from .thread_budget import resident_memory

    horizon = loaded[0].spec.step if step is None else step
    try:
        with _forks(state, step, physics, loaded) as first, _forks(state, step, physics, loaded) as second:
            first.predict(plan, horizon=horizon, decimate=10**9)
            before = resident_memory()
            second.predict(plan, horizon=horizon, decimate=10**9)
            after = resident_memory()
            memos = sum(memo.full for memo in second.memos)  # fills as plans run (cotwin.pmodel.memo)
    except Exception:  # noqa: BLE001 - not measured; the sweep's what-ifs say what fails
        return None
    if before is None or after is None:
        return None
    return max(after - before, 0) + memos


def _threaded(loaded: tuple, plans: list[list[Command]], state: bytes | None, horizon: float, step: float | None,
              physics: float | None, threads: int, report, hold=nullcontext) -> list[dict]:
    """The what-ifs on `threads` threads of this process, each taking the next plan and keeping its own forks of
    `loaded` (the twin and artefacts: not _SYSTEM, which another sweep of this process may set meanwhile);
    rows in the plans' order. An interrupt keeps the answers so far (SweepInterrupted) once each thread has
    ended the what-if in hand and closed its forks. Each thread holds the artefacts' folder while it runs
    (`hold()`: cotwin.twin.analysis.scratch.ScratchFolder.use), so that one left running by a second interrupt
    does not have its FMU removed from under it, and the last to end removes the folder."""
    rows: list[dict | None] = [None] * len(plans)
    pending = iter(range(len(plans)))
    lock, stop = threading.Lock(), threading.Event()
    errors: list[BaseException] = []
    done = 0

    ended = [threading.Event() for _ in range(threads)]  # set by each thread as it ends (see below)

    def work(ends: threading.Event) -> None:
        nonlocal done
        try:
            with hold(), _forks(state, step, physics, loaded) as forks:
                while not stop.is_set():
                    with lock:
                        k = next(pending, None)
                    if k is None:
                        return
                    row = _run(plans[k], state, horizon, step, forks)
                    with lock:
                        rows[k] = row
                        done += 1
                        report(done, len(plans))
        except BaseException as err:  # noqa: BLE001 - not a what-if's failure (those are rows): the sweep's
            errors.append(err)
            stop.set()
        finally:
            ends.set()

    from ...cosim.native import signals_held

    # waited for on `ended`, not Thread.join: Python 3.11's join interrupted by Ctrl-C marks the thread it waited
    # for ended though it runs on (bpo-45274's fix), and the interrupted sweep did not wait for that one
    pool = [threading.Thread(target=work, args=(ends,), name=f"cotwin-sweep-{n}", daemon=True)
            for n, ends in enumerate(ended)]
    try:
        with signals_held():  # an interrupt while threads start is raised once all have (one never started is unjoinable)
            for thread in pool:
                thread.start()
        for ends in ended:
            while not ends.wait(0.25):  # woken for an interrupt, which only this (the main) thread receives
                pass
    except KeyboardInterrupt:
        stop.set()
        try:  # each thread ends after the what-if in hand: one left inside the native loop would crash the exit
            for ends in ended:
                ends.wait()
        except KeyboardInterrupt:  # a second interrupt: the answers now, whatever the threads are doing
            pass
        with lock:
            answered = [row for row in rows if row is not None]
        raise SweepInterrupted(answered, len(plans), running=sum(not ends.is_set() for ends in ended)) from None
    if errors:
        raise errors[0]
    return rows  # type: ignore[return-value] - every plan answered when no thread failed


def _collect_stopped(pool: ProcessPoolExecutor, stop, futures: dict, answers: dict[int, list[dict]]) -> None:
    """After an interrupt: the chunks not started dropped, those in hand told to end after their what-if in hand
    (`stop`) and their answers so far kept in `answers` (a chunk's first plans: an interrupted sweep dropped every
    plan of the chunks in hand, up to 64 each, though most were answered). A worker that died meanwhile answers
    nothing."""
    from concurrent.futures import wait

    stop.set()
    for future in futures:  # cancelled here, not by shutdown's cancel_futures: its late cancelling hung wait()
        future.cancel()
    in_hand = [future for future, k in futures.items() if k not in answers and not future.cancelled()]
    wait(in_hand)
    for future in in_hand:
        if not future.cancelled() and future.exception() is None:
            answers[futures[future]] = future.result()


def _stop(pool: ProcessPoolExecutor) -> None:
    """End a pool at once: the chunks not started dropped, the workers stopped in the middle of theirs (an
    interrupted sweep waited for every chunk queued, then threw their answers away)."""
    workers = list((pool._processes or {}).values())  # CPython's; shutdown() forgets them
    pool.shutdown(wait=False, cancel_futures=True)
    for process in workers:
        process.terminate()
    for process in workers:
        process.join(timeout=5)


def _reachable(address: str, timeout: float = 5.0) -> None:
    """Refuse a Ray address nobody listens at, at once: Ray itself retries an unreachable head for
    minutes before it gives up ("auto" and "local" are Ray's to resolve)."""
    import socket

    if address in ("auto", "local"):
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise CotwinError(f"a Ray address is 'auto', 'HOST:PORT' or 'ray://HOST:PORT', not {address!r}")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as err:
        raise CotwinError(f"cannot reach the Ray cluster at {address!r}: {err.strerror or err}") from None


def join_hint(address: str, err: BaseException) -> str:
    """Why joining a Ray head failed, where the cause is known: a head with token authentication (what
    `ray start` sets up by default in recent Ray) joined by a driver that sends no token."""
    import os

    chain, seen = [], err
    while seen is not None and len(chain) < 8:
        chain.append(f"{type(seen).__name__}: {seen}")
        seen = seen.__cause__ or seen.__context__
    if not any("InvalidAuthToken" in c or c.startswith("AuthenticationError") for c in chain):
        return ""
    if os.environ.get("RAY_AUTH_MODE") != "token":
        return (" (the cluster asks for a token: set RAY_AUTH_MODE=token in cotwin's environment; Ray reads the "
                "token from ~/.ray/auth_token, RAY_AUTH_TOKEN_PATH or RAY_AUTH_TOKEN)")
    return (" (the cluster's token is not here or not the one it has: Ray reads it from ~/.ray/auth_token, "
            "RAY_AUTH_TOKEN_PATH or RAY_AUTH_TOKEN; give it the head's)")


def _on_ray(project, plans, state, horizon, step, address, artefacts, report, physics=None) -> list[dict]:
    try:
        import ray
    except ImportError:
        raise CotwinError("sweeps on Ray need the ray extra: pip install 'cotwin[ray]'") from None
    started_here = not ray.is_initialized()
    if started_here:
        _reachable(address)
        try:
            ray.init(address=address, logging_level="ERROR", log_to_driver=False)
        except (ConnectionError, RuntimeError, ValueError) as err:
            raise CotwinError(f"cannot join the Ray cluster at {address!r}: {err}{join_hint(address, err)}") from None
    try:
        remote = ray.remote(_ray_run)
        state_ref = ray.put(state)
        refs = [remote.remote(project, artefacts, plan, state_ref, horizon, step, physics) for plan in plans]
        deadline = time.monotonic() + max(600.0, 10.0 * len(plans))
        pending = list(refs)
        report(0, len(plans))
        while pending:
            ready, pending = ray.wait(pending, num_returns=len(pending), timeout=min(1.0, max(0.0, deadline - time.monotonic())))
            report(len(plans) - len(pending), len(plans))
            if pending and time.monotonic() >= deadline:
                raise CotwinError(f"the Ray cluster at {address!r} did not finish {len(plans)} what-ifs in time "
                                  f"({len(plans) - len(pending)} done; are its workers starting?)")
        return ray.get(refs)
    finally:
        if started_here:
            ray.shutdown()
