"""`cotwin import-urdf`: URDFs no one here wrote (example-robot-data's Panda and UR5) imported with exact
kinematics, checked against an independent forward kinematics of the URDF itself; the exported URDF
round-trips; names, meshes, packages, joints and devices; bad URDF reported at its place."""

from __future__ import annotations

import importlib.metadata
import os
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from cotwin.cli import main
from cotwin.diagnostics import CotwinError
from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.robosim.check import load_checked


def robot_data() -> Path:
    """example-robot-data's share folder (a test dependency: pip install -e '.[test]')."""
    try:
        folder = Path(importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data"))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (it is in the test extra: pip install -e '.[test]')")
    if not folder.is_dir():
        pytest.skip(f"example-robot-data's URDFs are not at {folder}")
    return folder


PUBLISHED = {"panda": "robots/panda_description/urdf/panda.urdf", "ur5": "robots/ur_description/urdf/ur5_robot.urdf"}


# ---- the URDF's own kinematics, written here independently of cotwin (ElementTree, scipy rotations) ----

def _origin(el) -> np.ndarray:
    T = np.eye(4)
    o = el.find("origin")
    if o is not None:
        T[:3, :3] = Rotation.from_euler("xyz", [float(v) for v in o.get("rpy", "0 0 0").split()]).as_matrix()
        T[:3, 3] = [float(v) for v in o.get("xyz", "0 0 0").split()]
    return T


def urdf_world_frames(path: Path, q: dict[str, float]) -> dict[str, np.ndarray]:
    """Every link's world frame of a URDF at joint values q (URDF names; the root at the identity)."""
    robot = ET.parse(path).getroot()
    joints = robot.findall("joint")
    children = {j.find("child").get("link") for j in joints}
    root = next(l.get("name") for l in robot.findall("link") if l.get("name") not in children)
    world, pending = {root: np.eye(4)}, list(joints)
    while pending:
        for j in list(pending):
            parent = j.find("parent").get("link")
            if parent not in world:
                continue
            pending.remove(j)
            T = world[parent] @ _origin(j)
            if j.get("type") != "fixed":
                a = j.find("axis")
                axis = np.array([float(v) for v in (a.get("xyz") if a is not None else "1 0 0").split()])
                axis /= np.linalg.norm(axis)
                motion = np.eye(4)
                if j.get("type") == "prismatic":
                    motion[:3, 3] = axis * q.get(j.get("name"), 0.0)
                else:
                    motion[:3, :3] = Rotation.from_rotvec(axis * q.get(j.get("name"), 0.0)).as_matrix()
                T = T @ motion
            world[j.find("child").get("link")] = T
    return world


def urdf_limits(path: Path) -> dict[str, dict[str, float]]:
    out = {}
    for j in ET.parse(path).getroot().findall("joint"):
        limit = j.find("limit")
        out[j.get("name")] = {k: float(v) for k, v in (limit.attrib.items() if limit is not None else ())
                              if k in ("lower", "upper", "effort", "velocity")}
        out[j.get("name")]["type"] = j.get("type")
    return out


def urdf_inertials(path: Path) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """Per link: mass, the inertial frame in the link frame, the inertia about the COM in the link's axes."""
    out = {}
    for link in ET.parse(path).getroot().findall("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        T = _origin(inertial)
        i = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
        I = np.array([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]], [i["ixz"], i["iyz"], i["izz"]]])
        out[link.get("name")] = (float(inertial.find("mass").get("value")), T[:3, 3], T[:3, :3] @ I @ T[:3, :3].T)
    return out


def random_configuration(tree, rng) -> dict[str, float]:
    q = {}
    for j in tree.actuated:
        low, high = (j.lower, j.upper) if j.lower is not None and j.upper is not None else (-np.pi, np.pi)
        q[j.name] = float(rng.uniform(low, high))
    return q


def mujoco_world_frames(tree, q: dict[str, float]) -> dict[str, np.ndarray]:
    """Every link's world frame from cotwin's pipeline: the tree's MJCF loaded by MuJoCo, kinematics at q."""
    model = mujoco.MjModel.from_xml_string(to_mjcf(tree, None, visual=False))
    data = mujoco.MjData(model)
    for name, value in q.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_kinematics(model, data)
    out = {}
    for link in tree.links:
        T = np.eye(4)
        T[:3, :3] = data.body(link.name).xmat.reshape(3, 3)
        T[:3, 3] = data.body(link.name).xpos
        out[link.name] = T
    return out


@pytest.fixture(scope="module", params=sorted(PUBLISHED))
def imported(request, tmp_path_factory):
    """(URDF path, import result, kinematic tree) of a published robot imported into a fresh folder."""
    urdf = robot_data() / PUBLISHED[request.param]
    result = import_urdf(urdf, tmp_path_factory.mktemp(request.param))
    return urdf, result, build_tree(load_checked([result.file]))


def test_every_link_frame_of_the_imported_pmodel_equals_the_urdfs_own_at_random_configurations(imported):
    urdf, result, tree = imported
    pm_link = {r.urdf: r.pmodel for r in result.renamings if r.kind == "link"}
    urdf_joint = {r.pmodel: r.urdf for r in result.renamings if r.kind == "joint"}
    assert len(tree.links) == result.links and len(tree.actuated) == len(result.devices) >= 6
    rng = np.random.default_rng(2024)
    worst = 0.0
    for _ in range(25):
        q = random_configuration(tree, rng)
        ours = mujoco_world_frames(tree, q)
        theirs = urdf_world_frames(urdf, {urdf_joint.get(k, k): v for k, v in q.items()})
        assert len(theirs) == len(ours)
        for name, T in theirs.items():
            worst = max(worst, float(np.abs(ours[pm_link.get(name, name)] - T).max()))
    assert worst < 1e-9, f"a link frame is {worst:.3g} m (or rad) off the URDF's own"


