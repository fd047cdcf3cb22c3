"""The Scene seam: what a world around the robot adds to the MJCF, its gravity, where the robot stands,
its obstacles and what the page draws, with a registry of scene kinds by name.

Core knows no particular cell: a scene kind is registered under a name (`register_scene`) or published
by an installed package under the entry-point group `cotwin.scenes` (an object `SceneKind`), and a
project names it (`[platform] scene = "NAME"`, its own keys in a `[scene]` table). Core itself registers
only generic kinds: "none" (the robot alone), "floor" (an empty floor) and "world" (a floor with walls
and obstacles, cotwin.pmodel.world). "auto" takes the world if the project gives one, else the first
kind whose `fits(mapping)` holds, else none.
"""

from __future__ import annotations

import threading
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from ..diagnostics import CotwinError, Finding, Location, Severity

ENTRY_POINTS = "cotwin.scenes"  # the entry-point group of installed scene kinds
EARTH = (0.0, 0.0, -9.81)


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
                    kind = ep.load()
                    _KINDS[kind.name] = kind
            _loaded = True
        return dict(_KINDS)


def scene_kind(name: str, at: Location | None = None) -> SceneKind:
    """The kind called `name`, or a located error listing the known ones."""
    kinds = scene_kinds()
    if name not in kinds:
        raise CotwinError([Finding(at or Location("<project>", 1, 1), Severity.ERROR,
                                   f"[platform] scene: no scene kind {name!r} (known: auto, "
                                   f"{', '.join(sorted(kinds))})")])
    return kinds[name]


def choose_kind(name: str, request: SceneRequest, at: Location | None = None) -> SceneKind:
    """The kind a project's `[platform] scene` names; "auto": the world if given, else the first kind
    (by name) that fits the mapping, else none."""
    if name != "auto":
        return scene_kind(name, at)
    if request.world is not None:
        return scene_kind("world")
    fitting = [k for k in scene_kinds().values() if k.fits is not None and k.fits(request.mapping)]
    return sorted(fitting, key=lambda k: k.name)[0] if fitting else scene_kind("none")


def build_scene(name: str, request: SceneRequest, at: Location | None = None):
    """The scene a project asks for; a `[scene]` key its kind does not read is an error (never ignored)."""
    kind = choose_kind(name, request, at)
    unread = [k for k in request.options if k not in kind.options]
    if unread:
        raise CotwinError([Finding(request.locate("scene", k), Severity.ERROR,
                                   f"[scene] {k}: the scene is '{kind.name}' ([platform] scene = \"{name}\"), "
                                   f"which would ignore it (it reads {', '.join(kind.options) or 'no keys'})")
                           for k in unread])
    return kind.build(request)


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
