"""Interrupts held over a block that must not be cut in two: a native stretch's steps committed and told, the
files of a test suite moved into place. SIGINT and SIGTERM, where Python handles them, are noted meanwhile and
handled as they would have been once the block ends."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

# signal's own functions, without the module's enum wrapping (which costs a caught ValueError per call, ~5 us:
# a tenth of a segment's Python time); the handlers the same objects
try:
    import _signal as _raw_signal
except ImportError:  # another Python than CPython
    _raw_signal = signal
_HELD_SIGNALS = (int(signal.SIGINT), int(signal.SIGTERM))


@contextmanager
def signals_held():
    """SIGINT and SIGTERM, where Python handles them, held until the block ends, then the first of them handled
    as it would have been (main thread only: signals are handled there)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[tuple[int, object]] = []
    previous = {sig: _raw_signal.getsignal(sig) for sig in _HELD_SIGNALS}
    caught = {sig: handler for sig, handler in previous.items() if callable(handler)}
    hold = lambda signum, frame: held.append((signum, frame))  # noqa: E731
    for sig in caught:
        _raw_signal.signal(sig, hold)
    try:
        yield
    finally:
        for sig, handler in caught.items():
            _raw_signal.signal(sig, handler)
        for signum, frame in held[:1]:
            caught[signum](signum, frame)
