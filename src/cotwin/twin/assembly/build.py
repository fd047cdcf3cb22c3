"""The artefacts of a twin project, built into an output folder and kept only while still valid.

Every artefact is content-addressed: `DIR/build.json` records, per file, a key made from what it was
built from (the model texts, the options, cotwin's version and generator sources); a file whose key
differs, or that is missing, is rebuilt. Files are written under a temporary name and renamed into
place, and the record is written after the file, so a build killed midway is redone next time.
A folder is used by one run at a time (`folder_lock`).
"""

from __future__ import annotations

import fcntl
import hashlib
import io
import json
import os
import re
import shutil
import tempfile
import uuid
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable

from ... import __version__
from ...diagnostics import CotwinError, Finding, Location, Severity
from ...files import check_outputs, open_exclusive, write_bytes, write_text
from .system import TwinSystem

RECORD = "build.json"
WRITTEN = "written"  # build.json's files the last `build` wrote, name -> digest of what it wrote (no artefact has that name)
DIGESTS = "digests"  # build.json's digest of each keyed artefact as written, name -> {key, sha256}: a reused one is not read
ARTEFACTS = ("dmodel.fmu", RECORD)  # and build()'s: the p-model files, the Python FMUs, multimodel.json
_GENERATORS = ("dmodel/ccode.py", "dmodel/fmu.py", "dmodel/fmi2_wrapper.c", "dmodel/ports.py", "dmodel/program.py",
               "dmodel/interpreter.py")


@contextmanager
def folder_lock(folder: Path, writes: Iterable[str | Path] = (), reads: Iterable[Path] = ()):
    """Hold DIR/.cotwin.lock for the duration; another run into the same folder is refused, and so is one
    that would write a file of `writes` (names in DIR, or paths) over one it reads (`reads`)."""
    folder = Path(folder)
    check_outputs([folder / name for name in writes], reads)
    fd = open_exclusive(folder / ".cotwin.lock")
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "another process"
            raise CotwinError(f"{folder} is in use by another cotwin run ({holder}); choose another output folder "
                              "or wait for it to finish") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}".encode(), 0)
        yield
    finally:
        os.close(fd)


