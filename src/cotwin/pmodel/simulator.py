"""The embedded platform simulator: MuJoCo running the MJCF generated from the p-model.

Names come from the p-model: sensors are read as `pmodel::link::sref.port` (the mapping's paths),
actuators are written by joint name, servo (aref) name or `pmodel::link::joint::aref.port`, the port
being the actuator's command input (`dangle` of a ServoMotor, `ControlIn` of a ControlledMotor): an
angle for position servos, a speed for velocity servos, an effort for motors.
The physics step (1 ms by default) is sub-stepped inside `advance(dt)`.

Ray sensors (a LiDAR, a sonar: cotwin.pmodel.kinds.ray_spec) scan at their update rate, at whole
multiples of its period from the start: every beam is cast from the sensor's site in its x-y plane
(MuJoCo's mj_multiRay over the world's geoms, not the robot's own), returns outside
[range_min, range_max] count as none, and the readings hold until the next scan. A port reading the
closest return gives its range (m) or bearing in degrees, 0 straight ahead, counter-clockwise
positive, in (-180, 180] (as ROS's LaserScan angles, in degrees: a d-model compares them with
angles such as 30 and 90); with no return both read inf and NaN. A port reading the range straight
ahead gives the first beam's.

A free base also reads its pose in the world: `pmodel::link.x`, `.y`, `.z` (m) and `.yaw` (rad), the
root link's frame (two-part paths, which no p-model sensor has). When the scene names obstacles
(a world's walls, boxes, cylinders), every contact of the robot with one is recorded in `touches`
(checked every CONTACT_PERIOD).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from ..diagnostics import CotwinError
from ..files import write_text
from .mjcf import TIMESTEP, load, pose_paths, site_name, to_mjcf
from .memo import StepMemo
from .sensing import SENSOR, flags_address
from .tree import KinematicTree, actuator_names, reading_path, servo_mode, servo_name


CONTACT_PERIOD = 0.005  # s between checks for contacts with the scene's obstacles
STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # time, positions, velocities, actuator states and history,
# solver warm start, controls, applied forces, mocap poses, equality activations, user and plugin data
_UNKNOWN = object()  # a value not looked up yet
DERIVED = ("sensordata", "xpos", "xmat")  # what cotwin reads between steps besides STATE, as mj_step left it


@dataclass(frozen=True)
class SimState:
    """A snapshot for what-if forks and rollbacks: MuJoCo's whole integration state (mjSTATE_INTEGRATION),
    from which a simulator of the same model continues bit for bit."""

    vector: np.ndarray
    scans: tuple = ()  # the ray sensors' last readings (they hold between scans)
    derived: tuple = ()  # (sensordata, xpos, xmat) as the last step left them (see PlatformSimulator.set_state)

    @property
    def time(self) -> float:
        return float(self.vector[0])


class RayScanner:
    """One ray sensor (every port of one sref): its beams, cast from its site at its update rate."""

    def __init__(self, sim: "PlatformSimulator", site: str, spec, ports: dict[str, str]):
        self.sim = sim
        self.site = sim.model.site(site).id
        self.spec = spec
        self.ports = ports  # mapping path -> ray quantity
        self.angles = spec.angles()
        self.directions = np.stack([np.cos(self.angles), np.sin(self.angles), np.zeros_like(self.angles)], axis=1)
        self.bearings = (np.degrees(self.angles) + 180.0) % 360.0 - 180.0
        self.bearings[self.bearings == -180.0] = 180.0
        self.period_steps = max(1, int(round(1.0 / (spec.update_rate * sim.timestep))))
        self._geomid = np.zeros(len(self.angles), dtype=np.int32)
        self._dist = np.zeros(len(self.angles))
        self._world = np.array([1, 0, 0, 0, 0, 0], dtype=np.uint8)  # geom group 0: the world, not the robot
        self.ranges = np.full(len(self.angles), np.inf)
        self.readings: dict[str, float] = {}

    def scan(self) -> None:
        model, data = self.sim.model, self.sim.data
        R = data.site_xmat[self.site].reshape(3, 3)
        vec = (self.directions @ R.T).ravel()
        mujoco.mj_multiRay(model, data, data.site_xpos[self.site].copy(), vec, self._world, 1, -1, self._geomid,
                           self._dist, None, len(self.angles), self.spec.range_max)
        ranges = self._dist.copy()
        ranges[(self._geomid < 0) | (ranges < self.spec.range_min) | (ranges > self.spec.range_max)] = np.inf
        self.ranges = ranges
        k = int(np.argmin(ranges))
        seen = bool(np.isfinite(ranges[k]))
        values = {"closest_range": float(ranges[k]) if seen else math.inf,
                  "closest_bearing": float(self.bearings[k]) if seen else math.nan, "range": float(ranges[0])}
        self.readings = {path: values[quantity] for path, quantity in self.ports.items()}


_PLAIN_INTEGRATORS = (int(mujoco.mjtIntegrator.mjINT_EULER), int(mujoco.mjtIntegrator.mjINT_IMPLICIT),
                      int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST))


class PlatformSimulator:
    def __init__(self, tree: KinematicTree, scene=None, timestep: float = TIMESTEP, mjcf: str | None = None,
                 base: str = "fixed", shared=None, prefix: str = ""):
        """`mjcf`: an MJCF text derived from `to_mjcf(tree, scene, timestep, visual=False, base=base)` to run
        instead of it (e.g. with a payload added by cotwin.pmodel.perturbation); names of joints, servos and
        sensors must be kept. `base`: "fixed" to the world or "free" (a mobile robot), as `to_mjcf`.
        `shared` (a cotwin.pmodel.shared.SharedWorld): this robot's view of a world of several robots, its
        names scoped by `prefix` there; the world steps, not the view."""
        self.tree = tree
        self.scene = scene
        self.base = base
        self.shared = shared
        self.prefix = prefix
        if shared is not None:
            self.xml, self.model, self.data = shared.xml, shared.model, shared.data
        else:
            self.xml = mjcf if mjcf is not None else to_mjcf(tree, scene, timestep, visual=False, base=base)
            self.model = load(self.xml, tree)  # a refusal names the p-model element
            self.data = mujoco.MjData(self.model)
        self.timestep = timestep
        self._inertial0 = (self.model.body_mass.copy(), self.model.body_inertia.copy())  # as compiled
        self.memo: StepMemo | None = None  # held steps remembered (cotwin.pmodel.memo: a sweep's forks turn it on)
        self._flag_word: ctypes.c_int | None | object = _UNKNOWN  # opt.disableflags where it lies (sensor_flags)
        self._state_size = mujoco.mj_stateSize(self.model, STATE)  # of get_state's vector
        self._joint_qpos = {j.name: self.model.joint(prefix + j.name).qposadr[0] for j in tree.actuated}
        self._joint_dof = {j.name: self.model.joint(prefix + j.name).dofadr[0] for j in tree.actuated}
        # every name an actuator answers to (cotwin.pmodel.tree.actuator_names, as every platform's) -> its control
        servo_of = {j.name: self.model.actuator(prefix + servo_name(j)).id for j in tree.actuated}
        names = actuator_names(tree)
        self._actuator: dict[str, int] = {name: servo_of[j.name] for name, j in names.items()}
        self._actuator_joint = {name: j.name for name, j in names.items()}
        self._sensors: dict[str, tuple[int, int]] = {}
        for sensor in tree.sensors:
            name = reading_path(tree.name, sensor)
            try:
                s = self.model.sensor(prefix + name)
            except KeyError:
                continue
            self._sensors[name] = (s.adr[0] + min(sensor.component, s.dim[0] - 1), 1)
        self._ctrl_range = self.model.actuator_ctrlrange.copy()
        # per actuator name: its control index and the range its targets are clipped to
        self._servos: dict[str, tuple[int, float, float]] = {}
        for name, index in self._actuator.items():
            low, high = (float(x) for x in self._ctrl_range[index])
            self._servos[name] = (index, low, high) if high > low else (index, -math.inf, math.inf)
        # arrays read in one go: joint positions and velocities, sensor values
        self._joints = list(self._joint_qpos)
        self._qpos_index = np.array([self._joint_qpos[j] for j in self._joints], dtype=int)
        self._qvel_index = np.array([self._joint_dof[j] for j in self._joints], dtype=int)
        self._sensor_paths = list(self._sensors)
        self._sensor_index = np.array([adr for adr, _ in self._sensors.values()], dtype=int)
        # views on MuJoCo's buffers, fetched once (each attribute access makes a new view)
        self._qpos, self._qvel = self.data.qpos, self.data.qvel
        self._ctrl, self._sensordata = self.data.ctrl, self.data.sensordata
        self._holds_position = {j.name for j in tree.actuated if servo_mode(j) == "position"}
        # the initial posture: within each joint's limits (TJoint.start), set in qpos by `reset`; never in
        # model.qpos0, which is MuJoCo's reference configuration (a hinge turns by qpos - qpos0): a joint whose
        # limits exclude 0 would read its start while its link stood at 0, every angle off by that much
        self._start = {j.name: float(j.start) for j in tree.actuated if j.name in self._joint_qpos}
        # ray sensors, by placed sensor; the free base's pose
        groups: dict[str, tuple] = {}
        for sensor in tree.sensors:
            if sensor.ray is not None:
                site = site_name(tree, sensor)
                path = reading_path(tree.name, sensor)
                groups.setdefault(site, (sensor.ray, {}))[1][path] = sensor.quantity
        self.scanners = [RayScanner(self, prefix + site, spec, ports) for site, (spec, ports) in groups.items()]
        self._root = self.model.body(prefix + tree.root.name).id
        self._pose_paths = pose_paths(tree) if base == "free" else []
        # contacts with the scene's obstacles
        names = list(scene.obstacle_names) if scene is not None and shared is None else []  # a world's: its own
        self._obstacles = {self.model.geom(n).id for n in names}
        robot_bodies = {self.model.body(prefix + l.name).id for l in tree.links}
        self._robot_geoms = {g for g in range(self.model.ngeom) if self.model.geom_bodyid[g] in robot_bodies}
        self._contact_steps = max(1, int(round(CONTACT_PERIOD / timestep)))
        self.touches: list[tuple[float, str, str]] = []  # (time, robot geom, obstacle) when a contact began
        self._touching: set[tuple[int, int]] = set()
        self.contact_watch: tuple[np.ndarray, float] | None = None  # see watch_contacts
        self.reset()

    # ---- names ----
    @property
    def sensor_names(self) -> list[str]:
        return list(self._sensors)

    @property
    def joint_names(self) -> list[str]:
        return list(self._joint_qpos)

    def actuators(self) -> dict[str, str]:
        """Every name an actuator answers to (cotwin.pmodel.tree.actuator_names: joint, servo, the command_path
        `pmodel::link::joint::aref.port`) -> joint."""
        return dict(self._actuator_joint)

    def saturated(self) -> list[tuple[str, float]]:
        """The joints whose actuator pushes at its force limit now (the URDF's effort), each with that limit: a
        servo too weak to hold or reach its goal, why a move can never complete."""
        out = []
        for name in self._joint_qpos:
            index = self._actuator[name]
            if not self.model.actuator_forcelimited[index]:
                continue
            limit = float(self.model.actuator_forcerange[index][1])
            if limit > 0 and abs(float(self.data.actuator_force[index])) >= limit * (1.0 - 1e-6):
                out.append((name, limit))
        return out

    # ---- the API ----
    def reset(self, q: dict[str, float] | None = None) -> None:
        """Back to the model's initial state (joints at q, default their start: 0 or the limit nearest it),
        position servos holding that position, speed and effort commands at 0. A view of a shared world resets
        its own joints only."""
        if self.shared is None:
            mujoco.mj_resetData(self.model, self.data)
        else:
            for name, adr in self._joint_qpos.items():
                self.data.qpos[adr] = self.model.qpos0[adr]
                self.data.qvel[self._joint_dof[name]] = 0.0
        for name, value in self._start.items():
            self.data.qpos[self._joint_qpos[name]] = value
        for name, value in (q or {}).items():
            self.data.qpos[self._joint_adr(name)] = value
        for name, adr in self._joint_qpos.items():
            self.data.ctrl[self._actuator[name]] = self.data.qpos[adr] if name in self._holds_position else 0.0
        mujoco.mj_forward(self.model, self.data)
        self._steps = 0
        self.touches = []
        self._touching = set()
        for scanner in self.scanners:
            scanner.scan()

    def _joint_adr(self, name: str) -> int:
        if name not in self._joint_qpos:
            raise CotwinError(f"unknown joint '{name}' (joints: {', '.join(self._joint_qpos)})")
        return self._joint_qpos[name]

    @property
    def plain_stepping(self) -> bool:
        """Whether `step(n)` is n of MuJoCo's mj_step and nothing between them (no ray sensor scans, no
        obstacle contacts checked, not a view of a shared world), with an integrator that advances time by one
        timestep per step: then a caller may make the steps itself (cotwin.mapping.native) and count them with `stepped`."""
        return self.shared is None and not self.scanners and not self._obstacles and \
            self.model.opt.integrator in _PLAIN_INTEGRATORS

    @property
    def obstacles(self) -> frozenset[int]:
        """The geoms whose contacts with the robot are checked between physics steps."""
        return frozenset(self._obstacles)

    def watch_contacts(self, geoms: list[int] | None, depth: float = 0.0) -> None:
        """Say that someone checks, after each communication step, the contacts of these geoms with the others
        deeper than `depth` (m): a what-if's record of the robot's contacts. A caller making many steps at
        once (cotwin.mapping.cstep) then stops after a step that has one. None: nobody checks."""
        if geoms is None:
            self.contact_watch = None
            return
        mask = np.zeros(max(1, self.model.ngeom), dtype=np.uint8)
        mask[list(geoms)] = 1
        self.contact_watch = (mask, float(depth))

    def stepped(self, n: int, check: bool = True) -> None:
        """Count n physics steps a caller made with mj_step itself, and check the state as `step` does (unless
        the caller checked it itself: `check` False)."""
        self._steps += n
        if check:
            self._check()

    def check(self) -> None:
        """CotwinError if the state is no longer finite (the physics blew up), as `step` says it."""
        self._check()

    def sensor_addresses(self) -> dict[str, int]:
        """Every p-model sensor port by its mapping path (as `read_sensors` keys it): its index in MuJoCo's
        sensordata (`read_sensors` reads that element; a ray scanner's or a free base's readings are not there)."""
        return {path: int(adr) for path, (adr, _) in self._sensors.items()}

    def joint_address(self, joint: str, kind: str = "position") -> int | None:
        """Where an actuated joint's position (in qpos) or velocity (in qvel) is, as `joint_positions` and
        `joint_velocities` read it; None for a joint the simulator does not have."""
        table = self._joint_qpos if kind == "position" else self._joint_dof
        return int(table[joint]) if joint in table else None

    def servo_slots(self, names) -> list[tuple[int, float, float]] | None:
        """Per actuator name, its control index and the range its targets are clipped to (as
        `write_actuators` clips them), for a caller writing many set-points of the same actuators into
        `controls`; None if a name is not an actuator (then `write_actuators` says so)."""
        servos = self._servos
        return [servos[n] for n in names] if all(n in servos for n in names) else None

    @property
    def controls(self) -> np.ndarray:
        """MuJoCo's control vector (data.ctrl), written by `write_actuators`."""
        return self._ctrl

    def write_actuators(self, targets: dict[str, float]) -> None:
        """Set actuator commands (rad or m for position servos, rad/s or m/s for velocity servos, N m or N
        for motors). Unknown names and non-finite values are errors; position targets outside a joint's
        limits are clipped to them."""
        ctrl, servos = self._ctrl, self._servos
        for name, value in targets.items():
            servo = servos.get(name)
            if servo is None:
                raise CotwinError(f"unknown actuator '{name}' (use a joint or servo name of p-model {self.tree.name})")
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise CotwinError(f"actuator '{name}': target {value!r} is not a finite number")
            index, low, high = servo
            value = float(value)
            ctrl[index] = low if value < low else high if value > high else value

    def read_sensors(self) -> dict[str, float]:
        """Every p-model sensor port, keyed by its mapping path (and a free base's pose, see the module doc)."""
        out = dict(zip(self._sensor_paths, self._sensordata[self._sensor_index].tolist()))
        for scanner in self.scanners:
            out.update(scanner.readings)
        if self._pose_paths:
            out.update(zip(self._pose_paths, self.base_pose()))
        return out

    def base_pose(self) -> tuple[float, float, float, float]:
        """The root link's x, y, z (m) and yaw (rad) in the world."""
        x, y, z = self.data.xpos[self._root]
        R = self.data.xmat[self._root]
        return float(x), float(y), float(z), float(math.atan2(R[3], R[0]))

    def scan_ranges(self) -> list[np.ndarray]:
        """Every ray sensor's last scan (m per beam, inf where nothing returned)."""
        return [s.ranges.copy() for s in self.scanners]

    def joint_positions(self) -> dict[str, float]:
        return dict(zip(self._joints, self._qpos[self._qpos_index].tolist()))

    def joint_velocities(self) -> dict[str, float]:
        return dict(zip(self._joints, self._qvel[self._qvel_index].tolist()))

    def set_joint_state(self, positions: dict[str, float], velocities: dict[str, float] | None = None) -> None:
        """Put these joints at these positions and velocities (a live twin's resync to its PT's measured
        state), the rest of the state kept, and recompute what is read between steps (mj_forward)."""
        for name, value in positions.items():
            self._qpos[self._joint_adr(name)] = float(value)
        for name, value in (velocities or {}).items():
            self._joint_adr(name)
            self._qvel[self._joint_dof[name]] = float(value)
        self._check()
        mujoco.mj_forward(self.model, self.data)

    def changed_bodies(self) -> dict[str, list[float]]:
        """Bodies whose mass or inertia was changed since the model was compiled (an estimated payload given to
        a DT), by name: [mass, ixx, iyy, izz]; a saved state carries them, as the model does not."""
        mass0, inertia0 = self._inertial0
        model = self.model
        changed = np.flatnonzero((model.body_mass != mass0) | np.any(model.body_inertia != inertia0, axis=1))
        return {model.body(int(b)).name: [float(model.body_mass[b]), *map(float, model.body_inertia[b])] for b in changed}

    def set_bodies(self, bodies: dict) -> None:
        """Give bodies a mass and principal inertia ([mass, ixx, iyy, izz] by name, as `changed_bodies` says),
        each checked: a body of this model, four finite numbers >= 0."""
        checked = {}
        for name, values in bodies.items():
            try:
                body = self.model.body(name).id if isinstance(name, str) else None
            except KeyError:
                body = None
            if body is None:
                raise CotwinError(f"the saved state changes a body {str(name)[:60]!r} that this model does not have")
            if not (isinstance(values, (list, tuple)) and len(values) == 4 and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0 for v in values)):
                raise CotwinError(f"the saved state's mass and inertia of body {name!r} are not 4 finite numbers >= 0")
            checked[body] = values
        for body, (mass, *inertia) in checked.items():
            if self.memo is not None and (self.model.body_mass[body] != mass or
                                          (self.model.body_inertia[body] != inertia).any()):
                self.memo.clear()  # its steps were of the model before
            self.model.body_mass[body] = mass
            self.model.body_inertia[body] = inertia

    def sensor_flags(self) -> int | None:
        """The address of the model's opt.disableflags for native loops that compute the sensors in a stretch's
        last step only (cotwin.pmodel.sensing), or None where every step computes them: found once, and None
        while the user has turned sensors off on the model (asked before each stretch: they stay off)."""
        if self._flag_word is _UNKNOWN:
            address = flags_address(self.model) if self.shared is None else None
            self._flag_word = ctypes.c_int.from_address(address) if address is not None else None
        word = self._flag_word
        return None if word is None or word.value & SENSOR else ctypes.addressof(word)  # the field, read in place

    def remember_held_steps(self) -> StepMemo | None:
        """Turn on the memo of held steps (cotwin.pmodel.memo) for the native loop, on a simulator of its own
        world; None where it cannot be (a view of a shared world, MuJoCo's library not found)."""
        if self.memo is None and self.shared is None:
            try:
                self.memo = StepMemo(self.model)
            except ValueError:
                return None
        return self.memo

    def _mj_steps(self, n: int) -> None:
        """n of MuJoCo's steps, the sensors computed in the last only (cotwin.pmodel.sensing), as the native loops
        make them: whoever reads them reads them after the call."""
        opt = self.model.opt
        if n > 1 and self.sensor_flags() is not None:
            opt.disableflags |= SENSOR
            try:
                mujoco.mj_step(self.model, self.data, n - 1)
            finally:
                opt.disableflags &= ~SENSOR
            n = 1
        mujoco.mj_step(self.model, self.data, n)

    def steps_for(self, dt: float) -> int:
        """The number of physics steps in dt seconds (dt rounded to whole steps)."""
        if not (math.isfinite(dt) and dt >= 0):
            raise CotwinError(f"cannot advance by {dt!r} s")
        return int(round(dt / self.timestep))

    def advance(self, dt: float) -> float:
        """Simulate dt seconds in physics steps of `timestep`; returns the simulation time."""
        return self.step(self.steps_for(dt))

    def step(self, steps: int) -> float:
        """Simulate `steps` physics steps (in one call into MuJoCo, split only where a ray sensor scans or
        obstacle contacts are checked); returns the simulation time. A view of a shared world does not step
        it: the world steps, once for all its robots."""
        if self.shared is not None:
            raise CotwinError(f"robot {self.tree.name} shares its world with other robots: the world steps, not one robot")
        if not self.scanners and not self._obstacles:
            if steps > 0:
                self._mj_steps(steps)
                self._steps += steps
                self._check()
            return self.data.time
        while steps > 0:
            n = steps
            for period in [s.period_steps for s in self.scanners] + ([self._contact_steps] if self._obstacles else []):
                n = min(n, period - self._steps % period)
            self._mj_steps(n)
            self._steps += n
            steps -= n
            self._check()
            if self._obstacles and self._steps % self._contact_steps == 0:
                self._contacts()
            for scanner in self.scanners:
                if self._steps % scanner.period_steps == 0:
                    scanner.scan()
        return self.data.time

    def _check(self) -> None:
        q = self._qpos
        if not math.isfinite(q.dot(q)):  # a non-finite (or huge) position: the physics blew up
            raise CotwinError(f"the physics became unstable at t = {self.data.time:.3f} s (non-finite state)")

    def _contacts(self) -> None:
        """Record the contacts of the robot with an obstacle that began since the last check."""
        now = set()
        contact = self.data.contact
        for k in range(self.data.ncon):
            a, b = int(contact.geom1[k]), int(contact.geom2[k])
            if a in self._obstacles and b in self._robot_geoms:
                a, b = b, a
            if a in self._robot_geoms and b in self._obstacles:
                now.add((a, b))
        for a, b in sorted(now - self._touching):
            self.touches.append((float(self.data.time), self.model.geom(a).name, self.model.geom(b).name))
        self._touching = now

    @property
    def time(self) -> float:
        return float(self.data.time)

    def get_state(self) -> SimState:
        vector = np.empty(self._state_size)
        mujoco.mj_getState(self.model, self.data, vector, STATE)
        return SimState(vector, tuple((dict(s.readings), s.ranges.copy()) for s in self.scanners),
                        tuple(getattr(self.data, name).copy() for name in DERIVED))

    def set_state(self, state: SimState) -> None:
        """Continue from `state`. What cotwin reads between steps (sensors, body poses) is as the saved
        simulator's last step left it, computed before that step's integration (mj_step), not as mj_forward
        would recompute it at the restored positions: a fork then reads what the original read, bit for bit;
        a state without them gets mj_forward's."""
        size = self._state_size
        vector = np.asarray(state.vector, dtype=np.float64)
        if vector.shape != (size,):
            raise CotwinError(f"the simulator state has {vector.size} numbers, this model's has {size}: "
                              "it is a state of another model")
        # (one pass: a NaN fails the comparison, an infinity the bound)
        if not abs(float(vector[0])) < 1e12 or not np.abs(vector[1:]).max(initial=0.0) <= mujoco.mjMAXVAL:
            raise CotwinError(f"the simulator state holds numbers that are not finite, beyond MuJoCo's {mujoco.mjMAXVAL:g} "
                              "(where it would reset the simulation) or a time beyond 1e12 s")
        scans = self._checked_scans(state.scans)
        derived = self._checked_derived(state.derived)
        mujoco.mj_setState(self.model, self.data, vector, STATE)
        mujoco.mj_forward(self.model, self.data)
        for name, values in zip(DERIVED, derived):
            getattr(self.data, name)[:] = values
        self._steps = int(round(self.data.time / self.timestep))
        self._touching = set()
        if scans is not None:
            for scanner, (readings, ranges) in zip(self.scanners, scans):
                scanner.readings, scanner.ranges = readings, ranges
        else:  # a state without scans (saved before ray sensors were read): scan where the robot is
            for scanner in self.scanners:
                scanner.scan()

    def _checked_derived(self, derived) -> tuple:
        """The saved sensors and body poses if they fit this model (arrays of its sizes, finite), else ()
        for a state without them; CotwinError for any other shape."""
        if not derived:
            return ()
        if len(derived) != len(DERIVED):
            raise CotwinError(f"the simulator state's derived quantities are not {', '.join(DERIVED)}")
        for name, values in zip(DERIVED, derived):
            live = getattr(self.data, name)
            if not isinstance(values, np.ndarray) or values.shape != live.shape or values.dtype != np.float64 or \
                    not np.all(np.isfinite(values)):
                raise CotwinError(f"the simulator state's {name} is not {live.size} finite numbers of this model")
        return tuple(derived)

    def _checked_scans(self, scans) -> list | None:
        """The ray sensors' saved readings, each (readings by path, ranges of every beam) as the scanner
        holds them, or None for a state without them; CotwinError for any other shape."""
        if not scans or len(scans) != len(self.scanners):
            return None
        out = []
        for k, (scanner, scan) in enumerate(zip(self.scanners, scans)):
            readings, ranges = scan if isinstance(scan, (tuple, list)) and len(scan) == 2 else (None, None)
            if not isinstance(readings, dict) or set(readings) != set(scanner.ports) or \
                    not all(isinstance(v, float) for v in readings.values()):
                raise CotwinError(f"the simulator state's scan {k + 1} does not hold the readings {', '.join(scanner.ports)}")
            if not isinstance(ranges, np.ndarray) or ranges.shape != scanner.ranges.shape or ranges.dtype != np.float64:
                raise CotwinError(f"the simulator state's scan {k + 1} does not hold {len(scanner.angles)} ranges")
            out.append((dict(readings), ranges.copy()))
        return out

    def body_pose(self, name: str) -> np.ndarray:
        try:
            body = self.model.body(self.prefix + name)
        except KeyError:
            raise CotwinError(f"no body '{name}' in the simulation") from None
        T = np.eye(4)
        T[:3, :3] = self.data.xmat[body.id].reshape(3, 3)
        T[:3, 3] = self.data.xpos[body.id]
        return T

    def write_mjcf(self, path: str | Path) -> Path:
        return write_text(path, self.xml)
