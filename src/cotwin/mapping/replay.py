"""A recorded robot as a platform endpoint: the physical twin's sensors come from a log.

`ReplayEndpoint` plays a `Recording` (times, arm joint positions and velocities, in the p-model's
convention) against the mapping: commands are taken (and kept, for the report) but move nothing,
since the recording already holds what the robot did; joint readings are interpolated linearly at
the endpoint's time. Time alignment: with an `offset`, recording time = offset + simulation time;
without one, the recording is aligned on its first motion: the first command the mapping sends
starts the recorded move, so a planned time and the controller's clock need not agree. Before the
recording starts and after it ends, the first and last samples hold. Sensors read what the log
has: joint position and velocity; an effort sensor reads 0 (a UR log has currents, not torques).
Actuators are named as the simulator names them (cotwin.pmodel.tree.actuator_names), whatever drives them;
a joint the log does not record holds the last position commanded to it (a speed or an effort command
leaves it where it is: the log does not say where that took it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import CotwinError
from ..pmodel.tree import KinematicTree
from .platform import Endpoint, NamedActuators, joint_readings
from .profile import IDENTITY, Convention


@dataclass
class Recording:
    times: np.ndarray  # s, increasing
    q: np.ndarray  # (n, joints) rad, p-model convention
    qd: np.ndarray  # (n, joints) rad/s
    joints: list[str]  # p-model joint names of the columns
    source: str = ""

    def __post_init__(self) -> None:
        if len(self.times) < 2 or np.any(np.diff(self.times) <= 0):
            raise CotwinError(f"{self.source}: a recording needs at least two samples at increasing times")

    def onsets(self, speed: float = 0.02, settle: float = 0.3) -> list[float]:
        """Times at which a move starts: the joint speed rises above `speed` rad/s after at least
        `settle` s below it."""
        moving = np.max(np.abs(self.qd), axis=1) > speed
        out, still_since = [], self.times[0] - settle
        for t, m in zip(self.times, moving):
            if m and t - still_since >= settle:
                out.append(float(t))
            if m:
                still_since = float("inf")
            elif still_since == float("inf"):
                still_since = float(t)
        return out

    def offset_problem(self, offset: float) -> str | None:
        """Why `offset` (the log's time at co-simulation time 0) cannot start a replay, if it cannot: at or past
        the log's end, the replay would hold its last sample for the whole run (before its start is allowed:
        the first sample holds until the log begins)."""
        t0, t1 = float(self.times[0]), float(self.times[-1])
        if offset < t1:
            return None
        return (f"the replay offset {offset!r} s is past the end of the log {self.source}, whose time runs from "
                f"{t0:g} to {t1:g} s ({t1 - t0:g} s long); the offset is the log's time at co-simulation time 0")

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        q = np.array([np.interp(t, self.times, self.q[:, k]) for k in range(len(self.joints))])
        qd = np.array([np.interp(t, self.times, self.qd[:, k]) for k in range(len(self.joints))])
        return q, qd


@dataclass
class ReplayEndpoint(NamedActuators, Endpoint):
    tree: KinematicTree
    recording: Recording
    offset: float | None = None  # recording time at simulation time 0 (None: align on the first command)
    time: float = 0.0
    goals: list[tuple[float, dict[str, float]]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._name_actuators(self.tree, "the recorded robot")  # the names the simulator takes, a speed's or an effort's too
        unknown = [j for j in self.recording.joints if j not in {a.name for a in self.tree.actuated}]
        if unknown:
            raise CotwinError(f"{self.recording.source}: the recording's joints {', '.join(unknown)} are not joints "
                              f"of p-model {self.tree.name}")
        self._held: dict[str, float] = {j.name: 0.0 for j in self.tree.actuated}
        onsets = self.recording.onsets()
        self._first_onset = onsets[0] if onsets else float(self.recording.times[0])

    # ---- the endpoint interface ----
    def start(self) -> None:
        self.time = 0.0

    def stop(self) -> None:
        pass

    def command(self, goals: dict[str, float]) -> None:
        if self.offset is None:
            self.offset = self._first_onset - self.time
        self.goals.append((self.time, dict(goals)))
        for name, value in goals.items():
            joint = self.joint(name)
            if joint not in self.recording.joints and joint in self._positioned:
                self._held[joint] = float(value)  # e.g. gripper fingers the log does not record

    def advance(self, dt: float) -> None:
        self.time += dt

    def recording_time(self) -> float:
        offset = self.offset if self.offset is not None else float(self.recording.times[0])
        return offset + self.time

    def joint_positions(self) -> dict[str, float]:
        q, _ = self.recording.at(self.recording_time())
        return self._held | dict(zip(self.recording.joints, map(float, q)))

    def joint_velocities(self) -> dict[str, float]:
        _, qd = self.recording.at(self.recording_time())
        return {j: 0.0 for j in self._held} | dict(zip(self.recording.joints, map(float, qd)))

    def ends(self) -> tuple[float, str] | None:
        """When the log ends in co-simulation time (known once it is aligned): its last sample holds after."""
        if self.offset is None:
            return None
        return float(self.recording.times[-1]) - self.offset, f"the replayed log {self.recording.source}"

    # ---- state (a twin restarted from its last saved state goes on where the replay was) ----
    saves_state = True

    def snapshot(self) -> dict:
        """Where the replay is: its time, its alignment and the joints it holds at commanded goals (the goals
        it took before are a report of the run so far, not state)."""
        return {"time": self.time, "offset": self.offset, "held": dict(self._held)}

    def restore(self, snapshot: dict) -> None:
        """Continue from a snapshot, checked against this recording's robot first."""
        from ..plaindata import fields, finite, of_type

        fields(snapshot, "replay", ("time", "offset", "held"))
        time = finite(snapshot["time"], "replay's time")
        offset = None if snapshot["offset"] is None else finite(snapshot["offset"], "replay's offset")
        held = of_type(snapshot["held"], dict, "replay's held joints")
        unknown = [j for j in held if j not in self._held]
        if unknown:
            raise CotwinError(f"the saved replay holds joints {', '.join(map(str, unknown))[:200]}, which are not "
                              f"joints of p-model {self.tree.name}")
        self.time, self.offset = time, offset
        self._held = {j: finite(v, f"replay's held {j}") for j, v in held.items()} | \
            {j: v for j, v in self._held.items() if j not in held}

    def read_sensors(self) -> dict[str, float]:
        return joint_readings(self.tree, self.joint_positions(), self.joint_velocities())


def read_rtde_log(path, joints: list[str], convention: Convention = IDENTITY) -> Recording:
    """The arm joints of a UR RTDE log (space-separated, header row; actual_q_*, actual_qd_*) as a Recording
    in the p-model's convention (the robot profile's, as the RTDE endpoint maps fields; identity by default)."""
    from .rtde import read_rtde

    log = read_rtde(path)
    return Recording(log.times, np.array([convention.to_model(q) for q in log.q]), log.qd, joints[: log.q.shape[1]],
                     str(path))
