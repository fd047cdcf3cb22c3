"""FMUs in a process of their own, behind the same Unit interface: what the FMU does to its process (a
memory fault, an abort, a corrupted heap, a loop that never returns) ends as a UnitError naming the
unit, the FMU, the FMI call it was in and the simulated time, and the co-simulation (its observers,
the rows written so far) goes on to close as after any unit error.

The worker is `python -m cotwin.cosim.isolated`, holding one FMUUnit. Parent and worker talk over two
pipes in frames of a fixed binary layout (an operation byte, a length, the payload), never pickle:
nothing the worker sends, whatever the FMU did to its memory, can run code in the master. Port values
cross as packed C numbers (a bound list of ports has a fixed struct layout), structure as JSON. One
step is one round trip: the inputs set since the last step go with the step request, and the answer
carries every bound output (and, when restarts are on, the FMU's serialised state). Which FMI call the
worker is in is kept in a page of memory shared with the parent, so that it survives the worker.

Every answer is awaited at most `timeout` seconds; a worker that does not answer in time is killed
and the call is reported as hanging. With `restart`, a failed step is retried once in a new worker
from the FMU's state after the last good step (FMUs that can get, set and serialise their state);
the restart is logged and recorded in `restarts`.

Why pipes (benchmarks/isolation.py, the three taking turns on the shared 2-core machine): a round trip
of 12 numbers each way costs 15-60 us, multiprocessing's Connection (pickle) 1.6-1.7x that, shared
memory with a one-byte pipe handshake 0-20 us less; all are two wake-ups of a process, and an isolated
step's 65-140 us are mostly Python on both sides, so a shared buffer would save little, while frames carry
answers of any size (states, errors) with no memory shared with the FMU's process but the call's name.
"""

from __future__ import annotations

import json
import logging
import mmap
import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time as wallclock
from pathlib import Path
from typing import Callable, Sequence

from ..diagnostics import CotwinError
from .state import unpack
from .units import (BoundByNames, FMUUnit, Port, Unit, UnitError, can_save_state, checked_value, fmu_state,
                    read_fmu)

DEFAULT_TIMEOUT = 30.0  # s an FMU call may take before its worker is stopped as hanging
MAX_FRAME = 1 << 30  # bytes of one request or answer (an FMU state): a larger length is a damaged worker
START_TIMEOUT = 120.0  # s for a worker to start (a Python process) and load its FMU
log = logging.getLogger("cotwin.isolated")

# operations (parent -> worker) and answers (worker -> parent)
INSTANTIATE, BIND, INITIALIZE, STEP, GET, GET_STATE, SET_STATE, TERMINATE = range(1, 9)
OK, ERROR = 0, 1
_FRAME = struct.Struct("<BI")  # operation, payload length
_STEP = struct.Struct("<ddB")  # t, h, send the state after the step (then the input blocks)
_BLOCK = struct.Struct("<HI")  # bound list id, bytes
_CODES = {"Real": "d", "Integer": "i", "Boolean": "?"}
_CALL_PAGE = 256  # bytes of the shared page naming the FMI call in progress
_SIGNALS = {signal.SIGSEGV: "a memory fault (SIGSEGV)", signal.SIGBUS: "a bus error (SIGBUS)",
            signal.SIGABRT: "an abort (SIGABRT)", signal.SIGFPE: "an arithmetic fault (SIGFPE)",
            signal.SIGILL: "an illegal instruction (SIGILL)", signal.SIGKILL: "SIGKILL (out of memory?)"}


class _Gone(Exception):
    """The worker's pipe closed, its answer did not come in time, or it was not a frame."""

    def __init__(self, hung: bool, malformed: str = ""):
        self.hung = hung
        self.malformed = malformed


def _write(fd: int, data: bytes, deadline: float) -> None:
    view = memoryview(data)
    while view:
        try:
            view = view[os.write(fd, view):]
        except BlockingIOError:
            _wait(fd, select.POLLOUT, deadline)
        except BrokenPipeError:
            raise _Gone(False) from None


def _wait(fd: int, events: int, deadline: float) -> None:
    poller = select.poll()
    poller.register(fd, events | select.POLLHUP | select.POLLERR)
    while True:
        left = deadline - wallclock.monotonic()
        if left <= 0:
            raise _Gone(True)
        if poller.poll(min(left, 3600.0) * 1000):
            return


def _read(fd: int, size: int, deadline: float | None) -> bytes:
    chunks, need = [], size
    while need:
        if deadline is not None:
            _wait(fd, select.POLLIN, deadline)
        chunk = os.read(fd, need)
        if not chunk:
            raise _Gone(False)
        chunks.append(chunk)
        need -= len(chunk)
    return b"".join(chunks)


