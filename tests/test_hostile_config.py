"""A hostile user's project and options files: every absurd, empty, duplicated, unbounded or non-finite
setting is a located error (file:line:col naming the key, or the option), exit status non-zero, no
traceback; nothing is silently rounded or accepted."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest
from click.testing import CliRunner

from cotwin.cli import main
from cotwin.diagnostics import CotwinError
from cotwin.twin.project import load_project

MODELS = '[models]\ndmodel = "arm.rst"\npmodel = "ur5e.pm"\nmapping = "mapping.pm"\n'


@pytest.fixture
def ur5e(tmp_path):
    """A copy of the UR5e example project to break."""
    from conftest import EXAMPLES

    target = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", target)
    return target


def refused(folder, text: str) -> str:
    """The error text of loading a project of `text` (which must be refused)."""
    path = folder / "hostile.toml"
    path.write_text(text)
    with pytest.raises(CotwinError) as err:
        load_project(path)
    return str(err.value)


def cotwin(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *map(str, args)], capture_output=True, text=True,
                          timeout=120)


def clean(proc) -> bool:
    """A refusal: exit 1 or 2 with a message, no traceback, no crash report."""
    return proc.returncode in (1, 2) and "Traceback" not in proc.stderr and "internal error" not in proc.stderr


def option_error(*args) -> str:
    """The usage error of a command refused while its options are parsed (click's exit 2)."""
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 2, (result.output, result.exception)
    return result.output


@pytest.mark.parametrize("table, line, message", [
    ('[scenario]\nrabbitmq = { exchange = "" }\n', "6:14", "[scenario.rabbitmq] exchange: must not be empty"),
    (f'[scenario]\nrabbitmq = {{ exchange = "{"x" * 300}" }}\n', "6:14", "is 300 bytes long; AMQP names hold at most 255"),
    ('[scenario]\nrabbitmq = { exchange = "bad name!" }\n', "6:14", "may hold only letters, digits"),
    ('[scenario]\nrabbitmq = { exchange = "amq.direct" }\n', "6:14", "reserved by the broker"),
    ('[scenario]\nrabbitmq = { exchange = "x", to_cosim = "" }\n', "6:30", "[scenario.rabbitmq] to_cosim: must not be empty"),
    ('[scenario]\nrabbitmq = { exchange = "x", from_cosim = "a\\nb" }\n', "6:30", "spaces or control characters"),
    ('[deviation]\nexchange = "a b"\n', "6:1", "[deviation] exchange: may hold only"),
    (f'[deviation]\nrouting_key = "{"k" * 256}"\n', "6:1", "[deviation] routing_key: is 256 bytes long"),
    ('[platform]\nqueue = ""\n', "6:1", "[platform] queue: must not be empty"),
    ('[scenario]\nrabbitmq = { exchange = "x", url = "amqp://127.0.0.1:00/" }\n', "6:30",
     "[scenario.rabbitmq] url: the broker's port 0 is no port"),
])
def test_amqp_exchange_queue_and_routing_key_names_are_checked(ur5e, table, line, message):
    text = refused(ur5e, MODELS + table)
    assert f"hostile.toml:{line}: error: " in text and message in text, text


@pytest.mark.parametrize("cosim, line, message", [
    ("step = 0.0005\nend = 1.0", 6, "[cosim] step: 0.0005 s is not a whole number of the simulator's 1 ms physics steps"),
    ("step = 0.1005\nend = 20.1", 6, "(nearest: 0.1 s)"),
    ("step = 0.1\nend = 20.05", 7, "[cosim] end: 20.05 s is not a whole number of steps of 0.1 s (it would be "
                                   "rounded): give 20 or 20.1"),
    ("step = 0.001\nend = 1e300", 7, "more than 1e+08"),
    ("step = 30\nend = 20", 7, "[cosim] end: 20 s is shorter than one step of 30 s"),
    ("step = 0.1\nend = 20.0\nparameters = { cycle_period = 0.03 }", 8,
     "[cosim] parameters cycle_period: 0.03 s does not divide the step of 0.1 s"),
    ("step = 0.1\nend = 20.0\nparameters = { cycle_period = 1e-12 }", 8, "d-model cycles per step"),
    ("step = 0.1\nend = 20.0\nparameters = { cycle_period = -1.0 }", 8, "cycle_period must be a number >= 0"),
])
def test_timing_a_run_cannot_keep_exactly_is_refused_at_its_key(ur5e, cosim, line, message):
    text = refused(ur5e, MODELS + "[cosim]\n" + cosim + "\n")
    assert f"hostile.toml:{line}:" in text and message in text, text


@pytest.mark.parametrize("value, said", [('"x"', "'x'"), ("nan", "nan"), ("[0.1]", "[0.1]"), ("true", "True"),
                                         ('"' + 'x' * 5000 + '"', "(5002 characters)")])
def test_a_cycle_period_that_is_no_number_is_one_error_at_its_value(ur5e, value, said):
    """It was two: one at the parameters' table (each parameter a number or a Boolean), one at cycle_period's value,
    which quoted a long value whole."""
    (ur5e / "hostile.toml").write_text(MODELS + f"[cosim]\nparameters = {{ seed = 7, cycle_period = {value} }}\n")
    with pytest.raises(CotwinError) as err:
        load_project(ur5e / "hostile.toml")
    [finding] = err.value.findings
    assert str(finding).startswith(f"{ur5e / 'hostile.toml'}:6:26: error: [cosim] parameters cycle_period must be a "
                                   "number >= 0 (s per d-model cycle; 0: one cycle per step), got "), str(finding)
    assert str(finding).endswith(said) and len(str(finding)) < 500, str(finding)


def test_timing_from_the_command_line_is_checked_with_the_project(ur5e, tmp_path):
    project = ur5e / "cotwin.toml"
    assert "--end: 20.05 s is not a whole number of steps of 0.1 s" in option_error(
        "run", project, "-o", tmp_path / "o", "--end", "20.05").replace("'", "").replace("Invalid value for ", "")
    assert "whole number of the simulator's 1 ms physics steps" in option_error(
        "run", project, "-o", tmp_path / "o", "--step", "0.0005")
    assert "more than 1e+08" in option_error("twin", project, "-o", tmp_path / "o", "--end", "1e300")
    assert not (tmp_path / "o").exists()  # refused before anything is written


def test_a_cycle_period_is_checked_against_the_step_the_run_takes(ur5e, tmp_path):
    """[cosim] step 0.1 and cycle_period 0.03 do not go together; a run at `--step 0.3` (ten cycles a step) runs, one
    at `--step 0.25` is refused quoting 0.25 s: both were refused quoting the project's 0.1 s, which they replace."""
    from conftest import cotwin_in_process

    path = ur5e / "timing.toml"
    path.write_text(MODELS + "[cosim]\nstep = 0.1\nend = 3.0\nparameters = { cycle_period = 0.03 }\n")
    with pytest.raises(CotwinError, match="cycle_period: 0.03 s does not divide the step of 0.1 s"):
        load_project(path)
    with pytest.raises(CotwinError, match="does not divide the step of 0.1 s"):
        load_project(path, end=0.6)  # the project's step, which the run takes
    assert load_project(path, step=0.3).step == 0.1  # the project as written; the run takes 0.3
    load_project(path, step=0.3).with_overrides(realtime=True)  # a command's change to it (cotwin twin --rabbitmq)
    for command in ("run", "twin"):
        said = " ".join(option_error(command, path, "-o", tmp_path / "o", "--step", "0.25").replace("'", "").split())
        assert f"--step: [cosim] parameters cycle_period ({path}:8:16):" in said, said
        assert "0.03 s does not divide the step of 0.25 s into whole d-model cycles" in said and "0.1 s" not in said
    proc = cotwin_in_process("run", path, "-o", tmp_path / "ran", "--step", "0.3", "--end", "0.6")
    assert proc.returncode == 0 and "0.6 s" in proc.stdout and "error:" not in proc.stderr and \
        "0 error(s)" in proc.stderr, proc.stdout + proc.stderr


def test_a_fleet_twins_cycle_period_is_checked_against_the_step_its_entry_gives(ur5e, tmp_path):
    """As `cotwin twin --step` (above): a fleet entry's step replaces the project's, with which the cycle_period
    did not go."""
    from cotwin.twin.analysis.fleet.spec import read_fleet

    project = ur5e / "timing.toml"
    project.write_text(MODELS + "[cosim]\nstep = 0.1\nend = 3.0\nparameters = { cycle_period = 0.03 }\n"
                                '[pt]\nendpoint = "opcua"\nurl = "opc.tcp://127.0.0.1:4841"\n')
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(f'[[twin]]\nname = "a"\nproject = "{project}"\nstep = 0.3\n')
    assert [t.name for t in read_fleet(fleet).twins] == ["a"]
    fleet.write_text(f'[[twin]]\nname = "a"\nproject = "{project}"\nstep = 0.25\n')
    with pytest.raises(CotwinError) as err:
        read_fleet(fleet)
    [finding] = err.value.findings
    assert str(finding) == f"{fleet}:4:1: error: twin 'a': [cosim] parameters cycle_period ({project}:8:16): 0.03 s " \
        "does not divide the step of 0.25 s into whole d-model cycles"


@pytest.mark.parametrize("deviation, message", [
    ("lag_steps = 1000000000000000000000", "[deviation] lag_steps: must be in [0, 1e+06] steps"),
    ("lag_steps = -1", "[deviation] lag_steps: must be in [0, 1e+06] steps, got -1"),
    ("debounce_steps = 0", "[deviation] debounce_steps: must be in [1, 1e+06] steps"),
    ("debounce_steps = 1e300", "[deviation] debounce_steps must be an integer"),
    ("variables = []", "[deviation] variables: names no variable"),
    ('variables = ["q0", "q1", "q0"]', "[deviation] variables: names 'q0' more than once"),
    ('variables = [""]', "[deviation] variables: an empty variable name"),
])
def test_deviation_settings_are_bounded_and_name_each_variable_once(ur5e, deviation, message):
    text = refused(ur5e, MODELS + "[deviation]\n" + deviation + "\n")
    assert "hostile.toml:6:1: error: " in text and message in text, text


@pytest.mark.parametrize("table, message", [
    ('[scenario]\nrabbitmq = { exchange = "x", timeout_s = 1e300 }', "timeout_s: must be in [0, 86400] s"),
    ('[scenario]\nrabbitmq = { exchange = "x", maxage_ms = 1e300 }', "maxage_ms: must be in [0, 8.64e+07] ms"),
    ('[scenario]\nrabbitmq = { exchange = "x", commands = ["a", "a"] }', "commands: names 'a' more than once"),
    ("[plant]\npayload = 1e300", "[plant] payload: must be at most 1000 kg"),
    ("[plant]\nfriction = { elbow_joint = 1e300 }", "joint 'elbow_joint' must be a number in [0, 10000]"),
    ("[plant]\ndamping = 1e9", "[plant] damping: must be at most 1000"),
    ("[plant]\nnoise = { position = 1e300 }", "sensor quantity 'position' must be a number in [0, 1000]"),
    ('[pt]\nendpoint = "opcua"\nurl = "opc.tcp://127.0.0.1:99999"', "[pt] url: bad OPC UA URL"),
    ('[pt]\nendpoint = "opcua"\nurl = "opc.tcp://127.0.0.1:0"', "[pt] url: port 0 is not in 1..65535"),
    ('[pt]\nendpoint = "opcua"\nurl = "http://127.0.0.1:4840"', "expected opc.tcp://HOST:PORT"),
])
def test_broker_plant_and_pt_settings_are_bounded(ur5e, table, message):
    text = refused(ur5e, MODELS + table + "\n")
    assert "hostile.toml:" in text and message in text, text


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e400"])
def test_every_number_key_and_option_is_finite(ur5e, tmp_path, value):
    for table in (f"[cosim]\nend = {value}", f"[deviation]\nabsolute = {value}", f"[plant]\nlatency_ms = {value}",
                  f"[pt]\nendpoint = \"replay\"\nlog = \"plan.csv\"\noffset = {value}"):
        text = refused(ur5e, MODELS + table + "\n")
        assert "hostile.toml:" in text and "finite" in text or "positive" in text or ">= 0" in text, text
    project = ur5e / "cotwin.toml"
    for args in (["run", project, "-o", tmp_path / "o", "--end", value],
                 ["sweep", project, "--event", "moveDiscreteCommand", "--arg", "target_X=1", "--horizon", value,
                  "-o", tmp_path / "s.csv"],
                 ["whatif", project, "--plan", ur5e / "plan.csv", "--horizon", value],
                 ["publish", project, "--period", value],
                 ["plant", project, "--payload", value]):
        out = option_error(*args)
        assert "Invalid value for" in out and "Traceback" not in out, (args, out)


def test_sweep_grids_refuse_empty_huge_and_repeated_arguments(ur5e, tmp_path):
    from cotwin.twin.assembly.run import load
    from cotwin.twin.analysis.sweep import MAX_PLANS, grid

    project, out = ur5e / "cotwin.toml", tmp_path / "s.csv"
    sweep = ["sweep", project, "--event", "moveDiscreteCommand", "-o", out]
    assert "target_X takes no value (an empty range" in option_error(*sweep, "--arg", "target_X=5..1")
    assert "target_X takes 1000000001 values" in option_error(*sweep, "--arg", "target_X=0..1000000000")
    assert "argument 'target_X' is given twice" in option_error(*sweep, "--arg", "target_X=1", "--arg", "target_X=2")
    huge = "9" * 400
    assert "values must be finite numbers" in option_error(*sweep, "--arg", f"target_X={huge}")
    assert "target_X takes countless values" in option_error(*sweep, "--arg", f"target_X=0..{huge}")
    program = load(project).models.program
    with pytest.raises(CotwinError, match=rf"a grid of 1001 target_X x 1001 target_Y is 1002001 what-ifs, more "
                                          rf"than {MAX_PLANS}"):
        grid(program, "moveDiscreteCommand", {"target_X": range(1001), "target_Y": range(1001)})
    with pytest.raises(CotwinError, match="argument target_Y: no values to sweep"):
        grid(program, "moveDiscreteCommand", {"target_X": [1], "target_Y": []})
    assert not out.exists()


def test_worlds_are_bounded_in_size_and_obstacles(tmp_path):
    from cotwin.pmodel.world import MAX_OBSTACLES, load_world

    path = tmp_path / "world.toml"
    path.write_text("[arena]\nsize = [1e9, 4.0]\nwall_height = 1e9\n[start]\nx = 1e300\n"
                    "[[cylinder]]\ncenter = [0.5, 0.5]\nradius = 1e300\n")
    with pytest.raises(CotwinError) as err:
        load_world(path)
    text = str(err.value)
    for where, message in [("2:1", "[arena] size: must be within 1000 m"), ("3:1", "[arena] wall_height: must be at "
                           "most 1000 m"), ("5:1", "[start] x: must be within 1000 m"),
                           ("8:1", "[[cylinder]] 1 radius: must be at most 1000 m")]:
        assert f"world.toml:{where}: error: {message}" in text, text
    many = ", ".join(f"{{ center = [{i % 100 * 0.5}, {i // 100 * 0.5}], radius = 0.1 }}" for i in range(MAX_OBSTACLES + 1))
    path.write_text(f"cylinder = [{many}]\n")
    with pytest.raises(CotwinError, match=rf"world.toml:1:1: error: the world has {MAX_OBSTACLES + 1} walls, boxes "
                                          rf"and cylinders, more than {MAX_OBSTACLES}"):
        load_world(path)


def lines(path) -> int:
    """How many lines a file has: problems in text appended to an example are located after them."""
    return len(path.read_text().splitlines())


def test_figure_panels_naming_unknown_units_or_variables_are_refused(ur5e):
    from cotwin.twin.assembly.run import load

    path = ur5e / "figure.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + '[figure]\npanels = [\n  { variables = ["mapping.q0"] },\n'
                    '  { variables = ["mapping.q9", "robot.q0"] },\n]\n')
    with pytest.raises(CotwinError) as err:
        load(path)
    text = str(err.value)
    at = lines(ur5e / "cotwin.toml") + 2  # the line of panels
    assert f"figure.toml:{at}:1: error: [figure] panel 2 variable 'mapping.q9': mapping shows no variable 'q9'" in text
    assert "[figure] panel 2 variable 'robot.q0': unit 'robot' is not one of this twin's" in text
    assert "panel 1" not in text
    text = refused(ur5e, MODELS + "[figure]\npanels = [{ variables = [] }]\n")
    assert "hostile.toml:6:1: error: " in text and "variables: names no variable" in text


