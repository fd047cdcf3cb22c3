"""Observers of an execution (libcosim's `observer`): they watch values after initialisation and after
every step, and never change the simulation. A result writer, a progress report, real-time pacing
and live publishers are all observers, so the step loop knows none of them.
"""

from __future__ import annotations

import fcntl
import math
import os
import queue
from itertools import chain
import time as wallclock
from pathlib import Path
from typing import Callable, Collection

import numpy as np

from ..diagnostics import CotwinError
from ..files import Reserved, open_exclusive, refuse_special, write_bytes
from ..interrupts import signals_held
from .algorithm import UNSET
from .appender import Appender


class Observer:
    """Callbacks of an execution; each is optional."""

    def simulation_initialized(self, execution) -> None: ...

    def step_complete(self, execution) -> None: ...

    def repeated(self, execution, rows) -> None:
        """Steps the native loop made at once (cotwin.cosim.native: `rows` is a StepRows of the values on the
        connections), in which nothing changed but continuous values and the discrete ones `whole_changes`
        lets pass; told before the last step of the stretch, which comes to `step_complete` as it is made. An
        observer that does not define it must see every step as it is made (it may read a unit's state, save
        the execution's ...): then the native loop does not run. One that reads only the values may tell
        itself each row in turn (`rows.replay`)."""
        raise NotImplementedError

    def whole_changes(self, execution) -> Collection[tuple[str, str]] | None:
        """The ports (unit, port) whose discrete changes this observer must be told of by `step_complete`, on a
        step made whole (the native loop ends a stretch after such a change); None: every port, as an observer
        that does not say. Asked before each stretch."""
        return None

    def whole_values(self, execution) -> dict[tuple[str, str], Collection[int]]:
        """Of the ports `whole_changes` names, those of which only the arrival of some values must be told whole
        (a machine entering some of its leaves): port -> those values (0..63; a change to a value beyond them is
        told whole too). Asked before each stretch, after `whole_changes`."""
        return {}

    def quiet_for(self, execution) -> int | None:
        """How many steps from now the native loop may make, the last of them told to `step_complete` as it is
        made (the others to `repeated`); None: any number."""
        return None

    def checkpoints(self, execution) -> list[tuple[tuple[str, str], object, int]]:
        """Steps it must be told whole if a port still holds a value then: (port, value, steps from now), e.g. a
        machine judged `patience` steps after it entered a state, if it is still there (a change of the port
        before is told whole or counted from the rows, as `whole_changes` says). Asked before each stretch."""
        return []

    def simulation_ended(self, execution, error: BaseException | None) -> None: ...


class Stop(Observer):
    """An observer that ends a run early (`Execution.advance(n, until=stop)`): `reached` is asked after each step
    it was told of by `step_complete`. In the native loop those are the last step of each stretch, so its
    `quiet_for` must end a stretch at any step at which it could be reached (a what-if that has seen enough:
    cotwin.twin.services.whatif)."""

    def reached(self, execution) -> bool:
        return False


def hears_repeats(observer: Observer) -> bool:
    """Whether the observer can be told of the native loop's repeated steps at once: it defines `repeated`,
    or it has nothing to do after a step."""
    kind = type(observer)
    return kind.repeated is not Observer.repeated or kind.step_complete is Observer.step_complete


def format_value(value) -> str:
    """Maestro's CSV spelling: Booleans true/false, reals as Python's shortest repr, nothing as ''
    (numpy scalars as the Python numbers they hold)."""
    if value is None or value is UNSET:
        return ""
    if type(value).__module__ == "numpy" and hasattr(value, "item"):
        value = value.item()
    if value is True or value is False:
        return "true" if value else "false"
    if isinstance(value, float):
        return float.__repr__(value)
    return str(value)


