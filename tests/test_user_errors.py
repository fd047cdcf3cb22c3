"""What a new user meets with broken inputs (the probe of issue 'errors a user meets'): each error names its
file, says what would be right, and nothing already produced is lost. Each through the real `cotwin` where
the command is what the user runs."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import cotwin_in_process
from cotwin.diagnostics import CotwinError

ROOT = Path(__file__).resolve().parents[1]


def cotwin(*args, cwd=None, timeout=600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout)


@pytest.fixture
def ur5e(tmp_path) -> Path:
    shutil.copytree(ROOT / "examples" / "ur5e", tmp_path / "ur5e")
    return tmp_path / "ur5e"


def test_a_whatif_plan_or_state_that_is_wrong_is_named(ur5e):
    """A JSON plan's problems and a --from that is not a state said 'error: plan item 1: ...' and 'error: not a
    cotwin state' without naming the file; an empty CSV plan predicted a completion in silence."""
    (ur5e / "w.json").write_text('[{"time": 1, "event": "moveDiscreteComand", "args": {}}]')
    proc = cotwin_in_process("whatif", ur5e / "cotwin.toml", "--plan", ur5e / "w.json")
    assert proc.returncode == 1 and proc.stderr.startswith(
        f"{ur5e / 'w.json'}: error: plan item 1: unknown event 'moveDiscreteComand'; did you mean "
        "'moveDiscreteCommand'?"), proc.stderr
    proc = cotwin_in_process("whatif", ur5e / "cotwin.toml", "--plan", ur5e / "plan.csv", "--from", ur5e / "plan.csv")
    assert proc.returncode == 1 and proc.stderr.startswith(f"{ur5e / 'plan.csv'}: error: not a cotwin state"), \
        proc.stderr
    (ur5e / "empty.csv").write_text((ur5e / "plan.csv").read_text().splitlines()[0] + "\n")
    proc = cotwin_in_process("whatif", ur5e / "cotwin.toml", "--plan", ur5e / "empty.csv", "--horizon", "1")
    assert f"{ur5e / 'empty.csv'}:1:1: warning: the plan holds no command" in proc.stderr


def test_a_sweep_takes_an_argument_by_the_port_name_a_whatif_prints():
    """The what-if prints MovementArgs_target_X=...; a sweep refused that name (it took only target_X)."""
    from cotwin.twin.assembly.run import load
    from cotwin.twin.analysis.sweep import grid

    program = load(ROOT / "examples" / "ur5e" / "cotwin.toml").models.program
    by_port = grid(program, "moveDiscreteCommand", {"MovementArgs_target_X": [1, 2], "target_Y": [3], "target_Z": [0]})
    assert [dict(p[0].values)["MovementArgs_target_X"] for p in by_port] == [1, 2]
    with pytest.raises(CotwinError, match="argument MovementArgs_target_X is given twice"):
        grid(program, "moveDiscreteCommand", {"MovementArgs_target_X": [1], "target_X": [2]})
    with pytest.raises(CotwinError, match="no argument target_x; did you mean 'target_X'"):
        grid(program, "moveDiscreteCommand", {"target_x": [1]})


def test_a_fleet_file_for_a_project_a_project_for_a_fleet_and_a_folder_for_a_file_say_what_to_run(ur5e, tmp_path):
    """`cotwin run fleet.toml` listed 'needs models' and every fleet key as unknown; `cotwin fleet cotwin.toml`
    every project table; `cotwin run .` said 'Is a directory'. Each now says what the file is and what to run."""
    from cotwin.twin.analysis.fleet.spec import read_fleet
    from cotwin.twin.project import load_project

    fleet = tmp_path / "fleet.toml"
    fleet.write_text(f'[[twin]]\nname = "a"\nproject = "{ur5e / "replay.toml"}"\n')
    with pytest.raises(CotwinError) as err:
        load_project(fleet)
    assert [str(f) for f in err.value.findings] == [
        f"{fleet}:1:1: error: this is a fleet file ([[twin]] entries naming projects), not a twin project: run it "
        "with `cotwin fleet fleet.toml -o DIR`, or give one of the projects it names"]
    with pytest.raises(CotwinError) as err:
        read_fleet(ur5e / "cotwin.toml")
    assert len(err.value.findings) == 1 and "this is a twin project ([models]), not a fleet file: run it with " \
        "`cotwin twin cotwin.toml -o DIR`" in str(err.value)
    with pytest.raises(CotwinError, match=r"cannot read project file: it is a folder: name the project file in it "
                                          r"\(it holds .*cotwin.toml"):
        load_project(ur5e)


