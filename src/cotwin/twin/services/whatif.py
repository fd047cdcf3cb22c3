"""What-if: fork the digital twin at a state and run a hypothetical plan ahead of real time.

`predict` builds a fresh DT of the same TwinSystem (same d-model FMU, same mapping, the embedded
simulator) whose command source plays the plan, restores the saved state of the live DT into its
d-model and mapping (the simulator, the trajectory in flight, the mapping's variables), and runs it
as fast as it goes. A state of a twin run with the FMI 3.0 d-model (`cotwin run --fmi 3`) is forked with that
d-model, its clock ticking at the saved period in the saved phase (cotwin.twin.assembly.clocked.saved_clock), as
the algorithm is the saved one: the fork goes on as the DT ran. The live twin is never touched: a state is bytes (cotwin.cosim.state), taken
between two of its steps. A plan's times are relative to the fork.

The answer (`Prediction`): the predicted trajectory of the monitored variables, the d-model's state
changes, per command what became of it (cotwin.twin.assembly.outcomes: when it was applied, whether the d-model
took it, its feasibility as the platform's answer says, when it was done: the d-model back at rest);
waits for answers that cannot come (cotwin.twin.assembly.waits; the what-if ends there); collisions (the
mapping's `collision` event, and contacts of the robot with the scene other than its fingers'); and
the completion time of the whole plan.
"""

from __future__ import annotations

import logging
import math
import numbers
import threading
import time
import time as wallclock
from concurrent.futures import CancelledError
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ... import safejson
from ...cosim.algorithm import algorithm as make_algorithm
from ...cosim.execution import Execution
from ...config import did_you_mean
from ...diagnostics import CotwinError
from ..assembly.build import dmodel_fmu
from ...logcap import CappedLog
from ...memo import once_per
from ...service import BackgroundService
from ..assembly.scenario import Command
from ..assembly.system import DMODEL, MAPPING, TwinSystem
from ..assembly.outcomes import CommandLedger, CommandOutcome, saturated_joints
from ..assembly.waits import WaitWatch
from ...cosim.observers import Stop

_WORKER = None  # (TwinSystem, artefacts) of a what-if worker process
MAX_REQUEST = 1 << 20  # bytes of a what-if request (a plan of thousands of commands)


@dataclass
class Prediction:
    start: float
    end: float
    step: float
    commands: list[CommandOutcome]
    states: list[tuple[float, str, str]]  # (time, machine, state)
    trajectory: dict[str, list[float]]
    collisions: list[dict]
    completion_time: float | None
    wall_seconds: float
    blocked: list[str] = field(default_factory=list)  # waits for answers that cannot come (cotwin.twin.assembly.waits)
    native_steps: int = 0  # of its steps, those made in the native loop (cotwin.cosim.native)
    saturated: list = field(default_factory=list)  # (joint, limit): at their effort limit at the end (Summary.saturated)

    def as_dict(self) -> dict:
        return asdict(self)


MAX_PHYSICS_STEP = 0.01  # s: a what-if's physics step at most (MuJoCo's contacts and servos need fine steps)
MIN_PHYSICS_STEP = 1e-4  # s: at least (a finer one is a typo more likely than a need: 1e-9 ran for hours)


def physics_timing(step: float, physics_step: float | None, what: str = "physics step") -> float | None:
    """`physics_step` (s) as a float, or CotwinError naming `what` unless it is a number from MIN_PHYSICS_STEP
    to MAX_PHYSICS_STEP of which the communication step is a whole number. cotwin's 1 ms is the default;
    a coarser one is for a twin whose calibrated fidelity was measured to hold at it (benchmarks/calibration.py
    replays a recorded run at several)."""
    from ..project.sections import off_physics

    if physics_step is None:  # cotwin's own: the step must be a whole number of it too (as a project's step is)
        off = off_physics(step)
        if off is not None:
            raise CotwinError(f"the communication step {off}: give a {what} of which it is a whole number")
        return None
    if isinstance(physics_step, bool) or not isinstance(physics_step, numbers.Real) or \
            not MIN_PHYSICS_STEP <= float(physics_step) <= MAX_PHYSICS_STEP:  # NaN fails both
        raise CotwinError(f"{what} {physics_step!r:.40} s: give a number of seconds from {MIN_PHYSICS_STEP:g} to "
                          f"{MAX_PHYSICS_STEP:g} (cotwin's is 0.001)")
    physics_step = float(physics_step)
    if off_physics(step, physics_step) is not None:
        raise CotwinError(f"{what} {physics_step:g} s: the communication step {step:g} s is not a whole number of "
                          f"them")
    return physics_step


DEPTH = 0.001  # m: a contact of the robot recorded when it is this deep (MuJoCo's dist <= -DEPTH)


