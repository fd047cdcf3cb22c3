"""Progress of a long command on stderr: a live bar on a terminal, else a plain line now and then.

Long commands (verify, testgen, calibrate, sweep, a paced twin) call `update(done, total, detail)` as they go.
On a terminal the line is redrawn in place (rich) and removed at the end; in a log (stderr not a
terminal) one line is written every COTWIN_PROGRESS_SECONDS seconds (default 10; 0: every update,
"off": never), so that a CI log shows that a run is alive and how far it is.
"""

from __future__ import annotations

import os
import sys
import time

EVERY = 10.0  # s between two progress lines in a log


def interval(environ=os.environ) -> float | None:
    """Seconds between log lines from COTWIN_PROGRESS_SECONDS, or None for no lines."""
    text = environ.get("COTWIN_PROGRESS_SECONDS", "").strip().lower()
    if not text:
        return EVERY
    if text in ("off", "no", "never"):
        return None
    try:
        value = float(text)
    except ValueError:
        return EVERY
    return value if value >= 0 else EVERY


class ProgressReport:
    """`with ProgressReport("verifying") as progress: progress.update(done, total, "detail")`."""

    def __init__(self, label: str, unit: str = "", stream=None, terminal: bool | None = None):
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self.terminal = self.stream.isatty() if terminal is None else terminal
        self.every = interval()
        self._bar = None
        self._task = None
        self._last = None
        self.started = time.monotonic()

    def __enter__(self) -> "ProgressReport":
        self.started = time.monotonic()
        if self.terminal:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            self._bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                 TimeElapsedColumn(), TextColumn("{task.fields[detail]}"),
                                 console=Console(file=self.stream, force_terminal=True), transient=True)
            self._bar.__enter__()
            self._task = self._bar.add_task(self.label, total=None, detail="")
        return self

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)
            self._bar = None

    def update(self, done: int | float, total: int | float | None = None, detail: str = "") -> None:
        if self._bar is not None:
            self._bar.update(self._task, completed=done, total=total, detail=detail)
            return
        if self.every is None:
            return
        now = time.monotonic()
        if now - (self.started if self._last is None else self._last) < self.every:
            return  # a command done within the interval prints no line
        self._last = now
        amount = f"{done:g}" if total is None else f"{done:g}/{total:g}"
        amount += f" {self.unit}" if self.unit else ""
        amount += f" ({100 * done / total:.0f}%)" if total else ""
        print(f"{self.label}: {amount}{', ' + detail if detail else ''} [{now - self.started:.0f} s]",
              file=self.stream, flush=True)

    def __call__(self, done, total=None, detail: str = "") -> None:
        self.update(done, total, detail)
