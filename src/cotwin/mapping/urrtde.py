"""A real Universal Robots arm over RTDE as the physical twin's endpoint (the `rtde` extra: ur-rtde).

One field mapping serves the live robot and its recorded logs (cotwin.mapping.rtde, the replay
endpoint): RTDE's `actual_q_k` / `actual_qd_k` (k = 0..5, the controller's convention) become the
p-model's arm joints with the project's robot profile (cotwin.mapping.profile; identity without one);
goals go the other way, their actuators named as the simulator names them (cotwin.pmodel.tree.actuator_names).
A command is a synchronised joint move (URScript's movej through ur-rtde's moveJ, with the project's speed and
acceleration), asynchronous so the twin keeps stepping: the robot takes joint positions only, so an actuator
that sets a speed or an effort is refused by name, at its p-model joint. `advance(dt)` waits until dt of wall
time has passed since the last step, since a real robot runs on its own clock.
"""

from __future__ import annotations

import math
import time as wallclock
from typing import Mapping

from ..diagnostics import CotwinError, Finding, Severity
from ..pmodel.tree import actuator_names, servo_mode
from .platform import Endpoint, joint_readings
from .profile import IDENTITY, Convention


def fields_to_state(fields: Mapping[str, float], arm: list[str],
                    convention: Convention = IDENTITY) -> tuple[dict[str, float], dict[str, float]]:
    """Arm joint positions and velocities (p-model names and convention) from RTDE output fields named as
    in a log's header (`actual_q_0`.., `actual_qd_0`..)."""
    try:
        q = [float(fields[f"actual_q_{k}"]) for k in range(len(arm))]
        qd = [float(fields[f"actual_qd_{k}"]) for k in range(len(arm))]
    except KeyError as err:
        raise CotwinError(f"RTDE data without the field {err.args[0]}") from None
    if not all(math.isfinite(v) for v in q + qd):
        raise CotwinError("RTDE data with a non-finite joint value")
    return dict(zip(arm, map(float, convention.to_model(q)))), dict(zip(arm, qd))


COMMANDED = {"velocity": "speed", "effort": "effort"}  # what an actuator's command sets, as a message says it


def undrivable(actuator: str, joint: str, mode: str) -> str:
    """Why a UR over RTDE refuses an actuator that sets its joint's speed or effort (it takes positions only)."""
    what = COMMANDED.get(mode, mode)
    return (f"a UR robot over RTDE cannot take {what} commands: actuator '{actuator}' sets joint {joint}'s {what}, "
            f"and the RTDE endpoint moves the arm to joint positions (moveJ); drive {joint} by a position servo "
            f"(a ServoMotor's dangle) in the p-model, or run this mapping on a simulated platform")


class RTDEEndpoint(Endpoint):
    """The platform endpoint of a UR robot at `host` (needs `pip install cotwin[rtde]`)."""

    def __init__(self, tree, host: str, speed: float = 1.05, acceleration: float = 1.4,
                 convention: Convention = IDENTITY, arm: list[str] | None = None):
        """`arm`: the joints the robot reports, from the base to the tool (the project's: TwinModels.arm; None:
        up to cotwin.pmodel.ik.find_tool's default tool)."""
        try:
            import rtde_control
            import rtde_receive
        except ImportError:
            raise CotwinError("the RTDE endpoint needs ur-rtde: pip install 'cotwin[rtde]'") from None
        from ..pmodel import ik

        self.tree = tree
        self.arm = list(arm) if arm is not None else ik.arm_joints(tree, ik.find_tool(tree))
        self.speed, self.acceleration, self.convention = speed, acceleration, convention
        host = host.removeprefix("rtde://").split(":")[0]
        try:
            self.receive = rtde_receive.RTDEReceiveInterface(host)
            self.control = rtde_control.RTDEControlInterface(host)
        except RuntimeError as err:
            raise CotwinError(f"cannot reach the robot's RTDE interface at {host}: {err}") from None
        self.time = 0.0
        self._actuators = actuator_names(tree)
        self._goal = None
        self._last = wallclock.monotonic()

    def _fields(self) -> dict[str, float]:
        q, qd = self.receive.getActualQ(), self.receive.getActualQd()
        return {**{f"actual_q_{k}": v for k, v in enumerate(q)}, **{f"actual_qd_{k}": v for k, v in enumerate(qd)}}

    def start(self) -> None:
        self._last = wallclock.monotonic()

    def stop(self) -> None:
        self.control.stopJ(self.acceleration)

    def joint(self, name: str) -> str:
        """The joint an actuator name (cotwin.pmodel.tree.actuator_names, the simulator's) commands; a speed- or
        effort-driven actuator is refused at its p-model joint, since the robot takes joint positions only."""
        joint = self._actuators.get(name)
        if joint is None:
            raise CotwinError(f"the robot has no actuator '{name}'")
        mode = servo_mode(joint)
        if mode != "position":
            raise CotwinError([Finding(joint.loc, Severity.ERROR, undrivable(name, joint.name, mode))])
        return joint.name

    def actuator_names(self) -> list[str]:
        """The actuator names it takes: those of the position-driven joints."""
        return [name for name, joint in self._actuators.items() if servo_mode(joint) == "position"]

    def command(self, goals: dict[str, float]) -> None:
        current = self.joint_positions()
        target = dict(current)
        for name, value in goals.items():
            if not math.isfinite(value):
                raise CotwinError(f"actuator '{name}': goal {value!r} is not a finite number")
            target[self.joint(name)] = float(value)
        q_controller = self.convention.to_controller([target[j] for j in self.arm])
        self.control.moveJ(list(q_controller), self.speed, self.acceleration, True)

    def advance(self, dt: float) -> None:
        self._last += dt
        delay = self._last - wallclock.monotonic()
        if delay > 0:
            wallclock.sleep(delay)
        self.time += dt

    def joint_positions(self) -> dict[str, float]:
        return fields_to_state(self._fields(), self.arm, self.convention)[0]

    def joint_velocities(self) -> dict[str, float]:
        return fields_to_state(self._fields(), self.arm, self.convention)[1]

    def read_sensors(self) -> dict[str, float]:
        return joint_readings(self.tree, *fields_to_state(self._fields(), self.arm, self.convention))
