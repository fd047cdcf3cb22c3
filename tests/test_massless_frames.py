"""Massless frames, as a new user imports a URDF. Found: a URDF link without <inertial> (TIAGo's hand_grasping_frame,
the Panda's panda_hand_tcp and panda_link8, every tool0) weighed 1 kg in the simulator: TIAGo carried a phantom
kilogram at its grasp point (arm_2_joint held 38.4 of its 39 N m at zero), the 65 URDFs of example-robot-data that
load 312 kg in all. Such a link is now a massless frame; where a moving joint carries one with nothing of mass fixed
to it (MuJoCo needs a mass there) MuJoCo's model gives it a gram, with a warning naming it; the kinematic tree and the
URDF/SDF exports keep it massless (the gram was the tree's once, and the exports wrote an <inertial> the URDF lacks)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.sdf import to_sdf
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree
from cotwin.pmodel.tree_build import MOVING_FRAME_MASS
from cotwin.pmodel.urdf import to_urdf
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.robosim import check_pmodel
from cotwin.robosim.check import load_checked
from test_urdf_import import robot_data

INERTIAL = ("<inertial><mass value='{m}'/><inertia ixx='0.001' ixy='0' ixz='0' iyy='0.001' iyz='0' izz='0.001'/>"
            "</inertial>")
HINGE = "<origin xyz='0 0 0.1'/><axis xyz='0 1 0'/><limit lower='-2' upper='2' effort='50' velocity='1'/>"


def _link(name: str, mass: float | None = None) -> str:
    return f"<link name='{name}'>{INERTIAL.format(m=mass) if mass is not None else ''}</link>"


def _joint(name: str, parent: str, child: str, kind: str) -> str:
    extra = HINGE if kind == "revolute" else "<origin xyz='0 0 0.05'/>"
    return f"<joint name='{name}' type='{kind}'><parent link='{parent}'/><child link='{child}'/>{extra}</joint>"


def _urdf_mass(path) -> float:
    """The robot's mass as its URDF declares it (a link without <inertial> has none)."""
    return sum(float(l.find("inertial/mass").get("value")) for l in ET.parse(path).getroot().findall("link")
               if l.find("inertial/mass") is not None)


def test_tiago_carries_no_phantom_kilogram_at_its_grasp_frame(tmp_path):
    urdf = robot_data() / "robots/tiago_description/robots/tiago.urdf"
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    result = import_urdf(urdf, tmp_path / "tiago", check=False)
    tree = build_tree(load_checked([result.file]))
    model = mujoco.MjModel.from_xml_string(to_mjcf(tree, visual=False, base="free"))
    for frame in ("hand_grasping_frame", "base_footprint"):  # URDF links without <inertial>, fixed to their parents
        assert model.body(frame).mass[0] == 0.0 and not model.body(frame).inertia.any(), frame
    assert model.body_subtreemass[0] == pytest.approx(_urdf_mass(urdf), abs=1e-9)  # 65.894 kg, 67.894 before
    assert not [f.message for f in tree.findings if "has no mass and" in f.message]


def _two_axis_robot(path) -> None:
    """`virtual` is the massless link between two revolutes of a two-axis joint (human.urdf's), `flag` a massless link
    on its own joint, `tcp` a massless link on a fixed joint, `holder` a massless link a joint moves with `weight`
    fixed to it."""
    path.write_text("<robot name='r'>\n" + "\n".join([
        _link("base", 2.0), _link("upper", 1.0), _link("tcp"), _link("virtual"), _link("hand", 0.5), _link("flag"),
        _link("holder"), _link("weight", 0.2),
        _joint("j1", "base", "upper", "revolute"), _joint("tcp_joint", "upper", "tcp", "fixed"),
        _joint("j2", "upper", "virtual", "revolute"), _joint("j3", "virtual", "hand", "revolute"),
        _joint("j4", "upper", "flag", "revolute"), _joint("j5", "upper", "holder", "revolute"),
        _joint("weight_joint", "holder", "weight", "fixed")]) + "\n</robot>")


