"""A fleet file (`cotwin fleet FLEET.toml`): many twin projects run together, each entry overriding what
differs between its twin and the project it names (where its PT is, how long it runs ...).

    [fleet]
    name = "cell-a"                 # optional: the fleet's name (default: the file's stem)
    history = "postgresql://127.0.0.1/cotwin"   # one store for every twin (default: DIR/history.sqlite)
    alarms = "amqp://127.0.0.1:5672/%2F"        # the broker every twin's alarms go to (default: each
                                                #   project's [scenario] rabbitmq url, if any)
    checkpoint_every = 10           # steps between a twin's saved states (where a restart goes on from)
    max_restarts = 3                # restarts of one twin before it is given up
    restart_delay = 1.0             # s before a failed twin is restarted
    workers = 0                     # Ray actors hosting the twins (0: one per twin)

    [[twin]]
    name = "arm-1"                  # unique in the fleet: its folder DIR/NAME, its alarms' routing key
    project = "arm/replay.toml"     # a project as `cotwin twin` takes it (relative to this file)
    pt_log = "logs/run1.csv"        # optional overrides, as cotwin twin's options: the replayed log,
    pt_url = "opc.tcp://127.0.0.1:4841"   # or where the PT is
    step = 0.1                      #   the communication step, end time, algorithm and pacing
    end = 24.0
    algorithm = "gauss-seidel"
    realtime = true
    dashboard = "127.0.0.1:8101"    # serve this twin's own page there (linked from the overview)

Every problem is reported at its key's line and column, all together; a project's own problems are
reported in the project file, each naming its twin and the entry's line.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from ....config import Key, Schema, TomlFile, raise_problems, within
from ....diagnostics import CotwinError, Finding, Severity
from ...project import (PTSettings, TwinProject, cycle_period, history_url_problem, load_project, pt_url_problem,
                        run_timing_message, timing_problems)

MAX_TWINS = 1000
_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-_")


def _twin_name(value: str) -> str | None:
    if not value or len(value) > 64 or not set(value) <= _NAME_CHARS:
        return f"{value[:70]!r} is not a twin name (1 to 64 letters, digits, '-' or '_': it names a folder and a routing key)"
    return None


def _address(value: str) -> str | None:
    from ...services.dashboard.app import parse_address

    try:
        parse_address(value)
    except ValueError as err:
        return str(err)
    return None


def _broker(value: str) -> str | None:
    from ...project.sections import _amqp_url

    return _amqp_url(value)


FLEET = Schema({
    "name": Key("str", check=_twin_name),
    "history": Key("str", check=history_url_problem),
    "alarms": Key("str", check=_broker),
    "checkpoint_every": Key("int", 10, check=within(1, 10 ** 6, "steps")),
    "max_restarts": Key("int", 3, check=within(0, 100)),
    "restart_delay": Key("nonnegative", 1.0, check=within(0, 600, "s")),
    "workers": Key("int", 0, check=within(0, MAX_TWINS)),
})
TWIN = Schema({
    "name": Key("str", required=True, check=_twin_name),
    "project": Key("str", required=True),
    "pt_log": Key("str"),
    "pt_url": Key("str"),
    "step": Key("positive"),
    "end": Key("positive"),
    "algorithm": Key("str", choices=("jacobi", "gauss-seidel")),
    "realtime": Key("bool"),
    "dashboard": Key("str", check=_address),
})
SCHEMA = Schema({"fleet": Key("table", {}, table=FLEET), "twin": Key("list", required=True)})


@dataclass(frozen=True)
class TwinEntry:
    """One twin of a fleet: its project and what the fleet file overrides in it (plain data: it travels
    to the process that runs the twin, which reads the project again there)."""

    name: str
    project: str  # absolute path
    overrides: dict = field(default_factory=dict)  # pt_log, pt_url, step, end, algorithm, realtime
    dashboard: str | None = None  # HOST:PORT of the twin's own page


@dataclass(frozen=True)
class FleetSpec:
    path: Path
    name: str
    twins: tuple[TwinEntry, ...]
    history: str | None = None
    alarms: str | None = None
    checkpoint_every: int = 10
    max_restarts: int = 3
    restart_delay: float = 1.0
    workers: int = 0


def twin_project(entry: TwinEntry) -> TwinProject:
    """The project of a fleet entry with the entry's overrides applied (as `cotwin twin`'s options do)."""
    o = entry.overrides
    spec = load_project(entry.project, o.get("pt_log"), step=o.get("step"), end=o.get("end"))  # the entry's run's
    if o.get("pt_log") is not None:
        log = Path(o["pt_log"])
        spec.pt = replace(spec.pt, endpoint="replay", log=log, url=None) if spec.pt else PTSettings("replay", log=log)
    if o.get("pt_url") is not None:
        spec.pt = replace(spec.pt, url=o["pt_url"]) if spec.pt else PTSettings("opcua", url=o["pt_url"])
    for key in ("step", "end", "algorithm", "realtime"):
        if o.get(key) is not None:
            setattr(spec, key, float(o[key]) if key in ("step", "end") else o[key])
    return spec


def read_fleet(path: str | Path) -> FleetSpec:
    """Read and check a fleet file and every project it names (see module doc)."""
    file = TomlFile(path, "fleet file")
    if "models" in file.data and "twin" not in file.data:  # a project given for a fleet file
        raise CotwinError([Finding(file.location(("models",)), Severity.ERROR, "this is a twin project ([models]), "
                                   f"not a fleet file: run it with `cotwin twin {file.path.name} -o DIR`, or name it "
                                   "in a fleet file's [[twin]] project = \"...\" (docs/fleet.md)")])
    problems: list[Finding] = []
    data = SCHEMA.read(file.data, file, (), problems)
    fleet = data["fleet"] or {}
    items = data["twin"] if isinstance(data["twin"], list) else []
    if isinstance(data["twin"], list) and not items:
        problems.append(Finding(file.location(("twin",)), Severity.ERROR, "a fleet needs at least one [[twin]]"))
    if len(items) > MAX_TWINS:
        problems.append(Finding(file.location(("twin",)), Severity.ERROR,
                                f"{len(items)} twins: a fleet holds at most {MAX_TWINS}"))
        items = []
    twins: list[TwinEntry] = []
    seen: dict[str, int] = {}
    pages: dict[str, int] = {}
    for k, item in enumerate(items):
        at = ("twin", k)
        if not isinstance(item, dict):
            problems.append(Finding(file.location(at), Severity.ERROR, "each [[twin]] must be a table"))
            continue
        before = len(problems)
        v = TWIN.read(item, file, at, problems)
        good = len(problems) == before  # a wrong key of the entry: its project is still checked
        name = v["name"] if isinstance(v["name"], str) else f"#{k + 1}"
        if name in seen:
            problems.append(Finding(file.location(at + ("name",)), Severity.ERROR,
                                    f"twin name {name!r} is already the name of twin {seen[name] + 1} (names are unique)"))
            good = False
        seen.setdefault(name, k)
        if v["dashboard"] is not None:
            if v["dashboard"] in pages:
                problems.append(Finding(file.location(at + ("dashboard",)), Severity.ERROR,
                                        f"twin {name!r}: dashboard {v['dashboard']} is already twin "
                                        f"{pages[v['dashboard']] + 1}'s"))
                good = False
            pages.setdefault(v["dashboard"], k)
        if not isinstance(v["project"], str):
            continue  # no project named (reported)
        entry = _entry(file, at, name, v, problems)
        if entry is not None and good:
            twins.append(entry)
    raise_problems(problems)
    return FleetSpec(file.path, fleet.get("name") or file.path.stem, tuple(twins), fleet.get("history"),
                     fleet.get("alarms"), fleet["checkpoint_every"], fleet["max_restarts"],
                     float(fleet["restart_delay"]), fleet["workers"])


def _entry(file: TomlFile, at: tuple, name: str, v: dict, problems: list[Finding]) -> TwinEntry | None:
    """A checked entry: its project exists and reads well, and its overrides fit that project. Each of the
    project's own problems stays at its place in the project file and says which twin (and fleet file
    line) it belongs to: sorted with the fleet's findings, it needs no header to be understood."""
    base = file.path.parent
    project = base / v["project"]
    if not project.is_file():
        problems.append(Finding(file.location(at + ("project",)), Severity.ERROR,
                                f"twin {name!r}: no project file {project}"))
        return None
    overrides = {k: v[k] for k in ("pt_log", "pt_url", "step", "end", "algorithm", "realtime") if v[k] is not None}
    if "pt_log" in overrides:
        log = base / overrides["pt_log"]
        if not log.is_file():
            problems.append(Finding(file.location(at + ("pt_log",)), Severity.ERROR,
                                    f"twin {name!r}: no log file {log}"))
            return None
        overrides["pt_log"] = str(log.resolve())
        if "pt_url" in overrides:
            problems.append(Finding(file.location(at + ("pt_url",)), Severity.ERROR,
                                    f"twin {name!r}: pt_url and pt_log name two different PTs: give one"))
            return None
    entry = TwinEntry(name, str(project.resolve()), overrides, v["dashboard"])
    try:
        spec = twin_project(entry)
    except CotwinError as err:
        named = file.location(at + ("project",))
        problems.append(Finding(named, Severity.ERROR, f"twin {name!r}: its project {project} has "
                                f"{len(err.findings)} problem(s), each said at its place with this twin's name"))
        problems.extend(replace(f, message=f"twin {name!r} (project of {named}): {f.message}") for f in err.findings)
        return None
    problems.extend(_fits(file, at, name, spec, overrides))
    return entry


def _fits(file: TomlFile, at: tuple, name: str, spec: TwinProject, overrides: dict) -> list[Finding]:
    """Problems of the overrides against the project: a PT to point them at, a url its endpoint takes,
    a step and end time the run can keep exactly."""
    out = []

    def say(key: str, message: str) -> None:
        out.append(Finding(file.location(at + (key,)), Severity.ERROR, f"twin {name!r}: {message}"))

    if spec.pt is None:
        say("project", f"its project {spec.path} has no [pt] table (a live twin needs a PT): give one there, or "
                       "pt_log / pt_url here")
    elif "pt_url" in overrides:
        if spec.pt.endpoint == "replay":
            say("pt_url", "the project's PT replays a log ([pt] endpoint = \"replay\"), which has no url")
        else:
            problem = pt_url_problem(spec.pt.endpoint, overrides["pt_url"])
            if problem is not None:
                say("pt_url", f"{problem} (for [pt] endpoint '{spec.pt.endpoint}')")
    if "step" in overrides or "end" in overrides:
        for key, message in timing_problems(spec.step, spec.end, cycle_period(spec)):
            say(key if key in overrides else next(iter(k for k in ("step", "end") if k in overrides)),
                run_timing_message(spec, key, message))
    return out
