"""Massless frames, as a new user imports a URDF. Found: a URDF link without <inertial> (TIAGo's hand_grasping_frame,
the Panda's panda_hand_tcp and panda_link8, every tool0) weighed 1 kg in the simulator: TIAGo carried a phantom
kilogram at its grasp point (arm_2_joint held 38.4 of its 39 N m at zero), the 65 URDFs of example-robot-data that
load 312 kg in all. Such a link is now a massless frame; where a moving joint carries one with nothing of mass fixed
to it (MuJoCo needs a mass there) it gets a gram, with a warning naming it."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree
from cotwin.pmodel.tree_build import MOVING_FRAME_MASS
from cotwin.pmodel.urdf import to_urdf
from cotwin.pmodel.urdf_import import import_urdf
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


def test_a_massless_link_a_moving_joint_carries_alone_gets_a_gram_with_a_warning_naming_it(tmp_path):
    """`virtual` is the massless link between two revolutes of a two-axis joint (human.urdf's), `flag` a massless link
    on its own joint: MuJoCo refuses a moving body without mass, so each gets a gram. `tcp` (fixed) and `holder`
    (moving, but carrying `weight` fixed to it, which MuJoCo accepts) stay massless."""
    urdf = tmp_path / "r.urdf"
    urdf.write_text("<robot name='r'>\n" + "\n".join([
        _link("base", 2.0), _link("upper", 1.0), _link("tcp"), _link("virtual"), _link("hand", 0.5), _link("flag"),
        _link("holder"), _link("weight", 0.2),
        _joint("j1", "base", "upper", "revolute"), _joint("tcp_joint", "upper", "tcp", "fixed"),
        _joint("j2", "upper", "virtual", "revolute"), _joint("j3", "virtual", "hand", "revolute"),
        _joint("j4", "upper", "flag", "revolute"), _joint("j5", "upper", "holder", "revolute"),
        _joint("weight_joint", "holder", "weight", "fixed")]) + "\n</robot>")
    result = import_urdf(urdf, tmp_path / "out")
    tree = build_tree(load_checked([result.file]))
    masses = {l.name: l.mass for l in tree.links}
    assert masses == {"base": 2.0, "upper": 1.0, "tcp": 0.0, "virtual": MOVING_FRAME_MASS, "hand": 0.5,
                      "flag": MOVING_FRAME_MASS, "holder": 0.0, "weight": 0.2}
    warned = [f.message for f in tree.findings if "has no mass and" in f.message]
    assert len(warned) == 2 and "link virtual has no mass and joint j2 moves it" in warned[0], warned
    assert "link flag has no mass and joint j4 moves it" in warned[1] and "1 g" in warned[1]
    sim = PlatformSimulator(tree)  # MuJoCo takes it
    model = sim.model
    assert model.body("tcp").mass[0] == 0.0 and model.body("holder").mass[0] == 0.0
    assert model.body("virtual").mass[0] == MOVING_FRAME_MASS and model.body("virtual").inertia.min() > 0
    assert model.body_subtreemass[0] == pytest.approx(3.7 + 2 * MOVING_FRAME_MASS, abs=1e-12)
    # the exported URDF says a massless frame as URDF does: no <inertial>
    exported = {l.get("name"): l for l in ET.fromstring(to_urdf(tree)).findall("link")}
    assert exported["tcp"].find("inertial") is None and exported["holder"].find("inertial") is None
    assert float(exported["flag"].find("inertial/mass").get("value")) == MOVING_FRAME_MASS
    assert np.isclose(float(exported["upper"].find("inertial/mass").get("value")), 1.0)