def test_cosim_parameters_are_checked_against_the_fmu_at_their_key(ur5e):
    from cotwin.twin.assembly.run import load

    path = ur5e / "params.toml"
    path.write_text((ur5e / "cotwin.toml").read_text().replace(
        "[cosim]", "[cosim]\nparameters = { cycle_period = 0.05, nope = 1 }"))
    with pytest.raises(CotwinError, match=r"params.toml:\d+:37: error: \[cosim\] parameters: the d-model has no "
                                          r"parameter 'nope'"):
        load(path)


def test_toml_with_a_bom_is_read_and_bad_nesting_names_file_and_key(ur5e):
    bom = ur5e / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + (ur5e / "cotwin.toml").read_bytes())
    assert load_project(bom).end == 20.0
    text = refused(ur5e, MODELS + "[[cosim]]\nstep = 0.1\n[monitor.readings.x]\ny = 1\n")
    assert "hostile.toml:5:1: error: 'cosim' must be a table, got [{'step': 0.1}]" in text, text
    assert "hostile.toml:7:1: error: [monitor] readings: each reading is a path (a string): 'x'" in text, text
    text = refused(ur5e, 'models = "arm.rst"\n[cosim]\nstep = { value = 0.1 }\n')
    assert "hostile.toml:1:1: error: 'models' must be a table, got 'arm.rst'" in text
    assert "hostile.toml:3:1: error: [cosim] step must be a positive number" in text


