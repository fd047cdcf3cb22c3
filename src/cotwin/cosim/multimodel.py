"""Maestro multimodel JSON in: units, connections, parameters, logged variables, algorithm, times.

Maestro ignores unknown keys, so a typo passes silently there; here unknown keys, malformed ports
(`{key}.instance.variable`) and ports the FMUs do not have are reported together, with the file.
The key `cotwin` (ignored by Maestro) may hold {"delayed": [units], "algorithm": "gauss-seidel",
"isolate": {"{key}.instance": true}, "unit_timeout": seconds}: which FMU instances run in a process of
their own (cotwin.cosim.isolated; by default those cotwin did not build) and how long their calls may take.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from .. import safejson
from ..diagnostics import CotwinError, Finding, Location, Severity
from ..files import read_text
from .algorithm import ALGORITHMS, algorithm as make_algorithm
from .execution import Execution
from .observers import CSVWriter, Observer, RealTimePacer
from .system import Connection, System
from .fmi3 import DEFAULT_TIMEOUT, fmu_unit

KNOWN_KEYS = {"fmus", "connections", "parameters", "logVariables", "algorithm", "startTime", "endTime",
              "simulationProgramDelay", "cotwin", "livestream", "overrideLogLevel", "loggingOn", "visible",
              "parallelSimulation", "stabalizationEnabled", "global_absolute_tolerance", "global_relative_tolerance"}
PORT = re.compile(r"^(\{[^}]+\})\.([A-Za-z_][\w]*)\.(.+)$")


@dataclass
class MultiModel:
    path: Path
    fmus: dict[str, Path]
    connections: list[tuple[str, str, str, str, str, str]]  # (key, inst, var) -> (key, inst, var)
    parameters: dict[tuple[str, str], dict[str, object]]
    log: dict[tuple[str, str], list[str]]
    step: float
    start: float
    end: float
    realtime: bool
    algorithm: str = "jacobi"
    delayed: set[tuple[str, str]] = field(default_factory=set)
    isolate: dict[tuple[str, str], bool] = field(default_factory=dict)  # instance -> in a process of its own
    unit_timeout: float = DEFAULT_TIMEOUT  # s an isolated FMU's call may take

    @property
    def instances(self) -> list[tuple[str, str]]:
        seen = []
        for c in self.connections:
            for inst in ((c[0], c[1]), (c[3], c[4])):
                if inst not in seen:
                    seen.append(inst)
        for inst in (*self.parameters, *self.log):
            if inst not in seen:
                seen.append(inst)
        return seen


def read_multimodel(path: str | Path) -> MultiModel:
    path = Path(path)
    problems: list[tuple[str, str | None]] = []  # (message, the JSON string it is about)
    text = read_text(path, "multimodel")  # capped; located errors
    try:
        data = safejson.decode(text)  # a key twice, a number of 5000 digits: refused, not one value chosen or a crash
    except safejson.Refused as err:  # at the refused number, constant or key where it can be found, else the start
        line, column = (safejson.position(text, err.token, err.nth) if err.token else None) or (1, 1)
        raise CotwinError([Finding(Location(str(path), line, column), Severity.ERROR, f"bad JSON: {err}")]) from None
    except RecursionError:
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR, "bad JSON: nested too deeply")]) from None
    except json.JSONDecodeError as err:
        raise CotwinError([Finding(Location(str(path), err.lineno, err.colno), Severity.ERROR, f"bad JSON: {err.msg}")]) from None
    if not isinstance(data, dict):
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR, "a multimodel is a JSON object")])
    for key in data:
        if key not in KNOWN_KEYS:
            problems.append((f"unknown key '{key}' (Maestro would ignore it silently)", key))
    fmus = {}
    for key, file in _section(data, "fmus", dict, problems).items():
        if not re.fullmatch(r"\{[^}]+\}", key):
            problems.append((f"fmus: key '{key}' must look like '{{name}}'", key))
        if not isinstance(file, str):
            problems.append((f"fmus: '{key}' must name an FMU file, not {type(file).__name__}", key))
            continue
        fmus[key] = (path.parent / file) if not Path(file).is_absolute() else Path(file)
        try:
            found = fmus[key].is_file()
        except OSError as err:  # e.g. a name longer than the file system takes
            problems.append((f"fmus: {key}: cannot look for {str(fmus[key])[:120]}: {err.strerror}", file))
            continue
        if not found:
            problems.append((f"fmus: {key}: no file {str(fmus[key])[:200]}", file))

    def port(text: str, where: str):
        m = PORT.match(text) if isinstance(text, str) else None
        if m is None:
            problems.append((f"{where}: '{text}' is not a port '{{key}}.instance.variable'", text))
            return None
        if m.group(1) not in fmus:
            problems.append((f"{where}: '{text}' names FMU {m.group(1)}, which 'fmus' does not list", text))
            return None
        return m.group(1), m.group(2), m.group(3)

    connections = []
    for out, targets in _section(data, "connections", dict, problems).items():
        src = port(out, "connections")
        for target in targets if isinstance(targets, list) else [targets]:
            dst = port(target, "connections")
            if src and dst:
                connections.append((*src, *dst))
    parameters: dict[tuple[str, str], dict] = {}
    for name, value in _section(data, "parameters", dict, problems).items():
        p = port(name, "parameters")
        if not isinstance(value, (bool, int, float, str)):
            problems.append((f"parameters: '{name}' must be a number, a Boolean or a string, got {json.dumps(value)[:60]}",
                             name))
        elif p:
            parameters.setdefault(p[:2], {})[p[2]] = value
    log: dict[tuple[str, str], list[str]] = {}
    for inst, names in _section(data, "logVariables", dict, problems).items():
        m = re.match(r"^(\{[^}]+\})\.([A-Za-z_]\w*)$", inst)
        if m is None or m.group(1) not in fmus:
            problems.append((f"logVariables: '{inst}' is not a known '{{key}}.instance'", inst))
            continue
        log[(m.group(1), m.group(2))] = _section(data["logVariables"], inst, list, problems, "logVariables", str)
    algorithm = _section(data, "algorithm", dict, problems)
    if algorithm.get("type", "fixed-step") != "fixed-step":
        problems.append(("algorithm: only {'type': 'fixed-step', 'size': seconds} is supported", "algorithm"))
    extra = _section(data, "cotwin", dict, problems)
    if extra.get("algorithm", "jacobi") not in ALGORITHMS:
        problems.append((f"cotwin.algorithm must be one of {', '.join(ALGORITHMS)}, got {extra['algorithm']!r}",
                         "algorithm"))
    delayed = set()
    for inst in _section(extra, "delayed", list, problems, "cotwin", str):
        m = re.match(r"^(\{[^}]+\})\.([A-Za-z_]\w*)$", inst)
        if m:
            delayed.add((m.group(1), m.group(2)))
        else:
            problems.append((f"cotwin.delayed: '{inst}' is not a '{{key}}.instance'", inst))
    isolate: dict[tuple[str, str], bool] = {}
    for inst, value in (extra.get("isolate") or {}).items() if isinstance(extra.get("isolate") or {}, dict) else ():
        m = re.match(r"^(\{[^}]+\})\.([A-Za-z_]\w*)$", inst)
        if m is None or m.group(1) not in fmus or not isinstance(value, bool):
            problems.append((f"cotwin.isolate: '{inst}' is not a '{{key}}.instance' of a listed FMU with true or false", inst))
        else:
            isolate[(m.group(1), m.group(2))] = value
    if not isinstance(extra.get("isolate") or {}, dict):
        problems.append(("cotwin.isolate: a table {\"{key}.instance\": true or false}", "isolate"))
    timeout = extra.get("unit_timeout", DEFAULT_TIMEOUT)
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not 0 < timeout < math.inf:
        problems.append((f"cotwin.unit_timeout must be a positive number of seconds, got {timeout!r}", "unit_timeout"))
    problems.extend(_phantoms(connections, log))
    for key, value in (("startTime", data.get("startTime", 0.0)), ("endTime", data.get("endTime", 10.0)),
                       ("algorithm.size", algorithm.get("size", 0.1))):
        if not _number(value):
            problems.append((f"{key} must be a finite number, got {value!r}", key.split(".")[-1]))
    if _number(algorithm.get("size")) and not algorithm["size"] > 0:
        problems.append((f"algorithm.size must be positive, got {algorithm['size']!r}", "size"))
    if not isinstance(data.get("simulationProgramDelay", False), bool):
        problems.append((f"simulationProgramDelay must be true or false, got {data['simulationProgramDelay']!r}", "simulationProgramDelay"))
    if not problems:  # a span the master can keep exactly, said at endTime (the CLI's --step/--end are checked apart)
        from .execution import step_count

        try:
            step_count(float(data.get("endTime", 10.0)) - float(data.get("startTime", 0.0)), float(algorithm.get("size", 0.1)))
        except CotwinError as err:
            problems.append((f"endTime {data.get('endTime', 10.0)!r} after startTime {data.get('startTime', 0.0)!r}: "
                             f"{err.findings[0].message}", "endTime"))
    if problems:
        raise CotwinError([Finding(Location(str(path), *_place(text, needle)), Severity.ERROR, message)
                           for message, needle in problems])
    return MultiModel(path, fmus, connections, parameters, log, float(algorithm.get("size", 0.1)),
                      float(data.get("startTime", 0.0)), float(data.get("endTime", 10.0)),
                      bool(data.get("simulationProgramDelay", False)), extra.get("algorithm", "jacobi"), delayed,
                      isolate, float(timeout))


def _number(value) -> bool:
    """A JSON number that is finite (not a Boolean, which Python counts as an int)."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def _section(table: dict, key: str, kind: type, problems: list, within: str = "", item: type | None = None):
    """`table[key]` when it is a `kind` (an object or a list, of `item`s), else empty with a problem: a list
    given for `fmus` was a crash, a string for `cotwin.delayed` was read as one unit per character."""
    value = table.get(key)
    if value is None:
        return kind()
    where = f"{within}.{key}" if within else key
    shown = {dict: "an object", list: "a list"}[kind] + (f" of {'strings' if item is str else item.__name__}" if item else "")
    if not isinstance(value, kind) or (item is not None and not all(isinstance(v, item) for v in value)):
        problems.append((f"{where} must be {shown}, got {json.dumps(value)[:60]}", key))
        return kind()
    return value


