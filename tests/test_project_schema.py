"""The project schema as typed settings: every example project reads into them and writes back unchanged,
problems are located and reported together (unknown keys with the nearest known one), overrides give a
new checked project, and a section is one dataclass plus one entry."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import pytest
from conftest import EXAMPLES

from cotwin.config import Key, TomlFile
from cotwin.diagnostics import CotwinError
from cotwin.settings import read, reference, setting
from cotwin.twin.project import load_project
from cotwin.twin.project.sections import SECTIONS, Cosim, ProjectSettings, project_settings

PROJECTS = sorted(p for p in EXAMPLES.glob("*/*.toml") if "[models]" in p.read_text())
MODELS = '[models]\ndmodel = "arm.rst"\npmodel = "ur5e.pm"\nmapping = "mapping.pm"\n'


@pytest.fixture
def ur5e(tmp_path) -> Path:
    target = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", target)
    return target


def test_every_example_project_is_found():
    assert len(PROJECTS) >= 6 and {p.parent.name for p in PROJECTS} == {"ur5e", "ur3e", "turtlebot", "flexcell2"}


def _resolved(value):
    if isinstance(value, Path):
        return value.resolve()
    if isinstance(value, tuple):  # e.g. [[robots]]
        return tuple(_resolved(v) for v in value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.replace(value, **{f.name: _resolved(getattr(value, f.name)) for f in dataclasses.fields(value)})
    return value


@pytest.mark.parametrize("project", PROJECTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_an_example_written_back_reads_as_the_same_project(project, tmp_path):
    try:
        spec = load_project(project)
    except CotwinError as err:
        if "shared" in str(err):
            pytest.skip("../shared is absent: the published models are not there")
        raise
    again = tmp_path / "written.toml"
    again.write_text(spec.to_toml(rebase=str))  # files named by absolute paths: read from anywhere
    copy = load_project(again)
    flat = [f.name for f in dataclasses.fields(spec) if f.name not in ("path", "locations", "file", "settings", "raw",
                                                                    "stand_ins")]
    assert copy.settings.platform.stand_in == spec.settings.platform.stand_in
    assert {k: _resolved(getattr(copy, k)) for k in flat} == {k: _resolved(getattr(spec, k)) for k in flat}
    for section in ("cosim", "monitor", "deviation", "plant", "figure", "history"):
        assert getattr(copy.settings, section) == getattr(spec.settings, section)


def test_sections_are_typed_and_frozen(ur5e):
    spec = load_project(ur5e / "twin.toml")
    s = spec.settings
    assert isinstance(s.cosim, Cosim) and s.pt.endpoint == "opcua" and s.deviation.variables[0] == "q0"
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.cosim.step = 1.0


def test_every_problem_is_reported_together_at_its_key(ur5e):
    path = ur5e / "hostile.toml"
    path.write_text(MODELS + "[cosim]\nsetp = 0.1\nrealtime = \"no\"\n[pt]\nurl = \"opc.tcp://h:1\"\n[plotform]\n")
    with pytest.raises(CotwinError) as err:
        load_project(path)
    text = str(err.value)
    assert f"{path}:6:1: error: unknown key 'setp' in [cosim]; did you mean 'step'?" in text
    assert f"{path}:7:1: error: [cosim] realtime must be true or false" in text
    assert f"{path}:8:1: error: [pt] needs 'endpoint'" in text
    assert "unknown key 'plotform' in the file; did you mean 'platform'?" in text
    assert len(err.value.findings) == 4


def test_a_nested_key_far_from_any_known_one_gets_no_guess(ur5e):
    path = ur5e / "hostile.toml"
    path.write_text(MODELS + '[scenario.rabbitmq]\nexchange = "x"\nzzz = 1\n')
    with pytest.raises(CotwinError) as err:
        load_project(path)
    assert f"{path}:7:1: error: unknown key 'zzz' in [scenario.rabbitmq] (known: exchange," in str(err.value)
    assert "did you mean" not in str(err.value)


def test_overrides_give_a_new_checked_project(ur5e):
    spec = load_project(ur5e / "twin.toml")
    other = spec.with_overrides(step=0.05, pt_url="opc.tcp://127.0.0.1:4999", scenario_plan=None)
    assert (other.step, other.pt.url, other.plan) == (0.05, "opc.tcp://127.0.0.1:4999", None)
    assert other.settings.cosim.step == 0.05 and other.settings.pt.url == "opc.tcp://127.0.0.1:4999"
    assert (spec.step, spec.pt.url) == (0.1, "opc.tcp://127.0.0.1:4840") and spec.plan is not None
    live = spec.with_overrides(scenario_plan=None, scenario_rabbitmq_exchange="my_twin", realtime=True)
    assert live.rabbitmq.exchange == "my_twin" and live.rabbitmq.to_cosim == "data.to_cosim" and live.realtime
    with pytest.raises(CotwinError, match=r"\[cosim\] step: 0.0015 s is not a whole number"):
        spec.with_overrides(step=0.0015)
    with pytest.raises(CotwinError, match=r"port 0 is not in 1..65535"):
        spec.with_overrides(pt_url="opc.tcp://127.0.0.1:0")
    with pytest.raises(TypeError, match="no project setting 'url' \\(several sections have it\\)"):
        spec.with_overrides(url="x")


def test_a_written_project_keeps_only_what_differs_from_the_defaults(ur5e):
    spec = load_project(ur5e / "cotwin.toml").with_overrides(end=3.0, deviation_absolute=0.2)
    text = spec.to_toml()
    assert "end = 3.0" in text and "absolute = 0.2" in text and "unit_timeout" not in text
    assert "[pt]" not in text and "[plant]" not in text
    (ur5e / "again.toml").write_text(text)
    assert load_project(ur5e / "again.toml").settings == spec.settings


def test_the_staged_copy_of_a_build_reads_back_as_the_project(ur5e, tmp_path):
    from cotwin.twin.assembly.build import staged_project
    from cotwin.twin.assembly.run import load

    system = load(load_project(ur5e / "pick_place_project.toml").with_overrides(step=0.05))
    staged_project(system, tmp_path / "stage")
    copy = load_project(tmp_path / "stage" / "cotwin.toml")
    for section in ("platform", "monitor", "cosim"):
        assert getattr(copy.settings, section) == getattr(system.spec.settings, section)
    assert copy.scene_options == {"bricks": [[8, 10]]} and copy.plan.name == "pick_place.toml" and copy.plan.parent == tmp_path / "stage"
    assert copy.dmodel.read_text() == system.spec.dmodel.read_text()


@dataclasses.dataclass(frozen=True)
class Extra:
    """A section another module adds."""

    tolerance: float = setting("how close is close", Key("positive", 0.5))
    names: tuple = setting("what is compared", Key("list[str]", []))


def test_a_new_section_is_a_dataclass_and_one_entry(tmp_path):
    settings = project_settings({**SECTIONS, "extra": setting("Something new.", section=Extra)})
    path = tmp_path / "p.toml"
    path.write_text(MODELS + "[extra]\ntolerance = 0.25\nnames = [\"a\"]\n")
    problems: list = []
    s = read(settings, TomlFile(path).data, TomlFile(path), (), problems)
    assert problems == [] and s.extra == Extra(0.25, ("a",)) and s.cosim == Cosim()
    doc = "\n".join(reference(settings))
    assert "## `[extra]`" in doc and "| `tolerance` | number > 0 | `0.5` | how close is close |" in doc
    path.write_text(MODELS + "[extra]\ntolerence = 0.25\n")
    read(settings, TomlFile(path).data, TomlFile(path), (), problems)
    assert [p.message for p in problems] == ["unknown key 'tolerence' in [extra]; did you mean 'tolerance'? "
                                             "(known: tolerance, names)"]
    assert "extra" not in {f.name for f in dataclasses.fields(ProjectSettings)}


def test_fields_set_after_loading_are_what_overrides_and_the_writer_keep():
    """A caller that sets a loaded project's fields (a test's exchange, a fleet's end) builds what it set:
    the build's staged copy (with_overrides, then to_toml) wrote the file's values instead, so the broker
    FMU listened on the file's exchange and the run waited for commands that went elsewhere."""
    from dataclasses import replace

    from cotwin.twin.project import load_project

    spec = load_project(EXAMPLES / "ur5e" / "live.toml")
    spec.rabbitmq = replace(spec.rabbitmq, exchange="cotwin_elsewhere")
    spec.end, spec.algorithm = 3.0, "gauss-seidel"
    staged = spec.with_overrides(models_fmu=None)
    assert (staged.rabbitmq.exchange, staged.end, staged.algorithm) == ("cotwin_elsewhere", 3.0, "gauss-seidel")
    text = staged.to_toml()
    assert 'exchange = "cotwin_elsewhere"' in text and "end = 3.0" in text and 'algorithm = "gauss-seidel"' in text