class CSVWriter(Observer):
    """Writes Maestro's outputs.csv: header `time,{key}.inst.var,...`, a row at the start and after every step.

    Rows are held as values and formatted `batch` at a time (in C where they are plain numbers, else one repr of
    them all: the per-row cost was a sixth of a 1 kHz step, issue 23); the native loop's stretches are held as
    its doubles and spelt on a thread of the writer's own (cotwin.cosim.appender), in C without the GIL, while
    the next stretch runs. They go to `<name>.part` in whole lines, handed to that thread every `batch` rows,
    at most `flush_seconds` after a row was made and at the end (also of a failed run, whose rows are all
    written before the file is closed), so a crash loses at most that much and never leaves half a line. A
    run that ends well renames the file into place; a failed run leaves the previous result untouched and keeps its own rows in
    `<stem>.partial.csv` (`partial_path`), which the error names.
    """

    def __init__(self, path: str | Path, columns: list[tuple[str, str]] | None = None,
                 column_name: Callable[[str, str], str] | None = None, flush_seconds: float = 0.5,
                 batch: int = 256):
        self.path = Path(path)
        self.columns = columns
        self.column_name = column_name or (lambda unit, var: f"{unit}.{var}")
        self.flush_seconds = flush_seconds
        self.part = self.path.with_name(self.path.name + ".part")
        self.partial_path = self.path.with_name(f"{self.path.stem}.partial{self.path.suffix}")
        self.rows = 0
        self.kept_in: Path | None = None  # where the rows went when the run ended (result or partial file)
        self.written: int | None = None  # rows in that file when the run ended
        self._fd: int | None = None
        self._file: Appender | None = None  # writes the lines (bytes) and native _Stretch-es given, in order
        self._rows: list[tuple] = []  # (time, values...) of steps not yet formatted
        self.batch = batch
        self._last_flush = 0.0
        self._slots: list[int] | None = None  # the columns' slots (for rows the native loop made)

    def simulation_initialized(self, execution) -> None:
        self.columns = self.columns if self.columns is not None else execution.system.observed()
        if self.path.is_dir():  # found before the run, not when its rows are to be put in place
            raise CotwinError(f"{self.path} is a folder: cannot write the results there; move it or choose "
                              "another output")
        refuse_special(self.path)  # its rows are renamed over it at the end: a device would be replaced
        fd = open_exclusive(self.part)  # never through a link or a hard link planted at the .part name
        try:  # one writer per result file: another run writing it would interleave rows of its own
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise CotwinError(f"{self.path} is being written by another run; choose another output file or "
                              "wait for it to finish") from None
        os.ftruncate(fd, 0)
        self._fd = fd
        header = ["time"] + [self.column_name(u, v) for u, v in self.columns]
        self._read = execution.reader(list(self.columns))
        self._formats = column_formats(execution.system, list(self.columns))
        self._file = Appender(fd, self._spell, name=f"cotwin-csv {self.path.name}")
        self._file.put((",".join(_csv_cell(h) for h in header) + "\n").encode())
        self._row(execution)
        self._flush()

    def step_complete(self, execution) -> None:
        rows = self._rows
        rows.append((round(execution.time, 12), *self._read()))
        self.rows += 1
        if len(rows) >= self.batch or wallclock.monotonic() - self._last_flush >= self.flush_seconds:
            self._flush()

    def repeated(self, execution, rows) -> None:
        """The stretch's rows, as the doubles they are (after the rows held before them), handed to the writer's
        thread, which spells them (cotwin.cosim.rowtext, without the GIL) while the next stretch runs."""
        from .rowtext import available

        slots = self._slots if self._slots is not None else self._slot_list(execution)
        if not available():  # no C here: as step_complete holds them
            self._rows.extend((round(t, 12), *values) for t, values in zip(rows.times, rows.values(slots)))
            if len(self._rows) >= self.batch:
                self._flush()
        else:
            if self._rows:  # the rows before the stretch's (its steps told whole), then the stretch: spelt on the thread
                self._file.put(self._rows)
                self._rows = []
            self._file.put(_Stretch(rows.rows.copy(), slots, "".join(rows.kinds[i] for i in slots), rows.counted))
        self.rows += len(rows)

    def whole_changes(self, execution) -> tuple:
        return ()  # every row is written as it is

    def _slot_list(self, execution) -> list[int]:
        slots = execution.algorithm.slots
        self._slots = [slots[c] for c in self.columns]
        return self._slots

    def _row(self, execution) -> None:
        self._rows.append((round(execution.time, 12), *self._read()))
        self.rows += 1

    def _spell(self, piece: list | _Stretch) -> bytes:
        """Rows (time, values...) or a native stretch as lines (on the writer's thread)."""
        return piece.text(self._formats) if piece.__class__ is _Stretch else _rows_bytes(piece, self._formats)

    def _flush(self) -> None:
        """The rows held, as lines handed to the writer's thread."""
        if self._rows and self._file is not None:
            self._file.put(_rows_bytes(self._rows, self._formats))
            self._rows.clear()
        self._last_flush = wallclock.monotonic()

    def kept(self) -> str:
        """Where the rows of a run that failed or was interrupted are, for its error message (in the result file
        itself if the run ended as asked before the interrupt came)."""
        if self.rows and self.kept_in is not None and self.kept_in.is_file():
            if self.written is not None and self.written < self.rows:
                return (f"the first {self.written} of the {self.rows} row(s) computed are in {self.kept_in} (the file "
                        "took no more)")
            return f"the {self.rows} row(s) computed are in {self.kept_in}"
        return "no rows computed"

    def simulation_ended(self, execution, error: BaseException | None) -> None:
        if self._fd is None:
            return
        file, self._file = self._file, None
        failed: BaseException | None = None
        with signals_held():  # every row given is written before the file is closed and put in place
            try:
                if self._rows:
                    file.put(_rows_bytes(self._rows, self._formats))
                    self._rows.clear()
                file.drain()
            except Exception as err:  # a write failed: the rows written before it are kept, as a failed run's
                failed = err
            finally:
                file.stop()
        os.close(self._fd)
        self._fd = None
        self.written = max(0, file.lines - 1)  # the header's line aside
        self.kept_in = self.partial_path if error is not None or failed is not None else self.path
        os.replace(self.part, self.kept_in)
        if failed is not None:
            raise CotwinError(f"{self.path}: cannot write the results: {getattr(failed, 'strerror', None) or failed}") \
                from None
        if error is None and self.partial_path.is_file():  # an earlier failed run's rows: this run replaces them
            self.partial_path.unlink()