class _Contacts:
    """Contacts of the robot's bodies (its tool's fingers excepted: the project's tool, as its IK takes it, else
    cotwin.pmodel.ik.find_tool's default) with the scene, in the embedded simulator."""

    def __init__(self, endpoint, tree, tool=None):
        from ...pmodel import ik
        from ...pmodel.mjcf import ROBOT_CONTYPE

        self.sim = endpoint.sim
        if self.sim is None:
            return
        model = self.sim.model
        tool = tool if tool is not None else once_per(tree, "default tool", lambda: ik.find_tool(tree))
        fingers = frozenset(j.child for j in tree.joints if j.name in tool.fingers)
        self.robot = frozenset(g for g in range(model.ngeom) if model.geom_contype[g] == ROBOT_CONTYPE
                               and model.body(model.geom_bodyid[g]).name not in fingers)
        # per geom, whether it is the robot's (a contact's geoms looked up in it); one more, never, for the -1 of a flex
        self._mask = np.zeros(model.ngeom + 1, dtype=bool)
        self._mask[sorted(self.robot)] = True
        self.seen: dict[tuple[str, str], dict] = {}

    def again(self) -> "_Contacts":
        """The same check for another what-if on the same simulator (a sweep's fork), nothing seen yet."""
        if self.sim is not None:
            self.seen = {}
        return self

    def start(self) -> None:
        """Watch the simulator's contacts while the what-if runs: a native stretch stops at a step with one."""
        if self.sim is not None:
            self.sim.watch_contacts(sorted(self.robot), DEPTH)

    def stop(self) -> None:
        if self.sim is not None:
            self.sim.watch_contacts(None)

    def check(self, t: float) -> None:
        if self.sim is None:
            return
        model, data = self.sim.model, self.sim.data
        if not data.ncon:
            return
        contact = data.contact  # the step's contacts as arrays: only the robot's penetrating ones, in order, in Python
        g1, g2, dist = contact.geom1, contact.geom2, contact.dist
        mine, theirs = self._mask[g1], self._mask[g2]
        for k in np.flatnonzero((mine != theirs) & (dist <= -DEPTH)):
            robot, other = (int(g1[k]), int(g2[k])) if mine[k] else (int(g2[k]), int(g1[k]))
            key = (model.body(model.geom_bodyid[robot]).name, model.body(model.geom_bodyid[other]).name)
            entry = self.seen.setdefault(key, {"kind": "contact", "robot": key[0], "with": key[1], "first": t,
                                               "depth": 0.0})
            entry["depth"] = max(entry["depth"], -float(dist[k]))


def check_horizon(horizon: float, step: float) -> None:
    """A what-if runs whole steps of the twin: a horizon shorter than one would run one step past it in silence."""
    if not horizon >= step * (1 - 1e-9):
        raise CotwinError(f"a what-if's horizon of {horizon:g} s is shorter than one step of the twin ({step:g} s): it "
                          f"runs whole steps; give a horizon of {step:g} s or more")


def predict(system: TwinSystem, plan: list[Command], state: bytes | None = None, horizon: float = 60.0,
            step: float | None = None, algorithm: str | None = None, artefacts: str | Path | None = None,
            settle: float = 0.3, decimate: int = 1, cc: str = "cc", fused: bool = True,
            physics_step: float | None = None) -> Prediction:
    """Run `plan` on a fork of the DT at `state` (None: from the project's initial state) under the state's algorithm
    and with its d-model (FMI 2.0's, or FMI 3.0's clocked as it was); see module doc.
    `fused`: in the fused loop (cotwin.cosim.fused, the same prediction), else step by step. `physics_step`:
    the fork's physics steps (s; None: cotwin's 1 ms; see `physics_timing`)."""
    import tempfile

    from ..assembly.run import simulated_endpoint

    started = wallclock.perf_counter()
    spec = system.spec
    step = spec.step if step is None else step
    check_horizon(horizon, step)
    physics_step = physics_timing(step, physics_step)
    start, period = 0.0, None
    if state is not None:
        from ...cosim.execution import saved_execution
        from ..assembly.clocked import saved_clock

        saved = saved_execution(state)
        start, algorithm = saved["time"], algorithm or saved["algorithm"]  # the fork goes on as the DT ran
        period = saved_clock(saved)  # an FMI 3.0 d-model's clock, as it ticked (None: FMI 2.0's)
    algorithm = algorithm or spec.algorithm
    shifted = sorted((Command(start + c.time, c.values, c.where) for c in plan), key=lambda c: c.time)
    fork = system.with_plan(shifted)
    with tempfile.TemporaryDirectory(prefix="cotwin-whatif-") as tmp:
        folder = Path(artefacts) if artefacts is not None else Path(tmp)
        endpoint = simulated_endpoint(fork, physics_step)
        if period is None:
            cosim = fork.instantiate(dmodel_fmu(fork, folder, cc), endpoint)
        else:  # the FMI 3.0 d-model, its clock's period and phase restored with its state (as run_twin built it)
            from ..assembly.clocked import clock_period, clocked_system

            period = clock_period(spec, step, period)  # a whole number of this fork's steps, else said here
            cosim = clocked_system(fork, dmodel_fmu(fork, folder, cc, fmi=3), endpoint, period)
        watch, ledger = WaitWatch(fork, prefix="what-if: "), CommandLedger(fork)
        execution = Execution(cosim, make_algorithm(algorithm), step, start, [watch, ledger], fused=fused)
        try:
            if state is not None:
                execution.set_state(state, units=[DMODEL.name, MAPPING.name])
            else:
                execution.initialize()
            return _watch(fork, execution, endpoint, shifted, start, horizon, settle, decimate, started, watch, ledger)
        finally:
            execution.close()