def send(fd: int, op: int, payload: bytes = b"", deadline: float = float("inf")) -> None:
    _write(fd, _FRAME.pack(op, len(payload)) + payload, deadline)


def receive(fd: int, deadline: float | None = None) -> tuple[int, bytes]:
    op, size = _FRAME.unpack(_read(fd, _FRAME.size, deadline))
    if size > MAX_FRAME:
        raise _Gone(False, f"a frame of {size} bytes")
    return op, _read(fd, size, deadline) if size else b""


class _Bound:
    """A list of ports bound once (a setter's or a getter's): their struct layout and their ports."""

    def __init__(self, ident: int, ports: list[Port], step: bool):
        self.id = ident
        self.ports = ports
        self.step = step  # a getter whose values every step's answer brings
        self.layout = struct.Struct("<" + "".join(_CODES[p.type] for p in ports))


# ---- the parent's side ----

class IsolatedUnit(BoundByNames, Unit):
    """An FMI 2.0 co-simulation FMU run by a worker process (see the module doc)."""

    def __init__(self, name: str, path: str | Path, timeout: float = DEFAULT_TIMEOUT, restart: bool = False):
        if not timeout > 0:
            raise CotwinError(f"unit {name}: the timeout of its calls must be positive, got {timeout!r}")
        self.name = name
        self.path = Path(path)
        self.md, self.ports, _ = read_fmu(name, self.path)
        self.timeout = float(timeout)
        self.restart = restart
        self.time = 0.0
        self.start = 0.0
        self.restarts: list[tuple[float, str]] = []  # (time, what happened) of each restart
        self._worker: _Worker | None = None
        self._bound: list[_Bound] = []
        self._step_getters: list[_Bound] = []
        self._outputs_size = 0  # bytes of the step getters' values in a step's answer
        self._pending: dict[int, bytes] = {}  # inputs set since the last call that sent them
        self._outputs: dict[int, tuple] = {}  # bound getter -> its values after the last step
        self._fresh = False  # _outputs are the FMU's current outputs
        self._setters: dict[tuple[str, ...], Callable] = {}
        self._getters: dict[tuple[str, ...], Callable] = {}
        self._good: tuple[float, bytes] | None = None  # (time, FMU state) after the last good step

    @property
    def can_save_state(self) -> bool:
        return can_save_state(self.md)

    # ---- the worker ----
    def _call(self, op: int, payload: bytes = b"", call: str = "", timeout: float | None = None) -> bytes:
        """One request and its answer; the worker's UnitError raised here as it was there; a worker that
        dies or does not answer becomes a UnitError saying what happened to its process."""
        worker = self._worker
        if worker is None:
            raise UnitError(self.name, self.time, call or "call", "the unit is not running (instantiate it first)")
        deadline = wallclock.monotonic() + (self.timeout if timeout is None else timeout)
        try:
            send(worker.to_worker, op, payload, deadline)
            answer, body = receive(worker.from_worker, deadline)
            if answer not in (OK, ERROR):
                raise _Gone(False, f"an answer of kind {answer}")
        except _Gone as gone:
            self._worker = None
            raise worker.lost(self, call, gone.hung, gone.malformed) from None
        except BaseException:  # an interrupt while the worker works: it is stopped, not waited for
            self._worker = None
            worker.stop()
            raise
        if answer == OK:
            return body
        try:
            error = json.loads(body.decode("utf-8"))
        except ValueError:
            error = {}
        detail = str(error.get("detail", "the FMU's worker sent an unreadable error"))[:4000]
        if error.get("call"):
            raise UnitError(self.name, self.time, str(error["call"])[:80], detail)
        raise CotwinError(detail)

    def instantiate(self, start: float) -> None:
        self.start = self.time = start
        self._worker = _Worker.start(self)
        body = json.dumps({"name": self.name, "path": str(self.path.resolve()), "start": start,
                           "folder": self._worker.folder}).encode()
        self._call(INSTANTIATE, body, "fmi2Instantiate", max(self.timeout, START_TIMEOUT))
        for bound in self._bound:  # a restarted worker: the same lists, bound again
            self._bind(bound)
        if self.restart and not self.can_save_state:
            log.warning("unit %s: its FMU %s cannot save its state (canGetAndSetFMUstate and canSerializeFMUstate "
                        "are not both true): a failure ends the run, it cannot be restarted", self.name, self.path.name)

    def _bind(self, bound: _Bound) -> None:
        self._call(BIND, json.dumps({"id": bound.id, "names": [p.name for p in bound.ports], "step": bound.step}).encode(),
                   "bind")

    def _new_bound(self, names: Sequence[str], step: bool = False) -> _Bound:
        unknown = [n for n in names if n not in self.ports]
        if unknown:
            raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
        bound = _Bound(len(self._bound), [self.ports[n] for n in names], step)
        self._bind(bound)
        self._bound.append(bound)
        if step:
            self._step_getters.append(bound)
            self._outputs_size += bound.layout.size
        return bound

    def setter(self, names: list[str]) -> Callable[[Sequence], None]:
        """Values checked as FMUUnit checks them, packed and kept until the next call to the worker."""
        bound = self._new_bound(names)
        kinds = [(p, p.type) for p in bound.ports]
        pack, pending, unit = bound.layout.pack, self._pending, self.name

        def write(values: Sequence) -> None:
            checked = []
            for (port, kind), value in zip(kinds, values):
                cls = value.__class__
                if not ((cls is float and value - value == 0.0) if kind == "Real" else
                        (cls is int and -2 ** 31 <= value < 2 ** 31) if kind == "Integer" else cls is bool):
                    value = checked_value(unit, port, value)
                checked.append(value)
            pending[bound.id] = pack(*checked)
            self._fresh = False
        return write

    def getter(self, names: list[str]) -> Callable[[], Sequence]:
        """The values the last step's answer brought (no call), else asked for."""
        bound = self._new_bound(names, step=True)

        def read() -> Sequence:
            if self._fresh:
                return self._outputs[bound.id]
            body = self._call(GET, struct.pack("<H", bound.id) + self._inputs(), "fmi2Get")
            if len(body) != bound.layout.size:
                raise UnitError(self.name, self.time, "fmi2Get", f"the FMU {self.path.name}'s worker answered "
                                f"{len(body)} bytes for {bound.layout.size} (a damaged process)")
            return bound.layout.unpack(body)
        return read

    def _inputs(self) -> bytes:
        """The pending inputs as blocks (sent with the next call, then forgotten)."""
        blocks = [_BLOCK.pack(k, len(v)) + v for k, v in self._pending.items()]
        self._pending.clear()
        return struct.pack("<H", len(blocks)) + b"".join(blocks)

    def initialize(self) -> None:
        self._call(INITIALIZE, self._inputs(), "fmi2ExitInitializationMode")
        self._fresh = False
        if self.restart and self.can_save_state:
            self._good = (self.time, unpack(self.get_state(), "FMU")["fmu"])

    def step(self, t: float, h: float) -> None:
        self.time = t
        inputs = dict(self._pending)
        try:
            self._step(t, h)
        except UnitError as err:
            if not self.restart or self._good is None:
                if self.restart:
                    raise UnitError(self.name, t, err.call, f"{err.detail}; it cannot be restarted from a state: "
                                    f"its FMU cannot save one") from None
                raise
            self._restart(err, inputs)
            try:
                self._step(t, h)
            except UnitError as again:
                raise UnitError(self.name, t, again.call, f"{again.detail} (again after a restart from its state "
                                f"at t = {self._good[0]:g} s)") from None

    def _step(self, t: float, h: float) -> None:
        checkpoint = self.restart and self._good is not None
        blocks = self._inputs()
        body = self._call(STEP, _STEP.pack(t, h, checkpoint) + blocks, "fmi2DoStep")
        if len(body) < self._outputs_size or (not checkpoint and len(body) != self._outputs_size):
            self._worker.stop()
            self._worker = None
            raise UnitError(self.name, t, "fmi2DoStep", f"the FMU {self.path.name}'s worker answered {len(body)} bytes "
                            f"for {self._outputs_size} bytes of outputs (a damaged process); it was stopped")
        at = 0
        for bound in self._step_getters:
            size = bound.layout.size
            self._outputs[bound.id] = bound.layout.unpack(body[at:at + size])
            at += size
        self._fresh = True
        if checkpoint:
            self._good = (t + h, body[at:])  # the FMU's serialised bytes: a state when it is needed

    def _restart(self, err: UnitError, inputs: dict[int, bytes]) -> None:
        """A new worker continuing from the last good state, this step's inputs set again."""
        good_time, state = self._good
        if self._worker is not None:
            self._worker.stop()
            self._worker = None
        message = (f"unit {self.name}: {err.call} failed at t = {err.time:g} s ({err.detail}); restarted its FMU "
                   f"{self.path.name} from its state at t = {good_time:g} s")
        log.warning("%s", message)
        self.restarts.append((err.time, message))
        self.instantiate(self.start)
        self._call(INITIALIZE, self._inputs(), "fmi2ExitInitializationMode")
        self._call(SET_STATE, fmu_state(self.md, state, good_time), "fmi2SetFMUstate")
        self.time = err.time
        self._pending.update(inputs)
        self._fresh = False

    def terminate(self) -> None:
        worker, self._worker = self._worker, None
        if worker is None:
            return
        try:
            deadline = wallclock.monotonic() + min(self.timeout, 10.0)
            send(worker.to_worker, TERMINATE, b"", deadline)
            receive(worker.from_worker, deadline)
        except (_Gone, OSError):
            pass
        worker.stop()

    # ---- state: the FMU's own (FMUUnit's format, so the two restore each other's) ----
    def get_state(self) -> bytes:
        if not self.can_save_state:
            raise UnitError(self.name, self.time, "fmi2GetFMUstate", "the FMU cannot save and serialise its state "
                            "(canGetAndSetFMUstate and canSerializeFMUstate are not both true)")
        return self._call(GET_STATE, self._inputs(), "fmi2GetFMUstate")

    def set_state(self, state: bytes) -> None:
        self._call(SET_STATE, bytes(state), "fmi2SetFMUstate")
        self._fresh = False
        self.time = float(unpack(state, "FMU")["time"])  # checked by the worker's FMUUnit