def test_a_broken_calibration_and_a_broken_plan_are_reported_together_at_their_places(ur5e):
    """The calibration was read (and failed) before the plan was: fixing it revealed the plan's errors; a
    [monitor] reading clashing with a mapping variable was said at the file's first line, not at the key."""
    from cotwin.twin.assembly.run import load

    (ur5e / "bad.csv").write_text("timestep,moveDiscreteComand\n1000,true\n")
    (ur5e / "badcal.toml").write_text("this is not toml\n")
    path = ur5e / "both.toml"
    path.write_text('[models]\ndmodel = "arm.rst"\npmodel = "ur5e.pm"\nmapping = "mapping.pm"\n[scenario]\n'
                    'plan = "bad.csv"\n[platform]\ncalibration = "badcal.toml"\n[monitor]\nreadings = { q0 = "x" }\n')
    with pytest.raises(CotwinError) as err:
        load(path)
    said = [str(f) for f in err.value.findings]
    assert any(s.startswith(f"{ur5e / 'bad.csv'}:1:10: error: unknown d-model input") for s in said), said
    assert any(s.startswith(f"{ur5e / 'badcal.toml'}:1:") for s in said), said
    assert any(s.startswith(f"{path}:10:14:") and "[monitor] readings q0: the mapping has variables" in s
               for s in said), said


def test_an_output_that_cannot_be_made_is_named_not_its_temporary_file(tmp_path):
    """A file written where it cannot be (inside a file here; a read-only place alike) raised a bare OSError,
    or one naming the temporary '.x.part' beside it."""
    from cotwin.files import write_text

    (tmp_path / "afile").write_text("precious")
    with pytest.raises(CotwinError) as err:
        write_text(tmp_path / "afile" / "x.txt", "x")
    assert str(err.value).startswith(f"{tmp_path / 'afile' / 'x.txt'}: error: cannot write here: ")
    assert (tmp_path / "afile").read_text() == "precious"


def test_names_checked_against_the_models_get_the_nearest_one(ur5e):
    from cotwin.twin.assembly.run import load

    path = ur5e / "names.toml"
    path.write_text('[models]\ndmodel = "arm.rst"\npmodel = "ur5e.pm"\nmapping = "mapping.pm"\n[cosim]\n'
                    'log = ["Q0"]\nparameters = { cycle_perod = 0.1 }\n')
    with pytest.raises(CotwinError) as err:
        load(path)
    text = str(err.value)
    assert "unknown mapping variable(s) Q0; did you mean 'q0'?" in text
    assert "no parameter 'cycle_perod'; did you mean 'cycle_period'?" in text


def test_monitor_joints_and_figure_panels_are_said_at_their_keys_with_the_nearest_name(ur5e):
    """[monitor] joints naming no joint said 'error: mirrored joints ...' with no file or line."""
    from cotwin.twin.assembly.run import load

    path = ur5e / "mon.toml"
    text = ('[models]\ndmodel = "arm.rst"\npmodel = "ur5e.pm"\nmapping = "mapping.pm"\n[monitor]\n'
            'joints = ["shoulder_pan_jont", "elbow_joint"]\n[figure]\n[[figure.panels]]\n'
            'variables = ["mapping.Q1", "dmodl.x"]\n')
    path.write_text(text)
    with pytest.raises(CotwinError) as err:
        load(path)
    assert str(err.value).startswith(f"{path}:6:1: error: [monitor] joints: shoulder_pan_jont is not an actuated joint "
                                     "of p-model ur5e; did you mean 'shoulder_pan_joint'?")
    path.write_text(text.replace("jont", "joint"))
    with pytest.raises(CotwinError) as err:
        load(path)
    said = str(err.value)
    assert "unit 'dmodl' is not one of this twin's; did you mean 'dmodel'?" in said
    assert "mapping shows no variable 'Q1'; did you mean 'q1'?" in said


