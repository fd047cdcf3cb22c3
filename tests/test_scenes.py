"""The Scene seam: scene kinds by name (core's generic ones, installed ones, a test's own), `[scene]` keys
read only by the kind that takes them, and the generic core free of the examples' names."""

from __future__ import annotations

import re
import shutil
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.pmodel.scenes import SceneBase, SceneKind, register_scene, scene_kinds
from cotwin.pmodel.xmltext import nums, sub

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_WORDS = re.compile(r"ur5e|flexcell|flex-cell|turtlebot|brick", re.IGNORECASE)
GENERIC = {"firebrick"}  # a CSS colour name (the vendored three.js)


@dataclass
class Pillar(SceneBase):
    """A scene of this test's own: one pillar (an obstacle) beside the robot, the robot raised on a stand."""

    name: str = "pillar"
    x: float = 0.6
    lift: float = 0.25

    @property
    def obstacle_names(self) -> list[str]:
        return ["pillar"]

    def add_to(self, worldbody: ET.Element) -> None:
        sub(worldbody, "geom", name="pillar", type="box", size="0.05 0.05 0.4", pos=nums([self.x, 0.0, 0.4]))

    def robot_pose(self, tree):
        import numpy as np

        pose = np.eye(4)
        pose[2, 3] = self.lift
        return pose

    def drawing(self) -> dict:
        return {"pillar": [self.x, 0.0]}


def _pillar(request):
    lift = request.options.get("lift", 0.25)
    if not isinstance(lift, (int, float)) or lift < 0:
        raise request.error("lift", f"must be a height >= 0 (m), got {lift!r}")
    return Pillar(lift=float(lift))


register_scene(SceneKind("test-pillar", "a pillar beside a raised robot", _pillar, options=("lift",)))


@pytest.fixture
def ur5e(tmp_path):
    shutil.copytree(ROOT / "examples" / "ur5e", tmp_path / "ur5e")
    return tmp_path / "ur5e"


def test_core_and_installed_kinds_are_known_by_name():
    kinds = scene_kinds()
    assert {"none", "floor", "world", "flexcell", "test-pillar"} <= set(kinds)
    assert kinds["flexcell"].options == ("bricks",) and kinds["flexcell"].fits is not None


def test_a_kind_of_ones_own_places_the_robot_its_obstacles_and_the_page(ur5e):
    """A project naming a kind registered outside cotwin gets that scene in its MJCF, simulator and page."""
    from cotwin.pmodel.mjcf import to_mjcf
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.services.dashboard.describe import scene_drawing
    from cotwin.twin.assembly.run import load

    path = ur5e / "pillar.toml"
    path.write_text((ur5e / "cotwin.toml").read_text().replace("[platform]", '[platform]\nscene = "test-pillar"')
                    + "\n[scene]\nlift = 0.4\n")
    system = load(path)
    scene = system.models.scene
    assert isinstance(scene, Pillar) and scene.lift == 0.4
    root = ET.fromstring(to_mjcf(system.models.tree, scene))
    assert root.find(".//geom[@name='pillar']") is not None
    base = root.find("worldbody/body")
    assert [float(v) for v in base.get("pos").split()][2] == pytest.approx(0.4 + system.models.tree.root.pose[2, 3])
    sim = PlatformSimulator(system.models.tree, scene)
    assert sim.model.geom("pillar").id in sim._obstacles
    assert scene_drawing(scene) == {"pillar": [0.6, 0.0]}


def test_a_scene_key_its_kind_does_not_read_is_refused_at_the_key(ur5e):
    from cotwin.twin.assembly.run import load

    path = ur5e / "pillar.toml"
    text = (ur5e / "cotwin.toml").read_text().replace("[platform]", '[platform]\nscene = "test-pillar"')
    path.write_text(text + "\n[scene]\nlift = -1\n")
    with pytest.raises(CotwinError, match=r"pillar.toml:\d+:1: error: \[scene\] lift: must be a height >= 0"):
        load(path)
    path.write_text(text + "\n[scene]\nbricks = [[1, 2]]\n")
    with pytest.raises(CotwinError, match=r"pillar.toml:\d+:1: error: \[scene\] bricks: the scene is 'test-pillar' "
                                          r".*which would ignore it \(it reads lift\)"):
        load(path)


def test_auto_chooses_the_kind_that_fits_the_mapping_and_floor_is_an_empty_floor(ur5e):
    from cotwin.twin.assembly.run import load

    assert type(load(ur5e / "cotwin.toml").models.scene).__name__ == "FlexCell"  # the mapping has the grid
    path = ur5e / "floor.toml"
    path.write_text((ur5e / "cotwin.toml").read_text().replace("[platform]", '[platform]\nscene = "floor"'))
    floor = load(path).models.scene
    assert floor.obstacle_names == [] and floor.geometry is None and floor.drawing() is None