class Forks:
    """What-ifs from one state, one after another, on forks built once (a sweep's many plans): the first plan
    of a shape (the ports its commands drive) builds its fork as `predict` does and keeps a checkpoint of it
    right after it is set up; every later plan of that shape swaps its commands into the fork's command
    source and goes back to that checkpoint (Execution.rollback: the d-model FMU's state, the simulator's, the
    mapping's, the values on the connections, kept in memory), instead of building the simulator, the mapping
    and the FMU instance anew. The fork's simulator remembers the held steps its plans share
    (cotwin.pmodel.memo). Each prediction is the one `predict` gives (tests/test_fused.py). A what-if that fails
    drops its fork (the next one of its shape builds anew). `close` ends them all (a context manager)."""

    def __init__(self, system: TwinSystem, state: bytes | None = None, step: float | None = None,
                 algorithm: str | None = None, artefacts: str | Path | None = None, cc: str = "cc",
                 physics_step: float | None = None):
        self.system, self.state, self.cc = system, state, cc
        self.step = system.spec.step if step is None else step
        self.physics_step = physics_timing(self.step, physics_step)
        self.artefacts = artefacts
        self.start, self.period = 0.0, None
        if state is not None:
            from ...cosim.execution import saved_execution
            from ..assembly.clocked import saved_clock

            saved = saved_execution(state)
            self.start, algorithm = saved["time"], algorithm or saved["algorithm"]  # as the DT ran
            self.period = saved_clock(saved)  # an FMI 3.0 d-model's clock period (None: FMI 2.0's), as `predict`
        self.algorithm = algorithm or system.spec.algorithm
        self._forks: dict[frozenset, tuple] = {}  # plan shape -> (fork, execution, endpoint, saved state)
        self._shared: dict[tuple, tuple] = {}  # (shape, steps, decimate, horizon) -> (state, watches' progress) then
        self._contacts: dict[frozenset, _Contacts] = {}  # plan shape -> its fork's contact check
        self._scratch = None

    def __enter__(self) -> "Forks":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def predict(self, plan: list[Command], horizon: float = 60.0, settle: float = 0.3, decimate: int = 1) -> Prediction:
        started = wallclock.perf_counter()
        check_horizon(horizon, self.step)
        start = self.start
        shifted = sorted((Command(start + c.time, c.values, c.where) for c in plan), key=lambda c: c.time)
        shape = frozenset(p for c in shifted for p, _ in c.values)
        built = self._forks.pop(shape, None)
        try:
            if built is None:
                built = self._build(shifted)
            fork, execution, endpoint, saved, fresh = built
            execution.system.units[fork.source.name].commands = shifted
            quiet = _quiet_start(self._counted, self.step, shifted)
            key = (shape, quiet, decimate, horizon)  # a start shared as long as the what-if lasts past it
            shared = self._shared.get(key) if quiet > 1 else None
            if shared is not None:
                execution.rollback(shared[0])  # the start this plan shares with the plans before it
            elif not fresh:
                execution.rollback(saved)  # the fork as it was set up (the source: this plan from its start)
            waits, ledger = WaitWatch(fork, prefix="what-if: "), CommandLedger(fork)
            watch = Watch(fork, endpoint, shifted, start, horizon, settle, decimate, waits, ledger,
                          self._contacts.get(shape))
            self._contacts[shape] = watch.contacts  # its robot's geoms worked out once per fork
            native = execution.native_steps
            execution.observers = [waits, ledger, watch]
            for o in execution.observers:
                o.simulation_initialized(execution)
            if shared is not None:
                waits.resume(shared[1])
                watch.resume(shared[2])
            elif quiet > 1:
                _advance(execution, watch, quiet)
                if not watch.over and not ledger.outcomes:
                    self._shared[key] = (execution.checkpoint(), waits.progress(), watch.progress())
            prediction = _advance(execution, watch).prediction(execution, fork, shifted, start, started)
            prediction.native_steps = execution.native_steps - native
        except BaseException:
            if built is not None:
                built[1].close()
            self._shared = {key: value for key, value in self._shared.items() if key[0] != shape}
            self._contacts.pop(shape, None)
            raise
        self._forks[shape] = (fork, execution, endpoint, saved, False)  # ran: the next plan restores `saved`
        return prediction

    def _build(self, shifted: list[Command]) -> tuple:
        import tempfile

        from ..assembly.run import simulated_endpoint

        fork = self.system.with_plan(shifted)
        artefacts = self.artefacts
        if artefacts is None:
            if self._scratch is None:
                self._scratch = tempfile.TemporaryDirectory(prefix="cotwin-whatif-")
            artefacts = self._scratch.name
        endpoint = simulated_endpoint(fork, self.physics_step)
        endpoint.sim.remember_held_steps()  # the steps its plans share, while they hold the arm alike, made once
        if self.period is None:
            cosim = fork.instantiate(dmodel_fmu(fork, Path(artefacts), self.cc), endpoint)
        else:  # the FMI 3.0 d-model, clocked as the saved run was (`predict`)
            from ..assembly.clocked import clock_period, clocked_system

            self.period = clock_period(self.system.spec, self.step, self.period)
            cosim = clocked_system(fork, dmodel_fmu(fork, Path(artefacts), self.cc, fmi=3), endpoint, self.period)
        execution = Execution(cosim, make_algorithm(self.algorithm), self.step, self.start, [], fused=True)
        try:
            if self.state is not None:
                execution.set_state(self.state, units=[DMODEL.name, MAPPING.name])
            else:
                execution.initialize()
            saved = execution.checkpoint()
        except BaseException:
            execution.close()
            raise
        self._counted = (*execution._origin, execution.steps)  # the start's steps, as counted (all forks alike)
        return fork, execution, endpoint, saved, True  # fresh: the first plan runs without a restore

    @property
    def memos(self) -> list:
        """The forks' memos of held steps (cotwin.pmodel.memo); a fork whose simulator cannot have one has none."""
        return [endpoint.sim.memo for _, _, endpoint, _, _ in self._forks.values() if endpoint.sim.memo is not None]

    @property
    def remembered(self) -> tuple[int, int]:
        """(taken from a memo, stepped in full) of the forks' held stretches (cotwin.pmodel.memo): the physics
        the plans shared after their start."""
        memos = self.memos
        return sum(m.hits for m in memos), sum(m.misses for m in memos)

    def close(self) -> None:
        for _, execution, _, _, _ in self._forks.values():
            execution.close()
        self._forks.clear()
        self._shared.clear()
        self._contacts.clear()
        if self._scratch is not None:
            self._scratch.cleanup()
            self._scratch = None


