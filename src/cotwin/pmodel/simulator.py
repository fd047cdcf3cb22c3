"""The embedded platform simulator: MuJoCo running the MJCF generated from the p-model.

Names come from the p-model: sensors are read as `pmodel::link::sref.port` (the mapping's paths),
actuators are written by joint name, servo (aref) name or `pmodel::link::joint::aref.port`, the port
being the actuator's command input (`dangle` of a ServoMotor, `ControlIn` of a ControlledMotor): an
angle for position servos, a speed for velocity servos, an effort for motors.
The physics step (1 ms by default) is sub-stepped inside `advance(dt)`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from ..diagnostics import CotwinError
from .mjcf import TIMESTEP, sensor_name, servo_mode, servo_name, to_mjcf
from .tree import KinematicTree


STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # time, positions, velocities, actuator states and history,
# solver warm start, controls, applied forces, mocap poses, equality activations, user and plugin data


@dataclass(frozen=True)
class SimState:
    """A snapshot for what-if forks and rollbacks: MuJoCo's whole integration state (mjSTATE_INTEGRATION),
    from which a simulator of the same model continues bit for bit."""

    vector: np.ndarray

    @property
    def time(self) -> float:
        return float(self.vector[0])


class PlatformSimulator:
    def __init__(self, tree: KinematicTree, scene=None, timestep: float = TIMESTEP, mjcf: str | None = None,
                 base: str = "fixed"):
        """`mjcf`: an MJCF text derived from `to_mjcf(tree, scene, timestep, visual=False, base=base)` to run
        instead of it (e.g. with a payload added by cotwin.pmodel.perturbation); names of joints, servos and
        sensors must be kept. `base`: "fixed" to the world or "free" (a mobile robot), as `to_mjcf`."""
        self.tree = tree
        self.scene = scene
        self.xml = mjcf if mjcf is not None else to_mjcf(tree, scene, timestep, visual=False, base=base)
        try:
            self.model = mujoco.MjModel.from_xml_string(self.xml)
        except ValueError as err:
            raise CotwinError(f"MuJoCo rejected the generated model: {err}") from None
        self.data = mujoco.MjData(self.model)
        self.timestep = timestep
        self._joint_qpos = {j.name: self.model.joint(j.name).qposadr[0] for j in tree.actuated}
        self._joint_dof = {j.name: self.model.joint(j.name).dofadr[0] for j in tree.actuated}
        self._actuator: dict[str, int] = {}
        for j in tree.actuated:
            index = self.model.actuator(servo_name(j)).id
            self._actuator[j.name] = index
            self._actuator[servo_name(j)] = index
            for servo in j.servos:
                self._actuator[f"{tree.name}::{j.source_link}::{j.source}::{servo.name}.{servo.port}"] = index
        self._sensors: dict[str, tuple[int, int]] = {}
        for sensor in tree.sensors:
            name = sensor_name(tree.name, sensor.link, sensor.name, sensor.port, sensor.via)
            try:
                s = self.model.sensor(name)
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
        self.reset()

    # ---- names ----
    @property
    def sensor_names(self) -> list[str]:
        return list(self._sensors)

    @property
    def joint_names(self) -> list[str]:
        return list(self._joint_qpos)

    def actuators(self) -> dict[str, str]:
        """Every name an actuator answers to (joint, servo, `pmodel::link::joint::aref.dangle`) -> joint."""
        joint_of = {self._actuator[j]: j for j in self._joint_qpos}
        return {name: joint_of[index] for name, index in self._actuator.items()}

    # ---- the API ----
    def reset(self, q: dict[str, float] | None = None) -> None:
        """Back to the model's initial state (joints at q, default 0), position servos holding that
        position, speed and effort commands at 0."""
        mujoco.mj_resetData(self.model, self.data)
        for name, value in (q or {}).items():
            self.data.qpos[self._joint_adr(name)] = value
        for name, adr in self._joint_qpos.items():
            self.data.ctrl[self._actuator[name]] = self.data.qpos[adr] if name in self._holds_position else 0.0
        mujoco.mj_forward(self.model, self.data)

    def _joint_adr(self, name: str) -> int:
        if name not in self._joint_qpos:
            raise CotwinError(f"unknown joint '{name}' (joints: {', '.join(self._joint_qpos)})")
        return self._joint_qpos[name]

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
        """Every p-model sensor port, keyed by its mapping path."""
        return dict(zip(self._sensor_paths, self._sensordata[self._sensor_index].tolist()))

    def joint_positions(self) -> dict[str, float]:
        return dict(zip(self._joints, self._qpos[self._qpos_index].tolist()))

    def joint_velocities(self) -> dict[str, float]:
        return dict(zip(self._joints, self._qvel[self._qvel_index].tolist()))

    def steps_for(self, dt: float) -> int:
        """The number of physics steps in dt seconds (dt rounded to whole steps)."""
        if not (math.isfinite(dt) and dt >= 0):
            raise CotwinError(f"cannot advance by {dt!r} s")
        return int(round(dt / self.timestep))

    def advance(self, dt: float) -> float:
        """Simulate dt seconds in physics steps of `timestep`; returns the simulation time."""
        return self.step(self.steps_for(dt))

    def step(self, steps: int) -> float:
        """Simulate `steps` physics steps (in one call into MuJoCo); returns the simulation time."""
        if steps > 0:
            mujoco.mj_step(self.model, self.data, steps)
            q = self._qpos
            if not math.isfinite(q.dot(q)):  # a non-finite (or huge) position: the physics blew up
                raise CotwinError(f"the physics became unstable at t = {self.data.time:.3f} s (non-finite state)")
        return self.data.time

    @property
    def time(self) -> float:
        return float(self.data.time)

    def get_state(self) -> SimState:
        vector = np.empty(mujoco.mj_stateSize(self.model, STATE))
        mujoco.mj_getState(self.model, self.data, vector, STATE)
        return SimState(vector)

    def set_state(self, state: SimState) -> None:
        """Continue from `state` (derived quantities such as sensors are recomputed at once)."""
        size = mujoco.mj_stateSize(self.model, STATE)
        vector = np.asarray(state.vector, dtype=np.float64)
        if vector.shape != (size,):
            raise CotwinError(f"the simulator state has {vector.size} numbers, this model's has {size}: "
                              "it is a state of another model")
        mujoco.mj_setState(self.model, self.data, vector, STATE)
        mujoco.mj_forward(self.model, self.data)

    def body_pose(self, name: str) -> np.ndarray:
        try:
            body = self.model.body(name)
        except KeyError:
            raise CotwinError(f"no body '{name}' in the simulation") from None
        T = np.eye(4)
        T[:3, :3] = self.data.xmat[body.id].reshape(3, 3)
        T[:3, 3] = self.data.xpos[body.id]
        return T

    def write_mjcf(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(self.xml)
        return path
