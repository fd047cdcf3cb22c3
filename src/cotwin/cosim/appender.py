"""A file appended to by a thread of its own (issue 23): a result writer hands it pieces in order (bytes, or
objects it spells), and spelling them and writing them overlap the next native stretch, which runs in C
without the GIL. Pieces are written in the order given; a write the file system takes only in part (a full
disk, a size limit) is cut back to its last whole line, so the file keeps every line written and never ends
in half a line. The thread's first error is raised on the caller's thread at its next `put` or `drain`, and nothing
after it is written.
"""

from __future__ import annotations

import os
import queue
import threading
from typing import Callable

_STOP = object()


class Appender:
    """Appends pieces to the open file `fd` on a thread of its own: bytes as they are, anything else as
    `spell(piece)` makes it. `drain` waits until every piece given is written; `stop` ends the thread after
    them (the file stays open: its owner closes it)."""

    def __init__(self, fd: int, spell: Callable[[object], bytes], name: str = "cotwin-appender"):
        self.fd, self._spell = fd, spell
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._given = self._written = 0  # pieces put, and pieces the thread is done with
        self._done = threading.Condition()
        self._error: BaseException | None = None
        self.size = os.lseek(fd, 0, os.SEEK_CUR)  # bytes in the file, whole writes only
        self.lines = 0  # newlines written
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    def put(self, piece: object) -> None:
        """Queue a piece after those given before (raises the thread's error, if it had one)."""
        self._raise()
        self._given += 1
        self._queue.put(piece)

    def drain(self) -> None:
        """Wait until every piece given is written (raises the thread's error, if it had one)."""
        with self._done:
            self._done.wait_for(lambda: self._written >= self._given)
        self._raise()

    def stop(self) -> None:
        """End the thread after the pieces given, whatever became of them (its error, if any, is not raised)."""
        self._queue.put(_STOP)
        self._thread.join()

    def _raise(self) -> None:
        if self._error is not None:
            raise self._error

    def _work(self) -> None:
        while True:
            piece = self._queue.get()
            if piece is _STOP:
                return
            try:
                if self._error is None:  # each piece a write of its own: one taken in part loses that piece only
                    self._write(piece if piece.__class__ is bytes else self._spell(piece))
            except BaseException as err:  # noqa: BLE001 -- kept for the caller's thread, which raises it
                self._error = err
            with self._done:
                self._written += 1
                self._done.notify_all()

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self.fd, view):]
        except BaseException:
            written = len(data) - len(view)
            if written:  # a part was written: cut back to its last whole line
                whole = data.rfind(b"\n", 0, written) + 1
                self.size += whole
                self.lines += data.count(b"\n", 0, whole)
                os.ftruncate(self.fd, self.size)
                os.lseek(self.fd, self.size, os.SEEK_SET)
            raise
        self.size += len(data)
        self.lines += data.count(b"\n")
