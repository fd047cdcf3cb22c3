"""A twin project whose cell geometry names the tool link (`[tool] link`) is read against that tool: the arm
of the IK is the joints from the base to that link, and `[ik] reference` must give one value per such joint.

Found on the Unitree Z1 (example-robot-data): its jaw is a revolute joint after the wrist, so the default
tool (the end of the longest chain) counts it as a 7th arm joint. Naming the gripper's fixed body as the
tool link gives the 6-joint arm the mapping's IK then solves for; but the project check compared
`[ik] reference` with the default tool's 7 joints, and the mapping with the named tool's 6: no reference
passed both (6 values refused before the run, 7 at the first IK call). The models here are written by
the test: a 6-joint arm with a revolute jaw, as a URDF imported by cotwin. On the same arm: a mapping goal
beyond a joint's limits (the jaw commanded past its stop) is said where the mapping commands it."""

from __future__ import annotations

from pathlib import Path
from typing import get_type_hints

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.runtime import FunctionRegistry
from cotwin.pmodel import ik
from cotwin.pmodel.urdf_import import import_urdf
from cotwin.twin.assembly.system import TwinModels, load_models
from cotwin.twin.project import load_project

# joint name, parent, child, origin xyz, axis: a Z1-like arm, its jaw a revolute joint after a fixed stator
CHAIN = [
    ("joint1", "base", "l1", "0 0 0.1", "0 0 1"),
    ("joint2", "l1", "l2", "0 0 0.05", "0 1 0"),
    ("joint3", "l2", "l3", "0.35 0 0", "0 1 0"),
    ("joint4", "l3", "l4", "0.2 0 0", "0 1 0"),
    ("joint5", "l4", "l5", "0.07 0 0", "0 0 1"),
    ("joint6", "l5", "l6", "0.05 0 0", "1 0 0"),
    ("jaw", "stator", "mover", "0.05 0 0", "0 1 0"),
]


def _urdf() -> str:
    links = ["base", "l1", "l2", "l3", "l4", "l5", "l6", "stator", "mover"]
    text = ['<?xml version="1.0"?>', '<robot name="arm">']
    for name in links:
        text.append(f'<link name="{name}"><inertial><mass value="0.5"/>'
                    '<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>'
                    '<collision><geometry><sphere radius="0.02"/></geometry></collision></link>')
    for name, parent, child, xyz, axis in CHAIN:
        text.append(f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
                    f'<origin xyz="{xyz}"/><axis xyz="{axis}"/>'
                    '<limit lower="-2.6" upper="2.6" effort="30" velocity="3"/></joint>')
    text.append('<joint name="stator_fixed" type="fixed"><parent link="l6"/><child link="stator"/>'
                '<origin xyz="0.05 0 0"/></joint>')
    text.append("</robot>")
    return "\n".join(text)


DMODEL = """
datatype Spot {
	x: real
	y: real
	z: real
}
interface Motion { reach(x: real, y: real, z: real) grip(width: real) }
interface Orders { event goTo: Spot }
interface Answers { event arrived }
stm Mover {
	cycleDef cycle == 1
	var goal: Spot
	input context { uses Orders uses Answers }
	output context { requires Motion }
	initial i0
	state Idle { }
	state Moving { entry $reach(goal.x, goal.y, goal.z) }
	transition init { from i0 to Idle }
	transition idle { from Idle to Idle exec condition not $goTo }
	transition go { from Idle to Moving condition $goTo?goal }
	transition wait { from Moving to Idle exec }
}
controller Ctl {
	cycleDef cycle == 1
	uses Orders uses Answers requires Motion
	sref s = Mover
	connection Ctl on goTo to s on goTo (_async)
	connection Ctl on arrived to s on arrived (_async)
}
module Arm {
	cycleDef cycle == 1
	robotic platform ArmPlatform { provides Motion uses Orders uses Answers }
	cref c = Ctl
	connection ArmPlatform on goTo to c on goTo (_async)
	connection ArmPlatform on arrived to c on arrived (_async)
}
"""