class _Worker:
    """A worker process, its pipes, the page naming its FMI call and where its output goes."""

    def __init__(self, process, to_worker: int, from_worker: int, page: mmap.mmap, output, folder: str):
        self.process, self.to_worker, self.from_worker = process, to_worker, from_worker
        self.page, self.output, self.folder = page, output, folder

    @classmethod
    def start(cls, unit: IsolatedUnit) -> "_Worker":
        down_r, down_w = os.pipe()
        up_r, up_w = os.pipe()
        page_fd = os.memfd_create("cotwin-call")
        os.ftruncate(page_fd, _CALL_PAGE)
        output = tempfile.TemporaryFile(prefix="cotwin-unit-")
        folder = tempfile.mkdtemp(prefix="cotwin-isolated-")
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        try:
            process = subprocess.Popen(
                [sys.executable, "-m", "cotwin.cosim.isolated", str(down_r), str(up_w), str(page_fd)],
                pass_fds=(down_r, up_w, page_fd), stdin=subprocess.DEVNULL, stdout=output, stderr=output, env=env,
                start_new_session=True)  # the master decides when it ends (an interrupt goes to the master)
        except OSError as err:
            for fd in (down_r, down_w, up_r, up_w, page_fd):
                os.close(fd)
            raise UnitError(unit.name, unit.time, "start", f"cannot start a process for its FMU: {err}") from None
        os.close(down_r)
        os.close(up_w)
        os.set_blocking(down_w, False)
        page = mmap.mmap(page_fd, _CALL_PAGE)
        os.close(page_fd)
        return cls(process, down_w, up_r, page, output, folder)

    def call(self) -> str | None:
        """The FMI call the worker is in (None between requests), from the shared page."""
        size = self.page[0]
        return bytes(self.page[1:1 + size]).decode("ascii", "replace") if 0 < size < _CALL_PAGE else None

    def said(self) -> str:
        """The last lines the worker's process wrote (the FMU's or the C library's own words)."""
        self.output.seek(0, os.SEEK_END)
        size = self.output.tell()
        self.output.seek(max(0, size - 2000))
        lines = [line.strip() for line in self.output.read().decode("utf-8", "replace").splitlines() if line.strip()]
        return " / ".join(lines[-3:])[-500:]

    def lost(self, unit: IsolatedUnit, call: str, hung: bool, malformed: str = "") -> UnitError:
        """The error of a worker that did not answer: stopped if it hangs, and what ended its process."""
        call = self.call() or call
        words = self.said()
        if malformed:
            self.stop()
            what = f"made its process answer with {malformed}, not a frame of cotwin's (a damaged process); it was stopped"
        elif hung:
            self.stop()
            what = f"did not return within {unit.timeout:g} s (a hang?); its process was stopped"
        else:
            try:
                code = self.process.wait(10)
            except subprocess.TimeoutExpired:
                code = None
            self.stop()
            if code is None:
                what = "closed its connection to the master"
            elif code < 0:
                what = f"crashed its process with {_SIGNALS.get(-code, f'signal {-code}')}"
            else:
                what = f"ended its process (exit status {code})"
        return UnitError(unit.name, unit.time, call, f"the FMU {unit.path.name} {what}"
                         + (f"; it wrote: {words}" if words else ""))

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        for fd in (self.to_worker, self.from_worker):
            try:
                os.close(fd)
            except OSError:
                pass
        self.to_worker = self.from_worker = -1
        self.output.close()
        shutil.rmtree(self.folder, ignore_errors=True)


