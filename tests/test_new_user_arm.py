"""A robot cotwin has not seen, as a new user brings it: the xArm7 of example-robot-data imported from its
URDF, a small inspection d-model of one's own (go to a point, take a picture, come home) and a mapping
written from the paths `import-urdf` prints, run through the CLI; the mistakes such a user makes get a
located error instead of a twin that silently does something else."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import cotwin_in_process
from cotwin.diagnostics import CotwinError
from test_urdf_import import robot_data

DMODEL = """
interface Ops {
	goto(x: real, y: real, z: real)
	snap()
	home()
}
interface Cmds {
	event inspectCommand: Point
	event homeCommand
}
interface Fb {
	event reached
	event unreachable
	event snapped
	event atHome
}
datatype Point {
	x: real
	y: real
	z: real
}
stm Inspector {
	cycleDef cycle == 1
	var p: Point
	input context {
		uses Cmds
		uses Fb
	}
	output context { requires Ops }
	initial i0
	state Idle { }
	state Going { entry $goto(p.x, p.y, p.z) }
	state Snapping { entry $snap() }
	state Homing { entry $home() }
	transition init { from i0 to Idle }
	transition idle { from Idle to Idle exec condition not ($inspectCommand \\/ $homeCommand) }
	transition go { from Idle to Going condition $inspectCommand?p }
	transition gohome { from Idle to Homing condition $homeCommand /\\ not $inspectCommand }
	transition wait { from Going to Going exec condition not ($reached \\/ $unreachable) }
	transition fail { from Going to Idle exec condition $unreachable }
	transition arrive { from Going to Snapping exec condition $reached /\\ not $unreachable }
	transition snapwait { from Snapping to Snapping exec condition not $snapped }
	transition snapdone { from Snapping to Idle exec condition $snapped }
	transition homewait { from Homing to Homing exec condition not $atHome }
	transition homedone { from Homing to Idle exec condition $atHome }
}
controller Ctl {
	cycleDef cycle == 1
	uses Cmds
	uses Fb
	requires Ops
	sref s = Inspector
	connection Ctl on inspectCommand to s on inspectCommand (_async)
	connection Ctl on homeCommand to s on homeCommand (_async)
	connection Ctl on reached to s on reached (_async)
	connection Ctl on unreachable to s on unreachable (_async)
	connection Ctl on snapped to s on snapped (_async)
	connection Ctl on atHome to s on atHome (_async)
}
module Station {
	cycleDef cycle == 1
	robotic platform Xarm {
		provides Ops
		uses Cmds
		uses Fb
	}
	cref c = Ctl
	connection Xarm on inspectCommand to c on inspectCommand (_async)
	connection Xarm on homeCommand to c on homeCommand (_async)
	connection Xarm on reached to c on reached (_async)
	connection Xarm on unreachable to c on unreachable (_async)
	connection Xarm on snapped to c on snapped (_async)
	connection Xarm on atHome to c on atHome (_async)
}
"""

JOINTS = [("link_base", "joint1")] + [(f"link{i}", f"joint{i + 1}") for i in range(1, 7)]


def mapping(commanded: int = 7) -> str:
    """The inspection mapping on the xArm7; `commanded`: how many of its joints the IK's vector and the
    operations name (fewer: the new user's mistake of a 6-joint arm's mapping reused)."""
    def path(i: int, port: str) -> str:
        link, joint = JOINTS[i]
        return f"UF_ROBOT::{link}::{joint}::{joint}_{port}"

    command = "\n".join(f"\t\tequation {path(i, 'motor.dangle')} == target_q[{i}]" for i in range(commanded))
    there = "\n".join(f"\t\tequation abs({path(i, 'position.output_position')} - target_q[{i}]) < TOL"
                      for i in range(commanded))
    zeros = ", ".join(["0.0"] * commanded)
    return f"""import physmod::math::*
