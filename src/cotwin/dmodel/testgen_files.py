"""A generated suite on disk, and read back: TESTS/suite.json, and per case a plan and an oracle.

- `suite.json`: the model (module, digest of its texts), the criterion, every item with what covers
  it, the unreachable and uncovered items with their reasons, the minimisation's counts, the commands
  and answers among the input events, and the cases (name, cycles, answers, items).
- `case_NN.csv`: the case as a TwinManager plan (cotwin.twin.assembly.scenario reads it): `timestep` in ms, then
  the events the case sends and their value ports; the inputs of cycle c at (c - 1) x period. A case
  whose answers are left to the platform lists its commands only, each `settle` seconds after the
  previous one when the platform had to answer in between.
- `case_NN.oracle.json`: per cycle the inputs, the operation calls and output events with their
  arguments, the active leaf states after it and the transitions it took.
- `case_NN.fmu` (cotwin testgen, unless --no-drivers): a stub case as a test driver FMU reporting a
  `verdict` (cotwin.dmodel.testgen_driver).

Everything is written in a stable order, so the same model and options give byte-identical files.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from ..diagnostics import CotwinError, Finding, Location, Severity
from ..files import write_text
from ..interrupts import signals_held
from .interpreter import Output
from .program import Program, get_path
from .testgen import Case, Suite, model_digest

FORMAT = "cotwin-testsuite/1"


def plain(value):
    """A d-model value as JSON data: records as objects, vectors, tuples and sequences as lists."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list, set, frozenset)):
        return [plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return value


def output_record(out: Output) -> dict:
    return {"kind": out.kind, "name": out.name, "args": plain(out.args)}


def _ms(seconds: float) -> str:
    text = f"{round(seconds * 1000.0, 6):.6f}".rstrip("0").rstrip(".")
    return text or "0"


def _cell(value, fmi: str) -> str:
    if fmi == "Boolean":
        return "true" if value else "false"
    if fmi == "Integer":
        return str(int(value))
    return repr(float(value))


def plan_rows(program: Program, case: Case, commands: set[str], period: float, settle: float) -> tuple[list[str], list[list[str]]]:
    """The case as plan rows (header, rows), see module doc."""
    sends = [ev for ev in program.inputs if any(ev.name in st.inputs for st in case.steps)
             and (case.answers == "stub" or ev.name in commands)]
    header = ["timestep"]
    columns = []  # (port, fmi type, event, path or None for the event itself)
    for ev in sends:
        header.append(ev.name)
        columns.append((ev.name, "Boolean", ev.name, None))
        for port, sc in ev.value_ports:
            header.append(port)
            columns.append((port, sc.fmi_type, ev.name, sc.path))
    held = {port: (False if fmi == "Boolean" else 0) for port, fmi, _, path in columns if path is not None}
    rows, delay, answered = [], 0.0, False
    for st in case.steps:
        sent = {n: v for n, v in st.inputs.items() if case.answers == "stub" or n in commands}
        if case.answers == "platform" and any(n not in commands for n in st.inputs):
            answered = True
        if not sent:
            continue
        if answered:
            delay += settle
            answered = False
        row = [_ms((st.cycle - 1) * period + delay)]
        for port, fmi, event, path in columns:
            if path is None:
                row.append(_cell(event in sent, fmi))
                continue
            if event in sent:
                value = sent[event]
                held[port] = get_path(value, path) if path else value
            row.append(_cell(held[port], fmi))
        rows.append(row)
    return header, rows


def oracle(case: Case) -> dict:
    return {"case": case.name, "answers": case.answers, "cycles": [
        {"cycle": st.cycle, "inputs": {k: plain(v) for k, v in st.inputs.items()},
         "outputs": [output_record(o) for o in st.outputs], "states": st.states, "transitions": st.transitions}
        for st in case.steps]}


def suite_record(suite: Suite, period: float, settle: float, drivers: bool = False) -> dict:
    program = suite.program
    graph = suite.graph
    return {
        "format": FORMAT,
        "module": program.module.name,
        "model_digest": model_digest(program),
        "criterion": suite.criterion,
        "period": period,
        "settle": settle,
        "max_cycles": suite.max_cycles,
        "exploration": {"states": len(graph.snapshots), "cycles": graph.edges, "complete": graph.complete,
                        "input_combinations": graph.input_combinations, "notes": graph.value_notes,
                        "domains": graph.domains, **({"unbounded": graph.unbounded} if graph.unbounded else {})},
        "commands": suite.commands,
        "answers": [ev.name for ev in program.inputs if ev.name not in suite.commands],
        "items": {"total": len(suite.total), "reachable": len(suite.reached), "covered": len(suite.covered)},
        "minimisation": {"walks": suite.walks, "cases": len(suite.cases), "cycles": suite.cycles},
        "unreachable": [{"item": i, "why": why} for i, why in suite.unreachable],
        "uncovered": [{"item": i, "why": why} for i, why in suite.uncovered],
        "cases": [{"name": c.name, "cycles": c.cycles, "answers": c.answers, **({"why": c.note} if c.note else {}),
                   "plan": f"{c.name}.csv", "oracle": f"{c.name}.oracle.json",
                   **({"driver": f"{c.name}.fmu"} if drivers and c.answers == "stub" else {}),
                   "covers": c.covers, "items": c.items}
                  for c in suite.cases],
    }


def _dump(data) -> str:
    return json.dumps(data, indent=1, sort_keys=False, allow_nan=False) + "\n"


def write_suite(suite: Suite, folder: str | Path, period: float = 0.1, settle: float = 10.0,
                drivers: bool = False, fmus: Iterable[Path] = ()) -> list[Path]:
    """Write the suite into `folder` (see module doc); returns the files written. Files of an earlier suite
    that this one does not have (more cases then), as its index names them, are removed, so the folder holds one
    suite; no other file is (every case_* file was, a user's case_study.csv too). With `drivers`
    the index names each stub case's test driver FMU (cotwin.dmodel.testgen_driver builds them).

    Every file is written whole (files.write_text) in a folder of its own beside the suite, and only then
    moved over the earlier suite's, the index last: a write that fails or is interrupted (a full disk, ^C)
    leaves the earlier suite as it was, with no part-written file among it. The moves are one block for ^C
    and SIGTERM (held until the last is done), so an interrupt never leaves a suite of old and new files.
    `fmus`, the stub cases' driver FMUs built on the same file system, are moved in within that block, before the
    index: moved after it, an interrupt in between left the new index beside the earlier suite's drivers."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    commands = set(suite.commands)
    files: dict[str, str] = {}
    keep = {f"{c.name}.fmu" for c in suite.cases if drivers and c.answers == "stub"}
    for case in suite.cases:
        header, rows = plan_rows(suite.program, case, commands, period, settle)
        files[f"{case.name}.csv"] = "\n".join(",".join(r) for r in [header, *rows]) + "\n"
        files[f"{case.name}.oracle.json"] = _dump(oracle(case))
    files["suite.json"] = _dump(suite_record(suite, period, settle, drivers))  # last: it names the cases
    earlier = _suite_files(folder)  # read before the new index replaces it
    with tempfile.TemporaryDirectory(prefix=".cotwin-suite-", dir=folder) as stage:
        for name, text in files.items():
            write_text(Path(stage) / name, text)
        moves = [*((Path(f), folder / Path(f).name) for f in fmus), *((Path(stage) / n, folder / n) for n in files)]
        written = []
        with signals_held():  # renames within one file system: no file is ever part-written, no ^C between them
            for source, target in moves:
                os.replace(source, target)
                written.append(target)
    for name in sorted(earlier - set(files) - keep):
        stale = folder / name
        if stale.is_file() or stale.is_symlink():
            stale.unlink()
    return written


def _suite_files(folder: Path) -> set[str]:
    """The files the suite index in `folder` names (plans, oracles, drivers), each a name in the folder; none when
    there is no index or it cannot be read as one."""
    try:
        data = _read_json(folder / "suite.json", "test suite index")
    except (CotwinError, OSError):
        return set()
    entries = data.get("cases") if isinstance(data, dict) and data.get("format") == FORMAT else None
    return {entry[key] for entry in entries if isinstance(entry, dict) for key in ("plan", "oracle", "driver")
            if isinstance(entry.get(key), str) and entry[key] == Path(entry[key]).name and entry[key] != "suite.json"
            } if isinstance(entries, list) else set()


# ---- reading a suite back ----


@dataclass
class SuiteCase:
    name: str
    answers: str
    covers: list[str]
    items: list[str]
    cycles: list[dict]  # the oracle's cycles
    plan: Path


@dataclass
class SuiteFile:
    folder: Path
    data: dict
    cases: list[SuiteCase]

    @property
    def criterion(self) -> str:
        return self.data["criterion"]

    @property
    def commands(self) -> list[str]:
        return list(self.data.get("commands", []))


def read_suite(folder: str | Path) -> SuiteFile:
    """A suite written by `write_suite`, every problem reported at its file."""
    folder = Path(folder)
    index = folder / "suite.json"
    data = _read_json(index, "test suite index (cotwin testgen -o FOLDER writes one)")
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CotwinError([Finding(Location(str(index), 1, 1), Severity.ERROR,
                                   f"not a cotwin test suite (format {FORMAT!r} expected)")])
    cases, problems = [], []
    period = data.get("period", 0.1)
    if isinstance(period, bool) or not isinstance(period, (int, float)) or not 1e-6 <= period <= 3600:  # NaN too
        problems.append(Finding(Location(str(index), 1, 1), Severity.ERROR,
                                f"period {period!r:.40} is not a number of seconds from 1e-06 to 3600"))
    entries = data.get("cases", [])
    if not isinstance(entries, list):
        problems.append(Finding(Location(str(index), 1, 1), Severity.ERROR, "cases is not a list of case entries"))
        entries = []
    for entry in entries:
        try:
            name, answers = entry["name"], entry["answers"]
            for key in ("plan", "oracle"):  # a suite's files live in its folder: none is reached outside it
                if not isinstance(entry[key], str):
                    raise TypeError(key)
                if os.path.isabs(entry[key]) or os.path.normpath(entry[key]).split(os.sep)[0] == os.pardir:
                    raise CotwinError([Finding(Location(str(index), 1, 1), Severity.ERROR,
                                               f"case entry {str(name)[:40]!r}: its {key} {entry[key][:200]!r} lies "
                                               f"outside the suite's folder (a suite's files live in its folder)")])
            oracle_path = folder / entry["oracle"]
            record = _read_json(oracle_path, "case oracle")
            cycles = record.get("cycles") if isinstance(record, dict) else None
            if not isinstance(cycles, list):  # the oracle's fault, at the oracle (not at the index)
                raise CotwinError([Finding(Location(str(oracle_path), 1, 1), Severity.ERROR,
                                           "not a case oracle: it has no list of cycles")])
            if answers not in ("stub", "platform"):
                raise KeyError("answers")
            cases.append(SuiteCase(name, answers, list(entry.get("covers", [])), list(entry.get("items", [])), cycles,
                                   folder / entry["plan"]))
        except CotwinError as err:
            problems.extend(err.findings)
        except (KeyError, TypeError):
            problems.append(Finding(Location(str(index), 1, 1), Severity.ERROR, f"case entry {entry!r:.80} is malformed"))
    if problems:
        raise CotwinError(problems)
    return SuiteFile(folder, data, cases)


SUITE_FILE_CAP = 64 * 1024 * 1024  # bytes of a suite's index or one oracle (a 30-cycle case's is a few KiB)


def _read_json(path: Path, what: str):
    from ..files import read_text

    # capped, and never blocking on a FIFO (Path.read_text read a file of any size whole, and waited on a FIFO)
    text = read_text(path, what, SUITE_FILE_CAP)
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise CotwinError([Finding(Location(str(path), err.lineno, err.colno), Severity.ERROR,
                                   f"bad JSON: {err.msg}")]) from None
    except RecursionError:
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR, "bad JSON: nested too deeply")]) from None
