"""Co-simulation units behind one interface: FMI 2.0 FMUs loaded with FMPy, and in-process Python units.

A unit has typed input and output ports, `initialize`, `set`, `step(t, h)`, `get` and `terminate`,
and saves and restores its whole state as bytes (`get_state`, `set_state`). Every FMI call of an
FMU goes through one checked path; a failure is raised as UnitError naming the unit, the time and
the call.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import shutil
import threading
import zipfile
import itertools
import logging
import weakref
from collections import deque
from ctypes import (POINTER, byref, c_bool, c_char_p, c_double, c_int, c_int64, c_size_t, c_uint, c_void_p,
                    create_string_buffer)
from ctypes import addressof, cast as ctypes_cast, string_at as ctypes_string_at
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path
from typing import Callable, Sequence

import fmpy
from fmpy import extract, read_model_description
from fmpy.fmi1 import printLogMessage
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)

from ..cache import Held, bound, hold
from ..diagnostics import CotwinError
from ..plaindata import PLAIN
from .state import fields, finite, of_type, pack, port_value, unpack
from .pythonfmu_exit import install as _release_pythonfmu_at_exit

_release_pythonfmu_at_exit()


INT32 = (-(2 ** 31), 2 ** 31 - 1)
log = logging.getLogger("cotwin.fmu")


class UnitError(CotwinError):
    def __init__(self, unit: str, time: float, call: str, detail: str):
        super().__init__(f"unit {unit}: {call} failed at t = {time:g} s: {detail}")
        self.unit, self.time, self.call, self.detail = unit, time, call, detail


def checked_value(unit: str, port: "Port", value) -> object:
    """`value` as the port's FMI type, or CotwinError naming the port: integers must fit int32 (never
    wrapped), reals must be finite numbers, Booleans must be Booleans (or 0/1)."""
    kind = port.type
    if kind == "Boolean":
        if isinstance(value, bool):
            return value
        if isinstance(value, int) and value in (0, 1):
            return bool(value)
    elif kind == "Integer":
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, int) and not isinstance(value, bool) and INT32[0] <= value <= INT32[1]:
            return value
        if isinstance(value, int) and not isinstance(value, bool):
            raise CotwinError(f"unit {unit}: {port.name} = {value} does not fit an FMI Integer (int32)")
    elif kind == "Real":
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            return float(value)
    raise CotwinError(f"unit {unit}: {port.name} takes a{'n' if kind[0] in 'IA' else ''} {kind}, "
                      f"not {value!r}" + (" (not finite)" if isinstance(value, float) else ""))


@dataclass(frozen=True)
class Port:
    name: str
    type: str  # Real | Integer | Boolean
    causality: str  # input | output | parameter


class Unit:
    """The interface the master drives.

    Besides `set` and `get` (dicts, for occasional use), a unit binds lists of ports once
    (`setter`, `getter`), which the algorithms call every step with values in that order. A unit's
    whole state can be saved as bytes (`get_state`) and restored into it or into another instance of
    the same unit (`set_state`), which is how a running twin is forked or rolled back.
    """

    name: str
    ports: dict[str, Port]

    # optional abilities, declared with what a unit without them has (nothing probes a unit with getattr)
    epoch: float | None = None  # wall time of simulation time 0, for a unit that keeps to a live clock
    restarts: Sequence[tuple[float, str]] = ()  # (time, what happened) of each restart from a saved state
    mapping = None  # an in-process mapping unit's runtime (cotwin.mapping.runtime): it can be asked
    executed: Sequence[tuple[float, str, dict]] = ()  # an in-process mapping unit's operations run
    command_queue = None  # a command source's commands not yet applied (cotwin.twin.assembly.commands.CommandQueue)
    ticks: int | None = None  # a clocked unit's clock ticks run so far (None: the unit has no clocks)

    def inputs(self) -> list[str]:
        return [p.name for p in self.ports.values() if p.causality == "input"]

    def outputs(self) -> list[str]:
        return [p.name for p in self.ports.values() if p.causality == "output"]

    def instantiate(self, start: float) -> None: ...
    def set(self, values: dict[str, object]) -> None: ...
    def initialize(self) -> None: ...
    def step(self, t: float, h: float) -> None: ...
    def get(self, names: list[str]) -> dict[str, object]: ...

    def native_part(self, execution):
        """Its step as C for the native loop (cotwin.cosim.native.NativePart), or why it has none (a str)."""
        return f"{type(self).__name__} has no native step"
    def terminate(self) -> None: ...

    def setter(self, names: list[str]) -> Callable[[Sequence], None]:
        """A function that sets these ports from a sequence of values in the same order."""
        names = list(names)
        return lambda values: self.set(dict(zip(names, values)))

    def getter(self, names: list[str]) -> Callable[[], Sequence]:
        """A function that returns the values of these ports, in the same order."""
        names = list(names)

        def read() -> list:
            values = self.get(names)
            return [values[n] for n in names]
        return read

    def get_state(self) -> bytes:
        """The unit's whole state (cotwin.cosim.state bytes)."""
        raise CotwinError(f"unit {self.name} cannot save its state")

    def set_state(self, state: bytes) -> None:
        """Continue from a state `get_state` returned (of this unit or another instance of it)."""
        raise CotwinError(f"unit {self.name} cannot restore a state")

    def checkpoint(self) -> object:
        """The unit's whole state kept in memory for `rollback` on this same unit (a fork restored plan after
        plan): its `get_state` bytes unless a unit keeps something cheaper."""
        return self.get_state()

    def rollback(self, checkpoint: object) -> None:
        """Continue from a `checkpoint` of this unit."""
        self.set_state(checkpoint)

    def forked(self) -> None:
        """This unit started afresh in a fork whose other units were then restored (Execution.set_state with
        `units`): what its initialisation showed in the event phase at the fork's time (cotwin.cosim.clocks) went to
        units since replaced by their saved state, whose instant had passed. A unit that keeps what it showed
        there (a command source's events) takes it back, to show it again from its first step; most have nothing
        to do."""