def _mapping(mirrors: int = 0) -> str:
    joints = [(parent, name) for name, parent, _, _, _ in CHAIN[:6]]
    variables = "".join(f"\tvar q{k}: real\n" for k in range(mirrors))
    equations = "\n".join(f"\t\tequation arm::{link}::{j}::{j}_motor.dangle == q[{k}]"
                          for k, (link, j) in enumerate(joints))
    return f"""import physmod::math::*
map ArmMap dmodel Arm to pmodel arm {{
	var q: vector(real, 6) = [| 0.0, 0.0, 0.0, 0.0, 0.0, 0.0 |]
{variables}	operation reach {{
		action q = inverse_kinematics(x, y, z)
{equations}
	}}
	operation grip {{
		equation arm::stator::jaw::jaw_motor.dangle == width * 10.0
	}}
	input event arrived {{ predicate false }}
	input event goTo {{ predicate false }}
}}
function inverse_kinematics(x: real, y: real, z: real): vector(real, 6) {{ }}
"""


def _project(folder: Path, reference: list[float] | None, mirrors: int = 0) -> Path:
    (folder / "arm.urdf").write_text(_urdf())
    import_urdf(folder / "arm.urdf", folder, check=False)
    (folder / "arm.rst").write_text(DMODEL)
    (folder / "mapping.pm").write_text(_mapping(mirrors))
    (folder / "cell.toml").write_text(f'[tool]\nlink = "stator"\npoint = "flange"\n[ik]\nreference = {reference}\n')
    platform = '[platform]\ncalibration = "cell.toml"\n' if reference is not None else ""  # None: no cell geometry
    (folder / "cotwin.toml").write_text('[models]\ndmodel = "arm.rst"\npmodel = "arm.pm"\nmapping = "mapping.pm"\n'
                                        f'{platform}[cosim]\nstep = 0.1\nend = 1.0\n')
    return folder / "cotwin.toml"


REFERENCE = [0.0, 1.0, -1.0, 0.5, 0.0, 0.0]  # one value per arm joint, base to the stator: joint1..joint6


def test_the_reference_posture_is_checked_against_the_tool_link_the_cell_names(tmp_path):
    models = load_models(load_project(_project(tmp_path, REFERENCE)))
    tool = models.calibration.geometry.find_tool(models.tree)
    assert tool.link == "stator"
    assert ik.arm_joints(models.tree, tool) == [f"joint{k}" for k in range(1, 7)]
    assert ik.arm_joints(models.tree, ik.find_tool(models.tree))[-1] == "jaw"  # the default tool's arm: 7


def test_a_reference_of_the_default_tools_arm_is_refused_at_its_key(tmp_path):
    with pytest.raises(CotwinError) as err:
        load_models(load_project(_project(tmp_path, REFERENCE + [0.0])))
    assert "cell.toml:5:1" in str(err.value)
    assert "the reference posture has 7 values, the arm has 6 joints (joint1, " in str(err.value)


class _Endpoint:
    """The mapping registry's view of the platform: the tree and where the joints are."""

    def __init__(self, tree):
        self.tree, self.geometry = tree, None

    def joint_positions(self):
        return {j.name: 0.0 for j in self.tree.actuated}


def test_the_mapping_solves_for_the_same_arm_the_project_checked(tmp_path):
    models = load_models(load_project(_project(tmp_path, REFERENCE)))
    registry = FunctionRegistry(_Endpoint(models.tree), models.calibration.geometry)
    assert registry.arm == [f"joint{k}" for k in range(1, 7)]
    assert len(registry.inverse_kinematics(0.3, 0.0, 0.2)) == 6


def test_a_goal_beyond_a_joints_limits_is_said_at_the_equation_commanding_it(tmp_path, caplog):
    """The jaw's limits are [-2.6, 2.6] rad: grip(0.3) commands 3 rad, where the simulated joint stops at 2.6 and
    an event waiting for the jaw to get there never comes; the run only said the command never completed."""
    import logging

    from cotwin.mapping.runtime import Mapping
    from cotwin.twin.assembly.run import load, simulated_endpoint

    system = load(_project(tmp_path, REFERENCE))
    mapping = Mapping(system.models.project, simulated_endpoint(system))
    mapping.start_mapping()
    with caplog.at_level(logging.WARNING, logger="cotwin.twin"):
        mapping.execute_operation("grip", {"width": 0.1})  # 1 rad: within the limits, nothing said
        assert not caplog.records
        mapping.execute_operation("grip", {"width": 0.3})
        mapping.execute_operation("grip", {"width": 0.4})  # said once per actuator
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1, said
    line, column = next((k, text.index("arm::") + 1) for k, text in enumerate(_mapping().splitlines(), 1)
                        if "jaw_motor.dangle" in text)
    assert f"mapping.pm:{line}:{column}: warning: operation grip commands joint jaw to 3 rad, beyond its limits " \
           "[-2.6, 2.6]: it stops at 2.6" in said[0]
    mapping.stop_mapping()