class Watch(Stop):
    """What a what-if sees after each step (its trajectory, the d-model's state changes, collisions, contacts,
    how long the arm has rested) and whether it has seen enough (`reached`): the plan applied and then done,
    blocked, or ignored, or the horizon passed. Told of a native stretch's repeated steps at once, in which no
    command was shown and no machine came to rest (`whole_changes`, `whole_values`: those are steps it sees
    whole); the states entered among them, a collision event and the trajectory are read from the rows, and the
    simulator's contact watch ended the stretch at any step with a contact (cotwin.mapping.cstep). What it asks of
    the ledger (a command applied, done) and of the wait watch (a wait blocked) changes only at such steps, or
    in time: `quiet_for` ends a stretch at the first step at which the what-if could be over."""

    def __init__(self, fork, endpoint, plan, start: float, horizon: float, settle: float, decimate: int,
                 waits: WaitWatch, ledger: CommandLedger, contacts: _Contacts | None = None):
        program = fork.models.program
        self.program, self.plan, self.settle, self.decimate = program, plan, settle, decimate
        self.waits, self.ledger, self.endpoint = waits, ledger, endpoint
        self.monitored = list(fork.log[MAPPING.name])
        self.state_ports = [(program.state_port(m), m) for m in program.machines]
        self.whole = [(DMODEL.name, port) for port, _ in self.state_ports] + \
            [(fork.source.name, event) for event in sorted(fork.command_events)] if fork.source is not None else None
        self.rest_leaves = {(DMODEL.name, port): [ledger.rest[port]] for port, _ in self.state_ports}
        self.collision_events = [e for e in fork.platform_events if e.lower() == "collision"]
        self.contacts = contacts.again() if contacts is not None else _Contacts(endpoint, fork.models.tree, fork.models.tool)
        self.trajectory: dict[str, list[float]] = {"time": [], **{v: [] for v in self.monitored}}
        self.states: list[tuple[float, str, str]] = []
        self.collisions: list[dict] = []
        self.last_state: dict[str, int] = {}
        self.at_rest_since: float | None = None
        self.occurrences = occurrences(program, fork.command_events, plan)  # what the ledger will see applied
        self.last_command = plan[-1].time if plan else start
        self.end = start + horizon
        self.over = False

    def simulation_initialized(self, execution) -> None:
        slots = execution.algorithm.slots
        self._values = execution.values
        self._slots = [slots[(MAPPING.name, v)] for v in self.monitored]
        self._collision_slots = [slots[(MAPPING.name, e)] for e in self.collision_events]
        self._state_slots = [slots[(DMODEL.name, port)] for port, _ in self.state_ports]
        self._state_keys = [(DMODEL.name, port) for port, _ in self.state_ports]
        self._collision_keys = [(e, (MAPPING.name, e)) for e in self.collision_events]
        self.resting = self.ledger.resting([self._values.get((DMODEL.name, port)) for port, _ in self.state_ports])
        self.record(execution)

    def record(self, execution) -> None:
        if execution.steps % self.decimate == 0:
            self.trajectory["time"].append(execution.time)
            for v in self.monitored:
                self.trajectory[v].append(self._values.get((MAPPING.name, v)))

    def step_complete(self, execution) -> None:
        t, values = execution.time, self._values
        self.record(execution)
        if self._collision_keys:
            self.collisions.extend({"kind": "event", "event": e, "time": t} for e, key in self._collision_keys
                                   if values.get(key) is True)
        current = [values.get(key) for key in self._state_keys]
        self._entered(t, current)
        self.resting = self.ledger.resting(current)
        self.contacts.check(t)
        if not self.resting:
            self.at_rest_since = None
        elif self.at_rest_since is None:
            self.at_rest_since = t
        self.over = self._over(t, execution.step_size)

    def _entered(self, t: float, current: list) -> None:
        """The machines' states at time t: those that changed noted."""
        for (port, m), index in zip(self.state_ports, current):
            if index != self.last_state.get(port):
                leaves = self.program.leaf_names(m)
                self.states.append((t, m.name, leaves[index] if isinstance(index, int) and 0 <= index < len(leaves)
                                    else "none"))
                self.last_state[port] = index

    def _over(self, t: float, h: float) -> bool:
        outcomes = self.ledger.outcomes
        applied = len(outcomes) >= len(self.occurrences)
        if applied and t >= self.last_command and self.waits.found:
            return True  # blocked for good: the horizon would add nothing
        if applied and t >= self.last_command and self.at_rest_since is not None and t - self.at_rest_since >= self.settle:
            last = outcomes[-1] if outcomes else None
            if last is None or last.done is not None:
                return True
            if not last.accepted and t - last.delivered >= self.settle + 3 * h:
                return True  # delivered, never acted upon: the d-model ignored it
        return t >= self.end - 1e-9

    def repeated(self, execution, rows) -> None:
        """Steps in which only continuous values changed: the trajectory's rows, a collision event held, and
        the rest the arm took from the first of them (see the class doc)."""
        times, steps = rows.times, rows.steps
        self._entered(times[0], list(rows.row(0, self._state_slots)))  # a run's first rows: its states seen here
        for k in rows.changes(self._state_slots):  # states entered among them (none a machine's rest: whole_values)
            current = list(rows.row(k, self._state_slots))
            self._entered(times[k], current)
            self.resting = self.ledger.resting(current)
            if not self.resting:
                self.at_rest_since = None
        kept = [k for k, s in enumerate(steps) if (s + 1) % self.decimate == 0]
        if kept:
            self.trajectory["time"].extend(times[k] for k in kept)
            for v, column in zip(self.monitored, zip(*rows.values(self._slots))):
                self.trajectory[v].extend(column[k] for k in kept)
        for e, column in zip(self.collision_events, zip(*rows.values(self._collision_slots))):
            self.collisions.extend({"kind": "event", "event": e, "time": t} for t, held in zip(times, column) if held)
        if self.resting and self.at_rest_since is None:
            self.at_rest_since = times[0]

    def whole_changes(self, execution) -> list | None:
        return self.whole  # the states and the commands shown (see the class doc); None without a command source

    def whole_values(self, execution) -> dict:
        """Of the states, the leaf each machine rests in: coming to rest starts the settling it times."""
        return self.rest_leaves

    def quiet_for(self, execution) -> int | None:
        """Steps until the first at which the what-if could be over, its discrete values as they are now: the
        first at which one of `_over`'s conditions on time (each spelt as `_over` spells it) turns true."""
        t, h = execution.time, execution.step_size
        origin, done = execution._origin
        at = lambda k: origin + (execution.steps + k - done) * h  # noqa: E731 (the time after k more steps, as counted)
        since, settle = self.at_rest_since, self.settle
        if since is None and self.resting:
            since = at(1)  # resting from the start: the rest counts from the first step (as `repeated` takes it)
        turns = [(lambda x: x >= self.end - 1e-9, self.end), (lambda x: x >= self.last_command, self.last_command)]
        if since is not None:
            turns.append((lambda x: x - since >= settle, since + settle))
        outcomes = self.ledger.outcomes
        if outcomes and outcomes[-1].delivered is not None and not outcomes[-1].accepted:  # taken: for good
            delivered = outcomes[-1].delivered
            turns.append((lambda x: x - delivered >= settle + 3 * h, delivered + settle + 3 * h))
        bounds = [_first(lambda k: turned(at(k)), (about - t) / h) for turned, about in turns if not turned(t)]
        return min((b for b in bounds if b is not None), default=None)

    def reached(self, execution) -> bool:
        return self.over

    def progress(self) -> tuple:
        """What it has seen so far, as copies (a start shared by a sweep's plans: Forks)."""
        return ({k: list(v) for k, v in self.trajectory.items()}, list(self.states), [dict(c) for c in self.collisions],
                {k: dict(v) for k, v in self.contacts.seen.items()}, dict(self.last_state), self.at_rest_since,
                self.resting)

    def resume(self, progress: tuple) -> None:
        """Go on from `progress` (a run restored to the step it was taken at)."""
        trajectory, states, collisions, seen, last, since, resting = progress
        self.trajectory = {k: list(v) for k, v in trajectory.items()}
        self.states, self.collisions = list(states), [dict(c) for c in collisions]
        if self.contacts.sim is not None:
            self.contacts.seen = {k: dict(v) for k, v in seen.items()}
        self.last_state, self.at_rest_since, self.resting = dict(last), since, resting

    def prediction(self, execution, fork, plan, start: float, started: float) -> Prediction:
        outcomes = list(self.ledger.outcomes)
        for c, event, args in self.occurrences[len(outcomes):]:  # not applied within the horizon
            outcomes.append(CommandOutcome(c.time, event, args, origin=c.where))
        collisions = self.collisions + (list(self.contacts.seen.values()) if self.contacts.sim is not None else [])
        # the plan is done when every command completed: one infeasible or stopped also comes back to rest
        done = [o.done if o.verdict == "completed" else None for o in outcomes]
        completion = max(done) if done and all(d is not None for d in done) else (None if outcomes else execution.time)
        return Prediction(start, execution.time, execution.step_size, outcomes, self.states, self.trajectory,
                          collisions, completion, wallclock.perf_counter() - started,
                          [str(b) for b in self.waits.found],
                          saturated=saturated_joints(self.endpoint))