def test_an_interrupted_sweep_keeps_the_what_ifs_it_answered(ur5e, tmp_path):
    """Ctrl-C in a sweep said 'interrupted' and wrote nothing: every what-if answered was lost. With workers,
    it then waited for every chunk queued (tens of seconds) and threw their answers away: it stops them."""
    import time

    from conftest import interrupted_sweep

    _, _, _, workers = interrupted_sweep(ur5e / "cotwin.toml", tmp_path, "--workers", "2")

    def running(pid: int) -> bool:
        try:
            return "zombie" not in Path(f"/proc/{pid}/status").read_text()
        except OSError:
            return False

    settled = time.monotonic() + 5  # a pool's resource tracker ends when it sees its parent gone, shortly after
    while any(running(pid) for pid in workers) and time.monotonic() < settled:
        time.sleep(0.1)
    assert not [pid for pid in workers if running(pid)], "the sweep's processes were left running"


def test_a_cell_plans_header_errors_are_at_their_columns_with_the_nearest_name(tmp_path):
    """A cell's plan said its header's problems at the cell's index (1:3 for the 35th character) and without
    a suggestion."""
    from cotwin.twin.assembly.cell import read_cell_plan
    from cotwin.twin.assembly.run import load

    program = load(ROOT / "examples" / "ur5e" / "cotwin.toml").models.program
    plan = tmp_path / "typo.csv"
    plan.write_text("timestep,ur5e.moveDiscreteCommand,ur5f.MovementArgs_target_X,panda.moveDiscreteComand\n"
                    "1000,true,1,true\n")
    with pytest.raises(CotwinError) as err:
        read_cell_plan(plan, program, ["ur5e", "panda"])
    said = [str(f) for f in err.value.findings]
    assert any(s.startswith(f"{plan}:1:10: error: column 'ur5e.moveDiscreteCommand' without its argument")
               for s in said), said
    assert any(s.startswith(f"{plan}:1:35: error: column 'ur5f.MovementArgs_target_X': a cell's plan names "
                            "ROBOT.port, ROBOT one of ur5e, panda; did you mean 'ur5e'?") for s in said), said
    assert any(s.startswith(f"{plan}:1:62: error: column 'panda.moveDiscreteComand': unknown d-model input "
                            "'moveDiscreteComand'; did you mean 'moveDiscreteCommand'?") for s in said), said


def test_cotwin_run_of_a_cell_says_which_of_its_tables_it_ignores(tmp_path):
    """A cell's run returned before the warnings of `cotwin run`: its [plant] and [deviation] (read by its
    live twin) were silently without effect."""
    cell = ROOT / "examples" / "flexcell2" / "twin.toml"
    proc = cotwin("run", cell, "-o", tmp_path / "out", "--end", "0.2")
    assert proc.returncode == 0, proc.stderr
    lines = cell.read_text().splitlines()
    for table, readers in (("plant", "cotwin plant, cotwin twin of a cell ([[robots]]: its PT)"),
                           ("deviation", "cotwin twin, cotwin fleet")):
        at = lines.index(f"[{table}]") + 1
        assert f"{cell}:{at}:1: warning: [{table}] applies only to {readers}: cotwin run ignores it" in proc.stderr
    # and, as cotwin check, what its models warn of, once: the Panda's joint 4 starts at its limit
    assert proc.stderr.count("warning: joint panda_joint4: its zero position is outside its limits") == 1, proc.stderr