def test_the_exported_urdf_round_trips_kinematics_inertials_and_limits(imported, tmp_path):
    urdf, result, tree = imported
    exported = tmp_path / "exported.urdf"
    run = CliRunner().invoke(main, ["export-pmodel", str(result.file), "--format", "urdf", "-o", str(exported)])
    assert run.exit_code == 0, run.output
    pm = {r.urdf: r.pmodel for r in result.renamings}
    back = {v: k for k, v in pm.items()}
    rng = np.random.default_rng(5)
    for _ in range(10):
        q = random_configuration(tree, rng)
        original = urdf_world_frames(urdf, {back.get(k, k): v for k, v in q.items()})
        again = urdf_world_frames(exported, q)
        for name, T in original.items():
            assert np.abs(again[pm.get(name, name)] - T).max() < 1e-9, name
    # limits: every bound the URDF gives comes back
    given, written = urdf_limits(urdf), urdf_limits(exported)
    for joint, limits in given.items():
        for key, value in limits.items():
            if key != "type" and limits["type"] != "fixed":
                assert written[pm.get(joint, joint)][key] == pytest.approx(value, abs=1e-12), (joint, key)
        assert written[pm.get(joint, joint)]["type"] == limits["type"]
    # inertials: equal, but where cotwin warned that it replaced an implausible inertia or a zero mass
    replaced = {f.message.split()[3] for f in result.findings if f.message.startswith("inertia of link")}
    massless = {f.message.split()[3] for f in result.findings if f.message.startswith("mass of link")}
    assert replaced <= {l.name for l in tree.links}
    mine, theirs = urdf_inertials(exported), urdf_inertials(urdf)
    compared = 0
    for link, (mass, com, inertia) in theirs.items():
        name = pm.get(link, link)
        if name in massless:
            assert mass == 0.0
            continue
        m2, c2, i2 = mine[name]
        assert m2 == pytest.approx(mass, rel=1e-12) and np.allclose(c2, com, atol=1e-12), link
        if name not in replaced:
            assert np.allclose(i2, inertia, atol=1e-12), link
            compared += 1
    ours = {pm.get(l, l) for l in theirs}  # a link without <inertial> is imported massless too, and not compared
    assert compared >= 4 and compared == len(theirs) - len(massless & ours) - len(replaced & ours)


def test_each_moving_joint_is_commanded_and_read_through_its_paths(imported):
    _, result, tree = imported
    sim = PlatformSimulator(tree)
    joints = {j.name: j for j in tree.actuated}
    targets = {}
    for k, d in enumerate(result.devices):  # somewhere inside each joint's limits, each joint elsewhere
        low, high = joints[d.joint].lower, joints[d.joint].upper
        targets[d.command] = low + (0.3 + 0.05 * k) * (high - low) if low is not None else 0.1 * (k + 1)
    sim.write_actuators(targets)
    sim.advance(5.0)  # default servo gains, effort limits (the Panda wrist 12 N m): settled within 4 s
    readings = sim.read_sensors()
    for d in result.devices:
        assert set(d.readings) == {"position", "velocity", "effort"}
        assert all(path in readings for path in d.readings.values())
        assert readings[d.readings["position"]] == pytest.approx(targets[d.command], abs=1e-4), d.joint


def test_the_output_is_byte_identical_from_any_working_directory(tmp_path, monkeypatch):
    urdf = robot_data() / PUBLISHED["ur5"]
    import_urdf(urdf, tmp_path / "a")
    monkeypatch.chdir(urdf.parent)
    import_urdf(urdf.name, tmp_path / "b")
    monkeypatch.chdir(tmp_path)
    import_urdf(urdf, "c")
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert len(files) == 15  # the p-model and 14 meshes
    for rel in files:
        data = (tmp_path / "a" / rel).read_bytes()
        assert data == (tmp_path / "b" / rel).read_bytes() == (tmp_path / "c" / rel).read_bytes(), rel
    assert str(tmp_path) not in (tmp_path / "a" / "ur5.pm").read_text()


# ---- a URDF of our own, with every feature the importer reads ----