def test_a_misspelt_value_of_a_closed_set_gets_the_nearest_valid_one(ur5e):
    """Enum values get a "did you mean" as unknown keys do: the algorithm, the resync mode, a base written
    in capitals when the project is read; the PT's endpoint (an open registry of kinds) when the twin is
    assembled."""
    path = ur5e / "typos.toml"
    path.write_text(MODELS + '[cosim]\nalgorithm = "jacobii"\n[pt]\nendpoint = "opcau"\nurl = "opc.tcp://h:4840"\n'
                    '[convergence]\nresync = "on_alarm"\n[platform]\nbase = "Free"\n')
    with pytest.raises(CotwinError) as err:
        load_project(path)
    text = str(err.value)
    for line, hint in ((6, "jacobi"), (11, "on-alarm"), (13, "free")):
        assert f"typos.toml:{line}:1: error: " in text and f"did you mean '{hint}'?" in text
    assert len(err.value.findings) == 3
    from cotwin.twin.assembly.endpoints import check_endpoints
    from cotwin.twin.assembly.system import TwinSystem

    path.write_text(MODELS + '[pt]\nendpoint = "opcau"\nurl = "opc.tcp://h:4840"\n')
    with pytest.raises(CotwinError) as err:
        check_endpoints(TwinSystem(load_project(path)), "pt")
    assert "typos.toml:6:1: error: " in str(err.value) and "did you mean 'opcua'?" in str(err.value)