def test_a_file_with_thousands_of_problems_prints_fifty_and_counts_the_rest(ur5e, tmp_path):
    path = ur5e / "many.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + "".join(f"bogus{i} = 1\n" for i in range(3000)))
    proc = cotwin("build", path, "-o", tmp_path / "o")
    assert clean(proc), proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 52 and all("many.toml:" in line for line in lines[:50])
    assert lines[-2] == "... and 2950 more problem(s) not shown (2950 error(s))"
    assert lines[-1] == "3000 error(s), 0 warning(s)"  # the command's closing count: each problem one
    assert not (tmp_path / "o").exists()


def test_an_empty_output_path_is_refused(ur5e):
    project = ur5e / "cotwin.toml"
    for args in (["run", project], ["build", project], ["twin", project],
                 ["sweep", project, "--event", "moveDiscreteCommand"], ["export-pmodel", ur5e / "ur5e.pm",
                                                                          "--format", "sdf"]):
        out = option_error(*args, "-o", "")
        assert "-o/--output: an empty path" in out, (args, out)


def test_calibration_files_are_bounded_and_an_empty_one_is_refused(tmp_path):
    from cotwin.twin.assembly.calibration import Calibration

    path = tmp_path / "calibration.toml"
    for text in ("", "# fitted by hand\n[fit]\nrmse = 1.0\n"):
        path.write_text(text)
        with pytest.raises(CotwinError, match=r"calibration.toml:1:1: error: the calibration file sets none of "
                                              r"\[plate\], \[tool\], \[ik\], \[motion\], \[timing\]"):
            Calibration.read(path)
    path.write_text("[plate]\nxyz = [1e300, 0, 0]\nsurface = -1e9\n[ik]\njoint_offsets = { elbow_joint = [0, 0, 1e300] }\n"
                    "[motion]\nprofile = \"movej\"\na = 1e300\ndelay = -1e300\n[timing]\nlatencies = [0.5, 1e300]\n")
    with pytest.raises(CotwinError) as err:
        Calibration.read(path)
    text = str(err.value)
    for where, message in [("2:1", "[plate] xyz must be within [-10, 10] m, got 1e+300"),
                           ("3:1", "[plate] surface must be within [-10, 10] m"),
                           ("5:19", "[ik] joint_offsets elbow_joint must be within [-10, 10] m"),
                           ("8:1", "[motion] a must be within [0, 1000] rad/s^2"),
                           ("9:1", "[motion] delay must be within [-3600, 3600] s"),
                           ("11:1", "[timing] latencies must be within [-3600, 3600] s, got 1e+300")]:
        assert f"calibration.toml:{where}: error: {message}" in text, text


