"""A persistent cache of inverse-kinematics solutions: a cell's targets (its holes) are solved once.

The solver is deterministic, so a solution stored under the solver's fingerprint (its chain, tool,
reference posture, seeds and code) and the target's pose is exactly what solving again would give;
a changed model, geometry or solver gives another fingerprint and another file. Files live in
$COTWIN_CACHE, else $XDG_CACHE_HOME/cotwin, else ~/.cache/cotwin (COTWIN_CACHE=off turns the cache
off); they are written whole under a temporary name and renamed, and one that cannot be read is
ignored (and rewritten), as is an entry that is not a solution as this module writes it.
"""

from __future__ import annotations

import fcntl
import json
import threading
from contextlib import contextmanager
from pathlib import Path

from ..config import is_number
from ..diagnostics import CotwinError
from ..files import cache_dir, write_text  # noqa: F401 - cache_dir: where callers have found it


def _solution(entry) -> bool:
    """A stored solution as `put` writes it (a damaged or hand-edited entry is dropped, then solved again)."""
    return (isinstance(entry, dict) and set(entry) == {"q", "position_error", "angle_error", "iterations"}
            and isinstance(entry["q"], dict) and all(isinstance(k, str) and is_number(v) for k, v in entry["q"].items())
            and is_number(entry["position_error"]) and is_number(entry["angle_error"])
            and isinstance(entry["iterations"], int) and not isinstance(entry["iterations"], bool))


def _stored(path: Path, fingerprint: str) -> tuple[dict[str, dict], bool]:
    """The solutions of `fingerprint` in the file at `path` (none for a file of another solver or one that cannot
    be read), and whether the file held only such solutions."""
    if not path.is_file():
        return {}, True
    try:
        data = json.loads(path.read_text())
        if isinstance(data, dict) and data.get("fingerprint") == fingerprint:
            solutions = data.get("solutions")
            stored = solutions.items() if isinstance(solutions, dict) else ()
            entries = {key: value for key, value in stored if _solution(value)}
            return entries, len(entries) == len(stored) and isinstance(solutions, dict)
    except (OSError, ValueError):
        pass
    return {}, True


_SAVING = threading.Lock()  # a sweep's threads, each with its forks' cache of one file, save in turn


@contextmanager
def _saving(path: Path):
    """The file at `path` for this save alone: another thread of this process (_SAVING) or another process (an
    flock on a file beside it: a pool's workers end their chunks at once) saving it waits, and so merges what this
    one wrote instead of writing over it."""
    with _SAVING, open(path.with_name(f"{path.name}.lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released as the file closes
        yield


class SolutionCache:
    """Solutions (plain data) by target key, for one solver fingerprint."""

    def __init__(self, fingerprint: str, folder: Path | None = None):
        folder = folder if folder is not None else cache_dir()
        self.path = None if folder is None else folder / "ik" / f"{fingerprint[:32]}.json"
        self.entries: dict[str, dict] = {}
        self.loaded = 0
        self._dirty = False
        if self.path is not None:
            self.entries, clean = _stored(self.path, fingerprint)
            self.loaded = len(self.entries)
            self._dirty = not clean  # rewrite it clean
        self.fingerprint = fingerprint

    @staticmethod
    def key(target) -> str:
        return ",".join(repr(float(v)) for v in target)

    def get(self, key: str) -> dict | None:
        return self.entries.get(key)

    def put(self, key: str, solution: dict) -> None:
        self.entries[key] = solution
        self._dirty = True

    def save(self) -> None:
        if self.path is None or not self._dirty:
            return
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with _saving(self.path):  # with the solutions saved since this cache was read (another thread's or process's)
                self.entries = {**_stored(self.path, self.fingerprint)[0], **self.entries}
                write_text(self.path, json.dumps({"fingerprint": self.fingerprint, "solutions": self.entries}))
            self._dirty = False
        except (OSError, CotwinError):  # a read-only home: the cache is an optimisation, never a failure
            pass