# FMI 2.0 status codes and the C prototypes of the calls made on every step (fmi2FunctionTypes.h)
FMI2_OK, FMI2_WARNING, FMI2_DISCARD, FMI2_ERROR, FMI2_FATAL, FMI2_PENDING = range(6)
STATUS = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending")
_VR = POINTER(c_uint)
BAD_INPUT = 3  # the native step's failure code for an input its setter would refuse

_PROTOTYPES = {
    "fmi2SetReal": (c_void_p, _VR, c_size_t, POINTER(c_double)),
    "fmi2SetInteger": (c_void_p, _VR, c_size_t, POINTER(c_int)),
    "fmi2SetBoolean": (c_void_p, _VR, c_size_t, POINTER(c_int)),
    "fmi2GetReal": (c_void_p, _VR, c_size_t, POINTER(c_double)),
    "fmi2GetInteger": (c_void_p, _VR, c_size_t, POINTER(c_int)),
    "fmi2GetBoolean": (c_void_p, _VR, c_size_t, POINTER(c_int)),
    "fmi2DoStep": (c_void_p, c_double, c_double, c_int),
    "fmi2SetupExperiment": (c_void_p, c_int, c_double, c_double, c_int, c_double),
    "fmi2EnterInitializationMode": (c_void_p,),
    "fmi2ExitInitializationMode": (c_void_p,),
    "fmi2Terminate": (c_void_p,),
    "fmi2GetFMUstate": (c_void_p, POINTER(c_void_p)),
    "fmi2SetFMUstate": (c_void_p, c_void_p),
    "fmi2FreeFMUstate": (c_void_p, POINTER(c_void_p)),
    "fmi2SerializedFMUstateSize": (c_void_p, c_void_p, POINTER(c_size_t)),
    "fmi2SerializeFMUstate": (c_void_p, c_void_p, c_char_p, c_size_t),
    "fmi2DeSerializeFMUstate": (c_void_p, c_char_p, c_size_t, POINTER(c_void_p)),
}
_C_TYPE = {"Real": c_double, "Integer": c_int, "Boolean": c_int}
_STATE_CALLS = ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize",
                "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate")


_LOGGING: dict[int, "weakref.ref[FMUUnit]"] = {}  # componentEnvironment -> the unit whose FMU logs


def _dispatch(env, instance, status, category, message) -> None:
    """The one logger of every FMU cotwin instantiates: the message goes to the unit named by the
    componentEnvironment; messages of FMUs FMPy instantiated itself are printed as FMPy does."""
    unit = _LOGGING.get(env or 0)
    unit = unit() if unit is not None else None
    if unit is not None:
        unit._log(status, category, message)
    else:
        printLogMessage(env, instance, status, category, message)


# One C callback for the whole process: FMPy's formatting proxy (which expands the FMU's printf-style
# arguments) keeps a single global logger, so per-unit callbacks would dangle when a unit is freed.
_LOGGER = fmi2CallbackLoggerTYPE(_dispatch)
_ENVIRONMENTS = itertools.count(1)


def _callbacks(unit: "FMUUnit") -> fmi2CallbackFunctions:
    env = next(_ENVIRONMENTS)
    _LOGGING[env] = weakref.ref(unit, lambda _, env=env: _LOGGING.pop(env, None))
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _LOGGER
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
    callbacks.componentEnvironment = env
    try:
        from fmpy.logging import addLoggerProxy

        addLoggerProxy(byref(callbacks))
    except Exception:  # noqa: BLE001 - without the proxy, messages arrive unformatted
        pass
    return callbacks