def test_exchange_options_are_checked_like_the_project(ur5e):
    project = ur5e / "cotwin.toml"
    assert "must not be empty" in option_error("twin", project, "-o", ur5e / "o", "--rabbitmq", "")
    assert "may hold only letters" in option_error("publish", project, "--exchange", "a b")


@pytest.mark.parametrize("table, message", [
    ("[monitor]\njoints = []", "[monitor] joints: names no joint"),
    ('[monitor]\njoints = ["elbow_joint", "elbow_joint"]', "[monitor] joints: names 'elbow_joint' more than once"),
    ('[monitor]\nreadings = { x = "" }', "[monitor] readings: each reading is a path (a string): 'x'"),
    ('[history]\nurl = ""', "[history] url: '' is not a sqlite:///FILE or postgresql://... URL"),
    ('[platform]\nstand_in = [{ mesh = "a.stl", shape = "sphere", size = [0.1], pos = [1e300, 0, 0] }]',
     "[[platform.stand_in]] 1 pos: must be 3 numbers within 10"),
    ('[platform]\nstand_in = [{ mesh = "a.stl", shape = "sphere", size = [1e300] }]',
     "size of a sphere is 1 positive number(s) (radius) of at most 10 m"),
])
def test_empty_duplicated_and_unbounded_platform_and_monitor_settings_are_refused(ur5e, table, message):
    text = refused(ur5e, MODELS + table + "\n")
    assert "hostile.toml:6:1: error: " in text and message in text, text
    text = refused(ur5e, MODELS.replace('mapping.pm"\n', 'mapping.pm"\nmodule = " "\n'))
    assert "hostile.toml:5:1: error: [models] module: must not be empty" in text, text


