"""Platform endpoints: where a mapping's actuator commands go and its sensor readings come from.

An endpoint takes servo goals by p-model path (`pmodel::link::joint::aref.port`) and moves each joint
there along a trajectory planned by a motion profile (cotwin.mapping.motion: by default a quintic at
the joints' velocity limits; a UR-style synchronised `movej`), all joints arriving together; it reads
sensors by path (`pmodel::link::sref.port`). The MuJoCo simulator is the default; any subclass of
cotwin.mapping.platform.Endpoint (the interface and its optional abilities) plugs in without touching the
mapping.
"""

from __future__ import annotations

import ctypes
from dataclasses import fields as dataclass_fields, replace
from typing import Protocol

import numpy as np

from ..diagnostics import CotwinError
from ..plaindata import fields, finite, of_type
from ..pmodel.cell import CellGeometry
from ..pmodel.simulator import PlatformSimulator, SimState
from .motion import MotionProfile, Quintic, Segment
from .platform import Endpoint, NamedActuators

CONTROL_PERIOD = 0.002  # s between trajectory set-points sent to the servos


class SharedEndpoint(Protocol):
    """A robot's endpoint on a world of several robots, which `advance_shared` drives: goals that take
    effect later (a perturbed plant's latency) are applied when due, set-points written before each stretch
    of physics steps."""

    def next_due(self) -> float | None: ...  # when the next goal waiting for its time takes effect
    def apply_due(self) -> None: ...  # apply the goals due by now
    def set_point(self, steps: int) -> bool: ...


def advance_shared(world, endpoints: list[SharedEndpoint], dt: float) -> None:
    """Run a world of several robots (cotwin.pmodel.shared.SharedWorld) for dt, each robot's servos
    following its own trajectory (set-points refreshed every CONTROL_PERIOD, as `SimulatedEndpoint.advance`
    does for one), the physics stepped once for all of them, split where a robot's delayed goal falls due."""
    world.begin()
    steps = world.steps_for(dt)
    period = max(1, int(round(CONTROL_PERIOD / world.timestep)))
    while steps > 0:
        for endpoint in endpoints:
            endpoint.apply_due()
        due = [int(round((d - world.time) / world.timestep)) for d in (e.next_due() for e in endpoints) if d is not None]
        until_due = min([k for k in due if k > 0] or [steps])
        n = min(period, steps, until_due)
        if all([endpoint.set_point(n) for endpoint in endpoints]):
            n = min(steps, until_due)
        world.step(n)
        steps -= n
    for endpoint in endpoints:
        endpoint.apply_due()


