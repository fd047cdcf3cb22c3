"""One registry of platform endpoints for both sides of a twin: the physical twin's (`[pt] endpoint`) and
the digital twin's (`[platform] endpoint`).

An endpoint kind is a name and a factory from the twin system and its endpoint settings (a PTSettings:
endpoint, url, queue, log, offset; for the DT, the [platform] table's) to a cotwin.mapping.platform.Endpoint.
Core registers its own kinds here: PT opcua, replay, broker, rtde; DT mujoco (the embedded simulator) and
broker. Another kind is a new module, not an edit of the core: `register_endpoint(EndpointKind(...))`, or an
installed package publishing an EndpointKind under the entry-point group `cotwin.endpoints`. A project
naming a kind no one registered gets a located error listing the known ones.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Callable

from ...diagnostics import CotwinError, Finding, Severity
from ...mapping.profile import robot_convention
from ..project import PT_KEYS, PTSettings

if TYPE_CHECKING:
    from ...mapping.platform import Endpoint
    from .system import TwinSystem

ENTRY_POINTS = "cotwin.endpoints"  # the entry-point group of installed endpoint kinds
SIDES = {"pt": "[pt] endpoint", "dt": "[platform] endpoint"}


@dataclass(frozen=True)
class EndpointKind:
    """A kind of platform endpoint: `make(system, settings)` builds one; `sides` says which side of a twin
    may use it ("pt", "dt"); `keys` the [pt] keys it reads besides `endpoint` (None: any; one it would
    ignore is an error at the key: core's kinds are checked so as the project is read)."""

    name: str
    make: Callable[["TwinSystem", PTSettings], "Endpoint"]
    sides: tuple[str, ...] = ("pt", "dt")
    doc: str = ""
    keys: tuple[str, ...] | None = None
    advice: Callable[["TwinSystem"], list[Finding]] | None = None  # warnings about the project for this kind


_KINDS: dict[str, EndpointKind] = {}
_loaded = False
_LOADING = threading.RLock()


def register_endpoint(kind: EndpointKind) -> EndpointKind:
    """Make `kind` known by its name (a later registration of the same name replaces it)."""
    unknown = [s for s in kind.sides if s not in SIDES]
    if unknown:
        raise CotwinError(f"endpoint kind {kind.name!r}: sides {', '.join(map(repr, unknown))} are not pt or dt")
    _KINDS[kind.name] = kind
    return kind


def endpoint_kinds(side: str | None = None) -> dict[str, EndpointKind]:
    """Every known kind (of one side, when given): core's and those installed packages publish."""
    global _loaded
    with _LOADING:
        if not _loaded:
            for ep in sorted(entry_points(group=ENTRY_POINTS), key=lambda e: e.name):
                if ep.name not in _KINDS:
                    register_endpoint(ep.load())
            _loaded = True
        return {n: k for n, k in _KINDS.items() if side is None or side in k.sides}


def endpoint_kind(system: "TwinSystem", side: str, name: str) -> EndpointKind:
    """The kind a project names for `side`, or an error located at its key listing the known ones."""
    kinds = endpoint_kinds(side)
    if name not in kinds:
        from difflib import get_close_matches

        key = ("pt", "endpoint") if side == "pt" else ("platform", "endpoint")
        near = get_close_matches(name.lower(), sorted(kinds), n=1)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        raise CotwinError([Finding(system.spec.location(*key), Severity.ERROR,
                                   f"{SIDES[side]}: no endpoint kind {name!r} (known: {', '.join(sorted(kinds))}){hint}")])
    return kinds[name]


def side_settings(system: "TwinSystem", side: str) -> PTSettings:
    """The endpoint settings of a side: the project's [pt] table, or the DT's [platform] endpoint keys."""
    spec = system.spec
    if side == "pt":
        if spec.pt is None:
            raise CotwinError(f"{spec.path}: a live twin needs a [pt] table (endpoint = "
                              f"{' | '.join(sorted(endpoint_kinds('pt')))})")
        return spec.pt
    return PTSettings(spec.endpoint, spec.url, None, spec.queue)


def check_endpoints(system: "TwinSystem", *sides: str) -> None:
    """The kinds the project names for these sides are known, and the PT's takes every [pt] key written
    (checked before anything is built)."""
    for side in sides:
        kind = endpoint_kind(system, side, side_settings(system, side).endpoint)
        if side == "pt" and kind.keys is not None:
            spec = system.spec
            ignored = [key[1] for key in spec.locations if len(key) == 2 and key[0] == "pt"
                       and key[1] not in ("endpoint", *kind.keys)]
            if ignored:
                raise CotwinError([Finding(spec.location("pt", key), Severity.ERROR,
                                           f"[pt] {key} does not apply to endpoint '{kind.name}' (it takes "
                                           f"{', '.join(kind.keys) or 'no other key'})") for key in ignored])


def endpoint_advice(system: "TwinSystem", side: str) -> list[Finding]:
    """The warnings of the kind the project names for `side` (EndpointKind.advice); none for a kind without."""
    kind = endpoint_kind(system, side, side_settings(system, side).endpoint)
    return kind.advice(system) if kind.advice is not None else []


def make_endpoint(system: "TwinSystem", side: str) -> "Endpoint":
    """The endpoint of a side of the twin, as the project names it."""
    settings = side_settings(system, side)
    return endpoint_kind(system, side, settings.endpoint).make(system, settings)


# ---- core's kinds ----
def _arm_convention(system: "TwinSystem"):
    arm = system.models.arm  # up to the cell geometry's [tool] link, as the mapping's IK counts the arm
    return arm, robot_convention(system.spec.profile, len(arm), system.spec.location("robot", "profile"))


def _opcua(system: "TwinSystem", settings: PTSettings):
    from ...mapping.opcua import OPCUAEndpoint

    return OPCUAEndpoint(system.models.tree, settings.url)


def _broker(system: "TwinSystem", settings: PTSettings):
    from ...mapping.broker import BrokerEndpoint

    return BrokerEndpoint(system.models.tree, settings.queue, settings.url or system.spec.url)


def _replay(system: "TwinSystem", settings: PTSettings):
    from ...mapping.replay import ReplayEndpoint, read_rtde_log

    arm, convention = _arm_convention(system)
    recording = read_rtde_log(settings.log, arm, convention)
    problem = recording.offset_problem(settings.offset) if settings.offset is not None else None
    if problem is not None:
        raise CotwinError(f"{system.spec.path}: [pt] offset: {problem}")
    return ReplayEndpoint(system.models.tree, recording, settings.offset)


def _rtde(system: "TwinSystem", settings: PTSettings):
    from ...mapping.urrtde import RTDEEndpoint

    arm, convention = _arm_convention(system)
    return RTDEEndpoint(system.models.tree, settings.url, convention=convention, arm=arm)


def _rtde_advice(system: "TwinSystem") -> list[Finding]:
    """A UR over RTDE moves its arm's joints (moveJ): the p-model's other position-driven joints (a gripper's
    fingers) are not sent, so the goals the mapping gives them reach the DT alone."""
    from ...pmodel.tree import servo_mode

    arm = set(system.models.arm)
    tree = system.models.tree
    others = [j.name for j in tree.actuated if j.name not in arm and servo_mode(j) == "position"]
    if not others:
        return []
    return [Finding(system.spec.location("pt", "endpoint"), Severity.WARNING,
                    f"[pt] endpoint = \"rtde\": the robot over RTDE moves its arm ({', '.join(system.models.arm)}) by "
                    f"joint positions (moveJ) only; p-model {tree.name}'s {', '.join(others)} "
                    f"{'is' if len(others) == 1 else 'are'} not sent to it, so the mapping's goals for "
                    f"{'it' if len(others) == 1 else 'them'} move the DT alone (a gripper on a UR is driven through "
                    "its tool I/O or its URCap, which this endpoint does not drive)")]


def _mujoco(system: "TwinSystem", settings: PTSettings):
    from .run import simulated_endpoint

    return simulated_endpoint(system)


register_endpoint(EndpointKind("opcua", _opcua, ("pt",), "a plant served over OPC UA (cotwin plant) at url",
                               PT_KEYS["opcua"]))
register_endpoint(EndpointKind("replay", _replay, ("pt",), "a recorded RTDE log, replayed", PT_KEYS["replay"]))
register_endpoint(EndpointKind("broker", _broker, ("pt", "dt"), "a robot behind RabbitMQ, on its request queue",
                               PT_KEYS["broker"]))
register_endpoint(EndpointKind("rtde", _rtde, ("pt",), "a UR robot over RTDE at url", PT_KEYS["rtde"],
                               advice=_rtde_advice))
register_endpoint(EndpointKind("mujoco", _mujoco, ("dt",), "the embedded MuJoCo simulator (calibrated when the "
                                                        "project names a calibration)", ()))