def test_bricks_off_the_plate_are_refused_at_their_key(ur5e):
    from cotwin.twin.assembly.run import load

    path = ur5e / "bricks.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + "\n[scene]\nbricks = [[-1, 1000000]]\n")
    with pytest.raises(CotwinError, match=r"bricks.toml:\d+:1: error: \[scene\] bricks: \[-1, 1000000\] is no hole "
                                          r"of the plate \(X in 0..15, Y in 0..23\)"):
        load(path)
    path.write_text((ur5e / "cotwin.toml").read_text() + "\n[scene]\nbricks = [[8, 10], [2, 3], [8, 10]]\n")
    with pytest.raises(CotwinError, match=r"bricks.toml:\d+:1: error: \[scene\] bricks: two bricks cannot stand on "
                                          r"one hole: \[8, 10\]"):
        load(path)


def test_an_unknown_scene_kind_is_refused_at_its_key_naming_the_known_ones(ur5e):
    from cotwin.twin.assembly.run import load

    path = ur5e / "kind.toml"
    path.write_text((ur5e / "cotwin.toml").read_text().replace("[platform]", '[platform]\nscene = "flexcel"'))
    with pytest.raises(CotwinError, match=r"kind.toml:\d+:1: error: \[platform\] scene: no scene kind 'flexcel'"
                                          r"; did you mean 'flexcell'\? \(known: auto, .*flexcell.*\)"):
        load(path)