class _Stretch:
    """A native stretch's rows for a CSVWriter: the doubles (a copy), the columns' slots and kinds, and how
    its rows' times are counted (StepRows.counted), spelt by `text` when the file gets them."""

    __slots__ = ("rows", "slots", "kinds", "counted")

    def __init__(self, rows: np.ndarray, slots: list[int], kinds: str, counted: tuple[float, int, float]):
        self.rows, self.slots, self.kinds, self.counted = rows, slots, kinds, counted

    def text(self, formats: list[Callable[[object], str]]) -> bytes:
        from .rowtext import rows_text

        text = rows_text(self.rows, self.slots, self.kinds, counted=self.counted, encoded=True)
        if text is not None:
            return text
        origin, n, h = self.counted  # the C text failed: as StepRows gives the rows
        typed = {"b": lambda v: v != 0.0, "i": int, "r": float}
        values = [[typed[kind](v) for v in self.rows[:, slot].tolist()] for slot, kind in zip(self.slots, self.kinds)]
        rows = [(round(origin + (n + k) * h, 12), *row) for k, row in enumerate(zip(*values) if values else
                                                                                [()] * len(self.rows))]
        return _rows_bytes(rows, formats)


def _rows_bytes(rows: list[tuple], formats: list[Callable[[object], str]]) -> bytes:
    """Rows (time, values...) as lines: in C when every value is plain (_plain_rows_text), else by one repr of
    them all when every value is a plain float, int or bool (what FMU ports hold), else cell by cell
    (Maestro's spelling: format_value)."""
    if not rows:
        return b""
    text = _plain_rows_text(rows) if len(rows[0]) > 1 else None
    if text is not None:
        return text
    if len(rows[0]) > 1 and _PLAIN.issuperset(map(type, chain.from_iterable(rows))):
        text = repr(rows)  # "[(t, v, ...), (t, v, ...)]": Python's repr spells each number as Maestro does
        text = text[2:-2].replace("), (", "\n").replace(", ", ",").replace("True", "true").replace("False", "false")
        return (text + "\n").encode()
    lines = []
    for time, *values in rows:
        if _PLAIN.issuperset(map(type, values)):
            line = ",".join(map(repr, values)).replace("True", "true").replace("False", "false")
        else:  # None, numpy scalars, ...: cell by cell
            line = ",".join([f(v) for f, v in zip(formats, values)])
        lines.append(f"{time!r},{line}\n" if values else f"{time!r}\n")
    return "".join(lines).encode()