class _NotPlain(Exception):
    """A value that needs the full check (checked_value) before it goes to the FMU."""


def _reals(values: Sequence) -> Sequence:
    for v in values:
        if v.__class__ is not float or v - v != 0.0:  # not a float, or inf or nan
            raise _NotPlain
    return values


def _integers(values: Sequence) -> Sequence:
    for v in values:
        if v.__class__ is not int or not INT32[0] <= v <= INT32[1]:
            raise _NotPlain
    return values


def _booleans(values: Sequence) -> Sequence:
    for v in values:
        if v.__class__ is not bool:
            raise _NotPlain
    return values


_FAST_CHECK = {"Real": _reals, "Integer": _integers, "Boolean": _booleans}


class _Block:
    """Ports of one FMI type moved in one call: value references and values in preallocated C arrays."""

    def __init__(self, kind: str, names: list[str], positions: list[int], refs: list[int]):
        self.kind = kind
        self.names = names
        self.positions = positions  # where each port is in the bound list
        self.n = len(names)
        self.refs = (c_uint * self.n)(*refs)
        self.values = (_C_TYPE[kind] * self.n)()


class BoundByNames:
    """`set` and `get` of a unit that moves values through bound lists (`setter`, `getter`): one list bound
    per tuple of names, kept in `_setters` and `_getters`."""

    _setters: dict[tuple[str, ...], Callable]
    _getters: dict[tuple[str, ...], Callable]

    def set(self, values: dict[str, object]) -> None:
        names = tuple(values)
        write = self._setters.get(names)
        if write is None:
            write = self._setters[names] = self.setter(list(names))
        write(list(values.values()))

    def get(self, names: list[str]) -> dict[str, object]:
        names = tuple(names)
        read = self._getters.get(names)
        if read is None:
            read = self._getters[names] = self.getter(list(names))
        return dict(zip(names, read()))


_READING = threading.Lock()  # libxml2's schema parser (FMPy validates every model description) is not thread-safe


def model_description(path: str | Path):
    """FMPy's model description of the FMU at `path`, read (and validated) one thread at a time: a sweep's
    threads reading theirs at once corrupted libxml2's schema types for the rest of the process."""
    with _READING:
        return read_model_description(str(path))


def read_fmu(name: str, path: Path):
    """An FMU's model description, its ports (Real, Integer and Boolean inputs, outputs and parameters) by
    name and their value references; CotwinError naming unit `name` for a file that is no co-simulation FMU."""
    if not path.is_file():
        raise CotwinError(f"unit {name}: no FMU at {path}")
    try:
        md = model_description(path)
    except Exception as err:  # FMPy raises many kinds for a bad zip or XML
        raise CotwinError(f"unit {name}: cannot read {path}: {err}") from None
    if md.coSimulation is None:
        raise CotwinError(f"unit {name}: {path} is not a co-simulation FMU")
    ports, vr = {}, {}
    for v in md.modelVariables:
        if v.type in ("Real", "Integer", "Boolean") and v.causality in ("input", "output", "parameter"):
            ports[v.name] = Port(v.name, v.type, v.causality)
            vr[v.name] = v.valueReference
    return md, ports, vr


def can_save_state(md) -> bool:
    """Whether an FMU can get, set and serialise its state (both capability flags)."""
    cs = md.coSimulation
    return bool(cs.canGetAndSetFMUstate and cs.canSerializeFMUstate)


def fmu_state(md, serialized: bytes, time: float) -> bytes:
    """An FMU unit's state (cotwin.cosim.state bytes): the FMU's serialised bytes at `time`, with its GUID."""
    return pack("FMU", {"guid": md.guid, "model": md.modelName, "time": time, "fmu": serialized})