enumeration Phase {{
	idle
	going
	unreachable
	snapping
	homing
}}
map XarmMapping dmodel Station to pmodel UF_ROBOT {{
	const TOL: real = 0.003
	var target_q: vector(real, {commanded}) = [| {zeros} |]
	var phase: Phase = Phase::idle
	var q0: real, q1: real, q2: real, q3: real, q4: real, q5: real, q6: real
	operation goto {{
		var ok: boolean = reachable(x, y, z)
		action target_q = if ok then inverse_kinematics(x, y, z) else target_q end
		action phase = if ok then Phase::going else Phase::unreachable end
{command}
	}}
	operation snap {{
		action phase = Phase::snapping
	}}
	operation home {{
		action target_q = [| {zeros} |]
		action phase = Phase::homing
{command}
	}}
	input event reached {{
		equation phase == Phase::going
{there}
	}}
	input event unreachable {{
		equation phase == Phase::unreachable
	}}
	input event snapped {{
		equation phase == Phase::snapping
	}}
	input event atHome {{
		equation phase == Phase::homing
{there}
	}}
	input event inspectCommand {{
		predicate false
	}}
	input event homeCommand {{
		predicate false
	}}
}}
function inverse_kinematics(x: real, y: real, z: real): vector(real, {commanded}) {{ }}
function reachable(x: real, y: real, z: real): boolean {{ }}
"""


PLAN = "timestep,inspectCommand,Point_x,Point_y,Point_z\n500,true,0.4,0.1,0.3\n"


def xarm_project(folder: Path, mapping_text: str, plan: str = PLAN, end: float = 4.0) -> Path:
    """The xArm7 imported by `cotwin import-urdf` into `folder`, with the inspection d-model, the mapping
    and the plan given: the project file's path."""
    urdf = robot_data() / "robots/xarm_description/urdf/xarm7.urdf"
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    imported = cotwin_in_process("import-urdf", urdf, "-o", folder)
    assert imported.returncode == 0, imported.stderr
    (folder / "inspect.rst").write_text(DMODEL)
    (folder / "mapping.pm").write_text(mapping_text)
    (folder / "plan.csv").write_text(plan)
    project = folder / "cotwin.toml"
    project.write_text('[models]\ndmodel = "inspect.rst"\npmodel = "UF_ROBOT.pm"\nmapping = "mapping.pm"\n'
                       f'[scenario]\nplan = "plan.csv"\n[cosim]\nstep = 0.1\nend = {end}\n')
    return project


def test_an_ik_vector_shorter_than_the_arm_is_a_located_error_not_a_joint_left_uncommanded(tmp_path):
    # a 6-joint arm's mapping reused on the 7-joint xArm: the type check cannot know the arm, and the run
    # used to leave joint7 where it was while every move 'completed', the tool off its target
    project = xarm_project(tmp_path, mapping(commanded=6))
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode != 0
    assert "completed" not in run.stdout
    line = next(k for k, text in enumerate(mapping(6).splitlines(), 1) if text.startswith("function inverse_kinematics"))
    assert f"mapping.pm:{line}:" in run.stderr
    assert "vector(real, 6)" in run.stderr and "7 moving joints" in run.stderr and "joint7" in run.stderr


def test_cotwin_check_reports_an_ik_vector_shorter_than_the_arm_where_the_run_would(tmp_path):
    # the p-model's arm and the declared size are both known before a run: check used to say "ok" and leave
    # the error to the run's first use of the kinematics
    project = xarm_project(tmp_path, mapping(commanded=6))
    check = cotwin_in_process("check", project)
    assert check.returncode != 0
    line = next(k for k, text in enumerate(mapping(6).splitlines(), 1) if text.startswith("function inverse_kinematics"))
    said = check.stdout + check.stderr
    assert f"mapping.pm:{line}:" in said and "error:" in said
    assert "vector(real, 6)" in said and "7 moving joints" in said and "declare vector(real, 7)" in said
    # the arm's size checks
    (tmp_path / "mapping.pm").write_text(mapping(commanded=7))
    assert cotwin_in_process("check", project).returncode == 0