def _phantoms(connections, log) -> list[tuple[str, str]]:
    """Instances that are almost always a misspelt instance name, beside another instance of the same
    FMU, which Maestro would run as a second, silent copy:
    - one that takes inputs while nothing reads or logs its outputs (the intended instance misses
      those inputs);
    - one that only sends, unlogged, beside an instance that takes inputs (the intended instance's
      output is never read: its readers get the copy's, which nothing drives)."""
    feeds, targets, first = set(), set(), {}
    for c in connections:
        feeds.add(c[:2])
        targets.add(c[3:5])
        first.setdefault(c[:2], f"{c[0]}.{c[1]}.{c[2]}")
        first.setdefault(c[3:5], f"{c[3]}.{c[4]}.{c[5]}")
    everything = feeds | targets | set(log)
    out = []
    advice = "a misspelt instance name? (log one of its variables if it is meant to be a separate instance)"
    for inst in sorted(everything - set(log)):
        twins = sorted(i for i in everything if i[0] == inst[0] and i != inst)
        named = ", ".join(f"{k}.{n}" for k, n in twins)
        if inst in targets and inst not in feeds and twins:
            out.append((f"instance {inst[0]}.{inst[1]} receives inputs but nothing reads its outputs or logs it, "
                        f"beside {named} of the same FMU: {advice}", first[inst]))
        elif inst in feeds and inst not in targets and any(i in targets for i in twins):
            out.append((f"instance {inst[0]}.{inst[1]} only sends outputs (nothing drives its inputs), beside "
                        f"{named} of the same FMU, which takes inputs: {advice}", first[inst]))
    return out