class SimulatedEndpoint(NamedActuators, Endpoint):
    """The embedded MuJoCo platform with a trajectory generator in front of its servos. The cell's
    geometry (for the mapping's kinematics functions) is the scene's unless given."""

    def __init__(self, simulator: PlatformSimulator, profile: MotionProfile | None = None,
                 geometry: CellGeometry | None = None):
        self.sim = simulator
        self.tree = simulator.tree
        self.profile: MotionProfile = profile or Quintic()
        self.geometry = geometry or (simulator.scene.geometry if simulator.scene is not None else None)
        self._name_actuators(self.tree, "the endpoint")
        self.segment: Segment | None = None
        self._held = None  # the segment whose final set-point the servos already hold
        self._plan: tuple | None = None  # (segment, per joint (control index, start, goal - start, low, high))
        self._native_plan = None  # the same as ctypes arrays for cotwin.mapping.native, and the joints' count
        self._native_memory = None  # the simulator's data and arrays as the C loop takes them
        self.direct: dict[str, float] = {}  # joint -> the speed or effort last commanded

    def start(self) -> None:
        self.segment = None

    def stop(self) -> None:
        self.segment = None

    placeable = saves_state = senses_contacts = True

    def place(self, positions: dict[str, float]) -> None:
        """Put the robot at rest at these joint positions (a live twin starts its DT where the PT is)."""
        known = {n: v for n, v in positions.items() if n in self.sim.joint_names}
        self.sim.reset(known)
        self.segment = None
        self.direct = {}

    def resync(self, positions: dict[str, float], velocities: dict[str, float] | None = None) -> None:
        """Take a measured joint state (a live twin's DT corrected to its PT). A move in progress continues
        from it: its set-points are re-timed to where along the move the measured joints are (else the
        servos would pull the robot straight back to the old set-point, undoing the correction)."""
        known = {n: v for n, v in positions.items() if n in self.sim.joint_names}
        speeds = {n: v for n, v in (velocities or {}).items() if n in self.sim.joint_names}
        self.sim.set_joint_state(known, speeds)
        segment = self.segment
        if segment is not None:
            self.segment = retimed(segment, known, self.sim.time)
            self._held = None  # its set-point is written again at the next step

    def read_sensors(self) -> dict[str, float]:
        return self.sim.read_sensors()

    def joint_positions(self) -> dict[str, float]:
        return self.sim.joint_positions()

    def joint_velocities(self) -> dict[str, float]:
        return self.sim.joint_velocities()

    def command(self, goals: dict[str, float]) -> None:
        """New servo goals (by actuator path, servo or joint name); joints not named keep their goal.
        Position goals are reached along a planned trajectory; speeds and efforts (wheels, motors) are
        the actuator's command at once."""
        planned, direct = {}, {}
        for name, value in goals.items():
            if not np.isfinite(value):
                raise CotwinError(f"actuator '{name}': goal {value!r} is not a finite number")
            joint = self.joint(name)
            if joint in self._positioned:
                planned[joint] = float(value)
            else:
                direct[name] = float(value)
                self.direct[joint] = float(value)
        if direct:
            self.sim.write_actuators(direct)
        if not planned:
            return
        now = self.sim.time
        current = self.segment.at(now) if self.segment else \
            {j: v for j, v in self.sim.joint_positions().items() if j in self._positioned}
        goal = dict(self.segment.goal) if self.segment else dict(current)
        goal.update(planned)
        start = {j: current.get(j, goal[j]) for j in goal}
        self.segment = self.profile.plan(self.tree, start, goal, now)

    def goals(self) -> dict[str, float]:
        """The goals in force by joint: position goals (their segment's end, else where the joint is) and
        the last speed or effort commanded."""
        q = self.sim.joint_positions()
        out = {j: q[j] for j in q if j in self._positioned}
        if self.segment is not None:
            out.update(self.segment.goal)
        return {**{j: 0.0 for j in q if j not in self._positioned}, **out, **self.direct}

    def advance(self, dt: float) -> None:
        """Run the platform for dt (whole physics steps), the servos' set-points refreshed every
        CONTROL_PERIOD to where the segment is at the end of that period; once the segment has ended
        its set-point no longer changes, so the rest runs in one go."""
        sim = self.sim
        steps = sim.steps_for(dt)
        period = max(1, int(round(CONTROL_PERIOD / sim.timestep)))
        segment = self.segment
        if steps > 0 and segment is not None and segment is not self._held and sim.plain_stepping:
            steps -= self._advance_natively(segment, steps, period)
        while steps > 0:
            n = min(period, steps)
            if self.set_point(n):
                n = steps
            sim.step(n)
            steps -= n

    def _advance_natively(self, segment: Segment, steps: int, period: int) -> int:
        """As many of `steps` as the C loop makes (cotwin.mapping.native: the same set-points and steps as the
        loop in `advance`), 0 where it does not run here; the physics steps made are returned."""
        from . import native

        function = native.advance_function()
        moves = self._moves(segment)
        if function is None or moves is None:
            return 0
        fn, mj_step = function
        sim = self.sim
        arrays, n = self._native_plan
        memory = self._native_memory
        if memory is None or memory[0] is not sim.data:  # the simulator's arrays, as C pointers, once
            data, double = sim.data, ctypes.POINTER(ctypes.c_double)
            memory = self._native_memory = (data, sim.model._address, data._address, float(sim.model.opt.timestep),
                                            sim.controls.ctypes.data_as(double), data.qpos.ctypes.data_as(double),
                                            data.qpos.size, ctypes.c_double(), ctypes.c_int(), ctypes.c_int())
        data, model_address, data_address, timestep, ctrl, qpos, nq, time, held, done = memory
        time.value, held.value = data.time, 0
        fn(mj_step, model_address, data_address, time, sim.timestep, timestep, steps, period, arrays[0], n,
           *arrays[1:], ctrl, qpos, nq, held, done, sim.sensor_flags())  # 1: a set-point not finite (the Python
        # loop says so); 2: unstable
        if done.value:
            sim.stepped(done.value)  # status 2 (the state not finite) raises here, as `step` does
        if time.value != sim.data.time:
            raise CotwinError(f"the native control loop kept time {time.value!r}, MuJoCo {sim.data.time!r}")
        if held.value:
            self._held = segment
        return done.value  # status 1: a set-point not finite; the Python loop goes on and says so

    def native_move(self):
        """The move in flight for a native loop (cotwin.mapping.cstep): (segment, the control loop's C arrays, the
        joints' count); None when the servos hold their set-point (no move, or its end reached); False when
        the move cannot run in C (an unknown actuator, a number that is not a float)."""
        segment = self.segment
        if segment is None or segment is self._held:
            return None
        if self._moves(segment) is None:
            return False
        arrays, joints = self._native_plan
        return segment, arrays, joints

    def stepped_natively(self, steps: int, held: object | None) -> None:
        """A native loop made `steps` physics steps (counted, not checked: the loop checked them), the move
        `held` reaching its end (its set-point held from then on) or None."""
        self.sim.stepped(steps, check=False)
        if held is not None:
            self._held = held

    def _moves(self, segment: Segment) -> list | None:
        """Per joint of the segment: (control index, start, goal - start, low, high), once per segment (and
        the same as ctypes arrays for the native loop); None when an actuator is unknown."""
        plan = self._plan
        if plan is None or plan[0] is not segment:
            slots = self.sim.servo_slots(list(segment.goal))
            moves = [(index, segment.start[j], segment.goal[j] - segment.start[j], low, high)
                     for j, (index, low, high) in zip(segment.goal, slots)] if slots is not None else None
            plan = self._plan = (segment, moves)
            if moves is not None and all(m[1].__class__ is float and m[2].__class__ is float for m in moves):
                n = len(moves)
                doubles = ctypes.c_double * n
                shape = (segment.t0, segment.duration, 1.0 if segment.shape == "trapezoid" else 0.0, segment.a,
                         segment.v, segment.distance)
                self._native_plan = ((ctypes.c_double * 6)(*map(float, shape)), (ctypes.c_int * n)(*(m[0] for m in moves)),
                                     *(doubles(*(m[k] for m in moves)) for k in (1, 2, 3, 4))), n
            else:
                self._native_plan = None
        return plan[1] if self._native_plan is not None else None

    def _set_point(self, segment: Segment, t: float) -> None:
        """The servos' set-point: `segment.at(t)` written as `write_actuators` writes it (clipped to each
        servo's range), without building a dict per control period: each joint's start, move and servo
        are looked up once per segment. The same floats (start + s * (goal - start)); anything unusual (a
        value not finite, an unknown actuator) goes through `write_actuators`, which says what is wrong."""
        self._moves(segment)
        moves = self._plan[1]
        if moves is None:
            self.sim.write_actuators(segment.at(t))
            return
        s = segment.fraction(t)
        ctrl = self.sim.controls
        for index, start, move, low, high in moves:
            value = start + s * move
            if value.__class__ is not float or value - value != 0.0:
                self.sim.write_actuators(segment.at(t))
                return
            ctrl[index] = low if value < low else high if value > high else value

    def set_point(self, steps: int) -> bool:
        """Write the servos' set-points for the next `steps` physics steps (where the segment is at their
        end); whether they hold from now on (no segment, or its end reached), so that the rest of a
        step runs in one go. (A world of several robots calls it for each before stepping them all.)"""
        sim = self.sim
        segment = self.segment
        if segment is not None and segment is not self._held:
            ahead = sim.time + steps * sim.timestep
            self._set_point(segment, ahead)
            if ahead >= segment.t0 + segment.duration:  # the set-point stays at the segment's end
                self._held = segment
        return segment is None or segment is self._held

    def next_due(self) -> float | None:
        return None  # its goals take effect at once

    def apply_due(self) -> None:
        return None

    def robot_contacts(self) -> set[str]:
        """The other robots this one touched in the step just made (none for a robot alone in its world)."""
        shared = self.sim.shared
        return shared.robot_contacts(self.sim.prefix[:-1]) if shared is not None else set()

    @property
    def time(self) -> float:
        return self.sim.time

    # ---- state (what-if forks and rollbacks): the simulator's and the segment in flight ----
    def snapshot(self) -> dict:
        """The endpoint's state as plain data: MuJoCo's integration state and the trajectory in flight."""
        state = self.sim.get_state()
        return {"simulator": state.vector, "scans": state.scans, "derived": state.derived,
                "segment": trajectory_data(self.segment), "direct": dict(self.direct),
                "bodies": self.sim.changed_bodies()}

    def restore(self, snapshot: dict) -> None:
        """Continue from a snapshot, checked against this platform first: the simulator's state (its size,
        finite numbers, the ray sensors' readings), the trajectory's joints and numbers, the speeds and
        efforts by joint, the masses of bodies changed while running (an estimated payload)."""
        fields(snapshot, "platform", ("simulator", "segment"), ("scans", "direct", "derived", "bodies"))
        of_type(snapshot["simulator"], np.ndarray, "platform's simulator state")
        direct = of_type(snapshot.get("direct", {}), dict, "platform's commanded speeds and efforts")
        commanded = {j.name for j in self.tree.actuated} - self._positioned if direct else set()
        for joint, value in direct.items():
            if joint not in commanded:
                raise CotwinError(f"the saved state commands a speed or effort of {joint!r:.60}, which is not a "
                                  f"speed- or effort-driven joint of this platform")
            finite(value, f"commanded speed or effort of {joint}")
        segment = trajectory_from(snapshot["segment"], self._positioned)
        self.sim.set_bodies(of_type(snapshot.get("bodies", {}), dict, "platform's changed bodies"))  # e.g. a payload
        self.sim.set_state(SimState(snapshot["simulator"], tuple(snapshot.get("scans", ())),
                                    tuple(of_type(snapshot.get("derived", ()), tuple, "platform's derived quantities"))))
        self.direct = {j: float(v) for j, v in direct.items()}
        self.segment = segment
        self._held = None  # written again at the next step (the same value: MuJoCo's controls are restored)


