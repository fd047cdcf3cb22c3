"""The Scene seam: what a world around the robot adds to the MJCF, its gravity, where the robot stands,
its obstacles and what the page draws, with a registry of scene kinds by name.

Core knows no particular cell: a scene kind is registered under a name (`register_scene`) or published
by an installed package under the entry-point group `cotwin.scenes` (an object `SceneKind`), and a
project names it (`[platform] scene = "NAME"`, its own keys in a `[scene]` table). Core itself registers
only generic kinds: "none" (the robot alone), "floor" (an empty floor) and "world" (a floor with walls
and obstacles, cotwin.pmodel.world). "auto" takes the world if the project gives one, else the first
kind whose `fits(mapping)` holds, else a floor under a free base (a mobile robot), else none.
"""

from __future__ import annotations

import logging
import threading
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from ..diagnostics import CotwinError, Finding, Location, Severity

ENTRY_POINTS = "cotwin.scenes"  # the entry-point group of installed scene kinds
EARTH = (0.0, 0.0, -9.81)
log = logging.getLogger("cotwin.scenes")


@runtime_checkable
class Scene(Protocol):
    """What the simulator, the endpoints and the page ask of the world around the robot."""

    name: str

    @property
    def gravity(self) -> tuple[float, float, float]: ...  # in the robot's frame
    @property
    def geometry(self): ...  # the cell's CellGeometry the mapping's kinematics use, or None
    @property
    def obstacle_names(self) -> list[str]: ...  # geoms whose contacts are collisions
    @property
    def walkable(self) -> bool: ...  # a floor a mobile robot walks on (its path drawn from above)
    def add_to(self, worldbody: ET.Element) -> None: ...
    def robot_pose(self, tree) -> np.ndarray | None: ...  # where the robot's base stands (None: the origin)
    def drawing(self) -> dict | None: ...  # what the page draws (None: nothing)
    def with_geometry(self, geometry, payloads: bool = True) -> "Scene": ...


class SceneBase:
    """Defaults of the Scene protocol: level gravity, no geometry, obstacles, placement or drawing."""

    name: str = ""
    walkable: bool = False
    gravity: tuple[float, float, float] = EARTH
    geometry = None  # (plain attributes: a dataclass scene may make them fields)
    obstacle_names: tuple[str, ...] = ()

    def add_to(self, worldbody: ET.Element) -> None:
        return None

    def robot_pose(self, tree) -> np.ndarray | None:
        return None

    def drawing(self) -> dict | None:
        return None

    def with_geometry(self, geometry, payloads: bool = True) -> "SceneBase":
        """This scene with the cell at `geometry` (None: as it is), without its loose payloads if not
        `payloads` (a calibration's clearance check); a scene without a cell geometry is unchanged."""
        return self


@dataclass
class SceneRequest:
    """What a scene kind is built from: the project's mapping, its `[scene]` table (`options`), the
    calibrated cell geometry and the project's world, and where to report a problem with an option."""

    mapping: Any  # cotwin.robosim.pmodel_elements.Mapping
    options: dict = field(default_factory=dict)
    geometry: Any = None  # cotwin.pmodel.cell.CellGeometry from [platform] calibration, or None
    world: Any = None  # cotwin.pmodel.world.World from [platform] world or [world], or None
    base: Any = None  # the project's folder (a scene's data files are relative to it)
    locate: Callable[..., Location] = field(default=lambda *key: Location("<project>", 1, 1))
    free_base: bool = False  # a mobile robot ([platform] base = "free"): "auto" stands it on a floor, not in a void

    def error(self, key: str, message: str) -> CotwinError:
        return CotwinError([Finding(self.locate("scene", key), Severity.ERROR, f"[scene] {key}: {message}")])


@dataclass(frozen=True)
class SceneKind:
    """A named kind of scene: `build(request)` makes one (or None: no scene); `options` are the `[scene]`
    keys it reads; `fits(mapping)`, if given, lets "auto" choose it for a mapping."""

    name: str
    summary: str
    build: Callable[[SceneRequest], Any]
    options: tuple[str, ...] = ()
    fits: Callable[[Any], bool] | None = None


_KINDS: dict[str, SceneKind] = {}
_BROKEN: dict[str, str] = {}  # entry-point name -> why it could not be loaded (an installation gone stale)
_loaded = False
_LOADING = threading.RLock()


def register_scene(kind: SceneKind) -> SceneKind:
    """Make `kind` known by its name (a later registration of the same name replaces it)."""
    _KINDS[kind.name] = kind
    return kind