def test_deviation_variables_get_the_nearest_monitored_one(ur5e, tmp_path):
    from cotwin.twin.project import load_project
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import LiveTwin

    path = ur5e / "dev.toml"
    path.write_text((ur5e / "replay.toml").read_text().replace('"q1",', '"Q1",'))
    system = load(load_project(path, ur5e / "plan.csv"))
    with pytest.raises(CotwinError, match=r"\[deviation\] variables Q1 are not monitored mapping variables; did you "
                                          r"mean 'q1'\?"):
        LiveTwin(system, tmp_path / "out")


def test_a_run_that_ended_early_says_its_cause_first_then_what_it_kept():
    """The cause of a failed run, however its place sorts, comes before "no rows computed" (or where the
    rows are), in the error and in the error carried across processes."""
    import pickle

    from cotwin.cosim.execution import ended_early
    from cotwin.diagnostics import Diagnostics, Location

    diag = Diagnostics()
    diag.error(Location("cotwin.toml", 3, 1), "unit 'arm' failed its step: the FMU returned fmi2Error")
    diag.error(Location("arm.fmu", 0, 0), "the FMU's log: division by zero")
    cause = CotwinError(diag.findings)
    for err in (ended_early(cause, 0.5, "no rows computed"),
                pickle.loads(pickle.dumps(ended_early(cause, 0.5, "no rows computed")))):
        lines = str(err).splitlines()
        assert lines[:2] == [str(f) for f in cause.findings] and lines[-1] == "error: no rows computed", lines
        assert [str(f) for f in err.findings] == lines


@pytest.mark.parametrize("vhost", ["", "  ", "cot\nwin"])
def test_broker_permissions_refuses_a_vhost_rabbitmq_would_refuse(ur5e, vhost):
    """--vhost '' printed `rabbitmqctl add_vhost ''` and permissions on it: a script that fails half-way."""
    from conftest import cotwin_in_process

    proc = cotwin_in_process("broker-permissions", ur5e / "live.toml", "--vhost", vhost)
    assert proc.returncode == 2 and "Invalid value for '--vhost'" in proc.stderr and proc.stdout == ""


INTERRUPTED_IMPORT = """
import importlib.abc, sys

class Interrupt(importlib.abc.MetaPathFinder):  # Ctrl-C arriving while cotwin's CLI is being imported
    def find_spec(self, name, path=None, target=None):
        if name == "cotwin.cli":
            raise KeyboardInterrupt
        return None

sys.meta_path.insert(0, Interrupt())
sys.argv = ["cotwin", "--help"]
import runpy
runpy.run_module("cotwin", run_name="__main__")
"""