def retimed(segment: Segment, positions: dict[str, float], now: float) -> Segment:
    """`segment` shifted in time so that its set-point at `now` is the point of the move nearest to
    `positions` (the fraction along start -> goal, by least squares over the moving joints); unchanged when
    nothing moves or the joints are not yet on their way and the move has not begun."""
    moving = [j for j in segment.goal if j in positions and abs(segment.goal[j] - segment.start[j]) > 1e-12]
    if not moving or segment.duration <= 0:
        return segment
    span = np.array([segment.goal[j] - segment.start[j] for j in moving])
    offset = np.array([positions[j] - segment.start[j] for j in moving])
    s = float(np.clip(offset @ span / (span @ span), 0.0, 1.0))
    if s <= 0.0 and segment.fraction(now) <= 0.0:
        return segment  # not begun on either side: the move starts when it was planned to
    low, high = 0.0, segment.duration  # the elapsed time at which the move's fraction is s (it never decreases)
    for _ in range(60):
        mid = 0.5 * (low + high)
        if segment.fraction(segment.t0 + mid) < s:
            low = mid
        else:
            high = mid
    return replace(segment, t0=now - high)


TRAJECTORIES = {"Segment": Segment}  # the trajectory kinds an endpoint state may hold, by class name


def trajectory_data(trajectory) -> dict | None:
    """A trajectory (a dataclass of TRAJECTORIES) as plain data: its kind and fields."""
    if trajectory is None:
        return None
    kind = type(trajectory).__name__
    if TRAJECTORIES.get(kind) is not type(trajectory):
        raise CotwinError(f"cannot save a trajectory of kind {kind}: not one of {', '.join(TRAJECTORIES)}")
    return {"kind": kind, "fields": {f.name: getattr(trajectory, f.name) for f in dataclass_fields(trajectory)}}


def trajectory_from(data: dict | None, joints: set[str] | None = None):
    """The trajectory `trajectory_data` saved, checked: a known kind, its fields and no others, finite numbers,
    goals only for `joints` (when given) and a start for every goal; CotwinError naming what is wrong."""
    if data is None:
        return None
    fields(data, "trajectory", ("kind", "fields"))
    if data["kind"] not in TRAJECTORIES:
        raise CotwinError(f"a saved trajectory of unknown kind {str(data['kind'])[:60]!r}")
    kind = TRAJECTORIES[data["kind"]]
    values = fields(data["fields"], "trajectory", [f.name for f in dataclass_fields(kind)])
    return kind(**{name: _checked_field(name, value, joints) for name, value in values.items()}).checked()


def _checked_field(name: str, value, joints: set[str] | None):
    if isinstance(value, dict):
        for joint, position in value.items():
            if joints is not None and joint not in joints:
                raise CotwinError(f"the saved trajectory moves {joint!r:.60}, not a position-driven joint of this platform")
            finite(position, f"trajectory's {name} of {joint}")
        return {j: float(v) for j, v in value.items()}
    if isinstance(value, str):
        return value
    return finite(value, f"trajectory's {name}")