def folder_holder(folder: str | Path) -> str | None:
    """Who holds `folder` now (`folder_lock`: 'pid N'), or None when no cotwin run does or it cannot be told; a file
    written into a folder a run holds was replaced by the run's own of that name, the command having said it was
    written. (The lock is taken shared for an instant: a run starting in that instant is refused as in use.)"""
    try:
        fd = os.open(Path(folder) / ".cotwin.lock", os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return os.pread(fd, 64, 0).decode(errors="replace").strip() or "another process"
    except OSError:
        return None
    finally:
        os.close(fd)
    return None


def _digest(*parts: bytes | str) -> str:
    h = hashlib.sha256()
    for part in parts:
        data = part.encode() if isinstance(part, str) else part
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return h.hexdigest()


def _sources(program, root: Path, fmi: int, generate) -> dict[str, str]:
    """The d-model FMU's generated sources, generated once per program object (a Program is not changed once
    built; what-if forks and sweeps share their twin's): the check that an FMU is up to date costed a C
    generation per what-if."""
    from ...memo import once_per

    return once_per(program, ("sources", str(root), fmi), lambda: generate(program, root))


def _cotwin_sources(names=_GENERATORS) -> list[bytes]:
    root = Path(__file__).resolve().parents[1]
    return [(root / n).read_bytes() for n in names if (root / n).is_file()]


class Record:
    """DIR/build.json: artefact name -> the key it was built with; and the digests of what this process wrote
    (`write`) and of each keyed artefact as written, so that `settle` records them without reading files back."""

    def __init__(self, folder: Path):
        self.path = folder / RECORD
        self.known: dict[str, str] = {}  # name -> sha256 of the bytes `write` put there in this process
        try:
            self.keys = json.loads(self.path.read_text()) if self.path.is_file() else {}
            if not isinstance(self.keys, dict):
                self.keys = {}
        except (OSError, ValueError):
            self.keys = {}

    def fresh(self, target: Path, key: str) -> bool:
        return target.is_file() and self.keys.get(target.name) == key

    def write(self, target: Path, data: bytes) -> Path:
        """`data` written to `target` (cotwin.files.write_bytes), its digest kept for `done` and `settle`."""
        write_bytes(target, data)
        self.known[target.name] = hashlib.sha256(data).hexdigest()
        return target

    def done(self, target: Path, key: str) -> None:
        """`target` built with `key`; its digest recorded with the key when this process `write`s it."""
        self.keys[target.name] = key
        digests = self.keys.get(DIGESTS)
        digests = self.keys[DIGESTS] = digests if isinstance(digests, dict) else {}
        if target.name in self.known:
            digests[target.name] = {"key": key, "sha256": self.known[target.name]}
        else:
            digests.pop(target.name, None)
        write_text(self.path, json.dumps(self.keys, indent=1, sort_keys=True) + "\n")

    def forget(self, target: Path) -> None:
        self.keys.pop(target.name, None)
        self.known.pop(target.name, None)
        if isinstance(self.keys.get(DIGESTS), dict):
            self.keys[DIGESTS].pop(target.name, None)

    def digest(self, name: str) -> str | None:
        """The SHA-256 of what cotwin wrote as `name` here: written by this process, or recorded by `done` with the
        key the artefact still has (it was reused); else that of the file as it is now (None: none there)."""
        if name in self.known:
            return self.known[name]
        digests, key = self.keys.get(DIGESTS), self.keys.get(name)
        entry = digests.get(name) if isinstance(digests, dict) else None
        if isinstance(entry, dict) and isinstance(key, str) and entry.get("key") == key and isinstance(entry.get("sha256"), str):
            return entry["sha256"]
        return _file_digest(self.path.parent / name)

    def settle(self, written, warn: Callable[[Finding], None] | None = None) -> list[Path]:
        """Remove the files an earlier build wrote here that this one did not (a robot no longer in the cell,
        a p-model renamed), and remember what this one wrote, with the digest of what it wrote (`digest`: known, not
        read back, so an artefact reused here and since edited is not taken for cotwin's); only files a build wrote
        are ever removed: a name of this folder recorded with the digest of what is there now. Any other name
        (a build.json planted or edited, or from a cotwin that recorded no digests) is kept and `warn`ed of
        (default: the cotwin.twin logger). Returns those removed."""
        names = sorted({Path(p).name for p in written} | {RECORD})
        before = self.keys.get(WRITTEN, {})
        if isinstance(before, list):  # an older record: names without digests, not proof that a build wrote them
            before = {name: None for name in before}
        folder, gone = self.path.parent, []
        for name, digest in before.items() if isinstance(before, dict) else []:
            if not isinstance(name, str) or name in names:
                continue
            path = folder / name if name == Path(name).name and name not in ("", ".", "..") else None
            if path is not None and not (path.is_file() or path.is_symlink()):
                continue  # gone already: nothing to remove
            if path is not None and path.is_file() and not path.is_symlink() and digest == _file_digest(path):
                path.unlink()
                gone.append(path)
                self.forget(path)
                continue
            why = ("not a file of this folder" if path is None else
                   "not a file this build wrote here (its content is not what cotwin wrote, or no digest is recorded)")
            (warn or _log_warning)(Finding(Location(str(self.path), 0, 0), Severity.WARNING,
                                           f"{WRITTEN!r} names {name!r}, {why}: kept, not removed"))
        self.keys[WRITTEN] = {name: self.digest(name) for name in names if name != RECORD}
        write_text(self.path, json.dumps(self.keys, indent=1, sort_keys=True) + "\n")
        return gone


def _file_digest(path: Path) -> str | None:
    """The SHA-256 of a regular file's content (None: not one, or unreadable)."""
    try:
        if path.is_symlink() or not path.is_file():
            return None
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _log_warning(finding: Finding) -> None:
    import logging

    logging.getLogger("cotwin.twin").warning(str(finding))


def dmodel_fmu(system: TwinSystem, folder: str | Path, cc: str = "cc", record: Record | None = None,
               fmi: int = 2) -> Path:
    """DIR/dmodel.fmu (FMI 2.0) or DIR/dmodel3.fmu (FMI 3.0, the cycle a clock), rebuilt only when its sources
    (the models, the module, where the model files lie in the project), the compiler or cotwin changed; a
    copy of [models] fmu when the project names one."""
    from ...dmodel.fmu import fmu_archive, fmu_sources, model_identifier

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    record = record or Record(folder)
    target = folder / ("dmodel.fmu" if fmi == 2 else "dmodel3.fmu")
    if system.spec.fmu is not None:  # built elsewhere ([models] fmu): copied, as the multimodel names it
        if fmi != 2:
            raise CotwinError(f"{system.spec.path}: [models] fmu names a d-model FMU built elsewhere; --fmi 3 builds "
                              "cotwin's own from the models")
        given = system.spec.fmu.read_bytes()
        key = _digest("given", given)
        if not record.fresh(target, key):
            record.forget(target)
            record.write(target, given)  # a new file renamed into place: never through a link left there
            record.done(target, key)
        return target
    root = system.spec.path.parent
    program = system.models.program
    if fmi == 2:
        sources, generators, platform = _sources(program, root, 2, fmu_sources), _cotwin_sources(), "linux64"
    else:
        from ...dmodel.fmi3 import PLATFORM, fmu3_sources

        sources = _sources(program, root, 3, lambda program, root: fmu3_sources(program, root=root))
        generators = _cotwin_sources((*_GENERATORS, "dmodel/fmi3.py", "dmodel/fmi3_wrapper.c"))
        platform = PLATFORM
    key = _digest(__version__, *(part for name in sorted(sources) for part in (name, sources[name])), cc, *generators)
    if not record.fresh(target, key):
        record.forget(target)
        # the sources generated above, compiled (dmodel.fmu.build_fmu and fmi3.build_fmu3 generate them again)
        record.write(target, fmu_archive(sources, model_identifier(program), cc, platform))
        record.done(target, key)
    return target


def build(system: TwinSystem, out: str | Path, cc: str = "cc",
          warn: Callable[[Finding], None] | None = None) -> dict[str, Path]:
    """Every artefact: the d-model FMU, SDF/URDF/MJCF, the Python FMUs and multimodel.json; `warn` is told of
    files build.json names that this build keeps (Record.settle)."""
    from ...pmodel.mjcf import to_mjcf
    from ...pmodel.sdf import to_sdf
    from ...pmodel.urdf import to_urdf

    out = Path(out)
    if system.spec.robots:
        return build_cell(system, out, cc, warn)
    tree, scene = system.models.tree, system.models.scene
    check_outputs([out / name for name in (*ARTEFACTS, f"{tree.name}.sdf", f"{tree.name}.urdf", f"{tree.name}_scene.xml",
                                           "multimodel.json", *(u.fmu for u in system.units))], system.spec.inputs)
    out.mkdir(parents=True, exist_ok=True)
    record = Record(out)
    written = {"dmodel": dmodel_fmu(system, out, cc, record)}
    for name, text in ((f"{tree.name}.sdf", to_sdf(tree)), (f"{tree.name}.urdf", to_urdf(tree)),
                       (f"{tree.name}_scene.xml", to_mjcf(tree, scene, base=system.spec.base))):
        written[name] = record.write(out / name, text.encode("utf-8"))
    written.update(python_fmus(system, out, record))
    written["multimodel"] = record.write(out / "multimodel.json", (json.dumps(system.multimodel(), indent=2) + "\n").encode())
    record.settle(written.values(), warn)
    return written


def build_cell(cell, out: Path, cc: str = "cc", warn: Callable[[Finding], None] | None = None) -> dict[str, Path]:
    """Every artefact of a cell of several robots (cotwin.twin.assembly.cell): the d-model FMU (one file, an instance
    per robot), each robot's SDF and URDF, the cell's world as MJCF, the Python FMUs and multimodel.json."""
    trees = [r.system.models.tree for r in cell.robots]
    names = [*(f"{r.name}.{kind}" for r in cell.robots for kind in ("sdf", "urdf")), "cell_scene.xml"]
    check_outputs([out / name for name in (*ARTEFACTS, *names, "multimodel.json", *(u.fmu for u in cell.units))],
                  cell.spec.inputs)
    out.mkdir(parents=True, exist_ok=True)
    record = Record(out)
    written = {"dmodel": dmodel_fmu(cell.robots[0].system, out, cc, record)}
    from ...pmodel.sdf import to_sdf
    from ...pmodel.urdf import to_urdf

    for robot, tree in zip(cell.robots, trees):
        written[f"{robot.name}.sdf"] = record.write(out / f"{robot.name}.sdf", to_sdf(tree).encode("utf-8"))
        written[f"{robot.name}.urdf"] = record.write(out / f"{robot.name}.urdf", to_urdf(tree).encode("utf-8"))
    written["cell_scene.xml"] = record.write(out / "cell_scene.xml", cell.world().xml.encode("utf-8"))
    written.update(python_fmus(cell, out, record))
    written["multimodel"] = record.write(out / "multimodel.json",
                                         (json.dumps(cell.multimodel(), indent=2) + "\n").encode())
    record.settle(written.values(), warn)
    return written


STAGED_SECTIONS = ("models", "robots", "scenario", "platform", "scene", "monitor", "cosim", "world")  # the FMUs read


def staged_project(system: TwinSystem, stage: Path) -> None:
    """A copy of the project's models and settings in `stage`, as the Python FMUs carry it: the
    platform endpoint and the command source included, so the FMUs drive the same robot."""
    spec = system.spec
    stage.mkdir(parents=True, exist_ok=True)
    names: dict[Path, str] = {}

    def copy(path: Path | None) -> str | None:
        if path is None:
            return None
        if path not in names:
            name = path.name if path.name not in names.values() else f"{len(names)}_{path.name}"
            shutil.copy(path, stage / name)
            names[path] = name
        return names[path]

    staged = spec.with_overrides(models_fmu=None, platform_world=None, world=spec.world.table if spec.world else None)
    text = staged.to_toml(STAGED_SECTIONS, rebase=lambda path: copy(path) if path.is_file() else None)
    (stage / "cotwin.toml").write_text(text)
    trees = [r.system.models.tree for r in system.robots] if spec.robots else [system.models.tree]
    for mesh in (m for tree in trees for m in mesh_files(tree)):  # the p-model names them relative to itself
        written = Path(mesh.written)
        if not written.is_absolute() and ".." not in written.parts:
            (stage / written).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(mesh.mesh, stage / written)


def mesh_files(tree) -> list:
    """The geoms of a kinematic tree that come from mesh files cotwin read (one per file)."""
    seen: dict[str, object] = {}
    for link in tree.links:
        for g in link.geoms:
            if g.kind == "mesh" and g.mesh and g.written:
                seen.setdefault(g.mesh, g)
    return list(seen.values())


def python_fmus(system: TwinSystem, out: str | Path, record: Record | None = None) -> dict[str, Path]:
    """The mapping and the command source as FMUs (one generic pythonfmu slave; they need cotwin installed
    where they run), so the multimodel runs in Maestro or any FMI importer."""
    from pythonfmu import FmuBuilder

    out = Path(out)
    record = record or Record(out)
    roles = list({u.fmu: u for u in system.units if u.role != "dmodel"}.values())  # a cell's: one FMU per kind
    written = {}
    with tempfile.TemporaryDirectory(prefix="cotwin-pyfmu-") as tmp:
        stage = Path(tmp) / "twin"
        staged_project(system, stage)
        staged = [p.read_bytes() for p in sorted(stage.rglob("*")) if p.is_file()]
        script = Path(__file__).parent / "fmu_slave.py"
        base_key = _digest(__version__, script.read_bytes(), *staged,
                           *_cotwin_sources(("mapping/runtime.py", "twin/mapping_unit.py", "twin/rabbitmq.py",
                                             "twin/cell.py", "pmodel/shared.py")))
        for unit in roles:
            role = Path(unit.fmu).stem  # mapping, controller, rabbitmq: a twin's instance, a cell's kind
            target = out / unit.fmu
            key = _digest(base_key, role)
            written[role] = target
            if record.fresh(target, key):
                continue
            record.forget(target)
            work = Path(tmp) / role
            work.mkdir()
            shutil.copy(script, work / "fmu_slave.py")
            shutil.copytree(stage, work / "twin")
            (work / "cotwin_unit.json").write_text(json.dumps({"role": role, "project": "twin/cotwin.toml"}))
            fmu = FmuBuilder.build_FMU(work / "fmu_slave.py", dest=work,
                                       project_files=[work / "twin", work / "cotwin_unit.json"],
                                       canGetAndSetFMUstate=True, canSerializeFMUstate=True)
            archive = io.BytesIO()
            reproducible_fmu(Path(fmu), archive)
            record.write(target, archive.getvalue())  # a new file renamed into place: never through a link left there
            record.done(target, key)
    return written


_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def reproducible_fmu(fmu: Path, into) -> None:
    """`fmu` (a pythonfmu build) rewritten into `into` (a path or a binary file) so that the same sources give the same bytes wherever
    and whenever it is built: entries in name order with a fixed date and modes, no generation date, and
    a GUID that is a digest of the content (pythonfmu draws a time-based one); its generationTool says
    cotwin built it (with pythonfmu), so that it runs in the master's process by default."""
    with zipfile.ZipFile(fmu) as zf:
        files = {info.filename: zf.read(info) for info in zf.infolist() if not info.is_dir()}
    description = files["modelDescription.xml"].decode("utf-8")
    description = re.sub(r'\s+generationDateAndTime="[^"]*"', "", description, count=1)
    description = re.sub(r'\bgenerationTool="([^"]*)"', r'generationTool="cotwin (\1)"', description, count=1)
    description = re.sub(r'\bguid="[^"]*"', 'guid="@GUID@"', description, count=1)
    files["modelDescription.xml"] = description.encode("utf-8")
    guid = str(uuid.UUID(_digest(*(part for name in sorted(files) for part in (name, files[name])))[:32]))
    files["modelDescription.xml"] = description.replace("@GUID@", guid).encode("utf-8")
    with zipfile.ZipFile(into, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(files):
            info = zipfile.ZipInfo(name, date_time=_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
            zf.writestr(info, files[name])