def _unpacked(path: Path, md, unzip_dir: str | None) -> tuple[str, bool, Held | None]:
    """Where an FMU's files are, whether they are this instance's own (removed at its end), and the hold on them
    when they are the cache's (released at its end). A cotwin-built FMU that may be instantiated more than once
    per process is extracted once per machine into cotwin's cache, under the digest of its bytes, and shared by
    every instance of it: its C keeps no state outside an instance and writes nothing into its folder, and
    extracting and removing its nine files cost each run about two milliseconds. The cached folder is held while an instance uses it (cotwin.cache.hold: the cache's bound never
    removes it); one removed between being found and held is extracted again. Any other FMU, no cache
    (COTWIN_CACHE=off), or a cache that cannot be written (read-only, full, a file) gets a folder of its own, as
    FMPy makes it: the cache is an optimisation, never a failure."""
    from ..files import cache_dir

    folder = cache_dir()
    if (unzip_dir is not None or folder is None or md.generationTool != "cotwin"
            or md.coSimulation is None or md.coSimulation.canBeInstantiatedOnlyOncePerProcess):
        return str(extract(str(path), unzip_dir)), True, None
    data = path.read_bytes()
    target = folder / "fmu" / hashlib.sha256(data).hexdigest()[:24]
    binary = target / "binaries" / fmpy.platform / f"{md.coSimulation.modelIdentifier}{fmpy.sharedLibraryExtension}"
    if binary.is_file():
        held = hold(target)
        if held is not None and binary.is_file():
            return str(target), False, held
        if held is not None:
            held.release()
    staged = target.with_name(f".{target.name}.{os.getpid()}.{threading.get_ident()}")
    shutil.rmtree(staged, ignore_errors=True)  # a killed run's with this process's and thread's id
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            archive.extractall(staged)
        os.replace(staged, target)  # whole, also when another process or thread extracts it at the same time
    except OSError:  # there already (another process or thread extracted it first: a folder is not replaced), or
        pass  # a cache that cannot be written
    finally:
        shutil.rmtree(staged, ignore_errors=True)
    held = hold(target) if binary.is_file() else None
    if held is None or not binary.is_file():  # not cached, or a folder of that name without the binary (damaged),
        if held is not None:  # or removed again at once: this instance's own
            held.release()
        return str(extract(str(path), None)), True, None
    bound(target)
    return str(target), False, held