def test_a_massless_link_a_moving_joint_carries_alone_gets_a_gram_in_mujoco_only_with_a_warning_naming_it(tmp_path):
    """MuJoCo refuses a moving body without mass, so its model gives `virtual` and `flag` a gram each. `tcp` (fixed)
    and `holder` (moving, but carrying `weight` fixed to it, which MuJoCo accepts) stay massless there too. The tree
    keeps all four massless, as the URDF says (it gave the two a gram once)."""
    urdf = tmp_path / "r.urdf"
    _two_axis_robot(urdf)
    result = import_urdf(urdf, tmp_path / "out")
    tree = build_tree(load_checked([result.file]))
    masses = {l.name: l.mass for l in tree.links}
    assert masses == {"base": 2.0, "upper": 1.0, "tcp": 0.0, "virtual": 0.0, "hand": 0.5, "flag": 0.0, "holder": 0.0,
                      "weight": 0.2}
    assert not any(tree.link(name).inertia.any() for name in ("tcp", "virtual", "flag", "holder"))
    assert [(l.name, mover) for l, mover in tree.moved_alone()] == [("virtual", "joint j2"), ("flag", "joint j4")]
    warned = [f.message for f in tree.findings if "has no mass and" in f.message]
    assert len(warned) == 2 and "link virtual has no mass and joint j2 moves it" in warned[0], warned
    assert "link flag has no mass and joint j4 moves it" in warned[1] and "1 g" in warned[1]
    sim = PlatformSimulator(tree)  # MuJoCo takes it
    model = sim.model
    assert model.body("tcp").mass[0] == 0.0 and model.body("holder").mass[0] == 0.0
    assert model.body("virtual").mass[0] == MOVING_FRAME_MASS and model.body("virtual").inertia.min() > 0
    assert model.body("flag").mass[0] == MOVING_FRAME_MASS and model.body("flag").inertia.min() > 0
    assert model.body_subtreemass[0] == pytest.approx(3.7 + 2 * MOVING_FRAME_MASS, abs=1e-12)


def test_a_urdf_massless_link_round_trips_through_the_urdf_and_sdf_exports_without_an_invented_inertial(tmp_path):
    """The gram MuJoCo needs is not the robot's: the exported URDF has no <inertial> where the source had none (it
    wrote `flag` and `virtual` 1 g once), and the SDF (which says a massless link by mass 0: without <inertial> SDF
    means 1 kg) gives them mass 0 and no inertia; imported again, the URDF gives the same tree masses."""
    urdf = tmp_path / "r.urdf"
    _two_axis_robot(urdf)
    tree = build_tree(load_checked([import_urdf(urdf, tmp_path / "out").file]))
    massless = {"tcp", "virtual", "flag", "holder"}
    exported = {l.get("name"): l for l in ET.fromstring(to_urdf(tree)).findall("link")}
    assert {name for name, l in exported.items() if l.find("inertial") is None} == massless
    assert np.isclose(float(exported["upper"].find("inertial/mass").get("value")), 1.0)
    sdf = {l.get("name"): l for l in ET.fromstring(to_sdf(tree)).iter("link")}
    for name in massless:
        assert float(sdf[name].find("inertial/mass").text) == 0.0, name
        assert not any(float(e.text) for e in sdf[name].find("inertial/inertia")), name
    again = tmp_path / "again.urdf"
    again.write_text(to_urdf(tree))
    tree2 = build_tree(load_checked([import_urdf(again, tmp_path / "again").file]))
    assert {l.name: l.mass for l in tree2.links} == {l.name: l.mass for l in tree.links}


def test_the_checkers_massless_warning_says_the_gram_mujoco_gives_by_its_constant(tmp_path, monkeypatch):
    """The checker's warning at a mass 0 says what a link a moving joint carries alone gets in MuJoCo from
    MOVING_FRAME_MASS (it wrote "1 g" in its text, which a new value would have left behind)."""
    urdf = tmp_path / "r.urdf"
    _two_axis_robot(urdf)
    monkeypatch.setattr(check_pmodel, "MOVING_FRAME_MASS", 0.002)
    said = [f.message for f in import_urdf(urdf, tmp_path / "out").findings if "is 0: a massless frame" in f.message]
    assert said and all("carries alone gets 2 g" in m for m in said), said
