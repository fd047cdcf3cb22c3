"""Deviation checking between a physical and a digital twin, step by step.

Per monitored variable, at step k the deviation is the smallest |PT - DT| over time shifts of at most
`lag_steps` either way (a DT that lags or leads by a few steps is not deviating), and the variable
deviates when that exceeds max(absolute, relative * |PT|), so negative angles are judged like positive
ones. An alarm is raised after `debounce_steps` consecutive deviating steps and cleared after as many
good ones; each change is an event handed to `publish` (JSON-ready dict) and kept. `report()` gives, per
variable, the RMSE of the raw difference, the largest aligned deviation and when, and alarm intervals.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Callable


@dataclass
class AlarmInterval:
    variable: str
    raised: float  # simulation time at which the alarm was raised
    first: float  # time of the first deviating step of the run of steps that raised it
    cleared: float | None = None
    peak: float = 0.0
    peak_time: float = 0.0

    def as_dict(self) -> dict:
        return {"variable": self.variable, "raised": self.raised, "first_deviating": self.first,
                "cleared": self.cleared, "peak": self.peak, "peak_time": self.peak_time}


@dataclass
class _Track:
    pt: deque
    dt: deque
    sum_sq: float = 0.0
    count: int = 0
    max_dev: float = 0.0
    max_time: float | None = None
    streak: int = 0  # consecutive deviating (positive) or good (negative) steps
    first_bad: float = 0.0
    alarm: AlarmInterval | None = None
    intervals: list[AlarmInterval] = field(default_factory=list)


class DeviationMonitor:
    def __init__(self, variables: list[str], absolute: float = 0.05, relative: float = 0.0, lag_steps: int = 3,
                 debounce_steps: int = 2, publish: Callable[[dict], None] | None = None, twin: str = "twin"):
        if absolute < 0 or relative < 0 or lag_steps < 0 or debounce_steps < 1:
            raise ValueError("thresholds and lag must be >= 0 and the debounce >= 1 step")
        self.variables = list(variables)
        self.absolute, self.relative = float(absolute), float(relative)
        self.lag, self.debounce = int(lag_steps), int(debounce_steps)
        self.publish = publish
        self.twin = twin
        self.events: list[dict] = []
        self.tracks = {v: _Track(deque(maxlen=self.lag + 1), deque(maxlen=self.lag + 1)) for v in self.variables}
        self.steps = 0
        self.last_time = 0.0

    def threshold(self, pt: float) -> float:
        return max(self.absolute, self.relative * abs(pt))

    def observe(self, t: float, pt: dict[str, float], dt: dict[str, float]) -> list[dict]:
        """Take the PT's and the DT's values at time t; returns the alarm events this step raised."""
        events = []
        self.steps += 1
        self.last_time = t
        for var, track in self.tracks.items():
            p, d = pt.get(var), dt.get(var)
            if p is None or d is None or not (math.isfinite(p) and math.isfinite(d)):
                continue
            track.pt.append(p)
            track.dt.append(d)
            track.sum_sq += (p - d) ** 2
            track.count += 1
            aligned = min(min(abs(p - x) for x in track.dt), min(abs(d - x) for x in track.pt))
            if aligned > track.max_dev or track.max_time is None:
                track.max_dev, track.max_time = aligned, t
            bad = aligned > self.threshold(p)
            if bad:
                track.first_bad = t if track.streak <= 0 else track.first_bad
                track.streak = track.streak + 1 if track.streak > 0 else 1
            else:
                track.streak = track.streak - 1 if track.streak < 0 else -1
            if track.alarm is not None and aligned > track.alarm.peak:
                track.alarm.peak, track.alarm.peak_time = aligned, t
            if track.alarm is None and track.streak >= self.debounce:
                track.alarm = AlarmInterval(var, t, track.first_bad, peak=aligned, peak_time=t)
                track.intervals.append(track.alarm)
                events.append(self._event("raised", var, t, aligned, p, d))
            elif track.alarm is not None and -track.streak >= self.debounce:
                track.alarm.cleared = t
                track.alarm = None
                events.append(self._event("cleared", var, t, aligned, p, d))
        for e in events:
            self.events.append(e)
            if self.publish is not None:
                self.publish(e)
        return events

    def _event(self, state: str, var: str, t: float, deviation: float, pt: float, dt: float) -> dict:
        return {"type": "deviation", "state": state, "twin": self.twin, "variable": var, "time": round(t, 9),
                "deviation": deviation, "threshold": self.threshold(pt), "pt": pt, "dt": dt}

    @property
    def active(self) -> list[str]:
        return [v for v, tr in self.tracks.items() if tr.alarm is not None]

    def report(self) -> dict:
        variables = {}
        for var, tr in self.tracks.items():
            variables[var] = {
                "rmse": math.sqrt(tr.sum_sq / tr.count) if tr.count else None,
                "max_deviation": tr.max_dev if tr.count else None,
                "max_deviation_time": tr.max_time,
                "samples": tr.count,
                "alarms": [a.as_dict() for a in tr.intervals],
            }
        return {"settings": {"absolute": self.absolute, "relative": self.relative, "lag_steps": self.lag,
                             "debounce_steps": self.debounce},
                "steps": self.steps, "end_time": self.last_time, "variables": variables,
                "alarms": sum(len(tr.intervals) for tr in self.tracks.values())}
