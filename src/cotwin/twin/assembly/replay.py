"""Replaying a physical twin's recorded run on the digital twin, and how far apart they are.

The DT here is its platform mapping over the simulated platform (cotwin.mapping: the mapping model,
its IK registry, a SimulatedEndpoint with a motion profile, MuJoCo). A command of the scenario turns
into the operation calls the d-model makes for it from its idle state (found by running the d-model's
interpreter for one command); a replay executes those calls at given times (a recorded run's motion
onsets), from the recorded initial posture, and samples the DT's joints at the log's sample times.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .scenario import Command
from ...diagnostics import CotwinError
from ...dmodel.interpreter import Interpreter
from ...dmodel.program import Program, assemble
from ...mapping.endpoint import SimulatedEndpoint
from ...mapping.motion import MotionProfile
from ...mapping.rtde import ArmLog, Motion
from ...mapping.runtime import Mapping
from ...pmodel.cell import CellGeometry
from ...pmodel.scenes import Scene
from ...pmodel.simulator import PlatformSimulator
from ...pmodel.tree import KinematicTree

SETTLE_CYCLES = 4  # d-model cycles allowed for a command to become an operation call


@dataclass(frozen=True)
class OperationCall:
    operation: str
    args: dict


def operation_calls(program: Program, command: Command) -> list[OperationCall]:
    """The platform operations the d-model calls for a command, from its initial (idle) state."""
    values = dict(command.values)
    raised = command.raises({event.name for event in program.inputs})  # as the controller sends it
    inputs = {}
    for event in program.inputs:
        if event.name in raised:
            inputs[event.name] = assemble(event.value_ports, values.get) if event.value_ports else None
    interpreter = Interpreter(program)
    interpreter.step({})  # enter the initial state
    params = {op.name: [p for p, _ in op.params] for op in program.operations}
    calls: list[OperationCall] = []
    for cycle in range(SETTLE_CYCLES):
        for out in interpreter.step(inputs if cycle == 0 else {}):
            if out.kind == "operation":
                calls.append(OperationCall(out.name, dict(zip(params[out.name], out.args))))
        if calls:
            break
    return calls


@dataclass
class DigitalTwin:
    """The parts of a DT that a replay runs: checked models, the p-model's tree, the cell (its
    geometry is replaced by the one under test)."""

    project: object  # the checked RoboSim project
    tree: KinematicTree
    scene: Scene | None  # the cell (cotwin.pmodel.scenes), or None: no scene
    profile: MotionProfile | None = None  # the DT's motion profile (None: the endpoint's default)
    geometry: CellGeometry | None = None  # the DT's cell geometry (None: the scene's)
    mapping_name: str | None = None

    def arm(self, geometry: CellGeometry | None = None) -> list[str]:
        """The arm's joints, from the base to the tool the cell geometry names (`geometry`, else the DT's, else the
        scene's: its [tool] link, as the mapping's IK takes it; else the default tool), in kinematic order."""
        from ...pmodel import ik

        geometry = geometry or self.geometry or (self.scene.geometry if self.scene is not None else None) or CellGeometry()
        return ik.arm_joints(self.tree, geometry.find_tool(self.tree))

    def mapping(self, geometry: CellGeometry | None = None, profile: MotionProfile | None = None,
                timestep: float | None = None) -> Mapping:
        """A fresh mapping runtime over a fresh simulator, the cell at `geometry`, moving by `profile`
        (each the DT's own when not given), its physics at `timestep` (s; cotwin's 1 ms when not given)."""
        geometry = geometry or self.geometry
        scene = self.scene
        if scene is not None and geometry is not None:
            scene = scene.with_geometry(geometry)
        simulator = PlatformSimulator(self.tree, scene) if timestep is None else PlatformSimulator(self.tree, scene, timestep)
        endpoint = SimulatedEndpoint(simulator, profile or self.profile, geometry)
        return Mapping(self.project, endpoint, self.mapping_name)


def commanded_points(twin: DigitalTwin, calls: list[list[OperationCall]]) -> list[list[tuple[float, float, float]]]:
    """Per command, the grid points its operations ask of the mapping's inverse_kinematics."""
    mapping = twin.mapping()
    mapping.start_mapping()
    out = []
    for group in calls:
        before = len(mapping.registry.requests)
        for call in group:
            mapping.execute_operation(call.operation, call.args)
        out.append(list(mapping.registry.requests[before:]))
    mapping.stop_mapping()
    return out


