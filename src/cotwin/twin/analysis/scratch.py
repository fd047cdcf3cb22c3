"""A sweep's scratch folder (where it builds the d-model FMU its workers share), removed however the sweep ends.

`close()` removes it when the sweep ends, normally or by an exception or interrupt; an interrupt arriving while
it is removed does not stop the removal (close says it came, for the caller to honour once the folder is gone).
Threads still inside their what-ifs when the sweep ends (a second Ctrl-C does not wait for them) hold it (`use`):
the last of them to let go removes it. A process that ends before they do (`os._exit`, or the interpreter's
exit under daemon threads) removes what is left first (`remove_left`, also an atexit hook); a thread that set up
a new fork in the instant between that removal and the process's end could still leave one behind.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
import threading
from contextlib import contextmanager
from typing import Iterator

_LEFT: set["ScratchFolder"] = set()  # folders made and not yet removed, for remove_left
_REGISTERED = threading.Lock()


class ScratchFolder:
    """A temporary folder (`path`) removed at `close()`, or after it by the last user still holding it."""

    def __init__(self, prefix: str):
        self.path = tempfile.mkdtemp(prefix=prefix)
        self._lock = threading.Lock()
        self._users = 0
        self._closed = False
        with _REGISTERED:
            _LEFT.add(self)

    @contextmanager
    def use(self) -> Iterator[str]:
        """Hold the folder while a worker (a sweep's thread) uses it; the last to let go of a closed folder removes it."""
        with self._lock:
            self._users += 1
        try:
            yield self.path
        finally:
            with self._lock:
                self._users -= 1
                last = self._closed and self._users == 0
            if last:
                self.remove()

    def close(self) -> bool:
        """The sweep is over: remove the folder now, or, while a worker still holds it, when the last one lets go.
        True when an interrupt came while the folder was removed (the removal went on regardless)."""
        with self._lock:
            self._closed = True
            held = self._users > 0
        return False if held else self.remove()

    def remove(self) -> bool:
        """Remove the folder whoever still uses it; True when an interrupt came meanwhile (the removal went on)."""
        interrupted = False
        while True:
            try:
                shutil.rmtree(self.path, ignore_errors=True)
                break
            except KeyboardInterrupt:  # Ctrl-C again as the sweep ends: the folder is removed all the same
                interrupted = True
        with _REGISTERED:
            _LEFT.discard(self)
        return interrupted


def remove_left() -> None:
    """Remove every scratch folder not removed yet (the process ends with workers still holding some)."""
    with _REGISTERED:
        left = list(_LEFT)
    for folder in left:
        folder.remove()


atexit.register(remove_left)  # the interpreter's exit under daemon threads still holding a folder