def fmu_unit(name: str, path: str | Path, isolate: bool | None = None, timeout: float = DEFAULT_TIMEOUT,
             restart: bool = False) -> Unit:
    """The unit of an FMU: isolated (`isolate`; by default, every FMU cotwin did not build: its
    modelDescription's generationTool does not start with "cotwin"; always with `restart`, which needs a
    process to replace) or in this process."""
    if isolate is None or restart:
        isolate = restart or not built_by_cotwin(name, Path(path))
    return IsolatedUnit(name, path, timeout, restart) if isolate else FMUUnit(name, path)


def built_by_cotwin(name: str, path: Path) -> bool:
    md, _, _ = read_fmu(name, path)
    return (md.generationTool or "").startswith("cotwin")


# ---- the worker's side ----

class _Recorded(FMUUnit):
    """An FMUUnit that writes the name of every FMI call it makes to the shared page first."""

    page: mmap.mmap

    def _call(self, call: str, fn, *args):
        name = call.encode("ascii", "replace")[:_CALL_PAGE - 1]
        self.page[1:1 + len(name)] = name
        self.page[0] = len(name)
        return super()._call(call, fn, *args)


def _values(unit: FMUUnit, bound: dict, body: bytes, at: int) -> int:
    """Apply the input blocks in `body` from `at`; where they end."""
    (count,) = struct.unpack_from("<H", body, at)
    at += 2
    for _ in range(count):
        ident, size = _BLOCK.unpack_from(body, at)
        at += _BLOCK.size
        layout, write = bound[ident][0], bound[ident][1]
        write(list(layout.unpack(body[at:at + size])))
        at += size
    return at