def test_toml_nested_thousands_deep_is_a_located_error(ur5e, tmp_path):
    path = ur5e / "deep.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + "x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    proc = cotwin("build", path, "-o", tmp_path / "o")
    at = lines(ur5e / "cotwin.toml") + 1  # the line of x
    assert clean(proc) and f"deep.toml:{at}:1: error: the project file nests arrays or tables too deeply" in proc.stderr, \
        proc.stderr


def test_an_empty_perturbation_file_and_absurd_world_headings_are_refused(ur5e, tmp_path):
    from cotwin.pmodel.perturbation import read_perturbation
    from cotwin.pmodel.world import load_world

    path = tmp_path / "plant.toml"
    path.write_text("# nothing yet\n")
    with pytest.raises(CotwinError, match=r"plant.toml:1:1: error: the perturbation file sets none of seed, payload"):
        read_perturbation(path)
    path.write_text("[start]\nyaw = 1e300\n[[box]]\ncenter = [1, 1]\nsize = [0.1, 0.1, 0.1]\nyaw = -1e9\n")
    with pytest.raises(CotwinError) as err:
        load_world(path)
    assert "plant.toml:2:1: error: [start] yaw: must be within 360 degrees" in str(err.value)
    assert "plant.toml:6:1: error: [[box]] 1 yaw: must be within 360 degrees" in str(err.value)