def test_a_section_the_command_does_not_read_is_a_warning_at_its_table(ur5e):
    """[convergence] in a project `cotwin run` co-simulates (no live twin) is said to be ignored, as are the
    other live-twin and plant sections; `cotwin twin` reads [convergence] and is not warned."""
    path = ur5e / "conv.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + '\n[convergence]\nresync = "on-alarm"\n'
                    '\n[deviation]\nabsolute = 0.1\n')
    spec = load_project(path)
    found = [str(f) for f in spec.ignored_sections("cotwin run")]
    at = path.read_text().splitlines().index("[convergence]") + 1
    assert found[0] == (f"{path}:{at}:1: warning: [convergence] applies only to cotwin twin, cotwin fleet: "
                        "cotwin run ignores it")
    assert len(found) == 2 and "[deviation]" in found[1]
    assert spec.ignored_sections("cotwin twin") == []
    assert load_project(ur5e / "cotwin.toml").ignored_sections("cotwin run") == []


def test_cotwin_run_shows_the_warning_of_a_section_it_ignores(ur5e, tmp_path):
    import subprocess
    import sys

    path = ur5e / "conv.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + '\n[convergence]\nresync = "on-alarm"\n')
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(path), "-o", str(tmp_path / "out"), "--end",
                           "0.2"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    at = path.read_text().splitlines().index("[convergence]") + 1
    assert f"conv.toml:{at}:1: warning: [convergence] applies only to cotwin twin, cotwin fleet: cotwin run ignores it" \
        in proc.stderr


