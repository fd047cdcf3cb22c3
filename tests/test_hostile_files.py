"""Files as a project shipped by someone else may lay them out: links left where outputs go, outputs named
like inputs, inputs of gigabytes or that are not files at all. Each run through the real `cotwin`."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import cotwin_in_process
from cotwin.diagnostics import CotwinError

ROOT = Path(__file__).resolve().parents[1]
UR5E = ROOT / "examples" / "ur5e"


# Where a test is about files written and messages, `cotwin_in_process`; `cotwin`, a process of its own with a
# time limit, where a regression would hang (a FIFO) or exhaust memory (inputs over their cap).
def cotwin(*args, cwd=None, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout)


@pytest.fixture
def project(tmp_path) -> Path:
    """The UR5e example copied, so that a test may put files beside it."""
    folder = tmp_path / "ur5e"
    shutil.copytree(UR5E, folder)
    return folder


def _victims(folder: Path, names: list[str]) -> dict[Path, Path]:
    """For each output name, a link from it (in `folder`) to a file elsewhere holding 'precious'."""
    elsewhere = folder.parent / "elsewhere"
    elsewhere.mkdir(exist_ok=True)
    out = {}
    for name in names:
        victim = elsewhere / name.replace("/", "_")
        victim.write_text("precious")
        link = folder / name
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(victim)
        out[link] = victim
    return out


def test_outputs_replace_links_left_where_they_go_and_never_write_through_them(project, tmp_path):
    out = tmp_path / "out"
    links = _victims(out, ["figure.png", "outputs.csv", "outputs.csv.part", "state", ".cotwin.lock", "build.json"])
    proc = cotwin_in_process("run", project / "cotwin.toml", "-o", out, "--end", "1")
    assert proc.returncode == 0, proc.stderr
    for link, victim in links.items():
        assert victim.read_text() == "precious", link.name  # untouched
        if link.name not in ("outputs.csv.part", ".cotwin.lock"):
            assert link.is_file() and not link.is_symlink(), link.name  # the output itself, in its place
    assert (out / "outputs.csv").read_text().startswith("time,")
    # the live twin's report and figure, and a history export
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.services.history import export_csv
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import LiveTwin

    live = tmp_path / "live"
    links = _victims(live, ["deviation.json", "figure.png", "dt/outputs.csv.part", "pt/outputs.csv", "export.csv"])
    system = load(project / "cotwin.toml")
    pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
    result = LiveTwin(system, live, pt=pt, end=1.0).run()
    export_csv(result.history_url, result.run_id, "dt", live / "export.csv")
    for link, victim in links.items():
        assert victim.read_text() == "precious", link.name
    assert (live / "deviation.json").read_text().startswith("{") and not (live / "deviation.json").is_symlink()
    assert (live / "export.csv").read_text() == (live / "dt" / "outputs.csv").read_text()


def test_a_hard_link_planted_where_a_result_is_written_is_refused_not_truncated(project, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    os.link(victim, out / "outputs.csv.part")
    proc = cotwin_in_process("run", project / "cotwin.toml", "-o", out, "--end", "0.5")
    assert proc.returncode == 1 and "outputs.csv.part" in proc.stderr and "hard links" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and victim.read_text() == "precious"


def test_no_output_replaces_a_file_the_command_reads(project, tmp_path):
    plan = project / "plan.csv"
    before = plan.read_text()
    # a project whose plan sits where the run writes its results
    (project / "out").mkdir()
    shutil.copy(plan, project / "out" / "outputs.csv")
    toml = project / "cotwin.toml"
    toml.write_text(toml.read_text().replace('plan = "plan.csv"', 'plan = "out/outputs.csv"'))
    proc = cotwin_in_process("run", toml, "-o", project / "out", "--end", "1")
    assert proc.returncode == 1 and "would replace" in proc.stderr and "which this command reads" in proc.stderr
    assert (project / "out" / "outputs.csv").read_text() == before and not (project / "out" / "dmodel.fmu").exists()
    toml.write_text(toml.read_text().replace('plan = "out/outputs.csv"', 'plan = "plan.csv"'))
    for args, kept in ((["whatif", toml, "--plan", plan, "--horizon", "1", "-o", plan], plan),
                       (["whatif", toml, "--plan", plan, "--horizon", "1", "-o", project / "arm.rst"], project / "arm.rst"),
                       (["export-pmodel", project / "ur5e.pm", "--format", "urdf", "-o", project / "ur5e.pm"],
                        project / "ur5e.pm"),
                       (["sweep", toml, "--event", "moveDiscreteCommand", "--arg", "target_X=0", "--arg", "target_Y=0",
                         "--arg", "target_Z=0", "-o", toml], toml)):
        text = kept.read_text()
        proc = cotwin_in_process(*args)
        assert proc.returncode == 1 and "would replace" in proc.stderr and "Traceback" not in proc.stderr, (args, proc.stderr)
        assert proc.stderr.count("would replace") == 1, proc.stderr  # the project's plan given as --plan: said once
        assert kept.read_text() == text
    # a fit never replaces the calibration it starts from
    log = tmp_path / "log.csv"
    log.write_text("timestamp\n")
    calibration = (project / "calibration.toml").read_text()
    proc = cotwin_in_process("calibrate", project / "calibrated.toml", "--pt-log", log, "-o", project / "calibration.toml")
    assert proc.returncode == 1 and "calibration.toml" in proc.stderr and "which this command reads" in proc.stderr
    assert (project / "calibration.toml").read_text() == calibration
    # history export onto the store it reads
    from cotwin.twin.services.history import HistoryRecorder

    store = tmp_path / "history.sqlite"
    recorder = HistoryRecorder(f"sqlite:///{store}", "p.toml", "twin", 0.1, "jacobi", {"dt": ["{mapping}.mapping.q0"]})
    recorder.record_sample("dt", 0, 0.0, [0.5])
    recorder.close()
    stored = store.read_bytes()
    for target in (store, tmp_path / "." / "history.sqlite"):
        proc = cotwin_in_process("history", "export", "1", "--dir", tmp_path, "-o", target)
        assert proc.returncode == 1 and "which this command reads" in proc.stderr, proc.stderr
    assert store.read_bytes() == stored
    proc = cotwin_in_process("history", "export", "1", "--dir", tmp_path, "-o", tmp_path / "run1.csv")
    assert proc.returncode == 0 and (tmp_path / "run1.csv").read_text() == "time,{mapping}.mapping.q0\n0.0,0.5\n"


def test_an_output_named_like_a_model_in_a_folder_given_as_models_is_refused(project, tmp_path):
    """`export-pmodel models -o models/arm.pm` wrote the URDF over the p-model it had just read (exit 0)."""
    models = tmp_path / "models"
    models.mkdir()
    for name in ("ur5e.pm", "arm.rst"):
        shutil.copy(project / name, models / name)
    for args, kept in ((["export-pmodel", models, "--format", "urdf", "-o", models / "ur5e.pm"], models / "ur5e.pm"),
                       (["build-dmodel", models, "-o", models / "arm.rst"], models / "arm.rst")):
        text = kept.read_text()
        proc = cotwin_in_process(*args)
        assert proc.returncode == 1 and "would replace" in proc.stderr and "Traceback" not in proc.stderr, (args, proc.stderr)
        assert proc.stderr.count("would replace") == 1, proc.stderr
        assert kept.read_text() == text


def test_an_output_that_is_a_device_or_a_fifo_is_refused_not_replaced(project, tmp_path):
    """`simulate -o /dev/null` run as root renamed the CSV over the device: /dev/null became a file. A FIFO
    stands in for the device here (replaced alike, by anyone)."""
    from cotwin.files import write_text

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    proc = cotwin_in_process("export-pmodel", project / "ur5e.pm", "--format", "urdf", "-o", fifo)
    assert proc.returncode == 2 and "is a FIFO, not a file" in proc.stderr, proc.stderr
    with pytest.raises(CotwinError, match="is a FIFO, not a file"):
        write_text(fifo, "x")
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / "outputs.csv")
    proc = cotwin_in_process("run", project / "cotwin.toml", "-o", out, "--end", "0.5")
    assert proc.returncode == 1 and "is a FIFO, not a file" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert fifo.is_fifo() and (out / "outputs.csv").is_fifo()


def _sparse(path: Path, size: int = 8 << 30) -> Path:
    with open(path, "wb") as f:
        f.truncate(size)  # no disk used: a hole of 8 GiB
    return path


def test_inputs_over_their_cap_are_located_errors_not_memory_errors(project, tmp_path):
    big = _sparse(tmp_path / "big.rst")
    proc = cotwin("check", big, timeout=60)
    assert proc.returncode == 1 and f"{big}:1:1: error: the file is 8192 MiB, over the 16 MiB cotwin reads" in proc.stderr
    toml = project / "cotwin.toml"
    original = toml.read_text()
    for key, name in (('dmodel = "arm.rst"', "dmodel = \"{}\""), ('plan = "plan.csv"', "plan = \"{}\"")):
        toml.write_text(original.replace(key, name.format(big)))
        proc = cotwin("run", toml, "-o", tmp_path / "out", timeout=60)
        assert proc.returncode == 1 and f"{big}:1:1: error:" in proc.stderr and "MiB cotwin reads" in proc.stderr, \
            proc.stderr
        assert "internal error" not in proc.stderr and "MemoryError" not in proc.stderr
    toml.write_text(original.replace('[platform]\nendpoint = "mujoco"',
                                     f'[platform]\nendpoint = "mujoco"\ncalibration = "{_sparse(tmp_path / "c.toml")}"'))
    proc = cotwin("run", toml, "-o", tmp_path / "out", timeout=60)
    assert proc.returncode == 1 and "c.toml:1:1: error: the calibration file is 8192 MiB" in proc.stderr, proc.stderr
    for args, where in ((["run", _sparse(tmp_path / "p.toml"), "-o", tmp_path / "out"], "p.toml:1:1: error: the project"),
                        (["simulate", _sparse(tmp_path / "mm.json")], "mm.json:1:1: error: the multimodel is 8192 MiB"),
                        (["twin", UR5E / "replay.toml", "-o", tmp_path / "out", "--pt-log", _sparse(tmp_path / "log.csv")],
                         "log.csv:1:1: error: the log is 8192 MiB"),
                        (["whatif", UR5E / "cotwin.toml", "--plan", _sparse(tmp_path / "plan.json"), "-o",
                          tmp_path / "p.json"], "the plan is 8192 MiB")):
        proc = cotwin(*args, timeout=60)
        assert proc.returncode in (1, 2) and where in proc.stderr and "internal error" not in proc.stderr, (args, proc.stderr)


def test_an_input_that_is_not_a_file_is_refused_at_once(project, tmp_path):
    fifo = tmp_path / "model.rst"
    os.mkfifo(fifo)  # opening it to read would wait for a writer for ever
    started = time.monotonic()
    proc = cotwin("check", fifo, timeout=60)
    assert proc.returncode == 1 and "not a regular file" in proc.stderr and time.monotonic() - started < 30
    toml = tmp_path / "project.toml"
    os.mkfifo(toml)
    proc = cotwin("run", toml, "-o", tmp_path / "out", timeout=60)
    assert proc.returncode == 1 and f"{toml}:1:1: error: cannot read project file: not a regular file" in proc.stderr
    from cotwin import files

    with pytest.raises(CotwinError, match="not a regular file"):
        files.read_text("/dev/zero", "model")


def test_an_output_folder_that_is_a_file_and_an_output_file_that_is_a_folder_are_refused_up_front(project, tmp_path):
    """-o naming a file where a folder is written (or a folder where a file is) said 'File exists: afile' or
    named a temporary '.x.part' file, after the work was done; now the option is refused before any."""
    (tmp_path / "afile").write_text("precious")
    for args, said in ((("run", project / "cotwin.toml", "-o", tmp_path / "afile"), "afile: is a file, not a folder"),
                       (("build", project / "cotwin.toml", "-o", tmp_path / "afile" / "x"),
                        "would be made inside " + str(tmp_path / "afile") + ", a file"),
                       (("build-dmodel", project / "arm.rst", "-o", tmp_path), "is a folder: name the file to write")):
        proc = cotwin_in_process(*args)
        assert proc.returncode == 2 and said in proc.stderr and "Invalid value for -o/--output" in proc.stderr, \
            proc.stderr
    assert (tmp_path / "afile").read_text() == "precious"
    from cotwin.files import write_text

    with pytest.raises(CotwinError, match="is a folder: cannot write a file there"):
        write_text(tmp_path, "x")


def test_an_output_whose_name_is_not_utf8_or_is_cut_inside_a_character_is_written(tmp_path):
    """Linux names are bytes: one that is not UTF-8 (spelled with surrogates) failed with UnicodeEncodeError,
    a traceback, since the temporary name beside it was cut to 200 bytes; a 255-byte name of 2-byte
    characters is cut inside one."""
    from cotwin.files import write_text

    for name in (os.fsdecode(b"\xffplan.json"), "\u00e9" * 125 + ".json", "a" + "\u00e9" * 124 + "b.json"):
        write_text(tmp_path / name, "{}\n")
        assert (tmp_path / name).read_text() == "{}\n"
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".part")]


def test_a_file_written_into_a_folder_a_run_holds_is_refused_naming_the_run(tmp_path):
    """`cotwin whatif -o DIR/state` (or a sweep's -o DIR/outputs.csv) while `cotwin run -o DIR` ran: the what-if said
    its answer was written, and the run's own file of that name replaced it at the end (found by the hostile probe).
    An output file in a folder another run holds is refused before anything runs; once the run is over, it is not."""
    from cotwin.twin.assembly.build import folder_lock

    out = tmp_path / "run"
    with folder_lock(out):
        proc = cotwin_in_process("whatif", UR5E / "cotwin.toml", "--plan", UR5E / "plan.csv", "-o", out / "state")
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert (f"{out / 'state'}: {out} is in use by another cotwin run (pid {os.getpid()}), which writes its files "
                "there") in proc.stderr
        assert not (out / "state").exists()
    proc = cotwin_in_process("whatif", UR5E / "cotwin.toml", "--plan", UR5E / "plan.csv", "-o", out / "state")
    assert proc.returncode == 0 and (out / "state").read_text().startswith("{"), proc.stderr


def test_an_output_on_a_read_only_file_system_says_so(tmp_path, monkeypatch):
    """-o into a read-only mount said 'no permission', which sent root to chmod in vain (found by the hostile probe
    on a tmpfs mounted ro); it says the file system is read-only, and 'no permission' where that is why."""
    real_access, real_statvfs = os.access, os.statvfs

    class ReadOnly:
        f_flag = os.ST_RDONLY

    monkeypatch.setattr(os, "access", lambda path, mode, **kw: False if Path(path) == tmp_path else real_access(path, mode, **kw))
    monkeypatch.setattr(os, "statvfs", lambda path: ReadOnly() if Path(path) == tmp_path else real_statvfs(path))
    for args in (["whatif", UR5E / "cotwin.toml", "--plan", UR5E / "plan.csv", "-o", tmp_path / "w.json"],
                 ["run", UR5E / "cotwin.toml", "-o", tmp_path / "run"]):
        proc = cotwin_in_process(*args)
        assert proc.returncode == 2 and f"cannot write into {tmp_path} (a read-only file system)" in proc.stderr, proc.stderr
    monkeypatch.setattr(os, "statvfs", real_statvfs)
    proc = cotwin_in_process("run", UR5E / "cotwin.toml", "-o", tmp_path / "run")
    assert proc.returncode == 2 and f"cannot write into {tmp_path} (no permission)" in proc.stderr, proc.stderr


def test_a_planted_build_record_removes_no_file_the_build_did_not_write(tmp_path):
    """build.json's 'written' list named the files a rebuild removes: a planted or edited one had `cotwin build`
    delete the user's own files in the folder. Now only a file recorded with the digest of what is there is removed
    (a stale artefact of an earlier build); others are kept, each named in a warning at build.json."""
    import hashlib
    import json

    out = tmp_path / "b"
    assert cotwin_in_process("build", UR5E / "cotwin.toml", "-o", out, cwd=tmp_path).returncode == 0
    (out / "mynotes.txt").write_text("mine\n")
    (out / "theirs.txt").write_text("also mine\n")
    (out / "old.sdf").write_text("an artefact an earlier build wrote\n")
    record = json.loads((out / "build.json").read_text())
    planted = {**record, "written": ["mynotes.txt"]}  # names alone, as cotwin recorded them before digests
    (out / "build.json").write_text(json.dumps(planted))
    first = cotwin_in_process("build", UR5E / "cotwin.toml", "-o", out, cwd=tmp_path)
    assert first.returncode == 0 and (out / "mynotes.txt").exists(), first.stderr
    record = json.loads((out / "build.json").read_text())
    record["written"] = {**record["written"], "mynotes.txt": None, "theirs.txt": "0" * 64,
                         "old.sdf": hashlib.sha256((out / "old.sdf").read_bytes()).hexdigest()}
    (out / "build.json").write_text(json.dumps(record))
    again = cotwin_in_process("build", UR5E / "cotwin.toml", "-o", out, cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert (out / "mynotes.txt").read_text() == "mine\n" and (out / "theirs.txt").exists()
    assert not (out / "old.sdf").exists()  # what a build wrote is still cleaned up
    for name in ("mynotes.txt", "theirs.txt"):
        assert f"build.json: warning: 'written' names '{name}'" in again.stderr, again.stderr


def test_a_reused_artefact_edited_since_is_recorded_as_cotwin_wrote_it_and_not_removed(tmp_path):
    """build.json's digests were read back from the files after every build: a reused FMU the user had replaced
    since was recorded with the digest of the user's file, and a later build that no longer wrote it removed the
    user's file. A digest is now that of what cotwin wrote (known, not read back), so that file is kept; a
    digests entry planted or of another key is not believed."""
    import hashlib
    import json

    from cotwin.twin.assembly.build import Record, build
    from cotwin.twin.assembly.run import load

    def sha(path: Path) -> str:
        return hashlib.sha256(path.read_bytes()).hexdigest()

    out, system = tmp_path / "b", load(str(UR5E / "cotwin.toml"), cells=True)
    written = build(system, out)
    ours = sha(out / "mapping.fmu")
    (out / "mapping.fmu").write_bytes(b"the user's own\n")  # same key: the next build reuses it
    build(system, out)
    record = json.loads((out / "build.json").read_text())
    assert record["written"]["mapping.fmu"] == ours
    assert all(digest == sha(out / name) for name, digest in record["written"].items() if name != "mapping.fmu")
    warned = []
    gone = Record(out).settle([path for role, path in written.items() if role != "mapping"], warned.append)
    assert gone == [] and (out / "mapping.fmu").read_bytes() == b"the user's own\n"
    assert [f.location.path for f in warned] == [str(out / "build.json")] and "'mapping.fmu'" in warned[0].message

    record = json.loads((out / "build.json").read_text())
    record["digests"] = {"controller.fmu": {"key": "another", "sha256": "0" * 64}, "dmodel.fmu": "junk"}
    (out / "build.json").write_text(json.dumps(record))
    build(system, out)
    record = json.loads((out / "build.json").read_text())
    assert record["written"]["controller.fmu"] == sha(out / "controller.fmu")
    assert record["written"]["dmodel.fmu"] == sha(out / "dmodel.fmu")


def test_the_files_a_build_keeps_are_warnings_counted_in_its_closing_line(tmp_path):
    """Record.settle's warnings (a file build.json names that the build keeps) were shown outside any count; they
    go through the command's counted warnings now, and `cotwin build` closes with the count as `cotwin run` does."""
    import json

    out = tmp_path / "b"
    first = cotwin_in_process("build", UR5E / "cotwin.toml", "-o", out, cwd=tmp_path)
    assert first.returncode == 0 and first.stderr.strip().splitlines()[-1] == "0 error(s), 0 warning(s)", first.stderr
    (out / "mynotes.txt").write_text("mine\n")
    record = json.loads((out / "build.json").read_text())
    record["written"] = {**record["written"], "mynotes.txt": None}  # no digest: not proof a build wrote it
    (out / "build.json").write_text(json.dumps(record))
    again = cotwin_in_process("build", UR5E / "cotwin.toml", "-o", out, cwd=tmp_path)
    assert again.returncode == 0 and (out / "mynotes.txt").exists(), again.stderr
    assert "build.json: warning: 'written' names 'mynotes.txt'" in again.stderr, again.stderr
    assert again.stderr.strip().splitlines()[-1] == "0 error(s), 1 warning(s)", again.stderr