def serve(requests: int, answers: int, page_fd: int) -> None:
    """The worker's loop: one request, one answer, until TERMINATE or the master is gone."""
    page = mmap.mmap(page_fd, _CALL_PAGE)
    unit: _Recorded | None = None
    bound: dict[int, tuple] = {}  # id -> (layout, setter, getter)
    step_getters: list[int] = []
    while True:
        try:
            op, body = receive(requests)
        except _Gone:
            break
        try:
            if op == INSTANTIATE:
                spec = json.loads(body)
                unit = _Recorded(spec["name"], spec["path"])
                unit.page, unit.unzip_dir = page, spec["folder"]
                unit.instantiate(spec["start"])
                answer = b""
            elif op == BIND:
                spec = json.loads(body)
                ports = [unit.ports[n] for n in spec["names"]]
                layout = struct.Struct("<" + "".join(_CODES[p.type] for p in ports))
                bound[spec["id"]] = (layout, unit.setter(spec["names"]), unit.getter(spec["names"]))
                if spec["step"]:
                    step_getters.append(spec["id"])
                answer = b""
            elif op == INITIALIZE:
                _values(unit, bound, body, 0)
                unit.initialize()
                answer = b""
            elif op == STEP:
                t, h, checkpoint = _STEP.unpack_from(body)
                _values(unit, bound, body, _STEP.size)
                unit.step(t, h)
                out = [bound[k][0].pack(*bound[k][2]()) for k in step_getters]
                if checkpoint:
                    out.append(unit.serialized())
                answer = b"".join(out)
            elif op == GET:
                (ident,) = struct.unpack_from("<H", body)
                _values(unit, bound, body, 2)
                answer = bound[ident][0].pack(*bound[ident][2]())
            elif op == GET_STATE:
                _values(unit, bound, body, 0)
                answer = unit.get_state()
            elif op == SET_STATE:
                unit.set_state(body)
                answer = b""
            elif op == TERMINATE:
                unit.terminate()
                send(answers, OK)
                break
            else:
                raise CotwinError(f"unknown request {op}")
            page[0] = 0  # no FMI call in progress
            send(answers, OK, answer)
        except UnitError as err:
            page[0] = 0
            send(answers, ERROR, json.dumps({"call": err.call, "detail": err.detail}).encode())
        except CotwinError as err:
            page[0] = 0
            send(answers, ERROR, json.dumps({"detail": "; ".join(f.message for f in err.findings)}).encode())
        except Exception as err:  # noqa: BLE001 - the master reports it; the worker serves on
            page[0] = 0
            send(answers, ERROR, json.dumps({"detail": f"{type(err).__name__}: {err}"}).encode())


if __name__ == "__main__":
    serve(int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]))