def test_an_ik_of_the_wrong_size_for_the_default_tool_says_how_to_name_the_tool(tmp_path):
    """Without a cell geometry the tool is the end of the longest chain, the jaw's link: 7 joints, where the mapping
    declares the wrist's 6. The error said only 'declare vector(real, 7) and command every one of them', which
    would make the IK swing the jaw to reach a target; and it came at the first call of inverse_kinematics, after
    the FMU was built and the first rows run, prefixed by the call's place ('mapping.pm:L:C: error: mapping.pm:..').
    Now the project check says it, once, at the declaration."""
    project = _project(tmp_path, None)
    with pytest.raises(CotwinError) as err:
        load_models(load_project(project))
    said = str(err.value)
    line = next(k for k, text in enumerate(_mapping().splitlines(), 1) if text.startswith("function inverse_kinematics"))
    assert f"mapping.pm:{line}:10: error: inverse_kinematics is declared to return vector(real, 6), but p-model " \
           "arm's arm from its base to the tool link mover has 7 moving joints " \
           "(joint1, joint2, joint3, joint4, joint5, joint6, jaw)" in said
    assert "name it by [tool] link in the cell geometry" in said
    assert said.count("mapping.pm:") == 1, said


def test_the_arm_mirrors_are_the_named_tools_arm_in_the_project_as_in_the_mapping(tmp_path):
    """`[monitor] joints = "arm"`: q<i> mirror the joints from the base to the tool. A mapping declaring q0..q6
    on the arm whose cell names the stator as its tool: the mapping mirrored q0..q5 (its IK's arm), the project
    logged q0..q6 (the default tool's, the jaw as q6), and `cotwin run` ended with 'logVariables: unit
    {mapping}.mapping has no variable 'q6''."""
    from cotwin.mapping.runtime import Mapping
    from cotwin.twin.assembly.run import load, monitored_units, simulated_endpoint

    system = load(_project(tmp_path, REFERENCE, mirrors=7))
    mapping = Mapping(system.models.project, simulated_endpoint(system), geometry=system.models.calibration.geometry)
    assert list(mapping.mirrors) == [f"q{k}" for k in range(6)]
    assert system.models.monitored == list(mapping.mirrors)
    assert {joint for joint, _ in mapping.mirrors.values()} == {f"joint{k}" for k in range(1, 7)}
    assert set(monitored_units(system)) == set(mapping.mirrors)


def _monitoring(project: Path, joints: str) -> Path:
    """The project with `[monitor] joints = <joints>` (TOML)."""
    project.write_text(project.read_text() + f"[monitor]\njoints = {joints}\n")
    return project


def test_the_page_moves_the_joints_the_mapping_mirrors(tmp_path):
    """The page's robot and its variables' joints came from the default tool's arm whatever [monitor] joints said:
    with `joints = ["jaw"]` the mapping mirrored q0 onto the jaw (and the log's units said so) while the page drew
    q0 as joint1 and swung the shoulder. One table now (TwinModels.mirrors) for the mapping's run, the log's units
    and the page."""
    from cotwin.twin.assembly.run import load, monitored_units
    from cotwin.twin.services.dashboard.describe import describe, observed_joints

    system = load(_monitoring(_project(tmp_path, REFERENCE, mirrors=1), '["jaw"]'))
    assert observed_joints(system) == {"q0": ("jaw", "position")}
    assert monitored_units(system)["q0"] == ("joint angle", "rad")
    page = describe(system, ["twin"], "run")
    assert [(v["name"], v["joint"]) for v in page["variables"]] == [("q0", "jaw")]


def test_joints_mirrored_by_no_variable_are_named_by_the_cells_tool(tmp_path):
    """A mapping declaring no q<i> with `[monitor] joints = "arm"`: the warning lists the arm the mapping would
    mirror, up to the cell's [tool] link (the stator: joint1..joint6), not the default tool's (the jaw as a 7th)."""
    models = load_models(load_project(_monitoring(_project(tmp_path, REFERENCE), '"arm"')))
    said = [f.message for f in models.warnings if "[monitor] joints" in f.message]
    assert len(said) == 1, said
    assert "no joint (joint1, joint2, joint3, joint4, joint5, joint6) is mirrored" in said[0]
    assert "`var q0: real, ..., q5: real`" in said[0]