def test_a_pt_log_replays_in_place_of_a_pt_table_of_another_endpoint(ur5e):
    """`cotwin twin twin.toml --pt-log LOG` (and a fleet entry's pt_log) on a project whose [pt] is an OPC UA
    plant: its url was refused as a key 'replay' does not take, though the table is not what runs."""
    spec = load_project(ur5e / "twin.toml", ur5e / "plan.csv")
    assert spec.pt.endpoint == "replay" and spec.pt.log == ur5e / "plan.csv"
    (ur5e / "bad.toml").write_text((ur5e / "twin.toml").read_text().replace('endpoint = "opcua"',
                                                                             'endpoint = "opcua"\nlog = "x.csv"'))
    with pytest.raises(CotwinError, match=r"\[pt\] log does not apply to endpoint 'opcua'"):
        load_project(ur5e / "bad.toml", ur5e / "plan.csv")  # the table as written is still checked


def test_the_checks_against_the_models_report_together(ur5e):
    """A plan naming a misspelt input, [cosim] log naming no variable and a parameter the d-model lacks: one
    error with the three, each at its place (they came one per attempt)."""
    from cotwin.twin.assembly.run import load

    (ur5e / "bad.csv").write_text("timestep,moveDiscreteComand\n1000,true\n")
    path = ur5e / "models.toml"
    path.write_text(MODELS + '[scenario]\nplan = "bad.csv"\n[cosim]\nlog = ["q9"]\nparameters = { seeed = 3 }\n')
    with pytest.raises(CotwinError) as err:
        load(path)
    said = [str(f) for f in err.value.findings]
    assert said[0].startswith(f"{ur5e / 'bad.csv'}:1:10: error: unknown d-model input 'moveDiscreteComand'; "
                              "did you mean 'moveDiscreteCommand'?")
    assert said[1].startswith(f"{path}:8:1: error: [cosim] log: unknown mapping variable(s) q9")
    assert said[2].startswith(f"{path}:9:16: error: [cosim] parameters: the d-model has no parameter 'seeed'")


def test_a_live_twin_without_a_pt_says_how_to_give_one_before_anything_else(ur5e, tmp_path):
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "cotwin", "twin", str(ur5e / "cotwin.toml"), "-o", str(tmp_path / "o"),
                           "--end", "1"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    assert proc.stderr == (f"{ur5e / 'cotwin.toml'}: error: a live twin needs a PT: a [pt] table (endpoint = opcua | "
                           "replay | broker | rtde), or --pt-log LOG (a recorded run) or --pt-url opc.tcp://HOST:PORT "
                           "(an OPC UA plant)\n"
                           "1 error(s), 0 warning(s)\n")  # not after the plan's warnings, nor without the options