def test_the_runtime_still_refuses_an_ik_vector_of_another_size_when_the_models_were_not_checked_as_a_twin(tmp_path):
    # the last line of defence: a Mapping made from the models alone (a script, a test) sets its kinematics up
    # on first use and says the same at the same place
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.mapping.runtime import Mapping
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.pmodel.tree import build_tree
    from cotwin.robosim.check import load_checked

    xarm_project(tmp_path, mapping(commanded=6))
    project = load_checked([tmp_path / "inspect.rst", tmp_path / "UF_ROBOT.pm", tmp_path / "mapping.pm"])
    with pytest.raises(CotwinError) as err:  # its q0..q6 mirror the arm: set up with the mapping
        Mapping(project, SimulatedEndpoint(PlatformSimulator(build_tree(project, "UF_ROBOT"))))
    line = next(k for k, text in enumerate(mapping(6).splitlines(), 1) if text.startswith("function inverse_kinematics"))
    assert f"mapping.pm:{line}:" in str(err.value) and "7 moving joints" in str(err.value)


def test_the_ik_vector_of_the_arms_size_runs_and_completes(tmp_path):
    project = xarm_project(tmp_path, mapping(commanded=7))
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode == 0, run.stderr
    assert "commands: 1, 1 completed" in run.stdout


def test_a_command_sent_while_the_arm_moves_is_not_taken_and_the_move_under_way_completes(tmp_path):
    # Going waits on itself by an exec self-loop, re-calling goto every cycle; its exec way out to Idle (on
    # $unreachable) could in principle be followed by Idle -> Going on the new command in one cycle. With
    # `unreachable` never sent, that way was not open: the second command was not taken, the first completed
    # (it used to be the other way round: the second 'completed', the first 'never completed').
    plan = "timestep,inspectCommand,Point_x,Point_y,Point_z\n500,true,0.4,0.1,0.3\n800,true,0.3,-0.2,0.2\n"
    project = xarm_project(tmp_path, mapping(), plan=plan)
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode == 0, run.stderr
    first, second = [line for line in run.stdout.splitlines() if line.strip().startswith("applied at")]
    assert "Point_x=0.4" in first and "completed at" in first
    assert "Point_x=0.3" in second and "not taken (the d-model was in state Going)" in second


def test_a_monitored_reading_named_like_an_operation_argument_is_an_error_at_its_key(tmp_path):
    # `[monitor] readings = { z = ... }` beside goto(x, y, z): the reading and the argument would be one port of
    # the mapping's unit; the run used to stop at wiring with "unit {mapping}.mapping has no input 'z'"
    project = xarm_project(tmp_path, mapping())
    text = project.read_text() + '[monitor]\nreadings = { z = "UF_ROBOT::link_base::joint1::joint1_position.output_position" }\n'
    project.write_text(text)
    line = text.splitlines().index("[monitor]") + 2
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode != 0
    assert f"cotwin.toml:{line}:" in run.stderr
    assert "z (already an argument of operation goto)" in run.stderr
    assert "has no input" not in run.stderr
    # another name runs
    project.write_text(text.replace("readings = { z =", "readings = { base_angle ="))
    assert cotwin_in_process("run", project, "-o", tmp_path / "out2").returncode == 0


