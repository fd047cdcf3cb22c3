"""One life cycle for cotwin's background services (the RabbitMQ bridge, the OPC UA plant, the history
writer, the alarm publisher, the what-if service, the pages): each runs on its own daemon thread, and
starting, waiting until it is ready, stopping and joining it, and reporting what went wrong on that
thread, are written once, here.

A service overrides `serve()` (run on its thread; it calls `ready()` once it serves, and returns when
`stopping` is set) and, when its loop waits on something other than `stopping`, `interrupt()` (called
from `stop()` to wake it). `start(timeout)` returns once the service is ready; if it failed first, its
error is raised in the caller (a CotwinError naming the service, `error_of(err)` says it); if it was
neither ready nor failed within the timeout, it is stopped and a CotwinError says so (`late(timeout)`). A failure after
it was ready is kept (`failure`) and raised by `check()`, so the thread that uses the service hears of it.
"""

from __future__ import annotations

import asyncio
import logging
import threading

from .diagnostics import CotwinError

log = logging.getLogger("cotwin.service")


def reason(err: BaseException) -> str:
    """A failure in a few words: its message, else its type."""
    if isinstance(err, CotwinError):
        return "; ".join(f.message for f in err.findings)
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0][:200]}" if text else type(err).__name__


class BackgroundService:
    """A job on its own daemon thread (see module doc)."""

    def __init__(self, name: str):
        self.name = name
        self.stopping = threading.Event()
        self.failure: BaseException | None = None
        self._ready = threading.Event()
        self._settled = threading.Event()  # ready, or the thread ended
        self._thread: threading.Thread | None = None

    # ---- what a service defines ----
    def serve(self) -> None:
        """The service's work, on its thread: call `ready()` once serving; return once `stopping` is set."""
        raise NotImplementedError

    def interrupt(self) -> None:
        """Wake `serve` so that it sees `stopping` (nothing by default: a loop that waits on `stopping`
        wakes by itself)."""

    def error_of(self, err: BaseException) -> CotwinError:
        """The error the caller gets for a failure on the thread."""
        return err if isinstance(err, CotwinError) else CotwinError(f"{self.name}: {reason(err)}")

    def late(self, timeout: float) -> CotwinError:
        """The error the caller gets when the service was neither ready nor failed within `timeout` s."""
        return CotwinError(f"{self.name} did not become ready within {timeout:g} s")

    # ---- on the service's thread ----
    def ready(self) -> None:
        """Say the service serves: `start` returns."""
        self._ready.set()
        self._settled.set()

    def _service_thread(self) -> None:
        try:
            self.serve()
        except BaseException as err:  # noqa: BLE001 - reported to the caller, never lost with the thread
            self.failure = err
            if self._ready.is_set():
                log.error("%s stopped: %s", self.name, reason(err))
        finally:
            self._settled.set()

    # ---- from the caller ----
    @property
    def started(self) -> bool:
        return self._thread is not None

    @property
    def running(self) -> bool:
        """Started, ready and not ended."""
        return self._thread is not None and self._thread.is_alive() and self._ready.is_set()

    @property
    def is_ready(self) -> bool:
        return self._ready.is_set()

    def start(self, timeout: float | None = 30.0):
        """Run `serve` on a new daemon thread; return once it is ready (see module doc). Starting a started
        service does nothing."""
        if self._thread is not None:
            return self
        self.stopping.clear()
        self.failure = None
        self._ready.clear()
        self._settled.clear()
        self._thread = threading.Thread(target=self._service_thread, name=self.name, daemon=True)
        self._thread.start()
        self._settled.wait(timeout)
        if self.failure is not None and not self._ready.is_set():
            failure = self.failure
            self.stop()
            raise self.error_of(failure) from None
        if not self._ready.is_set():
            ended = self._settled.is_set()
            self.stop()
            raise CotwinError(f"{self.name} ended before it was ready") if ended else self.late(timeout)
        return self

    def check(self) -> None:
        """Raise the failure that ended the service's thread, if one did."""
        if self.failure is not None:
            raise self.error_of(self.failure)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait for the service's thread to end by itself (at most `timeout` s); True when it has."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout)
        return thread is None or not thread.is_alive()

    def stop(self, timeout: float | None = 10.0) -> bool:
        """Ask the service to end and wait for its thread (at most `timeout` s; None: as long as it takes);
        True when it ended."""
        self.stopping.set()
        thread = self._thread
        if thread is None:
            return True
        if thread.is_alive():
            self.interrupt()
            thread.join(timeout)
        if thread.is_alive():
            log.warning("%s did not stop within %g s", self.name, timeout)
            return False
        self._thread = None
        return True

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class LoopThread(BackgroundService):
    """An asyncio event loop on its own thread, for synchronous code that runs coroutines there
    (`asyncio.run_coroutine_threadsafe(coroutine, thread.loop)`): ready once the loop runs; stopped, the
    loop is closed."""

    def __init__(self, name: str):
        super().__init__(name)
        self.loop = asyncio.new_event_loop()

    def serve(self) -> None:
        self.loop.call_soon(self.ready)
        self.loop.run_forever()

    def interrupt(self) -> None:
        if not self.loop.is_closed():
            self.loop.call_soon_threadsafe(lambda: self.loop.create_task(self._wind_down()))

    async def _wind_down(self, grace: float = 2.0) -> None:
        """Cancel what still runs on the loop (a call given up on, e.g. a connect that timed out), let it end
        (at most `grace` s), then stop the loop: a task still pending when the loop closes is a stray
        "Task was destroyed but it is pending!" on the user's stderr."""
        tasks = asyncio.all_tasks(self.loop) - {asyncio.current_task()}
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.wait(tasks, timeout=grace)
        self.loop.stop()

    def stop(self, timeout: float | None = 10.0) -> bool:
        ended = super().stop(timeout)
        if ended and not self.loop.is_closed():
            self.loop.close()
        return ended