def test_a_plan_holding_no_command_is_said_not_taken_for_success(ur5e, tmp_path):
    import subprocess
    import sys

    (ur5e / "empty.csv").write_text((ur5e / "plan.csv").read_text().splitlines()[0] + "\n")
    (ur5e / "empty.toml").write_text((ur5e / "cotwin.toml").read_text().replace("plan.csv", "empty.csv"))
    proc = subprocess.run([sys.executable, "-m", "cotwin", "run", str(ur5e / "empty.toml"), "-o", str(tmp_path / "o"),
                           "--end", "0.2"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert (f"{ur5e / 'empty.csv'}:1:1: warning: the plan holds no command: the d-model runs without commands from "
            "outside") in proc.stderr


PT = '\n[pt]\nendpoint = "opcua"\nurl = "opc.tcp://127.0.0.1:4840"\n'


@pytest.mark.parametrize("command, pt, reader", [
    (("whatif", "--plan", "none.csv"), "", "cotwin whatif"),  # each stops at its first input after the warnings
    (("sweep", "--event", "noSuchEvent", "-o", "answers.csv"), "", "cotwin sweep"),
    (("test", "none.json"), "", "cotwin test"),
    (("test", "none.json", "--pt", "opc.tcp://127.0.0.1:4840"), "", "cotwin test"),
    (("test", "none.json", "--pt"), PT, "cotwin test --pt project"),  # reads [pt]: no warning of it
], ids=["whatif", "sweep", "test", "test --pt URL", "test --pt"])
def test_a_single_robot_command_warns_of_the_convergence_table_it_ignores_as_run_does(ur5e, command, pt, reader):
    """[convergence] steers only a live twin: whatif, sweep and test say at the table, in `cotwin run`'s words
    (TwinProject.ignored_sections), that they ignore it; `cotwin test --pt` reads [pt] and says nothing of it."""
    from conftest import cotwin_in_process

    path = ur5e / "conv.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + pt + '\n[convergence]\nresync = "on-alarm"\n')
    at = path.read_text().splitlines().index("[convergence]") + 1
    proc = cotwin_in_process(command[0], path, *command[1:], cwd=ur5e)
    assert proc.returncode != 0  # the missing plan, event or suite, after the warning
    warnings = [line for line in proc.stderr.splitlines() if ": warning: " in line]
    assert warnings == [f"{path}:{at}:1: warning: [convergence] applies only to cotwin twin, cotwin fleet: {reader} "
                        "ignores it"], proc.stderr
    assert "Traceback" not in proc.stderr


def test_history_is_ignored_by_a_run_without_its_page(ur5e):
    path = ur5e / "hist.toml"
    path.write_text((ur5e / "cotwin.toml").read_text() + '\n[history]\nurl = "sqlite:///h.sqlite"\n')
    spec = load_project(path)
    assert [f.message for f in spec.ignored_sections("cotwin run")] == [
        "[history] applies only to cotwin twin, cotwin fleet, cotwin run --dashboard: cotwin run ignores it"]
    assert spec.ignored_sections("cotwin run --dashboard") == []


def test_a_boolean_written_as_a_number_is_not_called_a_string(ur5e):
    path = ur5e / "b.toml"
    path.write_text(MODELS + "[cosim]\nrealtime = 1\n")
    with pytest.raises(CotwinError) as err:
        load_project(path)
    assert str(err.value) == f"{path}:6:1: error: [cosim] realtime must be true or false (a TOML Boolean), got 1"


def test_a_model_named_by_a_folder_is_said_to_be_one(ur5e):
    path = ur5e / "dir.toml"
    path.write_text(MODELS.replace('"arm.rst"', '"."'))
    with pytest.raises(CotwinError) as err:
        load_project(path)
    assert str(err.value) == f"{path}:2:1: error: [models] dmodel: {ur5e / '.'} is a folder, not a file"


def test_a_projects_errors_come_with_its_models_errors(ur5e):
    """A typo in the project hid the d-model's syntax error until it was fixed: the models are read too when
    the project has errors, and their errors said with the project's."""
    (ur5e / "arm.rst").write_text((ur5e / "arm.rst").read_text().replace("sref stm_ref", "sref stm ref", 1))
    path = ur5e / "both.toml"
    path.write_text(MODELS + '[cosim]\nalgorithm = "jacobii"\n')
    with pytest.raises(CotwinError) as err:
        load_project(path)
    said = [str(f) for f in err.value.findings]
    assert any(s.startswith(f"{ur5e / 'arm.rst'}:") and "unexpected 'stm'" in s for s in said), said
    assert f"{path}:6:1: error: [cosim] algorithm must be one of 'jacobi', 'gauss-seidel', got 'jacobii'; " \
           "did you mean 'jacobi'?" in said
    (ur5e / "plain.toml").write_text(MODELS)
    assert load_project(ur5e / "plain.toml").dmodel == ur5e / "arm.rst"  # no error of its own: models read later