def occurrences(program, events: set[str], plan: list[Command]) -> list[tuple[Command, str, dict]]:
    """The occurrences the plan's commands raise, in the order the controller applies them (ScenarioUnit: one
    per event a command raises, in the command's order, with its own arguments): a plan row may raise several
    events or none (a TwinManager plan CSV's row with every event false)."""
    from ..assembly.scenario import occurrences as raised

    arguments = once_per(program, "event arguments", lambda: {ev.name: [port for port, _ in ev.value_ports]
                                                             for ev in program.inputs})
    return [(c, event, args) for c in plan for event, args in raised(c, events, arguments)]


def _first(holds, about: float, limit: int = 1 << 20) -> int | None:
    """The smallest k in 1..limit for which `holds(k)` (false, then true from some k on), or None; `about`:
    roughly where (a few steps either side), so that it is found in a few asks."""
    k = min(limit, max(1, math.ceil(about)))
    if holds(k):
        while k > 1 and holds(k - 1):
            k -= 1
        return k
    lo, step = k + 1, 1
    while lo <= limit and not holds(lo):  # past it by doubling, then back
        lo, step = lo + step, step * 2
    if lo > limit:
        if not holds(limit):
            return None
        lo = limit
    hi, lo = lo, lo - step // 2 if step > 1 else lo
    while lo < hi:
        mid = (lo + hi) // 2
        if holds(mid):
            hi = mid
        else:
            lo = mid + 1
    return hi