def test_readings_clashing_with_variables_and_ports_get_one_error_per_kind_at_the_first_names_key(tmp_path):
    # one table of the names taken (the mapping's variables, q<i> mirrors included; operations, their arguments
    # and events): a reading named like a variable is said as one, never again as a port
    from cotwin.twin.assembly.run import load

    project = xarm_project(tmp_path, mapping())
    reading = "UF_ROBOT::link_base::joint1::joint1_position.output_position"
    lines = ["[monitor.readings]", f'base = "{reading}"', f'z = "{reading}"', f'phase = "{reading}"',
             f'reached = "{reading}"', f'q3 = "{reading}"']
    text = project.read_text() + "\n".join(lines) + "\n"
    project.write_text(text)
    first = len(text.splitlines()) - len(lines) + 1  # the table's line
    with pytest.raises(CotwinError) as err:
        load(project)
    said = [str(f) for f in err.value.findings]
    assert len(said) == 2, said
    assert said[0].startswith(f"{project}:{first + 2}:") and "readings z (already an argument of operation goto), " \
        "reached (already event reached): each reading needs a name of its own (e.g. 'z_reading')" in said[0], said
    assert said[1].startswith(f"{project}:{first + 3}:") and \
        "readings phase, q3: the mapping has variables of these names" in said[1], said


def test_q_variables_past_the_monitored_joints_are_a_warning_at_the_first_of_them(tmp_path):
    # q0..q6 declared, [monitor] joints naming two: q2..q6 mirrored nothing and were not logged, in silence
    from cotwin.twin.assembly.run import load

    project = xarm_project(tmp_path, mapping())
    project.write_text(project.read_text() + '[monitor]\njoints = ["joint1", "joint2"]\n')
    said = [str(f) for f in load(project).warnings if "mirror no joint" in f.message]
    line = next(k for k, text in enumerate(mapping().splitlines(), 1) if "var q0: real" in text)
    assert len(said) == 1 and said[0].startswith(f"{tmp_path / 'mapping.pm'}:{line}:"), said
    assert "q2, q3, q4, q5, q6 mirror no joint: [monitor] joints gives 2 of p-model UF_ROBOT's (joint1, joint2)" \
        in said[0], said
    # the arm's seven (the default) mirror every one
    project.write_text(project.read_text().replace('joints = ["joint1", "joint2"]', 'joints = "arm"'))
    assert not [f for f in load(project).warnings if "mirror" in f.message]


def _weaken(project: Path, joint: str, effort: str = "0.001") -> None:
    """The imported p-model's `joint` given a servo too weak to move its arm (its URDF <limit effort>)."""
    pm = project.parent / "UF_ROBOT.pm"
    text = pm.read_text()
    at = text.index("effort = ", text.index(f"jref {joint} "))
    end = text.index(" ", at + len("effort = "))
    pm.write_text(text[:at] + f"effort = {effort}" + text[end:])


def test_the_live_twin_names_the_joints_at_their_effort_limit_as_a_run_does(tmp_path):
    """`cotwin run` and `whatif` said which joints pushed at their effort limit when a move never completed; the
    live twin, on the same models, said only 'accepted, never completed' for its PT and its DT."""
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import LiveTwin

    project = xarm_project(tmp_path / "xarm", mapping(), end=3.0)
    _weaken(project, "joint2")
    run = cotwin_in_process("run", project, "-o", tmp_path / "run")
    warning = ("1 command(s) never completed, and at the end these joints pushed at their effort limit: joint2 "
               "(0.001): too weak")
    assert warning in run.stderr + run.stdout
    system = load(project)
    pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
    result = LiveTwin(system, tmp_path / "live", pt=pt).run()
    for side in ("pt", "dt"):
        assert any(w.startswith(warning) for w in result.sides[side].summary().warnings()), side


def _payload_at(sim, prefix: str = "") -> tuple[str, list[float]]:
    """Where a simulator's payload body is (a world's robot's: its names after `prefix`): its parent body and its
    position there."""
    from cotwin.pmodel.perturbation import PAYLOAD_BODY

    body = sim.model.body(prefix + PAYLOAD_BODY)
    return sim.model.body(int(body.parentid[0])).name, [round(float(v), 9) for v in body.pos]