def replay(twin: DigitalTwin, schedule: list[tuple[float, OperationCall]], times: np.ndarray, start_q: np.ndarray,
           geometry: CellGeometry | None = None, profile: MotionProfile | None = None,
           timestep: float | None = None) -> np.ndarray:
    """The DT's arm joints at `times` (s), started at posture `start_q` (arm joints) at t = 0, with the
    operation calls of `schedule` executed at their times (to the simulator's step, `timestep`)."""
    mapping = twin.mapping(geometry, profile, timestep)
    arm = mapping.registry.arm
    endpoint = mapping.endpoint
    endpoint.place(dict(zip(arm, map(float, start_q))))
    mapping.start_mapping()
    pending = sorted(schedule, key=lambda item: item[0])
    out = np.empty((len(times), len(arm)))
    for k, t in enumerate(times):
        while pending and pending[0][0] <= t:
            when, call = pending.pop(0)
            mapping.step(max(when - endpoint.time, 0.0))
            mapping.execute_operation(call.operation, call.args)
        mapping.step(max(t - endpoint.time, 0.0))
        q = endpoint.joint_positions()
        out[k] = [q[j] for j in arm]
    mapping.stop_mapping()
    return out


@dataclass
class JointErrors:
    """Per joint: RMSE while the PT moves, the largest error while it rests after a move, RMSE overall."""

    joints: list[str]
    motion: np.ndarray  # rad
    settled: np.ndarray  # rad
    overall: np.ndarray  # rad
    rows: dict = field(default_factory=dict)  # how many rows each figure covers

    def lines(self, title: str) -> list[str]:
        width = max(len(j) for j in self.joints)
        out = [f"{title}", f"  {'joint':<{width}}  {'RMSE in motion':>16}  {'settled error':>14}  {'RMSE overall':>14}"]
        for j, m, s, o in zip(self.joints, self.motion, self.settled, self.overall):
            out.append(f"  {j:<{width}}  RMSE {m:10.4f} rad  {s:10.4f} rad  RMSE {o:8.4f} rad")
        return out


def moving_rows(log: ArmLog, rest_speed: float = 0.01) -> np.ndarray:
    """Rows where the PT moves: its set-point or its measured joints."""
    return log.moving(rest_speed) | (np.abs(log.qd).max(axis=1) > rest_speed)


def joint_errors(log: ArmLog, q_dt: np.ndarray, joints: list[str], motions: list[Motion] | None = None) -> JointErrors:
    """How far the DT's joints (rows of the log) are from the PT's."""
    diff = q_dt - log.q
    moving = moving_rows(log)
    motions = motions if motions is not None else log.motions()
    t = log.t
    rest = np.zeros(len(t), bool)
    for m, following in zip(motions, motions[1:] + [None]):
        until = following.onset if following else t[-1] + 1.0
        rest |= (t >= m.settled) & (t < until) & ~moving
    if not moving.any():
        raise CotwinError(f"{log.path}: the PT never moves in this log: nothing to compare")
    settled = np.abs(diff[rest]).max(axis=0) if rest.any() else np.full(diff.shape[1], np.nan)
    return JointErrors(joints, np.sqrt(np.mean(diff[moving] ** 2, axis=0)), settled, np.sqrt(np.mean(diff ** 2, axis=0)),
                       {"motion": int(moving.sum()), "settled": int(rest.sum()), "overall": len(t)})