def _quiet_start(counted: tuple[float, int, int], h: float, plan: list[Command]) -> int:
    """How many steps from the forks' start the command source offers nothing (the first command is due later):
    the start every plan of a shape with its first command at that time shares, as ScenarioUnit.step counts
    it. `counted`: the start's origin, steps since it and steps (Execution._origin, .steps)."""
    from ..assembly.scenario import steps_before_due

    if not plan:
        return 0
    origin, done, steps = counted
    return steps_before_due(plan[0].time, origin, steps - done, h, 1 << 20)


def _advance(execution, watch: Watch, steps: int | None = None) -> Watch:
    """Step the fork until its what-if is over (or `steps` more), the contact watch set meanwhile."""
    if steps is None:
        steps = math.ceil((watch.end - execution.time) / execution.step_size) + 1
    watch.contacts.start()
    try:
        if execution.time < watch.end - 1e-9 and not watch.over:
            execution.advance(steps, until=watch)
    finally:
        watch.contacts.stop()
    return watch


def _watch(fork, execution, endpoint, plan, start, horizon, settle, decimate, started, waits, ledger) -> Prediction:
    """Run the fork until its what-if is over (Watch), with the wait watch and the command ledger observing."""
    watch = Watch(fork, endpoint, plan, start, horizon, settle, decimate, waits, ledger)
    execution.observers = [waits, ledger, watch]
    watch.simulation_initialized(execution)
    native = execution.native_steps
    prediction = _advance(execution, watch).prediction(execution, fork, plan, start, started)
    prediction.native_steps = execution.native_steps - native
    return prediction