class FMUUnit(BoundByNames, Unit):
    """An FMI 2.0 co-simulation FMU in this process: FMPy reads, extracts, loads and instantiates it;
    every call into the FMU then goes through `_call`, which checks the returned status. Values move
    through C arrays allocated once per bound list of ports, one call per FMI type and step."""

    unzip_dir: str | None = None  # where to extract the FMU (None: a temporary folder of FMPy's)

    def __init__(self, name: str, path: str | Path):
        self.name = name
        self.path = Path(path)
        self.md, self.ports, self.vr = read_fmu(name, self.path)
        self.fmu = None
        self.component = None
        self.folder = None
        self._own_folder = True  # removed at terminate (not a shared, cached extraction: see _unpacked)
        self._held = None  # the hold on a shared, cached extraction, released at terminate
        self.time = 0.0
        self.status = "new"  # new | instantiated | error | fatal
        self.messages: deque[tuple[str, str, str]] = deque(maxlen=50)  # (status, category, message) logged
        self._fresh = 0  # messages logged since the last failure was reported
        self._blocks: dict[tuple[str, ...], list[_Block]] = {}
        self._setters: dict[tuple[str, ...], Callable] = {}
        self._getters: dict[tuple[str, ...], Callable] = {}
        self._fn: dict[str, object] = {}
        self._memory: dict[int, tuple[object, int]] | None = None
        self._native_clock: c_double | None = None  # the step's time while a native stretch runs (its C writes it)

    # ---- the one path into the FMU ----
    def _call(self, call: str, fn, *args):
        """Every FMI call goes through here: an fmi2Status above fmi2Warning (returned, or raised by
        FMPy) becomes a UnitError naming the unit, the time, the call and what the FMU logged, and the
        unit remembers an fmi2Error or fmi2Fatal so that `terminate` only makes the calls FMI allows."""
        try:
            result = fn(*args)
        except Exception as err:  # FMPy raises FMICallException, ctypes and OS errors their own kinds
            self._failed(call, getattr(err, "status", None), str(err))
        if result.__class__ is int and result > FMI2_WARNING:
            self._failed(call, result, f"returned {STATUS[result] if result < len(STATUS) else result}")
        return result

    def _failed(self, call: str, status: int | None, detail: str):
        self.status = "fatal" if status == FMI2_FATAL else "error"
        logged = [m for _, _, m in list(self.messages)[len(self.messages) - self._fresh:]] if self._fresh else []
        self._fresh = 0
        if logged:
            detail = f"{detail}: {logged[-1]}"
        raise UnitError(self.name, self.time, call, detail)

    def _log(self, status: int, category: bytes | None, message: bytes | None) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        self.messages.append((STATUS[status] if 0 <= status < len(STATUS) else str(status),
                              category.decode("utf-8", "replace") if category else "", text))
        self._fresh = min(self._fresh + 1, self.messages.maxlen)
        if status == FMI2_WARNING:  # the FMU goes on but says something is not quite right: the user hears it
            now = self._native_clock.value if self._native_clock is not None else self.time  # inside a native stretch
            log.warning("unit %s at t = %g s: %s", self.name, now, text)

    def _bind_functions(self) -> None:
        """The FMU's C functions with their prototypes (our own function objects, not FMPy's)."""
        dll = self.fmu.dll
        self._setters.clear()  # bound to the previous library's functions
        self._getters.clear()
        optional = () if self.can_save_state else _STATE_CALLS
        for name, argtypes in _PROTOTYPES.items():
            try:
                fn = dll[name]
            except AttributeError:
                if name in optional:
                    continue
                self._failed("load", None, f"the binary has no function {name}")
            fn.argtypes = argtypes
            fn.restype = c_int
            self._fn[name] = fn

    def _port_memory(self) -> dict[int, tuple[object, int]] | None:
        """Where a cotwin-built FMU keeps each port's value (value reference -> (C array, index)), from
        its `cotwin_ports` extension; None for other FMUs."""
        try:
            fn = self.fmu.dll["cotwin_ports"]
        except AttributeError:
            return None
        fn.restype = c_size_t
        kind, slot = c_char_p(), POINTER(c_int)()
        arrays = {"r": POINTER(c_double)(), "i": POINTER(c_int64)(), "b": POINTER(c_bool)()}
        n = fn(c_void_p(self.component), byref(kind), byref(slot), byref(arrays["r"]), byref(arrays["i"]),
               byref(arrays["b"]))
        kinds = ctypes_string_at(kind, n).decode("ascii") if n else ""
        if n == 0 or len(kinds) != n or any(k not in arrays for k in kinds):
            return None
        memory = {vr: (arrays[kinds[vr]], slot[vr]) for vr in range(n)}
        expected = {"Real": "r", "Integer": "i", "Boolean": "b"}
        if any(memory.get(self.vr[p.name], (None,))[0] is not arrays[expected[p.type]] for p in self.ports.values()):
            return None  # the tables disagree with the model description: use FMI calls only
        return memory

    @property
    def can_save_state(self) -> bool:
        return can_save_state(self.md)

    # ---- life cycle ----
    def instantiate(self, start: float) -> None:
        self.time = start
        try:
            self.folder, self._own_folder, self._held = _unpacked(self.path, self.md, self.unzip_dir)
        except Exception as err:  # a bad zip
            raise UnitError(self.name, start, "extract", str(err)) from None
        self.fmu = self._call("load", lambda: FMU2Slave(
            guid=self.md.guid, unzipDirectory=self.folder, modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName=self.name))
        self._bind_functions()
        self.callbacks = _callbacks(self)  # kept alive as long as the instance
        try:
            self._call("fmi2Instantiate", lambda: self.fmu.instantiate(callbacks=self.callbacks))
        except UnitError:
            self.fmu.freeLibrary()
            self.fmu = None  # no instance: nothing to free
            raise
        self.component = self.fmu.component
        self.status = "instantiated"
        self._memory = self._port_memory()
        fn = self._fn
        self._call("fmi2SetupExperiment", fn["fmi2SetupExperiment"], self.component, 0, 0.0, start, 0, 0.0)
        self._call("fmi2EnterInitializationMode", fn["fmi2EnterInitializationMode"], self.component)

    def initialize(self) -> None:
        self._call("fmi2ExitInitializationMode", self._fn["fmi2ExitInitializationMode"], self.component)

    def step(self, t: float, h: float) -> None:
        self.time = t
        self._call("fmi2DoStep", self._fn["fmi2DoStep"], self.component, t, h, 1)

    def terminate(self) -> None:
        """End the instance as FMI 2.0 allows from its state: fmi2Terminate then fmi2FreeInstance when
        healthy, only fmi2FreeInstance after an fmi2Error, and no call at all after fmi2Fatal (the FMU's
        memory is then leaked rather than touched)."""
        if self.fmu is not None:
            if self.status == "instantiated":
                try:
                    self._call("fmi2Terminate", self._fn["fmi2Terminate"], self.component)
                except UnitError:
                    pass
            if self.status != "fatal":
                try:
                    self._call("fmi2FreeInstance", self.fmu.freeInstance)
                except UnitError:
                    pass
            self.fmu = None
            self.component = None
        if self.folder:
            if self._own_folder:
                shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None
        if self._held is not None:
            self._held.release()
            self._held = None

    # ---- port values ----
    def _plan(self, names: tuple[str, ...]) -> list[_Block]:
        """The ports grouped by FMI type into preallocated blocks, once per list of names (the master
        binds the same ports every step)."""
        blocks = self._blocks.get(names)
        if blocks is None:
            unknown = [n for n in names if n not in self.ports]
            if unknown:
                raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
            blocks = []
            for kind in ("Real", "Integer", "Boolean"):
                positions = [k for k, n in enumerate(names) if self.ports[n].type == kind]
                if positions:
                    chosen = [names[k] for k in positions]
                    blocks.append(_Block(kind, chosen, positions, [self.vr[n] for n in chosen]))
            self._blocks[names] = blocks
        return blocks

    def setter(self, names: list[str]) -> Callable[[Sequence], None]:
        """Values checked against their port's type (cheaply when they already have it) into the
        block's C array, one fmi2Set call per FMI type. Ports bound grouped by type (as the algorithms
        bind them) are taken as slices of the sequence. A cotwin-built FMU's values are written straight
        into its port arrays (no call at all)."""
        if self._memory is not None:
            return self._memory_setter(names)
        blocks = []
        for b in self._plan(tuple(names)):
            ports = [self.ports[n] for n in b.names]
            start = b.positions[0]
            contiguous = b.positions == list(range(start, start + b.n))
            blocks.append((b, ports, _FAST_CHECK[b.kind], self._fn[f"fmi2Set{b.kind}"], f"fmi2Set{b.kind}",
                           slice(start, start + b.n) if contiguous else None))
        unit, call = self.name, self._call

        def write(values: Sequence) -> None:
            for block, ports, fast, fn, name, part in blocks:
                chosen = values[part] if part is not None else [values[k] for k in block.positions]
                try:
                    block.values[:] = fast(chosen)
                except _NotPlain:
                    block.values[:] = [checked_value(unit, p, v) for p, v in zip(ports, chosen)]
                call(name, fn, self.component, block.refs, block.n, block.values)
        return write

    def getter(self, names: list[str]) -> Callable[[], Sequence]:
        """One fmi2Get call per FMI type into the block's C array; ports bound grouped by type come
        back as the arrays' values joined, others are placed one by one. A cotwin-built FMU's values
        are read straight from its port arrays."""
        if self._memory is not None:
            return self._memory_getter(names)
        blocks = [(b, self._fn[f"fmi2Get{b.kind}"], f"fmi2Get{b.kind}") for b in self._plan(tuple(names))]
        size, call = len(names), self._call
        in_order = [k for b, _, _ in blocks for k in b.positions] == list(range(size))
        if in_order:
            def read_grouped() -> list:
                out: list = []
                for block, fn, name in blocks:
                    values = block.values
                    call(name, fn, self.component, block.refs, block.n, values)
                    out += list(map(bool, values[:])) if block.kind == "Boolean" else values[:]
                return out
            return read_grouped

        def read() -> list:
            out = [None] * size
            for block, fn, name in blocks:
                call(name, fn, self.component, block.refs, block.n, block.values)
                values = block.values[:]
                if block.kind == "Boolean":
                    values = [v != 0 for v in values]
                for position, value in zip(block.positions, values):
                    out[position] = value
            return out
        return read

    def _memory_setter(self, names: list[str]) -> Callable[[Sequence], None]:
        self._plan(tuple(names))  # unknown names are an error here too
        kinds = {"Real": 0, "Integer": 1, "Boolean": 2}
        targets = [(*self._memory[self.vr[n]], self.ports[n], kinds[self.ports[n].type]) for n in names]
        unit, low, high = self.name, INT32[0], INT32[1]

        def write(values: Sequence) -> None:
            for (array, slot, port, kind), value in zip(targets, values):
                cls = value.__class__
                if (cls is float and value - value == 0.0) if kind == 0 else \
                        (cls is int and low <= value <= high) if kind == 1 else cls is bool:
                    array[slot] = value
                else:
                    array[slot] = checked_value(unit, port, value)
        return write

    def _memory_getter(self, names: list[str]) -> Callable[[], Sequence]:
        self._plan(tuple(names))
        sources = [self._memory[self.vr[n]] for n in names]
        return lambda: [array[slot] for array, slot in sources]

    def native_part(self, execution):
        """Its step for the native loop (cotwin.cosim.native): inputs written into a cotwin-built FMU's port
        arrays, fmi2DoStep called through its pointer, outputs read from the arrays; a reason (str) where it
        cannot (an FMU of another tool, which keeps its values its own way)."""
        from .native import NativePart, feeds, outputs

        if self._memory is None:
            return f"unit {self.name}'s FMU does not show its port arrays (not built by cotwin)"
        arrays: list = []

        def place(name: str) -> str:
            array, index = self._memory[self.vr[name]]
            if all(a is not array for a in arrays):
                arrays.append(array)
            k = next(i for i, a in enumerate(arrays) if a is array)
            kind = {"Real": "double", "Integer": "int64_t", "Boolean": "bool"}[self.ports[name].type]
            return f"(({kind} *)PP[{3 + k}])[{index}]"

        lines = []
        inputs = feeds(execution, self)
        for name, slot in inputs:  # checked as the setter checks them: a Real finite, an Integer an int32
            kind = self.ports[name].type
            if kind == "Real":
                lines.append(f"if (!(IN({slot}) - IN({slot}) == 0.0)) FAIL({BAD_INPUT});")
            elif kind == "Integer":
                lines.append(f"if (!(IN({slot}) >= {INT32[0]}.0 && IN({slot}) <= {INT32[1]}.0)) FAIL({BAD_INPUT});")
        for name, slot in inputs:
            kind = self.ports[name].type
            value = f"IN({slot})" if kind == "Real" else f"(int64_t)IN({slot})" if kind == "Integer" else f"(IN({slot}) != 0.0)"
            lines.append(f"{place(name)} = {value};")
        lines.append("*(double *)PP[2] = t;  /* the step's time, for what the FMU logs during it */")
        lines.append("{ int status = ((cotwin_do_step)PP[0])(PP[1], t, H, 1); if (status > 1) FAIL(10 + status); }")
        for name, slot in outputs(execution, self).items():
            kind = self.ports[name].type
            read = place(name)
            lines.append(f"N[{slot}] = " + (f"{read};" if kind == "Real" else f"(double){read};" if kind == "Integer"
                                             else f"{read} ? 1.0 : 0.0;"))
        do_step = ctypes_cast(self._fn["fmi2DoStep"], c_void_p).value
        clock = c_double(self.time)
        pointers = [do_step, self.component, addressof(clock),
                    *(ctypes_cast(a, c_void_p).value for a in arrays)]

        def begin() -> None:
            self._native_clock = clock

        def end(first: int, made: int, rows, doubles) -> None:
            self._native_clock = None
            if made:  # as `step` leaves it: the last step's start
                origin, done = execution._origin
                self.time = origin + (first + made - 1 - done) * execution.step_size

        def failed(code: int, t: float) -> None:
            self.time = t
            if code == BAD_INPUT:  # the setter says which input and why
                data = execution.algorithm.data
                self.setter([name for name, _ in inputs])([data[slot] for _, slot in inputs])
            status = code - 10
            self._failed("fmi2DoStep", status, f"returned {STATUS[status] if 0 <= status < len(STATUS) else status}")

        return NativePart("\n".join(lines), pointers=pointers, begin=begin, end=end, failed=failed,
                          writes=frozenset(outputs(execution, self)), takes=frozenset(name for name, _ in inputs),
                          sets_inputs=True)

    # ---- state ----
    def get_state(self) -> bytes:
        """fmi2GetFMUstate and fmi2SerializeFMUstate: the FMU's bytes, with its GUID and the unit's time."""
        return fmu_state(self.md, self.serialized(), self.time)

    def serialized(self) -> bytes:
        """The FMU's own serialised state (fmi2GetFMUstate, fmi2SerializeFMUstate)."""
        if not self.can_save_state:
            raise UnitError(self.name, self.time, "fmi2GetFMUstate", "the FMU cannot save and serialise its state "
                            "(canGetAndSetFMUstate and canSerializeFMUstate are not both true)")
        fn, handle = self._fn, c_void_p()
        self._call("fmi2GetFMUstate", fn["fmi2GetFMUstate"], self.component, byref(handle))
        try:
            size = c_size_t()
            self._call("fmi2SerializedFMUstateSize", fn["fmi2SerializedFMUstateSize"], self.component, handle,
                       byref(size))
            buffer = create_string_buffer(size.value)
            self._call("fmi2SerializeFMUstate", fn["fmi2SerializeFMUstate"], self.component, handle, buffer, size)
        finally:
            self._call("fmi2FreeFMUstate", fn["fmi2FreeFMUstate"], self.component, byref(handle))
        return buffer.raw

    def set_state(self, state: bytes) -> None:
        """fmi2DeSerializeFMUstate and fmi2SetFMUstate from bytes `get_state` returned for this FMU (its
        GUID; the FMU checks its own bytes)."""
        data = fields(unpack(state, "FMU"), f"unit {self.name}", ("guid", "time", "fmu"), ("model",))
        if not self.can_save_state:
            raise UnitError(self.name, self.time, "fmi2SetFMUstate", "the FMU cannot restore a state")
        saved = f"{str(data.get('model', '?'))[:60]} (GUID {str(data['guid'])[:60]})"
        if data["guid"] != self.md.guid:
            raise UnitError(self.name, self.time, "fmi2SetFMUstate", f"the state is of another FMU: {saved}, this "
                            f"unit runs {self.md.modelName} (GUID {self.md.guid})"
                            + (": another build of the same model (other sources or another cotwin)"
                               if data.get("model") == self.md.modelName else ""))
        time = finite(data["time"], f"unit {self.name}'s time")
        of_type(data["fmu"], bytes, f"unit {self.name}'s FMU state")
        self._set_serialized(data["fmu"])
        self.time = time

    def checkpoint(self) -> tuple[float, bytes]:
        """The unit's time and the FMU's own serialised state, not packed as a state file's are: `rollback` on
        this same unit takes them back as they are (its GUID is this FMU's)."""
        return self.time, self.serialized()

    def rollback(self, checkpoint: tuple[float, bytes]) -> None:
        time, raw = checkpoint
        self._set_serialized(raw)
        self.time = time

    def _set_serialized(self, raw: bytes) -> None:
        """fmi2DeSerializeFMUstate and fmi2SetFMUstate (the FMU checks its own bytes)."""
        fn, handle = self._fn, c_void_p()
        self._call("fmi2DeSerializeFMUstate", fn["fmi2DeSerializeFMUstate"], self.component, raw, len(raw),
                   byref(handle))
        try:
            self._call("fmi2SetFMUstate", fn["fmi2SetFMUstate"], self.component, handle)
        finally:
            self._call("fmi2FreeFMUstate", fn["fmi2FreeFMUstate"], self.component, byref(handle))