def scene_kinds() -> dict[str, SceneKind]:
    """Every known kind: core's generic ones and those installed packages publish (entry points), loaded
    once under a lock (twins loaded in threads at once saw a registry half loaded: "auto" chose none)."""
    global _loaded
    with _LOADING:
        if not _loaded:
            for ep in sorted(entry_points(group=ENTRY_POINTS), key=lambda e: e.name):
                if ep.name not in _KINDS:
                    try:
                        kind = ep.load()
                    except Exception as err:  # noqa: BLE001 - a package's module gone or broken: said where used
                        _BROKEN[ep.name] = f"{ep.value}: {type(err).__name__}: {str(err)[:200]}"
                        continue
                    if not isinstance(kind, SceneKind):
                        _BROKEN[ep.name] = f"{ep.value} is a {type(kind).__name__}, not a SceneKind"
                        continue
                    _KINDS[kind.name] = kind
            _loaded = True
        return dict(_KINDS)


def broken_kinds() -> dict[str, str]:
    """Scene kinds installed packages publish (entry points) that could not be loaded, each with why: an
    installation gone stale (its module removed or renamed) or a broken package."""
    scene_kinds()
    return dict(_BROKEN)


def _unloadable(name: str) -> str:
    return (f"scene kind {name!r} is published by an installed package but cannot be loaded "
            f"({_BROKEN[name]}); reinstall that package (cotwin's own kinds: `make install`)")


def scene_kind(name: str, at: Location | None = None) -> SceneKind:
    """The kind called `name`, or a located error listing the known ones (or saying why an installed one
    cannot be loaded)."""
    from ..config import did_you_mean

    kinds = scene_kinds()
    if name in _BROKEN and name not in kinds:
        raise CotwinError([Finding(at or Location("<project>", 1, 1), Severity.ERROR,
                                   f"[platform] scene: {_unloadable(name)}")])
    if name not in kinds:
        raise CotwinError([Finding(at or Location("<project>", 1, 1), Severity.ERROR,
                                   f"[platform] scene: no scene kind {name!r}{did_you_mean(name, ['auto', *kinds])} "
                                   f"(known: auto, {', '.join(sorted(kinds))})")])
    return kinds[name]


def choose_kind(name: str, request: SceneRequest, at: Location | None = None) -> SceneKind:
    """The kind a project's `[platform] scene` names; "auto": the world if given, else the first kind
    (by name) that fits the mapping, else a floor under a free base, else none. An "auto" that could not
    consider every installed kind (one whose package cannot be loaded) says so in a warning: its choice may not
    be the one meant."""
    if name != "auto":
        return scene_kind(name, at)
    if request.world is not None:
        return scene_kind("world")
    fitting = [k for k in scene_kinds().values() if k.fits is not None and k.fits(request.mapping)]
    unfit = "floor" if request.free_base else "none"  # a free base with nothing under it fell for ever
    chosen = sorted(fitting, key=lambda k: k.name)[0] if fitting else scene_kind(unfit)
    if _BROKEN:
        where = at or request.locate("platform", "scene")
        log.warning("%s", Finding(where, Severity.WARNING, f'[platform] scene = "auto" chose \'{chosen.name}\' '
                                  f"but could not consider every installed kind: "
                                  f"{'; '.join(_unloadable(n) for n in sorted(_BROKEN))}; name the scene to be sure"))
    return chosen


def build_scene(name: str, request: SceneRequest, at: Location | None = None):
    """The scene a project asks for; a `[scene]` key its kind does not read is an error (never ignored)."""
    kind = choose_kind(name, request, at)
    unread = unread_options(kind, name, request.options, request.locate)
    if unread:
        raise CotwinError(unread)
    return kind.build(request)


def unread_options(kind: SceneKind, name: str, options: dict, locate: Callable[..., Location]) -> list[Finding]:
    """An error at each `[scene]` key the scene kind (chosen for `[platform] scene = name`) does not read."""
    from ..config import did_you_mean

    return [Finding(locate("scene", k), Severity.ERROR,
                    f"[scene] {k}: the scene is '{kind.name}' ([platform] scene = \"{name}\"), which would ignore it "
                    f"(it reads {', '.join(kind.options) or 'no keys'}){did_you_mean(k, kind.options)}")
            for k in options if k not in kind.options]


# ---- core's generic kinds ----------------------------------------------------------------------

def _world(request: SceneRequest):
    if request.world is None:
        raise CotwinError([Finding(request.locate("platform", "scene"), Severity.ERROR,
                                   "[platform] scene = \"world\" needs a world: [platform] world = \"<file>\" "
                                   "or a [world] table")])
    return request.world


def _floor(request: SceneRequest):
    from .world import World

    return World(name="floor")


register_scene(SceneKind("none", "the robot alone", lambda request: None))
register_scene(SceneKind("world", "a floor with walls and obstacles ([platform] world or [world])", _world))
register_scene(SceneKind("floor", "an empty floor", _floor))
