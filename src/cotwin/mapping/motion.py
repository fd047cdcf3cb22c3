"""Motion profiles: how an endpoint moves its joints from where they are to new servo goals.

A profile plans a `Segment` (start, goal, start time, duration, and a normalised shape s(t) going
from 0 to 1); every joint follows start + s(t) (goal - start), so all joints start and arrive
together. Two profiles:
- `Quintic` (the default): a quintic polynomial whose peak speed keeps each joint within its velocity
  limit from the p-model (the fastest smooth move the hardware allows);
- `JointMove`: a UR controller's `movej(q, a, v)`: a trapezoidal speed profile for the leading joint
  (the revolute joint with the largest displacement) with acceleration a and speed v, triangular
  when the distance is too short to reach v; the other joints are scaled to arrive together.
Both may start `delay` seconds after the command (negative: the set-point leads, which compensates a
simulated servo that lags more than the physical one).

TOML ([motion] table of a calibration file):

    [motion]
    profile = "movej"   # or "quintic"
    a = 1.4             # rad/s^2, leading joint
    v = 1.05            # rad/s, leading joint
    delay = 0.0         # s
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from ..pmodel.tree import KinematicTree
from ..config import Key, Schema, TomlFile
from ..diagnostics import CotwinError, Finding, Severity

QUINTIC_PEAK = 1.875  # peak of d/dtau of 10 tau^3 - 15 tau^4 + 6 tau^5


@dataclass
class Segment:
    """A planned move, as plain data (an endpoint's saved state holds it): every joint goes from start
    to goal along the same normalised shape, from t0 for `duration` seconds."""

    start: dict[str, float]
    goal: dict[str, float]
    t0: float  # when the motion starts
    duration: float
    shape: str = "quintic"  # quintic | trapezoid
    a: float = 0.0  # trapezoid: the leading joint's acceleration, speed and distance
    v: float = 0.0
    distance: float = 0.0

    def fraction(self, t: float) -> float:
        elapsed = t - self.t0
        if self.duration <= 0 or elapsed >= self.duration:
            return 1.0
        if elapsed <= 0:
            return 0.0
        if self.shape == "trapezoid":
            return travelled(self.a, self.v, self.distance, elapsed) / self.distance
        tau = elapsed / self.duration
        return tau ** 3 * (10 - 15 * tau + 6 * tau * tau)

    def at(self, t: float) -> dict[str, float]:
        s = self.fraction(t)
        return {j: self.start[j] + s * (self.goal[j] - self.start[j]) for j in self.goal}

    @property
    def end(self) -> float:
        return self.t0 + max(self.duration, 0.0)

    def checked(self) -> "Segment":
        """This segment if its fields make a move (a saved state's, before it runs): goals with a start
        each, a known shape, a duration at least 0 and, for a trapezoid that takes time, positive a, v and
        distance; CotwinError otherwise."""
        if not set(self.goal) <= set(self.start):
            raise CotwinError(f"the saved trajectory has goals without a start: {', '.join(sorted(set(self.goal) - set(self.start)))}")
        if self.shape not in ("quintic", "trapezoid"):
            raise CotwinError(f"the saved trajectory's shape is {self.shape[:40]!r}, not quintic or trapezoid")
        if not self.duration >= 0 or (self.shape == "trapezoid" and self.duration > 0 and
                                      not (self.a > 0 and self.v > 0 and self.distance > 0)):
            raise CotwinError("the saved trajectory's duration, acceleration, speed or distance cannot make a move")
        return self


def trapezoid_duration(a: float, v: float, distance: float) -> float:
    """How long a trapezoidal (triangular when short) move of `distance` takes at acceleration a, speed v."""
    if distance <= 0:
        return 0.0
    if distance >= v * v / a:
        return distance / v + v / a
    return 2.0 * math.sqrt(distance / a)


def travelled(a: float, v: float, distance: float, elapsed: float) -> float:
    """How far a trapezoidal move of `distance` has gone after `elapsed` seconds."""
    total = trapezoid_duration(a, v, distance)
    if elapsed >= total:
        return distance
    if elapsed <= 0:
        return 0.0
    peak = min(v, math.sqrt(a * distance))
    ramp = peak / a
    if elapsed <= ramp:
        return 0.5 * a * elapsed * elapsed
    if elapsed <= total - ramp:
        return 0.5 * peak * ramp + peak * (elapsed - ramp)
    left = total - elapsed
    return distance - 0.5 * a * left * left


class MotionProfile(Protocol):
    delay: float

    def plan(self, tree: KinematicTree, start: dict[str, float], goal: dict[str, float], t0: float) -> Segment: ...

    def tables(self) -> dict: ...


def _largest(tree: KinematicTree, start: dict[str, float], goal: dict[str, float]) -> float:
    """The leading joint's distance: over the revolute joints (rad) if any moves, else over all."""
    revolute = {j.name for j in tree.actuated if j.kind == "revolute"}
    moves = {j: abs(goal[j] - start.get(j, goal[j])) for j in goal}
    return max((d for j, d in moves.items() if j in revolute), default=0.0) or max(moves.values(), default=0.0)


@dataclass(frozen=True)
class Quintic:
    """Quintic at the joints' velocity limits (cotwin's default)."""

    delay: float = 0.0

    def duration(self, tree: KinematicTree, start: dict[str, float], goal: dict[str, float]) -> float:
        """Shortest quintic duration in which no joint exceeds its velocity limit (0 if nothing moves)."""
        limits = {j.name: j.velocity for j in tree.actuated}
        return max((QUINTIC_PEAK * abs(target - start.get(name, 0.0)) / (limits.get(name) or 1.0)
                    for name, target in goal.items()), default=0.0)

    def plan(self, tree, start, goal, t0) -> Segment:
        return Segment(start, goal, t0 + self.delay, self.duration(tree, start, goal))

    def tables(self) -> dict:
        return {"profile": "quintic", "delay": self.delay}


@dataclass(frozen=True)
class JointMove:
    """URScript's movej: trapezoidal speed of the leading joint, all joints arriving together."""

    a: float = 1.4  # rad/s^2
    v: float = 1.05  # rad/s
    delay: float = 0.0

    def duration(self, distance: float) -> float:
        return trapezoid_duration(self.a, self.v, distance)

    def travelled(self, distance: float, elapsed: float) -> float:
        """How far the leading joint has gone after `elapsed` seconds of a move of `distance`."""
        return travelled(self.a, self.v, distance, elapsed)

    def plan(self, tree, start, goal, t0) -> Segment:
        distance = _largest(tree, start, goal)
        return Segment(start, goal, t0 + self.delay, self.duration(distance), "trapezoid", self.a, self.v, distance)

    def tables(self) -> dict:
        return {"profile": "movej", "a": self.a, "v": self.v, "delay": self.delay}


PROFILES = ("quintic", "movej")
MOTION = Schema({"profile": Key("str", "quintic", choices=PROFILES), "a": Key("positive"), "v": Key("positive"),
                 "delay": Key("number", 0.0)})


def profile_from_values(values: dict | None, file: TomlFile, problems: list[Finding],
                        default: MotionProfile | None = None) -> MotionProfile | None:
    """The profile of a [motion] table as read by MOTION (None: the table is absent)."""
    if values is None:
        return default
    if values["profile"] == "quintic":
        for key in ("a", "v"):
            if values.get(key) is not None:
                problems.append(Finding(file.location(("motion", key)), Severity.ERROR,
                                        f"[motion] {key} applies to profile 'movej' only"))
        return Quintic(float(values["delay"]))
    a = values["a"] if values.get("a") is not None else JointMove.a
    v = values["v"] if values.get("v") is not None else JointMove.v
    return JointMove(float(a), float(v), float(values["delay"]))