def test_auto_puts_a_free_base_that_nothing_else_fits_on_a_floor(tmp_path):
    """A new user's mobile robot (base = "free", no world, a mapping no scene kind fits) got scene 'none' and fell
    for ever (its base at z = -314 m after 8 s) while its commands all 'completed'. "auto" puts it on a floor;
    named "none" it is still none, and a fixed base stays without one."""
    from cotwin.twin.assembly.run import load

    walk = ROOT / "examples" / "turtlebot"
    models = "\n".join(f'{k} = "{walk / v}"' for k, v in (("dmodel", "random_walk.rst"),
                                                         ("pmodel", "turtlebot3_burger.pm"), ("mapping", "walk_mapping.pm")))
    for platform, kind in (('base = "free"', "floor"), ('base = "free"\nscene = "none"', "none"), ("", "none")):
        path = tmp_path / "mobile.toml"
        path.write_text(f"[models]\n{models}\n[platform]\n{platform}\n[cosim]\nstep = 0.2\nend = 1.0\n")
        scene = load(path).models.scene  # None: no scene
        assert (scene.name if scene is not None else "none") == kind, platform


def test_the_generic_core_names_no_example():
    """No file under src/cotwin names an example's robot, cell or world (they live in examples/ and in
    packages registering scene kinds, such as cotwin_cells); the one generic word allowed is the CSS
    colour `firebrick` in the vendored three.js."""
    found = []
    for path in sorted((ROOT / "src" / "cotwin").rglob("*")):
        if not path.is_file() or "__pycache__" in path.parts:
            continue
        text = path.read_bytes().decode("utf-8", "replace")
        for match in EXAMPLE_WORDS.finditer(text):
            word = text[max(0, match.start() - 4):match.end()].lower()
            if word not in GENERIC:
                line = text.count("\n", 0, match.start()) + 1
                found.append(f"{path.relative_to(ROOT)}:{line}: {text[max(0, match.start() - 40):match.end() + 40]!r}")
    assert not found, "\n".join(found)


def test_a_projects_scene_errors_are_reported_with_its_other_errors(ur5e):
    """[scene] keys and the kind named are checked with the rest of the file, not in a round of their own
    once the others are fixed; a misspelt kind or key gets the nearest valid one."""
    from cotwin.twin.project import load_project

    path = ur5e / "rounds.toml"
    text = (ur5e / "cotwin.toml").read_text().replace("[platform]", '[platform]\nscene = "floor"')
    path.write_text(text.replace('algorithm = "jacobi"', 'algorithm = "jacobii"') + "\n[scene]\ncolour = 1\n")
    with pytest.raises(CotwinError) as err:
        load_project(path)
    text_of = str(err.value)
    assert re.search(r"rounds.toml:\d+:1: error: \[cosim\] algorithm .*did you mean 'jacobi'", text_of)
    assert re.search(r"rounds.toml:\d+:1: error: \[scene\] colour: the scene is 'floor'", text_of)
    path.write_text(text.replace('scene = "floor"', 'scene = "flexcel"') + "\n[scene]\nbrick = [[1, 2]]\n")
    with pytest.raises(CotwinError, match=r"no scene kind 'flexcel'; did you mean 'flexcell'"):
        load_project(path)
    path.write_text(text.replace('scene = "floor"', 'scene = "flexcell"') + "\n[scene]\nbrick = [[1, 2]]\n")
    with pytest.raises(CotwinError, match=r"\[scene\] brick: .*did you mean 'bricks'"):
        load_project(path)


@pytest.fixture
def stale_kind(tmp_path, monkeypatch):
    """An installed distribution publishing a scene kind whose module is gone (an installation gone stale)."""
    from cotwin.pmodel import scenes

    info = tmp_path / "site" / "stalecells-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: stalecells\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[cotwin.scenes]\nghost = stalecells_gone.ghost:KIND\n")
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    monkeypatch.setattr(scenes, "_KINDS", dict(scenes._KINDS))
    monkeypatch.setattr(scenes, "_BROKEN", {})
    monkeypatch.setattr(scenes, "_loaded", False)
    return "ghost"


def test_a_scene_kind_whose_package_is_gone_is_named_and_auto_says_what_it_could_not_consider(ur5e, stale_kind,
                                                                                               caplog):
    from cotwin.twin.assembly.run import load

    path = ur5e / "ghost.toml"
    path.write_text((ur5e / "cotwin.toml").read_text().replace("[platform]", '[platform]\nscene = "ghost"'))
    with pytest.raises(CotwinError, match=r"ghost.toml:\d+:1: error: \[platform\] scene: scene kind 'ghost' is "
                                          r"published by an installed package but cannot be loaded "
                                          r"\(stalecells_gone.ghost:KIND: ModuleNotFoundError"):
        load(path)
    with caplog.at_level("WARNING", logger="cotwin.scenes"):
        system = load(ur5e / "cotwin.toml")  # "auto": still the kind that fits, and a warning naming the lost one
    assert type(system.models.scene).__name__ == "FlexCell"
    assert any("scene = \"auto\" chose 'flexcell' but could not consider every installed kind: scene kind 'ghost'"
               in r.getMessage() for r in caplog.records)
