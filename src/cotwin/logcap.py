"""A warning log a hostile client cannot flood: at most `burst` warnings per `window` seconds are
written; the others are counted and summed up in one line ("N more ... not logged") when the next
window opens or the log is closed. What was refused is counted in full either way. Nor can it forge
lines: the text arguments of a warning (a request's path, a message's words) are logged with their line
breaks and other control characters escaped, so one warning is one line of the log.
"""

from __future__ import annotations

import logging
import threading
import time as wallclock


def printable(text: str) -> str:
    """`text` with every character that is not printable (line breaks, terminal escapes) as its escape."""
    return text if text.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class CappedLog:
    """Warnings about one kind of refused input (`what`, e.g. "dropped messages") on `logger`."""

    def __init__(self, logger: logging.Logger, what: str, burst: int = 20, window: float = 10.0):
        self.logger, self.what = logger, what
        self.burst, self.window = burst, window
        self.count = 0  # warnings asked for, logged or not
        self.suppressed = 0  # not logged in the current window
        self._opened = float("-inf")
        self._in_window = 0
        self._lock = threading.Lock()

    def warning(self, text: str, *args) -> bool:
        """Log `text % args` unless this window's quota is spent; True if it was logged."""
        with self._lock:
            self.count += 1
            now = wallclock.monotonic()
            if now - self._opened >= self.window:
                self._summary()
                self._opened, self._in_window = now, 0
            if self._in_window >= self.burst:
                self.suppressed += 1
                return False
            self._in_window += 1
        self.logger.warning(text, *(printable(a) if isinstance(a, str) else a for a in args))
        return True

    def close(self) -> None:
        """Say how many were not logged since the last summary."""
        with self._lock:
            self._summary()

    def _summary(self) -> None:
        if self.suppressed:
            self.logger.warning("%d more %s not logged (at most %d per %g s)", self.suppressed, self.what,
                                self.burst, self.window)
            self.suppressed = 0


class CappedFilter(logging.Filter):
    """The same cap for a logger whose calls are not ours (e.g. uvicorn's "Invalid HTTP request
    received." for every malformed request): attached to it, it lets `burst` records per `window`
    through and says how many it held back when the next window opens."""

    def __init__(self, what: str, burst: int = 20, window: float = 10.0):
        super().__init__()
        self.what, self.burst, self.window = what, burst, window
        self.suppressed = 0
        self._opened = float("-inf")
        self._in_window = 0
        self._lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.ERROR:
            return True  # the server's own failures are never held back
        with self._lock:
            now = wallclock.monotonic()
            if now - self._opened >= self.window:
                if self.suppressed:
                    record.msg = f"%s (and %d more {self.what} not logged in the last %g s)"
                    record.args = (record.getMessage(), self.suppressed, self.window)
                self.suppressed = 0
                self._opened, self._in_window = now, 0
            if self._in_window >= self.burst:
                self.suppressed += 1
                return False
            self._in_window += 1
            return True