def _plain_rows_text(rows: list[tuple]) -> bytes | None:
    """Rows (time, values...) as lines made in C (cotwin.cosim.rowtext: repr's text, byte for byte) when every
    value is a bool, an int a double carries exactly or a float, each column of one class in all of them (what
    FMU ports hold); else None (then repr spells them): a row's repr cost 20 us, a tenth of a native stretch."""
    from .rowtext import rows_text

    classes = tuple(map(type, rows[0]))
    kinds = "".join(_KIND_OF.get(cls, "?") for cls in classes[1:])
    if classes[0] is not float or "?" in kinds or any(tuple(map(type, row)) != classes for row in rows[1:]):
        return None
    ints = [k + 1 for k, kind in enumerate(kinds) if kind == "i"]
    if any(abs(row[k]) > 2 ** 53 for row in rows for k in ints):
        return None
    values = np.array(rows, dtype=np.float64)
    return rows_text(values, list(range(1, len(classes))), kinds, times=values[:, 0], encoded=True)


def _real(value) -> str:
    return repr(value) if value.__class__ is float else format_value(value)


def _boolean(value) -> str:
    return ("true" if value else "false") if value is True or value is False else format_value(value)


def _integer(value) -> str:
    return str(value) if value.__class__ is int else format_value(value)


_PLAIN = frozenset((float, int, bool))  # what FMU ports hold; repr spells them as Maestro does, but Booleans
_KIND_OF = {bool: "b", int: "i", float: "r"}  # a value's kind in cotwin.cosim.rowtext
_FORMAT = {"Real": _real, "Boolean": _boolean, "Integer": _integer}


def column_formats(system, columns: list[tuple[str, str]]) -> list[Callable[[object], str]]:
    """A formatter per column, chosen once from the port's type (Maestro's spelling, see format_value)."""
    formats = []
    for unit, var in columns:
        port = system.units[unit].ports.get(var) if unit in system.units else None
        formats.append(_FORMAT.get(port.type if port else None, format_value))
    return formats


def _csv_cell(text: str) -> str:
    return '"' + text.replace('"', '""') + '"' if any(c in text for c in ',"\n') else text


class Progress(Observer):
    """Calls report(step, total) after every step."""

    def __init__(self, report: Callable[[int, int], None]):
        self.report = report

    def step_complete(self, execution) -> None:
        self.report(execution.steps, execution.total_steps)

    def repeated(self, execution, rows) -> None:
        return None  # the stretch's last step reports

    def whole_changes(self, execution) -> tuple:
        return ()


def epoch_of(units, now: float, slack: float = 1.0) -> float | None:
    """The wall-clock time (time.time()) of simulation time 0 announced by a unit (`epoch`, e.g. the
    RabbitMQ source's t0), kept within [now - slack, now] so that a far-off publisher clock cannot
    stall or rush the run; None when no unit announces one."""
    epochs = [u.epoch for u in units if u.epoch is not None]
    return min(max(min(epochs), now - slack), now) if epochs else None


class Pacer:
    """Keeps simulated time from running ahead of wall-clock time (scaled by `factor`): `begin` marks the
    epoch, `wait(t)` waits until factor * (wall time since the epoch) >= t - start. The epoch is when
    `begin` is called, or the wall time of simulation time 0 a unit announces (a live command source), so
    that a run keeps to the publisher's clock. One pacer for `cotwin run --realtime` (RealTimePacer) and
    the live twin (cotwin.twin.live.live_observers.Pacing)."""

    def __init__(self, factor: float = 1.0):
        if not (factor > 0 and math.isfinite(factor)):
            raise ValueError("the real-time factor must be a positive number")
        self.factor = factor
        self.started = 0.0
        self.start = 0.0

    def begin(self, units, start: float) -> None:
        """The epoch: now, or the wall time of simulation time 0 one of `units` announces; `start` the
        simulated time the run begins at."""
        self.start = start
        self.started = wallclock.perf_counter()
        epoch = epoch_of(units, wallclock.time())
        if epoch is not None:
            self.started -= wallclock.time() - epoch

    def wait(self, time: float) -> None:
        ahead = (time - self.start) / self.factor - (wallclock.perf_counter() - self.started)
        if ahead > 0:
            wallclock.sleep(ahead)