def plan_from_json(items: list, program) -> list[Command]:
    """A what-if plan from JSON (a broker request or a file): [{"time": s, "event": name, "args": {...}}],
    checked like a TOML scenario; CotwinError naming the item otherwise."""
    from ..assembly.scenario import command_values

    if not isinstance(items, list) or not items:
        raise CotwinError("a what-if plan is a non-empty list of {time, event, args}")
    events = {ev.name: ev for ev in program.inputs}
    out = []
    for k, item in enumerate(items, start=1):
        if not isinstance(item, dict) or set(item) - {"time", "event", "args"}:
            raise CotwinError(f"plan item {k}: expected {{time, event, args}}, got {item!r:.80}")
        t, name, args = item.get("time"), item.get("event"), item.get("args", {})
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not (0 <= t < 1e6):
            raise CotwinError(f"plan item {k}: time must be a number of seconds >= 0, got {t!r:.80}")
        if name not in events:
            raise CotwinError(f"plan item {k}: unknown event {name!r:.80}{did_you_mean(name, events)} "
                              f"(known: {', '.join(events)})")
        if not isinstance(args, dict):
            raise CotwinError(f"plan item {k}: args must be an object")
        values, wrong = command_values(events[name], args)
        if wrong:
            raise CotwinError([f"plan item {k}: {message}" for _, message in wrong])
        out.append(Command(float(t), tuple(values), f"plan item {k}"))
    return out


# ---- what-if requests over the broker ------------------------------------------------------------