def test_a_payload_sits_at_the_projects_tool_not_the_iks_default(tmp_path):
    """The project names its tool ([tool] link and point in its cell geometry); a plant's payload, a cell's and the
    DT's body of an estimated payload ([convergence]) were welded at cotwin.pmodel.ik.find_tool's default instead
    (the xArm7's link_eef origin), so the perturbation loaded another point than the one the IK moves."""
    from cotwin.pmodel.perturbation import Perturbation, perturbed_world
    from cotwin.pmodel.shared import PlacedRobot
    from cotwin.twin.assembly.run import load, simulated_endpoint
    from cotwin.twin.services.plant import load_plant

    project = xarm_project(tmp_path / "xarm", mapping())
    (project.parent / "cell.toml").write_text('[tool]\nlink = "link7"\npoint = [0.0, 0.0, 0.05]\n')
    project.write_text(project.read_text() + '[platform]\ncalibration = "cell.toml"\n')
    expected = ("link7", [0.0, 0.0, 0.05])
    plant = load_plant(project, payload=2.0)
    assert _payload_at(plant.endpoint.sim) == expected
    system = load(project)
    assert system.models.tool.link == "link7"
    world = perturbed_world([PlacedRobot("arm", system.models.tree, np.eye(4))], None, Perturbation(payload=2.0),
                            tools={"arm": system.models.tool})
    assert _payload_at(world, "arm/") == ("arm/link7", [0.0, 0.0, 0.05])
    project.write_text(project.read_text() + '[convergence]\nestimate = "payload"\n')
    assert _payload_at(simulated_endpoint(load(project)).sim) == expected


def test_an_arm_on_a_free_base_is_said_not_weight_compensated(tmp_path):
    """A mobile arm ([platform] base = "free"; the xArm7 here, TIAGo alike) got no gravity compensation, silently: a
    fixed arm's (MuJoCo's gravcomp) would lift the free base by the arm's weight. Its servos carry the arm, so its
    joints sag where a fixed arm's hold; the check and the run now say so, naming the robot and its arm."""
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.pmodel.tree import build_tree
    from cotwin.pmodel.urdf_import import import_urdf
    from cotwin.pmodel.world import World
    from cotwin.robosim.check import load_checked

    project = xarm_project(tmp_path / "xarm", mapping())
    fixed = cotwin_in_process("check", project, cwd=tmp_path)
    assert fixed.returncode == 0 and "not weight-compensated" not in fixed.stdout + fixed.stderr
    project.write_text(project.read_text() + '[platform]\nbase = "free"\n')
    check = cotwin_in_process("check", project, cwd=tmp_path)
    said = check.stdout + check.stderr
    assert check.returncode == 0, said
    assert "cotwin.toml:" in said and ("warning: p-model UF_ROBOT is a free-base mobile arm: its arm (joint1, joint2, "
                                       "joint3, joint4, joint5, joint6, joint7) is not weight-compensated") in said
    # what it warns of, on TIAGo (a mobile arm whose heavy base stands where the xArm's tips): a posture held on a
    # fixed base and on a free one on a floor
    tiago = robot_data() / "robots/tiago_description/robots/tiago.urdf"
    if not tiago.is_file():
        pytest.skip(f"example-robot-data has no {tiago}")
    tree = build_tree(load_checked([import_urdf(tiago, tmp_path / "tiago", check=False).file]))
    held = {"torso_lift_joint": 0.1, "arm_1_joint": 0.2, "arm_4_joint": 0.5}
    sag = {}
    for base, scene in (("fixed", None), ("free", World(name="floor"))):
        sim = PlatformSimulator(tree, scene, base=base)
        sim.reset(held)
        sim.write_actuators(held)
        sim.advance(2.0)
        sag[base] = abs(sim.joint_positions()["torso_lift_joint"] - held["torso_lift_joint"])
    assert sag["fixed"] < 1e-4 and sag["free"] > 0.01, sag  # its torso lift sank 9 cm under the arm's weight