class PythonUnit(Unit):
    """An in-process unit: subclasses keep their port values in `self.values`.

    Its state is `snapshot()` (plain data: the port values and `time`, the time its last step reached,
    which subclasses keep; they add their own keys and extend `restore`), saved as bytes by `get_state`."""

    def __init__(self, name: str, ports: list[Port]):
        self.name = name
        self.ports = {p.name: p for p in ports}
        self.values: dict[str, object] = {p.name: (False if p.type == "Boolean" else 0) for p in ports}
        self.time = 0.0

    def instantiate(self, start: float) -> None:
        self.time = start

    def set(self, values: dict[str, object]) -> None:
        for name, value in values.items():
            if name not in self.ports:
                raise CotwinError(f"unit {self.name} has no port '{name}'")
            self.values[name] = value

    def initialize(self) -> None:
        pass

    def get(self, names: list[str]) -> dict[str, object]:
        return {n: self.values[n] for n in names}

    def setter(self, names: list[str]) -> Callable[[Sequence], None]:
        unknown = [n for n in names if n not in self.ports]
        if unknown:
            raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
        names = list(names)
        return lambda values: self.values.update(zip(names, values))

    def getter(self, names: list[str]) -> Callable[[], Sequence]:
        unknown = [n for n in names if n not in self.ports]
        if unknown:
            raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
        if not names:
            return lambda: ()
        pick = itemgetter(*names)
        if len(names) == 1:
            return lambda: (pick(self.values),)
        return lambda: pick(self.values)

    def terminate(self) -> None:
        pass

    # ---- state ----
    STATE_KEYS: tuple[str, ...] = ("values", "time")  # of a snapshot; subclasses add theirs

    def snapshot(self) -> dict:
        """The unit's state as plain data; subclasses add their own keys (STATE_KEYS)."""
        return {"values": dict(self.values), "time": self.time}

    def restore(self, snapshot: dict) -> None:
        """Continue from a snapshot, checked first: exactly STATE_KEYS, a value of its type for every port,
        a finite time (subclasses check their own keys, then call this). Values of ports this unit does not
        have are left out: a fork's unit may have fewer (its command source drives some of its events)."""
        what = f"unit {self.name}"
        fields(snapshot, what, self.STATE_KEYS)
        saved = fields(snapshot["values"], f"{what}'s values", list(self.ports), snapshot["values"])
        ports = self.ports
        if all(saved[name].__class__ in PLAIN.get(port.type, ()) for name, port in ports.items()):
            values = {name: saved[name] for name in ports}  # each a Python value of its type: nothing to say
        else:
            values = {name: port_value(saved[name], port.type, f"{what}'s {name}") for name, port in ports.items()}
        time = finite(snapshot["time"], f"{what}'s time")
        self.values.clear()  # in place: bound setters and getters keep working
        self.values.update(values)
        self.time = time

    def checkpoint(self) -> dict:
        """The snapshot itself (no bytes made). The contract that makes it safe: `snapshot` shares no mutable
        object with the live unit, and `restore` copies what it keeps or keeps only what the unit rebinds and
        never changes in place, so the runs that follow leave the checkpoint as it was (tests/test_fused.py)."""
        return self.snapshot()

    def rollback(self, checkpoint: dict) -> None:
        self.restore(checkpoint)

    def get_state(self) -> bytes:
        return pack(type(self).__name__, self.snapshot())

    def set_state(self, state: bytes) -> None:
        self.restore(unpack(state, type(self).__name__))