def test_ctrl_c_while_the_command_is_still_importing_is_an_interrupt_not_a_traceback():
    """The first tenths of a second of every command are imports: an interrupt there exits 130 with one line."""
    proc = subprocess.run([sys.executable, "-c", INTERRUPTED_IMPORT], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 130 and proc.stderr == "interrupted\n", proc.stderr[-2000:]


def test_cotwin_run_shows_the_warnings_cotwin_check_shows_once(ur5e, tmp_path):
    """A joint whose limits leave out its zero position starts at its nearest limit, which `cotwin check` warned
    of and `cotwin run` kept to itself: the robot started off its home posture without a word."""
    pmodel = ur5e / "ur5e.pm"
    lines = pmodel.read_text().splitlines()
    at = next(k for k, line in enumerate(lines) if "limit = Limit { lower = -2*PI" in line and k > 150)
    lines[at] = lines[at].replace("lower = -2*PI", "lower = 0.2")
    pmodel.write_text("\n".join(lines) + "\n")
    warning = "warning: joint elbow_joint: its zero position is outside its limits [0.2, 6.28319]"
    checked = cotwin_in_process("check", ur5e / "cotwin.toml")
    assert checked.returncode == 0 and (checked.stdout + checked.stderr).count(warning) == 1, checked
    ran = cotwin_in_process("run", ur5e / "cotwin.toml", "-o", tmp_path / "out", "--end", "0.2")
    assert ran.returncode == 0, ran.stderr
    said = [line for line in ran.stderr.splitlines() if warning in line]
    assert len(said) == 1 and said[0].startswith(f"{pmodel}:"), ran.stderr


def test_monitor_joints_for_a_mapping_without_q_variables_is_a_warning_at_its_key(tmp_path):
    """`[monitor] joints` on a mapping declaring no q0..qN/qd0..qdN mirrored nothing, logged nothing and said
    nothing: the user who asked for the wheels' angles got a run without them and no reason."""
    from cotwin.twin.assembly.run import load

    shutil.copytree(ROOT / "examples" / "turtlebot", tmp_path / "tb")
    project = tmp_path / "tb" / "cotwin.toml"
    lines = project.read_text().splitlines()
    at = next(k for k, line in enumerate(lines) if line.startswith("[monitor]")) + 1
    lines[at - 1] = '[monitor]\njoints = "actuated"'
    project.write_text("\n".join(lines) + "\n")
    said = [str(f) for f in load(project).warnings if "[monitor] joints" in f.message]
    assert len(said) == 1 and said[0].startswith(f"{project}:{at + 1}:1: warning: [monitor] joints: mapping "
                                                 "WalkMapping declares no variable q0"), said
    assert "(LeftWheelJoint, RightWheelJoint)" in said[0] and "`var q0: real, q1: real`" in said[0], said
    assert "or remove [monitor] joints" in said[0]
    checked = cotwin_in_process("check", project)
    assert checked.returncode == 0 and (checked.stdout + checked.stderr).count(said[0]) == 1, checked


def test_a_reading_path_the_pmodel_lacks_is_an_error_at_its_key_with_the_nearest_paths(ur5e):
    """A misspelt [monitor] reading checked ok, then stopped the run's first step with 'error: monitored variable
    elbow: the platform has no reading ...' and every reading of the platform (22 for the UR5e, 40 and more for
    a bigger robot), at no place."""
    path = ur5e / "cotwin.toml"
    path.write_text(path.read_text() + '[monitor]\nreadings = { elbow = "ur5e::upper_arm_link::PS3.position" }\n')
    line = len(path.read_text().splitlines())
    proc = cotwin_in_process("check", path)
    assert proc.returncode == 1, proc.stdout
    errors = [line for line in (proc.stdout + proc.stderr).splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith(
        f"{path}:{line}:14: error: [monitor] readings elbow: p-model ur5e has no reading "
        "'ur5e::upper_arm_link::PS3.position' (the nearest: ur5e::upper_arm_link::PS3.output_position, "), errors
    assert errors[0].endswith(", ... and 17 more)") and errors[0].count("ur5e::") == 6, errors
    # a free base's pose on a fixed base: said so
    path.write_text(path.read_text().replace("ur5e::upper_arm_link::PS3.position", "ur5e::base_link.x"))
    proc = cotwin_in_process("check", path)
    assert proc.returncode == 1 and "'ur5e::base_link.x' is the pose of a free base, and p-model ur5e's is fixed: " \
        'set [platform] base = "free"' in proc.stdout + proc.stderr, proc.stdout + proc.stderr


def test_a_plan_separated_by_semicolons_is_named_so(ur5e):
    """A plan saved by a spreadsheet in a locale that separates by ';' was refused for its header's first column
    ('timestep', which it has): the error names the separator, at the header's first one."""
    plan = ur5e / "plan.csv"
    text = plan.read_text()
    plan.write_text(text.replace(",", ";"))
    proc = cotwin_in_process("check", ur5e / "cotwin.toml")
    assert proc.returncode == 1, proc.stderr
    assert f"{plan}:1:9: error: the plan's columns are separated by ';': a plan is comma-separated (CSV), " \
           "e.g. 'timestep,moveDiscreteCommand" in proc.stderr, proc.stderr


def test_a_whatif_or_sweep_horizon_shorter_than_a_step_is_refused_once(ur5e):
    """A what-if runs whole steps: `--horizon 0.05` with the twin's 0.1 s step ran one step to 0.1 s in silence;
    a sweep would have refused every what-if alike. Both say so once, before any what-if runs."""
    proc = cotwin_in_process("whatif", ur5e / "cotwin.toml", "--plan", ur5e / "plan.csv", "--horizon", "0.05")
    assert proc.returncode == 1 and "a what-if's horizon of 0.05 s is shorter than one step of the twin (0.1 s)" \
        in proc.stderr, proc.stderr
    proc = cotwin_in_process("sweep", ur5e / "cotwin.toml", "--event", "moveDiscreteCommand", "--arg", "target_X=0..1",
                             "--arg", "target_Y=2", "--arg", "target_Z=0", "--horizon", "0.05", "--workers", "1",
                             "-o", ur5e / "sweep.csv")
    assert proc.returncode == 1 and proc.stderr.count("shorter than one step") == 1, proc.stderr


def test_a_mapping_index_past_its_vector_is_said_by_check_in_the_range_mappings_count_in(tmp_path):
    """A mapping's vectors count from 0 (q[0] is the first joint's): `target_q[6]` of a 6-vector was said only by
    the run, at its first evaluation; check compared with RoboChart's 1..6 and found it in range."""
    for name in ("ur3e", "ur5e"):  # the UR3e's project takes the UR5e's d-model
        shutil.copytree(ROOT / "examples" / name, tmp_path / name)
    project = tmp_path / "ur3e"
    mapping = project / "mapping.pm"
    text = mapping.read_text()
    line = "M6.dangle == target_q[5]"
    assert line in text
    mapping.write_text(text.replace(line, "M6.dangle == target_q[6]", 1))
    proc = cotwin_in_process("check", project / "cotwin.toml")
    at = next(k for k, row in enumerate(mapping.read_text().splitlines(), start=1) if "target_q[6]" in row)
    assert f"{mapping}:{at}:" in proc.stdout + proc.stderr and "index 6 is out of range 0..5" in proc.stdout + proc.stderr, \
        proc.stdout + proc.stderr


def test_a_plan_row_raising_two_commands_says_they_are_applied_a_step_apart(ur5e, tmp_path):
    """Two command events true in one row were applied one per step without a word, where two rows of one time
    are said to be (the source applies one command per step)."""
    (ur5e / "plan.csv").write_text("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,"
                                   "MovementArgs_target_Z,openGripperCommand\n1000,true,0,23,1,true\n"
                                   "2000,false,0,0,0,true\n")
    proc = cotwin_in_process("run", ur5e / "cotwin.toml", "--end", "2.5", "-o", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    said = [line for line in (proc.stdout + proc.stderr).splitlines() if "one command is applied per step" in line]
    assert said == [f"{ur5e / 'plan.csv'}:2:1: warning: this row raises moveDiscreteCommand, openGripperCommand: one "
                    "command is applied per step, moveDiscreteCommand first and each other in a later step"], said


def test_a_plan_row_whose_event_is_false_is_warned_of_at_its_line(tmp_path):
    """A row whose event column is false (or 0) raised nothing, was not counted and not reported: the run said
    'commands: 1' of a three-row plan, with no word of the others. It is accepted as 'no event this row' and
    warned of at its file and line, by cotwin run and cotwin whatif alike."""
    project = tmp_path / "ur5e"
    shutil.copytree(ROOT / "examples" / "ur5e", project)
    (project / "plan.csv").write_text("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,"
                                      "MovementArgs_target_Z\n1000,true,0,23,1\n5500,false,3,20,2\n8000,0,8,10,0\n")
    ran = cotwin_in_process("run", project / "cotwin.toml", "-o", tmp_path / "out", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    for line, time in ((3, "5.5"), (4, "8")):
        assert f"plan.csv:{line}:1: warning: this row at {time} s raises no event" in ran.stderr, ran.stderr
    assert "commands: 1, 1 completed" in ran.stdout
    asked = cotwin_in_process("whatif", project / "cotwin.toml", "--plan", project / "plan.csv", "--horizon", "3",
                              cwd=tmp_path)
    assert asked.returncode == 0, asked.stderr
    assert "plan.csv:3:1: warning: this row at 5.5 s raises no event" in asked.stderr, asked.stderr