def test_a_joints_sensor_read_without_its_joint_is_refused_at_its_key_before_the_run(tmp_path):
    """The project check took `arm::base::joint1_position.output_position` (the sensor declared in joint1, named
    without the joint, as the UR's RTDE and a replay name it), but the DT's simulator reads it only as
    `arm::base::joint1::joint1_position.output_position`: the run's first step stopped with 'monitored variable r:
    the platform has no reading', at no place. The check now takes what the simulator reads."""
    project = _project(tmp_path, REFERENCE)
    text = project.read_text()
    project.write_text(text + '[monitor]\nreadings = { r = "arm::base::joint1_position.output_position" }\n')
    with pytest.raises(CotwinError) as err:
        load_models(load_project(project))
    line = len(text.splitlines()) + 2
    assert f"cotwin.toml:{line}:14: error: [monitor] readings r: p-model arm has no reading " \
           "'arm::base::joint1_position.output_position' (the nearest: " \
           "arm::base::joint1::joint1_position.output_position, " in str(err.value), str(err.value)
    project.write_text(text + '[monitor]\nreadings = { r = "arm::base::joint1::joint1_position.output_position" }\n')
    assert load_models(load_project(project)).monitored[-1] == "r"


def test_a_tool_link_the_pmodel_lacks_is_said_at_its_key_with_arm_mirrors(tmp_path):
    """A misspelt [tool] link and a mapping declaring q<i>: the project's arm mirrors asked for that link again, so
    load_models ended with its unlocated 'tool link ... is not a link' (and nothing else gathered) instead of the
    error at the cell geometry's key."""
    project = _project(tmp_path, REFERENCE, mirrors=2)
    (tmp_path / "cell.toml").write_text((tmp_path / "cell.toml").read_text().replace('"stator"', '"statr"'))
    with pytest.raises(CotwinError) as err:
        load_models(load_project(project))
    assert [f"{f.location.path.rsplit('/', 1)[-1]}:{f.location.line}" for f in err.value.findings] == ["cell.toml:2"]
    assert "tool link 'statr' is not a link of p-model arm" in str(err.value)


def test_the_arm_of_a_robots_log_profile_and_calibration_is_the_one_the_mapping_solves_for(tmp_path):
    """One arm for the project (TwinModels.arm, up to the cell's [tool] link): a replayed or live robot's joint
    order (its profile's convention), `cotwin calibrate`'s start geometry and its replays counted the default tool's
    arm, the jaw as a 7th joint, where the mapping's IK and the log have 6."""
    from cotwin.pmodel.cell import CellGeometry
    from cotwin.twin.assembly.replay import DigitalTwin

    six = [f"joint{k}" for k in range(1, 7)]
    models = load_models(load_project(_project(tmp_path, REFERENCE)))
    assert models.arm == six
    assert isinstance(models.tool, ik.Tool) and get_type_hints(TwinModels)["tool"] == ik.Tool | None  # typed as held
    twin = DigitalTwin(models.project, models.tree, models.scene, None, models.calibration.geometry)
    assert twin.arm() == six
    assert twin.arm(CellGeometry()) == [*six, "jaw"]  # a geometry naming no tool link: the default tool's arm


def test_a_target_that_is_not_a_finite_point_is_not_reachable_and_has_no_posture(tmp_path):
    """A grid point of nan or inf (0/0 in the mapping, a range sensor that sees nothing): `reachable` said False,
    but `inverse_kinematics` gave a posture all the same, which a mapping not guarding the call commanded."""
    models = load_models(load_project(_project(tmp_path, REFERENCE)))
    registry = FunctionRegistry(_Endpoint(models.tree), models.calibration.geometry)
    for bad in (float("nan"), float("inf")):
        assert registry.reachable(bad, 0.0, 0.2) is False
        with pytest.raises(CotwinError, match="the target is not a finite point"):
            registry.inverse_kinematics(0.3, bad, 0.2)
    assert len(registry.inverse_kinematics(0.3, 0.0, 0.2)) == 6 and registry.requests == [(0.3, 0.0, 0.2)]