def finite(value):
    """`value` (JSON-ready) with NaN and infinities, which JSON lacks, as null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def _worker_init(project: str, artefacts: str | None) -> None:
    global _WORKER
    from ..assembly.run import load

    _WORKER = (load(project), artefacts)


def _worker_predict(plan_json: list, state: bytes, horizon: float, decimate: int) -> dict:
    system, artefacts = _WORKER
    plan = plan_from_json(plan_json, system.models.program)
    return predict(system, plan, state, horizon=horizon, artefacts=artefacts, decimate=decimate).as_dict()


class WhatIfService(BackgroundService):
    """Answers what-if requests of a live twin sent over the broker, without disturbing it.

    A request is a JSON object `{"plan": [{"time": s, "event": name, "args": {...}}], "horizon": s,
    "decimate": n}` published on the twin's topic exchange (`[deviation] exchange`, default `cotwin.twin`)
    with routing key `twin.whatif` (or `twin.whatif.<anything>`), with `reply_to` and `correlation_id`
    set. Between two steps the twin hands its DT's state to a separate process, which runs the plan on a
    fork; the answer (`Prediction.as_dict()`, or `{"error": why}`) is published to `reply_to` (a
    broker-named `amq.gen-*` queue: named queues get no answer) with the request's `correlation_id`.
    Requests are validated like any broker message; a bad one gets an error answer and never reaches the
    twin; one without a broker-named `reply_to` could never be answered and is dropped (and logged, at
    most 20 lines per 10 s: a flood cannot fill the log); at most MAX_PENDING run at a time (the count is
    shared by the broker's, the twin's and the pool's threads, under a lock); those accepted before the
    twin ends are answered within `close`'s wait. Who may send requests is the broker's business: the
    `whatif` role of docs/security.md may publish `twin.whatif` on the twin's exchange."""

    def __init__(self, url: str, exchange: str, project: str | Path, artefacts: str | Path | None = None,
                 workers: int = 1, routing_key: str = "twin.whatif"):
        import queue
        from concurrent.futures import ProcessPoolExecutor
        from multiprocessing import get_context

        from ...mapping.amqp import connect, declare_exchange
        from ..assembly.rabbitmq import EVENTS

        BackgroundService.__init__(self, "cotwin what-if")
        self.exchange, self.routing_key = exchange, routing_key
        self.requests: queue.Queue = queue.Queue()
        self.answered = 0
        self.dropped = 0  # requests that could not be answered (no reply_to)
        self._pending = 0
        self._lock = threading.Lock()
        self._futures: set = set()  # forked and not yet answered
        self._closing = False
        self.log = CappedLog(logging.getLogger("cotwin.whatif"), "dropped what-if requests")
        self._pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=_worker_init,
                                         initargs=(str(Path(project).resolve()), str(artefacts) if artefacts else None))
        self._connection = None
        try:
            self._connection = connect(url, "cotwin what-if")
            channel = self._connection.channel()
            declare_exchange(channel, exchange, "topic", url, EVENTS)
        except CotwinError:
            self._pool.shutdown(wait=False)
            if self._connection is not None:
                self._connection.close()
            raise
        self.queue = channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
        for key in (routing_key, routing_key + ".#"):
            channel.queue_bind(self.queue, exchange, routing_key=key)
        channel.basic_consume(self.queue, self._on_request, auto_ack=True)
        self._channel = channel
        self.start()

    def serve(self) -> None:
        """The broker's thread: requests taken as they come, until the service stops or the broker is lost."""
        self.ready()
        while not self.stopping.is_set():
            try:
                self._connection.process_data_events(time_limit=0.05)
            except Exception:  # noqa: BLE001 - a lost broker ends the service, not the twin
                import logging

                logging.getLogger("cotwin.whatif").warning("what-if service: lost the broker; no more requests")
                return

    def _reply(self, props, answer: dict) -> None:
        import json

        import pika

        if not props.reply_to or not props.reply_to.startswith("amq.gen-"):
            return  # answers go only to broker-named (exclusive) reply queues, never to a named queue
        body = json.dumps(finite(answer), default=float, allow_nan=False).encode()  # a diverged fork: null, not NaN
        self._connection.add_callback_threadsafe(lambda: self._channel.basic_publish(
            "", props.reply_to, body, pika.BasicProperties(correlation_id=props.correlation_id,
                                                           content_type="application/json")))

    MAX_PENDING = 4  # requests queued or running; more are answered "busy" (a fork costs a process's time)

    def _on_request(self, channel, method, props, body) -> None:
        if not props.reply_to or not props.reply_to.startswith("amq.gen-"):
            self.dropped += 1
            self.log.warning("what-if request dropped: %s (correlation_id %r)", "no reply_to" if not props.reply_to
                             else f"reply_to {props.reply_to[:80]!r} is not a broker-named queue (amq.gen-*)",
                             (props.correlation_id or "")[:80])
            return
        if self._closing:
            self._reply(props, {"error": "the twin is stopping; it takes no more what-if requests"})
            return
        with self._lock:
            busy = self._pending >= self.MAX_PENDING
            if not busy:
                self._pending += 1  # taken now, so no two threads both see room for one more
        if busy:
            self._reply(props, {"error": f"busy: {self.MAX_PENDING} what-ifs pending; try again later"})
            return
        try:
            request = safejson.loads(body, MAX_REQUEST)
            if not isinstance(request, dict):
                raise ValueError("a request is a JSON object {plan, horizon, decimate}")
            unknown = sorted(set(request) - {"plan", "horizon", "decimate"})
            if unknown:
                raise ValueError(f"unknown key {', '.join(repr(k[:40]) for k in unknown[:10])} "
                                 "(a request is {plan, horizon, decimate})")
            horizon = request.get("horizon", 30.0)
            decimate = request.get("decimate", 1)
            if isinstance(horizon, bool) or not isinstance(horizon, (int, float)) or not 0 < horizon <= 3600:
                raise ValueError("horizon must be a number of seconds in (0, 3600]")
            if isinstance(decimate, bool) or not isinstance(decimate, int) or decimate < 1:
                raise ValueError("decimate must be a positive integer")
            if not isinstance(request.get("plan"), list) or not request["plan"]:
                raise ValueError("plan must be a non-empty list")
        except ValueError as err:
            self._release()
            self._reply(props, {"error": f"bad what-if request: {err}"})
            return
        self.requests.put((props, request["plan"], float(horizon), decimate))

    def poll(self, execution) -> None:
        """Between two steps of the live twin: fork the DT's state for every waiting request."""
        while not self.requests.empty():
            props, plan, horizon, decimate = self.requests.get_nowait()
            try:
                state = execution.get_state()
            except CotwinError as err:
                self._release()
                self._reply(props, {"error": "; ".join(f.message for f in err.findings)})
                continue
            try:
                future = self._pool.submit(_worker_predict, plan, state, horizon, decimate)
            except RuntimeError as err:  # the pool is shut down or broken (a worker died): the twin runs on
                self._release()
                self._reply(props, {"error": f"the what-if workers are gone ({type(err).__name__})"})
                continue
            with self._lock:
                self._futures.add(future)
            future.add_done_callback(lambda f, props=props: self._done(props, f))

    def _done(self, props, future) -> None:
        try:
            answer = future.result()
        except CotwinError as err:
            answer = {"error": "; ".join(f.message for f in err.findings)}
        except CancelledError:
            answer = {"error": "the twin stopped before this what-if ran"}
        except Exception as err:  # noqa: BLE001 - the worker's failure is the requester's answer
            answer = {"error": f"{type(err).__name__}: {err}"}
        with self._lock:
            self.answered += 1
            self._futures.discard(future)
        self._release()
        self._reply(props, answer)

    def _release(self) -> None:
        with self._lock:
            self._pending -= 1

    @property
    def pending(self) -> int:
        """Requests queued or running."""
        with self._lock:
            return self._pending

    def close(self, wait: float = 60.0) -> None:
        """Stop taking requests; answer those already forked (for at most `wait` seconds in all: a worker
        still starting when the twin ends gets its queued requests done too), then drop the others."""
        from concurrent.futures import wait as wait_for

        self._closing = True
        with self._lock:
            futures = list(self._futures)
        wait_for(futures, timeout=wait)
        running = list((getattr(self._pool, "_processes", None) or {}).values())
        self._pool.shutdown(wait=False, cancel_futures=True)
        deadline = time.monotonic() + wait
        for process in running:
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
        self.stop(5)
        self.log.close()
        try:
            self._connection.close()
        except Exception:  # noqa: BLE001
            pass