def test_number_options_are_bounded(ur5e, tmp_path):
    project = ur5e / "cotwin.toml"
    for args, option in [(["sweep", project, "--event", "moveDiscreteCommand", "--arg", "target_X=1", "--workers",
                           "1000000", "-o", tmp_path / "s.csv"], "--workers"),
                         (["verify", ur5e / "arm.rst", "--max-states", str(10 ** 12)], "--max-states"),
                         (["calibrate", project, "--pt-log", project, "-o", tmp_path / "c.toml", "--log-start",
                           "1e300"], "--log-start"),
                         (["whatif", project, "--plan", ur5e / "plan.csv", "--horizon", "1e9"], "--horizon"),
                         (["plant", project, "--noise", "1e9"], "--noise")]:
        out = option_error(*args)
        assert f"Invalid value for '{option}'" in out and "is not in the range" in out, (args, out)
    out = option_error("calibrate", project, "--pt-log", project, "-o", tmp_path / "c.toml", "--tool", "1e300,0,0")
    assert "Invalid value for --tool" in out and "within 10 m" in out, out
    assert not (tmp_path / "s.csv").exists() and not (tmp_path / "c.toml").exists()


def test_a_run_asked_for_by_a_program_keeps_the_same_timing_rules(ur5e, tmp_path):
    from cotwin.twin.assembly.run import load, run_twin
    from cotwin.twin.live.runtime import LiveTwin

    system = load(ur5e / "cotwin.toml")
    with pytest.raises(CotwinError, match=r"end: 1.05 s is not a whole number of steps of 0.1 s"):
        run_twin(system, tmp_path / "o", end=1.05)
    with pytest.raises(CotwinError, match=r"step: 0.0015 s is not a whole number of the simulator's 1 ms"):
        LiveTwin(system, tmp_path / "o", step=0.0015, end=0.3)
    with pytest.raises(CotwinError, match=r"need a positive step and end time \(step nan"):
        run_twin(system, tmp_path / "o", step=float("nan"))
    assert not (tmp_path / "o").exists()


def test_deviation_variables_the_mapping_does_not_monitor_are_located(ur5e, tmp_path):
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import LiveTwin

    path = ur5e / "dev.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + '\n[deviation]\nvariables = ["q0", "q7"]\n')
    at = lines(ur5e / "cotwin.toml") + 3  # the line of variables
    with pytest.raises(CotwinError, match=rf"dev.toml:{at}:1: error: \[deviation\] variables q7 are not monitored"):
        LiveTwin(load(path), tmp_path / "o")