class RealTimePacer(Observer, Pacer):
    """A Pacer as an execution's observer: the epoch when the run was initialised, a wait after every step."""

    def simulation_initialized(self, execution) -> None:
        self.begin(execution.system.units.values(), execution.start)

    def step_complete(self, execution) -> None:
        self.wait(execution.time)

    def quiet_for(self, execution) -> int | None:
        return 1  # every step waits for its time as it is made: nothing runs ahead of the wall clock

    def repeated(self, execution, rows) -> None:
        for time in rows.times:  # (never more than the last step: see quiet_for)
            self.wait(time)

    def whole_changes(self, execution) -> tuple:
        return ()


class LiveFeed(Observer):
    """Publishes a sample {time, wall, values} per step to subscribers' bounded queues, never blocking
    the run: a subscriber that falls behind loses its oldest samples (counted in `dropped`)."""

    def __init__(self, variables: list[tuple[str, str]] | None = None, every: int = 1):
        self.variables = variables
        self.every = max(1, int(every))
        self.subscribers: list[queue.Queue] = []
        self.dropped = 0

    def subscribe(self, maxsize: int = 1000) -> queue.Queue:
        q: queue.Queue = queue.Queue(maxsize=maxsize)
        self.subscribers.append(q)
        return q

    def unsubscribe(self, q: queue.Queue) -> None:
        if q in self.subscribers:
            self.subscribers.remove(q)

    def simulation_initialized(self, execution) -> None:
        self.variables = self.variables if self.variables is not None else execution.system.observed()
        self._publish(execution)

    def step_complete(self, execution) -> None:
        if execution.steps % self.every == 0:
            self._publish(execution)

    def repeated(self, execution, rows) -> None:
        for _ in rows.replay(execution):  # it reads only the values on the connections
            self.step_complete(execution)

    def whole_changes(self, execution) -> tuple:
        return ()  # each row is published as it is

    def _publish(self, execution) -> None:
        if not self.subscribers:
            return
        values = execution.values
        sample = {"time": execution.time, "wall": wallclock.time(),
                  "values": {f"{u}.{v}": values.get((u, v)) for u, v in self.variables}}
        for q in list(self.subscribers):
            try:
                q.put_nowait(sample)
            except queue.Full:
                try:
                    q.get_nowait()
                    self.dropped += 1
                    q.put_nowait(sample)
                except (queue.Empty, queue.Full):
                    self.dropped += 1


class StateFile(Observer):
    """Saves the execution's state (cotwin.cosim.state bytes) to `path` after its last step, so that a
    what-if can start where the run ended (`cotwin whatif --from`). A system that cannot save its
    state (e.g. a remote robot) is noted in `skipped` and nothing is written. The file is made when the run
    starts (files.Reserved): a place it cannot be written fails the run before its first step, not after
    its last, and the run's end only writes it; a run that ends without saving leaves `path` as it was."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.skipped: str | None = None
        self._reserved: Reserved | None = None

    def simulation_initialized(self, execution) -> None:
        self._discard()
        self._reserved = Reserved(self.path)

    def step_complete(self, execution) -> None:
        if execution.total_steps and execution.steps >= execution.total_steps:
            self.save(execution)

    def repeated(self, execution, rows) -> None:
        return None  # never the last step: a stretch's last step comes to step_complete

    def whole_changes(self, execution) -> tuple:
        return ()

    def save(self, execution) -> None:
        try:
            blob = execution.get_state()
        except CotwinError as err:
            self.skipped = "; ".join(f.message for f in err.findings)
            return
        reserved, self._reserved = self._reserved, None
        if reserved is None:  # saved again, or outside a run
            write_bytes(self.path, blob)
        else:
            reserved.put(blob)

    def simulation_ended(self, execution, error: BaseException | None) -> None:
        self._discard()

    def _discard(self) -> None:
        if self._reserved is not None:
            self._reserved.discard()
            self._reserved = None
