"""What watches a live twin: the observer protocol of cotwin.twin.live.runtime.LiveTwin.

A LiveTwin only steps its two sides and tells its observers: `twin_started(twin)` once both sides are
initialised (or restored), `twin_step(twin, k, t)` after step k of both, `twin_alarm(twin, event)` for each
deviation alarm raised or cleared, and `twin_ended(twin, status)` once the run is over ("done", "stopped"
or "failed"; `twin.message` says why when it did not finish), also when it failed before it started. Every
callback is a no-op here: an observer overrides the ones it needs. The twin's own services (deviation
checking, history, alarms on the broker, what-if requests, convergence, real-time pacing) are observers
too (cotwin.twin.live.live_observers), registered by the runtime before the caller's.
"""

from __future__ import annotations


class TwinObserver:
    """Callbacks of a live twin (see module doc); each is optional."""

    def twin_started(self, twin) -> None:
        """Both sides are initialised: bind what is read each step."""

    def twin_step(self, twin, k: int, t: float) -> None:
        """Step k of both sides ended at simulated time t."""

    def twin_alarm(self, twin, event: dict) -> None:
        """A deviation alarm was raised or cleared (cotwin.twin.services.deviation's event)."""

    def twin_ended(self, twin, status: str) -> None:
        """The run is over: "done", "stopped" or "failed" (`twin.message` says why, if it says)."""