def test_bricks_or_a_world_the_scene_would_ignore_are_refused(ur5e):
    from cotwin.twin.assembly.run import load

    path = ur5e / "scene.toml"
    base = (ur5e / "cotwin.toml").read_text()
    path.write_text(base.replace("[platform]", '[platform]\nscene = "none"') + "\n[scene]\nbricks = [[8, 10]]\n")
    with pytest.raises(CotwinError, match=r"scene.toml:\d+:1: error: \[scene\] bricks: the scene is 'none' "
                                          r"\(\[platform\] scene = \"none\"\), which would ignore it"):
        load(path)
    path.write_text(base.replace("[platform]", '[platform]\nscene = "flexcell"') + '[world]\nname = "arena"\n')
    at = lines(ur5e / "cotwin.toml") + 2  # the line of [world], after the added scene line
    with pytest.raises(CotwinError, match=rf"scene.toml:{at}:1: error: \[world\]: the scene is 'flexcell'"):
        load(path)


@pytest.mark.parametrize("pt, line, message", [
    ('endpoint = "replay"\nlog = "plan.csv"\nurl = "opc.tcp://127.0.0.1:4840"', 8,
     "[pt] url does not apply to endpoint 'replay' (it takes log, offset)"),
    ('endpoint = "opcua"\nurl = "opc.tcp://127.0.0.1:4840"\noffset = 3.0', 8,
     "[pt] offset does not apply to endpoint 'opcua' (it takes url)"),
    ('endpoint = "broker"\nurl = "amqp://twin:secret@127.0.0.1/"', 7, "[pt] url: a password in the project file is refused"),
    ('endpoint = "rtde"\nurl = "robot one"', 7, "[pt] url: 'robot one' is not a robot's host"),
])
def test_pt_keys_its_endpoint_would_ignore_and_bad_pt_urls_are_refused(ur5e, pt, line, message):
    text = refused(ur5e, MODELS + "[pt]\n" + pt + "\n")
    assert f"hostile.toml:{line}:1: error: {message}" in text, text
    assert "secret" not in text


def test_an_integer_too_large_for_any_float_is_a_located_error(ur5e, tmp_path):
    from cotwin.pmodel.world import load_world
    from cotwin.twin.assembly.calibration import Calibration

    huge = "9" * 400
    text = refused(ur5e, MODELS + f"[cosim]\nend = {huge}\n[platform]\nstand_in = [{{ mesh = \"a\", shape = "
                                  f"\"sphere\", size = [{huge}] }}]\n")
    assert f"hostile.toml:6:1: error: [cosim] end must be a positive number, got {huge[:65]}... (400 characters)" \
           in text, text
    assert "hostile.toml:8:1: error: [[platform.stand_in]] size of a sphere" in text, text
    path = tmp_path / "w.toml"
    path.write_text(f"[[box]]\ncenter = [{huge}, 0]\nsize = [1, 1, 1]\n")
    with pytest.raises(CotwinError, match=r"w.toml:2:1: error: \[\[box\]\] 1 center: must be a list of 2 numbers"):
        load_world(path)
    path.write_text(f"[ik]\njoint_offsets = {{ elbow_joint = [0, 0, {huge}] }}\n")
    with pytest.raises(CotwinError, match=r"w.toml:2:19: error: \[ik.joint_offsets\] elbow_joint: must be a list of 3 finite "
                                          r"numbers, got \[0, 0, 9+\.\.\. \(408 characters\)"):
        Calibration.read(path)


@pytest.mark.parametrize("name", ["9" * 400 + ".pm"])
def test_a_model_path_the_system_cannot_look_up_is_a_located_error(ur5e, name):
    """A path longer than the system takes (found by the input fuzzer) raised OSError 'File name too long'
    out of the project loader; it is an error at its key, the path cut short."""
    text = (ur5e / "twin.toml").read_text()
    assert 'mapping = "mapping.pm"' in text
    (ur5e / "twin.toml").write_text(text.replace('mapping = "mapping.pm"', f'mapping = "{name}"'.replace("\0", "\\u0000")))
    with pytest.raises(CotwinError) as err:
        load_project(ur5e / "twin.toml")
    said = [f for f in err.value.findings if "[models] mapping" in f.message]
    assert said and "cannot be looked up" in said[0].message and len(said[0].message) < 400
    assert said[0].location.line >= 1