def _place(text: str, needle: str | None) -> tuple[int, int]:
    """Line and column of the first JSON string `needle` in the file's text (1:1 when it is not there)."""
    if needle is None:
        return 1, 1
    at = text.find(json.dumps(needle))
    if at < 0:
        return 1, 1
    return text.count("\n", 0, at) + 1, at - text.rfind("\n", 0, at)


def unit_name(instance: tuple[str, str]) -> str:
    return f"{instance[0]}.{instance[1]}"


def system_of(mm: MultiModel, restart: bool = False) -> System:
    """The multimodel's units (one FMU instance each, FMI 2.0 or 3.0 by its model description, isolated as
    `cotwin.isolate` says, all of them with `restart`) and connections, checked."""
    try:
        units = [fmu_unit(unit_name(inst), mm.fmus[inst[0]], mm.isolate.get(inst), mm.unit_timeout, restart)
                 for inst in mm.instances]
        connections = [Connection(unit_name(c[:2]), c[2], unit_name(c[3:5]), c[5]) for c in mm.connections]
        return System.of(units, connections, delayed={unit_name(d) for d in mm.delayed},
                         log={unit_name(k): v for k, v in mm.log.items()},
                         parameters={unit_name(k): v for k, v in mm.parameters.items()})
    except CotwinError as err:  # name the multimodel that holds the problem
        raise CotwinError([Finding(Location(str(mm.path), 0, 0), f.severity, f.message) for f in err.findings]) from None


def execution_for(mm: MultiModel, csv_path: str | Path | None = None, step: float | None = None,
                  algorithm: str | None = None, observers: list[Observer] | None = None,
                  restart: bool = False) -> Execution:
    """An execution of the multimodel (FMUs through FMPy), writing Maestro's CSV when given a path and
    pacing to wall-clock time when the multimodel asks for it (`simulationProgramDelay`); with `restart`,
    every FMU is isolated and a failed step is retried in a new process from its last good state."""
    observers = list(observers or [])
    if csv_path is not None:
        observers.insert(0, CSVWriter(csv_path))
    if mm.realtime:
        observers.append(RealTimePacer())
    return Execution(system_of(mm, restart), make_algorithm(algorithm or mm.algorithm), step or mm.step, mm.start,
                     observers)