def box_stl(path: Path, half=(0.02, 0.03, 0.05)) -> Path:
    """A binary STL of a box centred at the origin."""
    hx, hy, hz = half
    c = [np.array([sx * hx, sy * hy, sz * hz]) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6),
             (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    data = bytearray(80) + struct.pack("<I", len(faces))
    for a, b, d in faces:
        data += struct.pack("<12fH", 0, 0, 0, *c[a], *c[b], *c[d], 0)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(bytes(data))
    return path


ARM = """<?xml version="1.0"?>
<robot name="my-arm">
  <link name="world"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0.1 -0.2 0.05" rpy="0 0 0.3"/></joint>
  <link name="base">
    <inertial><origin xyz="0 0 0.05" rpy="0.1 0.2 0.3"/><mass value="3.0"/>
      <inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.025" iyz="0" izz="0.03"/></inertial>
    <collision><origin xyz="0 0 0.05"/><geometry><cylinder radius="0.08" length="0.1"/></geometry></collision>
    <visual><geometry><mesh filename="package://my_description/meshes/base.stl" scale="0.5 1 2"/></geometry>
      <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material></visual>
  </link>
  <joint name="link" type="continuous"><parent link="base"/><child link="2nd-link"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/><limit effort="40" velocity="2"/>
    <dynamics damping="0.5" friction="0.2"/></joint>
  <link name="2nd-link">
    <inertial><mass value="2.0"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial>
    <collision><origin xyz="0.1 0 0" rpy="0 1.5707963267948966 0"/><geometry><box size="0.2 0.05 0.04"/></geometry></collision>
    <collision><geometry><mesh filename="meshes/part.stl" scale="1 1 1"/></geometry></collision>
  </link>
  <joint name="elbow.joint" type="revolute"><parent link="2nd-link"/><child link="fore"/>
    <origin xyz="0.2 0 0" rpy="1.5707963267948966 0 0.4"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-2" upper="2.5" effort="30" velocity="3"/></joint>
  <link name="fore">
    <inertial><origin xyz="0.1 0 0"/><mass value="1.0"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.004" iyz="0" izz="0.004"/></inertial>
    <collision><origin xyz="0.1 0 0"/><geometry><sphere radius="0.04"/></geometry></collision>
  </link>
  <joint name="slide" type="prismatic"><parent link="fore"/><child link="finger_a"/>
    <origin xyz="0.2 0 0"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.1"/></joint>
  <joint name="slide_b" type="prismatic"><parent link="fore"/><child link="finger_b"/>
    <origin xyz="0.2 0 0"/><axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.1"/>
    <mimic joint="slide" multiplier="1.0" offset="0.0"/></joint>
  <link name="finger_a"><inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>
    <collision><origin xyz="0.02 0 0"/><geometry><box size="0.04 0.01 0.02"/></geometry></collision></link>
  <link name="finger_b"><inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>
    <collision><origin xyz="0.02 0 0"/><geometry><box size="0.04 0.01 0.02"/></geometry></collision></link>
  <transmission name="t1"/>
</robot>
"""


@pytest.fixture
def own_arm(tmp_path):
    """An arm of our own: its URDF in a package folder, meshes by package:// and by a relative name."""
    package = tmp_path / "src" / "my_description"
    (package / "package.xml").parent.mkdir(parents=True)
    (package / "package.xml").write_text("<package><name>my_description</name></package>")
    box_stl(package / "meshes" / "base.stl")
    box_stl(package / "urdf" / "meshes" / "part.stl", (0.05, 0.01, 0.01))
    urdf = package / "urdf" / "arm.urdf"
    urdf.write_text(ARM)
    return urdf


def test_our_own_arm_imports_with_every_feature_read(own_arm, tmp_path):
    result = import_urdf(own_arm, tmp_path / "out", [tmp_path / "src"])
    assert result.file == tmp_path / "out" / "my_arm.pm"
    renamed = {(r.kind, r.urdf): r.pmodel for r in result.renamings}
    assert renamed == {("robot", "my-arm"): "my_arm", ("link", "world"): "world_link", ("link", "2nd-link"): "_2nd_link",
                       ("joint", "elbow.joint"): "elbow_joint"}
    text = result.file.read_text()
    assert "jref ^link = Continuous" in text  # a keyword is kept, escaped
    assert 'annotation Mimic { leader = "slide" multiplier = 1.0 offset = 0.0 }' in text
    assert "dynamics = Dynamics { damping = 0.5 _friction = 0.2 }" in text
    assert 'annotation Visual { geometry = "mesh" file = "meshes/my_description/meshes/base.stl" scale = (|0.5, 1.0, 2.0|) material = "grey" rgba = (|0.5, 0.5, 0.5, 1.0|) }' in text
    assert sorted(p.relative_to(tmp_path / "out").as_posix() for p in result.meshes) == [
        "meshes/meshes/part.stl", "meshes/my_description/meshes/base.stl"]
    assert result.ignored == {"transmission": 1}
    tree = build_tree(load_checked([result.file]))
    joints = {j.name: j for j in tree.joints}
    assert joints["link"].kind == "revolute" and joints["link"].lower is None and joints["link"].damping == 0.5
    assert joints["link"].effort == 40 and joints["elbow_joint"].upper == 2.5
    assert joints["slide"].kind == "prismatic" and joints["slide_b"].upper == 0.04
    base = tree.link("base")
    assert base.mass == 3.0 and np.allclose(base.com[:3, 3], [0, 0, 0.05])
    assert np.allclose(base.inertia, [[0.02, 0.001, 0], [0.001, 0.025, 0], [0, 0, 0.03]])
    part = next(g for g in tree.link("_2nd_link").geoms if g.kind == "mesh")
    assert part.size == pytest.approx({"length": 0.1, "width": 0.02, "height": 0.02}, abs=1e-6)
    # frames: exact against the URDF's own, through MuJoCo
    rng = np.random.default_rng(3)
    names = {"world": "world_link", "2nd-link": "_2nd_link"}
    for _ in range(10):
        q = random_configuration(tree, rng)
        ours = mujoco_world_frames(tree, q)
        theirs = urdf_world_frames(own_arm, {"elbow.joint": q.pop("elbow_joint"), **q})
        for name, T in theirs.items():
            assert np.abs(ours[names.get(name, name)] - T).max() < 1e-9, name
    notes = "\n".join(str(f) for f in result.findings)
    assert "arm.urdf:" in notes and "mimics 'slide'" in notes and "friction 0.2" in notes


def test_a_hand_edited_pmodel_or_mesh_is_kept_unless_force_and_an_identical_one_is_no_conflict(own_arm, tmp_path):
    out = tmp_path / "out"
    args = ["import-urdf", str(own_arm), "-o", str(out), "--package-path", str(tmp_path / "src")]
    assert CliRunner().invoke(main, args).exit_code == 0
    pm, mesh = out / "my_arm.pm", out / "meshes" / "meshes" / "part.stl"
    written = pm.read_bytes()
    again = CliRunner().invoke(main, args)  # the same bytes: no conflict, the import repeats
    assert again.exit_code == 0, again.output
    pm.write_bytes(written + b"// my hand edit\n")
    mesh.write_bytes(mesh.read_bytes() + b"\0")
    edited_mesh = mesh.read_bytes()
    refused = CliRunner().invoke(main, args)
    assert isinstance(refused.exception, CotwinError)  # cotwin's entry reports it as located errors
    shown = str(refused.exception)
    assert f"{pm}: already there with other content" in shown and "--force" in shown
    assert f"{mesh}: already there with other content" in shown
    assert pm.read_bytes().endswith(b"// my hand edit\n") and mesh.read_bytes() == edited_mesh
    forced = CliRunner().invoke(main, [*args, "--force"])
    assert forced.exit_code == 0, forced.output
    assert pm.read_bytes() == written and mesh.read_bytes() != edited_mesh


def test_the_exported_urdf_keeps_a_continuous_joint_continuous(own_arm, tmp_path):
    result = import_urdf(own_arm, tmp_path / "out", [tmp_path / "src"])
    exported = tmp_path / "again.urdf"
    run = CliRunner().invoke(main, ["export-pmodel", str(result.file), "--format", "urdf", "-o", str(exported)])
    assert run.exit_code == 0, run.output
    limits = urdf_limits(exported)
    assert limits["link"] == {"type": "continuous", "effort": 40.0, "velocity": 2.0}
    assert limits["elbow_joint"] == {"type": "revolute", "lower": -2.0, "upper": 2.5, "effort": 30.0, "velocity": 3.0}


def test_a_negative_moment_that_rounds_zero_is_imported_and_a_real_one_refused(tmp_path):
    """iCub's r_hip_2 has ixx = iyy = -5.42101e-20 (a CAD export's zero): refusing every negative moment refused
    example-robot-data's icub.urdf and icub_reduced.urdf, which the import took before."""
    def robot(moment: str) -> Path:
        urdf = tmp_path / f"hip{moment}.urdf"
        urdf.write_text(f"<robot name='hip'><link name='a'><inertial><mass value='0.526'/><inertia ixx='{moment}' "
                        f"ixy='0' ixz='0' iyy='{moment}' iyz='0' izz='0'/></inertial></link></robot>")
        return urdf

    result = import_urdf(robot("-5.42101e-20"), tmp_path / "icub")
    assert any("inertia of link a is not physical" in f.message for f in result.findings), result.findings
    with pytest.raises(CotwinError, match="a negative moment of inertia"):
        import_urdf(robot("-1e-6"), tmp_path / "bad")


def test_an_exported_mesh_uri_in_a_folder_named_with_a_hash_reads_back(own_arm, tmp_path):
    """Exported as file:///.../my #1 robot/meshes/..., the '#' cut the URI (a fragment): importing cotwin's own
    URDF export said 'no such file (.../my )'."""
    result = import_urdf(own_arm, tmp_path / "my #1 robot", [tmp_path / "src"])
    exported = tmp_path / "again.urdf"
    for fmt, out in (("urdf", exported), ("sdf", tmp_path / "again.sdf")):
        run = CliRunner().invoke(main, ["export-pmodel", str(result.file), "--format", fmt, "-o", str(out)])
        assert run.exit_code == 0, run.output
        assert "my %231 robot/meshes/" in out.read_text() and "my #1" not in out.read_text()
    again = import_urdf(exported, tmp_path / "back")  # the collision meshes (visuals are not exported)
    assert [m.name for m in again.meshes] == ["part.stl"], again.meshes


def test_a_continuous_joint_without_limit_is_exported_without_one(tmp_path):
    """A continuous joint the URDF gave no <limit> came back with effort="0" velocity="0": a joint that,
    read by ROS, can neither push nor move."""
    urdf = tmp_path / "spin.urdf"
    urdf.write_text("<robot name='spin'>" + _links("a", "b") + _joint("wheel", "a", "b", "continuous") + "</robot>")
    result = import_urdf(urdf, tmp_path / "out")
    exported = tmp_path / "again.urdf"
    run = CliRunner().invoke(main, ["export-pmodel", str(result.file), "--format", "urdf", "-o", str(exported)])
    assert run.exit_code == 0, run.output
    assert urdf_limits(exported)["wheel"] == {"type": "continuous"}
    assert ET.parse(exported).getroot().find("joint[@name='wheel']/limit") is None


def test_package_uris_resolve_through_the_package_path_ros_package_path_and_the_urdfs_folders(own_arm, tmp_path):
    # the folder holding the package, given with --package-path
    assert import_urdf(own_arm, tmp_path / "a", [tmp_path / "src"]).meshes
    # the package folder itself, from ROS_PACKAGE_PATH
    assert import_urdf(own_arm, tmp_path / "b", [], {"ROS_PACKAGE_PATH": str(own_arm.parents[1])}).meshes
    # a package.xml naming it, a few folders down
    other = tmp_path / "ws"
    (other / "x" / "y").mkdir(parents=True)
    (own_arm.parents[1]).rename(other / "x" / "y" / "renamed")
    moved = other / "x" / "y" / "renamed" / "urdf" / "arm.urdf"
    assert import_urdf(moved, tmp_path / "c", [other], {}).meshes
    # nowhere: the URDF's own folders name it (package.xml above the URDF)
    assert import_urdf(moved, tmp_path / "d", [], {}).meshes
    (other / "x" / "y" / "renamed" / "package.xml").unlink()
    with pytest.raises(CotwinError) as err:
        import_urdf(moved, tmp_path / "e", [tmp_path / "nowhere"], {})
    assert "arm.urdf:9:" in str(err.value) and "no package 'my_description' found" in str(err.value)
    assert not (tmp_path / "e").exists()  # nothing written when the URDF cannot be imported


def test_file_uris_and_absolute_names_are_copied_in(tmp_path):
    mesh = box_stl(tmp_path / "elsewhere" / "shape.stl")
    urdf = tmp_path / "robot" / "r.urdf"  # the mesh is not below the URDF's folder: copied by its name
    urdf.parent.mkdir()
    urdf.write_text(f"""<robot name="r"><link name="a"><collision><geometry><mesh filename="file://{mesh}"/></geometry>
      </collision><visual><geometry><mesh filename="{mesh}"/></geometry></visual></link></robot>""")
    result = import_urdf(urdf, tmp_path / "out")
    assert [p.name for p in result.meshes] == ["shape.stl"]  # one file, named twice
    assert 'shape "meshes/shape.stl"' in result.file.read_text()


# ---- bad URDF: every problem at its place, all of them at once ----

def _links(*names) -> str:
    return "".join(f'<link name="{n}"/>' for n in names)


def _joint(name, parent, child, kind="fixed", extra="") -> str:
    return f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>{extra}</joint>'


BAD = [
    ("<robot name='r'><link name='a'>\n<link name='b'/></robot>", "2:19", "malformed XML: mismatched tag"),
    ("", "1:1", "malformed XML: no element found"),
    ("<robot name='r'>\n  <xacro:macro name='m'/>\n" + _links("a") + "</robot>", "2:3", "xacro left unexpanded"),
    ("<robot name='r'>\n" + _links("a") + "\n<link name='${prefix}b'/></robot>", "3:1", "xacro substitution left unexpanded"),
    ("<model name='r'/>", "1:1", "the document is a <model>, not a URDF <robot>"),
    ("<robot name='r'>\n" + _links("a", "b") + "\n" + _joint("j", "a", "b", "ball") + "</robot>", "3:1",
     "unknown joint type 'ball'"),
    ("<robot name='r'>\n" + _links("a", "b") + "\n" + _joint("j", "a", "b", "floating") + "</robot>", "3:1",
     "a floating joint has several degrees of freedom"),
    ("<robot name='r'>\n" + _links("a", "b", "c") + "\n" + _joint("j", "a", "b") + "</robot>", "2:",
     "a URDF has one root; roots: 'a' (line 2), 'c' (line 2)"),
    ("<robot name='r'>\n" + _links("a", "b", "c") + "\n" + _joint("j1", "b", "c") + "\n" + _joint("j2", "c", "b")
     + "</robot>", "4:1", "joints form a cycle: b --j1--> c -> c --j2--> b"),
    ("<robot name='r'>\n" + _links("a", "b") + "\n" + _joint("j1", "a", "b") + "\n" + _joint("j2", "a", "b") + "</robot>",
     "4:1", "link 'b' is the child of joints 'j1' (line 3) and 'j2'"),
    ("<robot name='r'>\n" + _links("a") + "\n" + _joint("j", "a", "ghost") + "</robot>", "3:1",
     "joint 'j' names link 'ghost', which the robot does not declare"),
    ("<robot name='r'>\n" + _links("a", "b") + "\n" + _joint("j", "a", "b", "revolute") + "</robot>", "3:1",
     "a revolute joint needs <limit>"),
    ("<robot name='r'>\n" + _links("a", "b") + "\n" + _joint("j", "a", "b", "revolute", "\n<limit lower='1' upper='0'/>")
     + "</robot>", "4:1", "<limit> has no effort and no velocity"),
    ("<robot name='r'>\n" + _links("a", "b") + "\n" + _joint("j", "a", "b", "prismatic",
     "<limit effort='1' velocity='1'/>\n<axis xyz='0 0 0'/>") + "</robot>", "4:1", "joint 'j': a zero axis"),
    ("<robot name='r'>\n<link name='a'><inertial><mass value='-1'/><inertia ixx='1' ixy='0' ixz='0' iyy='1' iyz='0' "
     "izz='1'/></inertial></link></robot>", "2:26", "a negative mass"),
    ("<robot name='r'>\n<link name='a'><inertial><mass value='1e300'/><inertia ixx='1' ixy='0' ixz='0' iyy='1' "
     "iyz='0' izz='1'/></inertial></link></robot>", "2:26", "a mass of 1e+300 kg, more than a link may have"),
    ("<robot name='r'>\n<link name='a'><inertial><mass value='nan'/><inertia ixx='1' ixy='0' ixz='0' iyy='1' "
     "iyz='0' izz='1'/></inertial></link></robot>", "2:26", "value=\"nan\" must be 1 finite number"),
    ("<robot name='r'>\n<link name='a'><inertial><mass value='1'/>\n<inertia ixx='-1' ixy='0' ixz='0' iyy='1' "
     "iyz='0' izz='1'/></inertial></link></robot>", "3:1", "a negative moment of inertia (ixx=-1 kg m^2)"),
    ("<robot name='r'>\n<link name='a'><inertial><mass value='1'/>\n<inertia ixx='1' ixy='1e300' ixz='0' iyy='1' "
     "iyz='0' izz='1'/></inertial></link></robot>", "3:1", "inertia ixy=1e+300 kg m^2, more than a link may have"),
    ("<robot name='r'>\n<link name='a'><inertial><mass value='1'/>\n<inertia ixx='1' ixy='0' iyy='1' iyz='0' "
     "izz='1'/></inertial></link></robot>", "3:1", "<inertia> has no 'ixz' attribute"),
    ("<robot name='r'>\n<link name='a'><collision><geometry>\n<box size='1 2'/></geometry></collision></link></robot>",
     "3:1", "size=\"1 2\" must be 3 finite numbers"),
    ("<robot name='r'>\n<link name='a'><collision><geometry>\n<cylinder radius='nan' length='1'/></geometry></collision>"
     "</link></robot>", "3:1", "radius=\"nan\" must be 1 finite number"),
    ("<robot name='r'>\n<link name='a'><visual><geometry>\n<mesh filename='meshes/none.stl'/></geometry></visual></link>"
     "</robot>", "3:1", "mesh 'meshes/none.stl': no such file"),
    ("<robot name='r'>\n<link name='a'><visual><geometry>\n<mesh filename='http://x/y.stl'/></geometry></visual></link>"
     "</robot>", "3:1", "not http://"),
    ("<robot name='r'>\n<link name='a'><visual><geometry>\n<mesh/></geometry></visual></link></robot>", "3:1",
     "<mesh> has no 'filename' attribute"),
    ("<robot name='r'>\n<link name='a'><visual><geometry>\n<cone radius='1'/></geometry></visual></link></robot>", "3:1",
     "unknown geometry <cone>"),
    ("<robot>\n" + _links("a") + "</robot>", "1:1", "<robot> has no 'name' attribute"),
    ("<robot name='r'>\n<link/></robot>", "2:1", "a link: <link> has no 'name' attribute"),
    ("<robot name='r'>\n" + _links("a", "a") + "</robot>", "2:17", "link 'a' is declared twice (first at line 2)"),
    ("<robot name='r'>\n" + _links("a", "b", "c") + "\n" + _joint("j1", "a", "b", "prismatic",
     "<limit effort='1' velocity='1'/>") + "\n" + _joint("j2", "a", "c", "prismatic",
     "<limit effort='1' velocity='1'/>\n<mimic joint='j9'/>") + "</robot>", "5:1",
     "joint 'j2' mimics joint 'j9', which the robot does not declare"),
]


def _moving(extra: str, kind: str = "revolute") -> str:
    """A robot of two links and one joint with `extra` in the joint, after a line break (its line is 4)."""
    return ("<robot name='r'>\n" + _links("a", "b") + "\n" + _joint("j", "a", "b", kind,
            "<limit effort='1' velocity='1'/>\n" + extra) + "</robot>")


def _shape(geometry: str, origin: str = "") -> str:
    """A robot of one link with a collision: `origin` on line 3, the geometry on the next line."""
    return f"<robot name='r'>\n<link name='a'><collision>\n{origin or '<origin/>'}<geometry>\n{geometry}</geometry>" \
           "</collision></link></robot>"


BAD += [  # numbers no robot has: not finite (what cannot be computed), or finite beyond any robot's
    (_moving("<origin xyz='nan 0 0'/>"), "4:1", "joint 'j': origin xyz=\"nan 0 0\" must be 3 finite numbers"),
    (_moving("<origin rpy='0 -inf 0'/>"), "4:1", "joint 'j': origin rpy=\"0 -inf 0\" must be 3 finite numbers"),
    (_moving("<axis xyz='0 0 inf'/>"), "4:1", "axis of joint 'j': axis xyz=\"0 0 inf\" must be 3 finite numbers"),
    (_moving("<origin xyz='1e300 0 0'/>"), "4:1",
     "joint 'j': origin xyz=\"1e300 0 0\": 1e+300 m, beyond any robot's (1e+06 m; a unit slip?)"),
    (_moving("<origin rpy='0 0 1e300'/>"), "4:1", "joint 'j': origin rpy=\"0 0 1e300\": 1e+300 rad, beyond any robot's"),
    (_moving("<axis xyz='1e300 1e300 0'/>"), "4:1", "joint 'j': axis xyz=\"1e300 1e300 0\" is too long to normalise"),
    (_moving("<limit effort='1e300' velocity='1'/>").replace("<limit effort='1' velocity='1'/>\n", "\n"), "4:1",
     "limit of joint 'j': limit effort=\"1e300\": 1e+300, beyond any robot's (1e+20; a unit slip?)"),
    (_moving("<limit effort='1' velocity='1' upper='2e6'/>", "prismatic").replace("<limit effort='1' velocity='1'/>\n",
     "\n"), "4:1", "limit of joint 'j': limit upper=\"2e6\": 2e+06 m, beyond any robot's"),
    (_shape("<box size='1 1e300 1'/>"), "4:1", "collision of link 'a': box size=\"1 1e300 1\": 1e+300 m, beyond"),
    (_shape("<cylinder radius='0.1' length='1e7'/>"), "4:1", "cylinder length=\"1e7\": 1e+07 m, beyond any robot's"),
    (_shape("<sphere radius='1'/>", "<origin xyz='0 0 -1e9'/>"), "3:1",
     "collision of link 'a': origin xyz=\"0 0 -1e9\": 1e+09 m, beyond any robot's"),
]


@pytest.mark.parametrize("text, where, message", BAD, ids=[m for _, _, m in BAD])
def test_bad_urdf_is_reported_at_its_place(tmp_path, text, where, message):
    urdf = tmp_path / "bad.urdf"
    urdf.write_text(text)
    with pytest.raises(CotwinError) as err:
        import_urdf(urdf, tmp_path / "out")
    shown = str(err.value)
    assert f"bad.urdf:{where}" in shown and message in shown, shown
    assert not (tmp_path / "out").exists()


ONE = [  # each said once, as what it is
    ("<robot name=''>\n" + _links("a") + "</robot>", "1:1", "the robot: <robot> has an empty 'name'"),
    ("<robot name='r'>\n<link name=''/></robot>", "2:1", "a link: <link> has an empty 'name'"),
    ("<robot name='r'>\n" + _links("a", "b") + "\n<joint name=' ' type='fixed'><parent link='a'/><child link='b'/>"
     "</joint></robot>", "3:1", "a joint: <joint> has an empty 'name'"),
    ("<robot name='r'>\n<link name='a'><visual><geometry>\n<mesh filename='package://'/></geometry></visual></link>"
     "</robot>", "3:1", "mesh 'package://': names no package"),
    ("<robot name='r'>\n<link name='a'><visual><geometry>\n<mesh filename='meshes'/></geometry></visual></link>"
     "</robot>", "3:1", "mesh 'meshes': a folder, not a mesh file"),
    ("<robot name='r'>\n<link name='a'><visual><geometry>\n<mesh filename='pipe.stl'/></geometry></visual></link>"
     "</robot>", "3:1", "mesh 'pipe.stl': not a regular file (a FIFO, a device?)"),
    ("<robot name='r'>\n" + _links("a", "b", "c", "d") + "\n" + "\n".join(
        _joint(f"j{k}", p, c, "continuous", f"<mimic joint='j{k % 3 + 1}'/>") for k, (p, c) in
        enumerate((("a", "b"), ("b", "c"), ("c", "d")), 1)) + "</robot>", "3:",
     "mimic joints form a cycle: j1 -> j2 -> j3 -> j1"),
    ("<robot name='r'>\n<xacro:include filename='x'/>" + _links("a") + "</robot>", "2:1",
     "expand it first (`xacro arm.urdf.xacro > arm.urdf`)"),
]


@pytest.mark.parametrize("text, where, message", ONE, ids=[m for _, _, m in ONE])
def test_an_empty_name_a_mesh_that_is_no_file_and_a_bare_package_uri_are_one_error_each(tmp_path, text, where, message):
    """Mimics in a loop were imported (with a warning per joint); an empty link name was imported as `_` and an empty robot name replaced by the file's; `package://` was
    looked for as the first package folder ('no such file' and 'one slash too many'); a folder or a FIFO named as
    a mesh was 'no such file'; an empty <link> also gave 'robot has no <link>'; the xacro hint for arm.urdf.xacro
    said `> arm.urdf.urdf`."""
    (tmp_path / "meshes").mkdir()
    os.mkfifo(tmp_path / "pipe.stl")
    urdf = tmp_path / "arm.urdf.xacro"
    urdf.write_text(text)
    with pytest.raises(CotwinError) as err:
        import_urdf(urdf, tmp_path / "out", package_path=[tmp_path])
    (finding,) = err.value.findings
    assert f"arm.urdf.xacro:{where}" in str(err.value) and message in finding.message, str(err.value)
    assert not (tmp_path / "out").exists()


def test_every_problem_of_a_file_is_reported_together(tmp_path):
    urdf = tmp_path / "many.urdf"
    urdf.write_text("<robot name='r'>\n" + _links("a", "b", "c", "d") + "\n" + _joint("j1", "a", "b", "hinge") + "\n"
                    + _joint("j2", "a", "c", "revolute") + "\n<link name='e'><visual><geometry>\n"
                    "<mesh filename='gone.stl'/></geometry></visual></link>\n" + _joint("j3", "a", "zz") + "</robot>")
    with pytest.raises(CotwinError) as err:
        import_urdf(urdf, tmp_path / "out")
    lines = [str(f) for f in err.value.findings]
    assert len(lines) == 4, lines
    for where, text in (("3:1", "unknown joint type 'hinge'"), ("4:1", "a revolute joint needs <limit>"),
                        ("6:1", "gone.stl"), ("7:1", "names link 'zz'")):
        assert any(f"many.urdf:{where}" in line and text in line for line in lines), (where, lines)


def test_a_links_impossible_mass_and_inertia_and_a_zero_axis_are_refused_together_at_their_elements(tmp_path):
    urdf = tmp_path / "heavy.urdf"
    urdf.write_text("<robot name='r'>\n<link name='a'/>\n<link name='b'><inertial>\n<mass value='1e300'/>\n"
                    "<inertia ixx='1' ixy='0' ixz='0' iyy='-2' iyz='0' izz='1'/></inertial></link>\n"
                    + _joint("j", "a", "b", "revolute", "<limit effort='1' velocity='1'/>\n<axis xyz='0 0 0'/>")
                    + "</robot>")
    with pytest.raises(CotwinError) as err:
        import_urdf(urdf, tmp_path / "out")
    lines = [str(f) for f in err.value.findings]
    assert len(lines) == 3, lines
    for where, text in (("4:1", "link 'b': a mass of 1e+300 kg"), ("5:1", "a negative moment of inertia (iyy=-2"),
                        ("7:1", "joint 'j': a zero axis")):
        assert any(f"heavy.urdf:{where}: error:" in line and text in line for line in lines), (where, lines)
    assert not (tmp_path / "out").exists()


def test_numbers_no_robot_has_are_refused_together_with_an_impossible_mass(tmp_path):
    urdf = tmp_path / "odd.urdf"
    urdf.write_text("<robot name='r'>\n<link name='a'><inertial>\n<mass value='1e300'/>\n<inertia ixx='1' ixy='0' ixz='0' "
                    "iyy='1' iyz='0' izz='1'/></inertial><collision><geometry>\n<sphere radius='1e300'/></geometry>"
                    "</collision></link>\n<link name='b'/>\n" + _joint("j", "a", "b", "fixed", "\n<origin xyz='nan 0 0'/>")
                    + "</robot>")
    with pytest.raises(CotwinError) as err:
        import_urdf(urdf, tmp_path / "out")
    lines = [str(f) for f in err.value.findings]
    assert len(lines) == 3, lines
    for where, text in (("3:1", "link 'a': a mass of 1e+300 kg"), ("5:1", "sphere radius=\"1e300\": 1e+300 m, beyond"),
                        ("8:1", "joint 'j': origin xyz=\"nan 0 0\" must be 3 finite numbers")):
        assert any(f"odd.urdf:{where}: error:" in line and text in line for line in lines), (where, lines)
    assert not (tmp_path / "out").exists()


def test_numbers_beyond_a_robots_are_warned_of_at_their_element_and_kept(tmp_path):
    """An origin 2 km away, an angle in degrees, a 5 km box, a mesh scaled 5000 times: finite, possible for
    the simulator, but no robot's: a warning at each element naming the attribute, the value kept."""
    (tmp_path / "m.stl").write_text("solid m\nendsolid m\n")
    urdf = tmp_path / "far.urdf"
    urdf.write_text("<robot name='r'>\n<link name='a'><visual>\n<origin rpy='0 0 90'/><geometry>\n<box size='5000 1 1'/>"
                    "</geometry></visual><visual><geometry>\n<mesh filename='m.stl' scale='5000 5000 5000'/></geometry>"
                    "</visual></link>\n<link name='b'/>\n" + _joint("j", "a", "b", "fixed", "\n<origin xyz='0 2000 0'/>")
                    + "</robot>")
    result = import_urdf(urdf, tmp_path / "out", check=False)
    lines = [str(f) for f in result.findings]
    for where, text in (("3:1", "visual of link 'a': origin rpy=\"0 0 90\": 90 rad, more than a robot has (6.28319 rad; "
                         "degrees written for radians?): kept as written"),
                        ("4:1", "visual of link 'a': box size=\"5000 1 1\": 5000 m, more than a robot has (1000 m"),
                        ("5:1", "mesh scale=\"5000 5000 5000\": 5000, more than a robot has (1000;"),
                        ("8:1", "joint 'j': origin xyz=\"0 2000 0\": 2000 m, more than a robot has (1000 m; a unit slip?)")):
        assert any(f"far.urdf:{where}: warning:" in line and text in line for line in lines), (where, lines)
    text = result.file.read_text()
    assert "y = 2000.0" in text and "rpy = (|0.0, 0.0, 90.0|)" in text and "size = (|5000.0, 1.0, 1.0|)" in text


def test_the_command_from_another_folder_prints_what_it_did_and_refuses_bad_input(own_arm, tmp_path, monkeypatch):
    import subprocess
    import sys

    monkeypatch.chdir(tmp_path)
    run = subprocess.run([sys.executable, "-m", "cotwin", "import-urdf", str(own_arm), "-o", "imported",
                          "--package-path", "src"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "imported/my_arm.pm: p-model my_arm: 6 links, 1 revolute, 1 continuous, 2 prismatic, 1 fixed joints" in run.stdout
    assert "link  2nd-link    -> _2nd_link  (not a RoboSim name)" in run.stdout
    assert "link  world       -> world_link  (MuJoCo reserves the name)" in run.stdout
    assert "left out (no kinematics or inertia in them): 1 <transmission>" in run.stdout
    assert "slide_b (prismatic): my_arm::fore::slide_b::{slide_b_motor.dangle; slide_b_position.output_position" in run.stdout
    assert "mimics 'slide'" in run.stderr
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='r'><link name='a'>")
    run = subprocess.run([sys.executable, "-m", "cotwin", "import-urdf", str(bad), "-o", "x"], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 1 and "bad.urdf:1:" in run.stderr and "malformed XML" in run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "x").exists()


def test_an_output_that_is_a_file_or_a_urdf_that_is_missing_is_refused(own_arm, tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("mine")
    with pytest.raises(CotwinError, match="not a folder"):
        import_urdf(own_arm, taken, [tmp_path / "src"])
    assert taken.read_text() == "mine"
    with pytest.raises(CotwinError) as err:
        import_urdf(tmp_path / "none.urdf", tmp_path / "out")
    assert "none.urdf: error: cannot read the URDF" in str(err.value) and not (tmp_path / "out").exists()


def test_a_robot_name_too_long_for_a_file_name_is_refused_at_the_robot_and_the_longest_is_written(tmp_path):
    """A robot named by 5000 characters failed with "File name too long: " and the whole name, an empty output
    folder left; one of 252 (a p-model file name of 255 bytes) failed on the temporary file written first."""
    urdf = tmp_path / "long.urdf"
    urdf.write_text("<robot name='" + "x" * 5000 + "'>\n" + _links("a") + "</robot>")
    with pytest.raises(CotwinError) as err:
        import_urdf(urdf, tmp_path / "out")
    assert "long.urdf:1:1: error: the robot's name (5000 characters" in str(err.value)
    assert len(str(err.value)) < 400 and not (tmp_path / "out").exists()
    urdf.write_text("<robot name='" + "x" * 252 + "'>\n" + _links("a") + "</robot>")
    result = import_urdf(urdf, tmp_path / "out")
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["x" * 252 + ".pm"] == [result.file.name]


def test_a_pmodel_the_importer_wrote_wrongly_is_reported_as_its_bug(own_arm, tmp_path, monkeypatch):
    from cotwin.pmodel import urdf_import

    monkeypatch.setattr(urdf_import.Writer, "text", lambda self: "pmodel broken {\n")
    with pytest.raises(CotwinError) as err:
        import_urdf(own_arm, tmp_path / "out", [tmp_path / "src"])
    assert "a bug of the importer" in str(err.value) and "my_arm.pm:2:" in str(err.value)


def test_an_arm_of_fewer_than_six_joints_reaches_what_its_joints_can_and_is_told_once(own_arm, tmp_path, caplog,
                                                                                      monkeypatch):
    """A 2-joint arm imported and twinned found every hole 'infeasible' (the IK reached for a full pose), then was
    refused ('needs 6 or more'): it now reaches the points its joints reach, the orientation as near as they allow,
    `reachable` judging by that, and is told once what the IK holds for it."""
    import logging

    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.mapping.runtime import FunctionRegistry
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.pmodel.tree import build_tree
    from cotwin.robosim.check import load_checked

    monkeypatch.setenv("COTWIN_CACHE", str(tmp_path / "cache"))
    result = import_urdf(own_arm, tmp_path / "out", [tmp_path / "src"])
    tree = build_tree(load_checked([result.file]))
    registry = FunctionRegistry(SimulatedEndpoint(PlatformSimulator(tree, None)))  # a mapping mirroring q<i> makes one
    assert registry.arm == ["link", "elbow_joint"] and registry.solver.task == "position"
    point = registry.solver.chain.pose(np.array([0.4, 0.7]))[:3, 3]  # where its fingertips are at that posture
    with caplog.at_level(logging.WARNING, logger="cotwin.ik"):
        assert registry.reachable(*point)
        q = registry.inverse_kinematics(*point)
        assert not registry.reachable(*(point + [0.0, 0.0, 0.05]))  # off the surface its two joints sweep
    assert np.linalg.norm(registry.solver.chain.pose(np.array(q))[:3, 3] - point) < 1e-9
    told = [r.getMessage() for r in caplog.records if r.name == "cotwin.ik"]
    assert len(told) == 1 and "has 2 moving joints (link, elbow_joint)" in told[0] and "as near" in told[0], told


def test_a_mesh_path_spelled_otherwise_is_among_the_renamings(own_arm, tmp_path):
    """A mesh under a folder with a space and non-ASCII letters is copied under a portable name: the renaming
    is printed with the others (docs/urdf-import.md says every renaming is), not done silently."""
    package = own_arm.parent.parent
    box_stl(package / "meshes ü" / "lïnk 1.stl")
    own_arm.write_text(own_arm.read_text().replace("package://my_description/meshes/base.stl",
                                                   "package://my_description/meshes ü/lïnk 1.stl"))
    result = import_urdf(own_arm, tmp_path / "out", [tmp_path / "src"])
    meshes = [(r.urdf, r.pmodel) for r in result.renamings if r.kind == "mesh"]
    assert meshes == [("meshes/my_description/meshes ü/lïnk 1.stl", "meshes/my_description/meshes__/l_nk_1.stl")]
    assert (tmp_path / "out" / "meshes" / "my_description" / "meshes__" / "l_nk_1.stl").is_file()


def test_a_urdf_that_is_a_fifo_is_refused_not_waited_on(tmp_path):
    import os

    fifo = tmp_path / "robot.urdf"
    os.mkfifo(fifo)
    with pytest.raises(CotwinError, match="cannot read the URDF: not a regular file"):
        import_urdf(fifo, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_robot_whose_zero_posture_is_beyond_its_limits_starts_at_them(tmp_path):
    """The Kinova j2s6s200's joints 2, 3 and 5 have limits excluding 0 ([0.82, 5.46] rad...): started at 0, the
    simulator threw them against their limits (joint 5 to 2.5 rad within 0.2 s, a torque that a mapping reads as a
    stall). Each starts at the limit nearest 0, with a warning at the joint; the robot then rests where it starts."""
    result = import_urdf(robot_data() / "robots/kinova_description/robots/kinova.urdf", tmp_path / "kinova")
    tree = build_tree(load_checked([result.file]))
    starts = {j.name: j.start for j in tree.actuated if j.start != 0.0}
    assert set(starts) == {"j2s6s200_joint_2", "j2s6s200_joint_3", "j2s6s200_joint_5"}
    assert all(start == next(j.lower for j in tree.actuated if j.name == name) for name, start in starts.items())
    said = "\n".join(f.message for f in tree.findings)
    assert "joint j2s6s200_joint_2: its zero position is outside its limits [0.820305, 5.46288]" in said
    sim = PlatformSimulator(tree)
    for step in range(2):
        q = sim.joint_positions()
        assert all(abs(q[name] - start) < 1e-6 for name, start in starts.items()), (step, q)
        sim.step(200)


@pytest.mark.parametrize("name, text, said", [
    ("cut.stl", "solid x\n facet normal 0 0 1\n outer loop\n vertex 0 0 0\n vertex 1 0 0\n vertex 0 1", "its vertex #3"),
    ("word.stl", "solid x\n vertex a b c\n", "its vertex #1"),
    ("short.obj", "v 1 2\nv 3 4 5\n", "its v #1"),
])
def test_a_text_mesh_with_a_vertex_that_is_not_three_numbers_is_a_named_placeholder(tmp_path, name, text, said):
    """A truncated ASCII STL was an internal error (IndexError) after the p-model was written; a vertex of words,
    or of two numbers, a warning in Python's or numpy's words that named no file."""
    (tmp_path / name).write_text(text)
    urdf = tmp_path / "r.urdf"
    urdf.write_text(f"<robot name='r'><link name='a'><collision><geometry><mesh filename='{name}'/></geometry>"
                    "</collision></link></robot>")
    result = import_urdf(urdf, tmp_path / "out")
    shown = [f.message for f in result.findings if name in f.message]
    assert len(shown) == 1 and said in shown[0] and "is not three numbers" in shown[0], result.findings


def test_a_forced_import_replaces_a_mesh_hard_linked_to_another_file_and_leaves_that_file(own_arm, tmp_path):
    """`--force` copied the mesh into the file there: a hard link planted at meshes/... had its other name
    (a file outside the output folder) overwritten."""
    out = tmp_path / "out"
    result = import_urdf(own_arm, out, [tmp_path / "src"])
    mesh = result.meshes[0]
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    mesh.unlink()
    os.link(victim, mesh)
    again = import_urdf(own_arm, out, [tmp_path / "src"], force=True)
    assert victim.read_text() == "precious"
    assert mesh in again.meshes and os.stat(mesh).st_nlink == 1 and mesh.read_bytes() != b"precious"


def test_a_massless_tool_frame_is_imported_massless_not_as_a_one_kg_m2_flywheel(tmp_path):
    """A URDF link without <inertial> is massless (a tool or sensor frame: tool0, tcp, a nozzle). Imported without
    inertial information it took RoboTool's default, 1 kg m^2 about each axis: on a small arm's continuous wrist
    that flywheel swung for ever and no move completed. It is imported as mass 0, with the zero mass warned of at the
    link: a massless frame fixed to its parent (it weighed the simulator's 1 kg before: tests/test_massless_frames.py)."""
    urdf = tmp_path / "r.urdf"
    urdf.write_text("<robot name='r'>\n"
                    "<link name='a'><inertial><mass value='1'/><inertia ixx='0.01' ixy='0' ixz='0' iyy='0.01' iyz='0' "
                    "izz='0.01'/></inertial></link>\n" + _links("tip") + "\n"
                    + _joint("mount", "a", "tip", "fixed", "<origin xyz='0.1 0 0'/>") + "</robot>")
    result = import_urdf(urdf, tmp_path / "out")
    tree = build_tree(load_checked([result.file]))
    tip = next(l for l in tree.links if l.name == "tip")
    assert tip.mass == 0.0 and not tip.inertia.any(), tip.inertia
    said = "\n".join(f.message for f in result.findings)
    assert "mass of link tip is 0" in said and "1 kg m^2" not in said


def _serial_arm(path: Path, names: list[str]) -> Path:
    """A URDF of a serial chain of revolute joints j1.. between the links `names`, axes alternating z and y."""
    def link(name):
        return (f"<link name='{name}'><inertial><mass value='1'/><inertia ixx='0.01' ixy='0' ixz='0' iyy='0.01' iyz='0' "
                f"izz='0.01'/></inertial></link>")

    joints = [_joint(f"j{k + 1}", names[k], names[k + 1], "revolute",
                     f"<origin xyz='0 0 0.1'/><axis xyz='{'0 0 1' if k % 2 == 0 else '0 1 0'}'/>"
                     "<limit lower='-3' upper='3' effort='10' velocity='1'/>") for k in range(len(names) - 1)]
    path.write_text(f"<robot name='{path.stem}'>" + "".join(map(link, names)) + "".join(joints) + "</robot>")
    return path


def test_the_import_says_which_tool_link_and_arm_joints_the_ik_takes_by_default(tmp_path):
    """Unitree's Z1 ends in a revolute jaw: the IK's default tool was the jaw, and the jaw its arm's 7th joint, without a
    word. The import names the tool link and the arm's joints, and where another tool link is named."""
    urdf = _serial_arm(tmp_path / "jaw_arm.urdf", ["base", "l1", "l2", "l3", "l4", "l5", "stator", "jaw"])
    run = CliRunner().invoke(main, ["import-urdf", str(urdf), "-o", str(tmp_path / "out")])
    assert run.exit_code == 0, run.output
    assert ("inverse_kinematics: tool link jaw (the end of the longest chain of moving joints), arm joints j1, j2, j3, "
            "j4, j5, j6, j7 (7); another tool link: [tool] link in the cell geometry (docs/calibration.md)") in run.output


def test_the_import_says_what_the_ik_reaches_for_an_arm_of_five_joints(tmp_path):
    """A 5-joint arm was left without the IK note (the IK refused it); the note now names its tool and arm and
    what the IK reaches for it: the position and approach axis, the roll left free."""
    urdf = _serial_arm(tmp_path / "five.urdf", ["base", "l1", "l2", "l3", "l4", "hand"])
    run = CliRunner().invoke(main, ["import-urdf", str(urdf), "-o", str(tmp_path / "out")])
    assert run.exit_code == 0, run.output
    assert ("inverse_kinematics: tool link hand (the end of the longest chain of moving joints), arm joints j1, j2, j3, "
            "j4, j5 (5: the position and approach axis, the roll left free); another tool link") in run.output
