"""Package a module as an FMI 2.0 co-simulation FMU: modelDescription.xml, C sources, linux64 binary.

The sources are the module's cycle (model.c/model.h, cotwin.dmodel.ccode), its ports as tables
(ports.h, from cotwin.dmodel.ports) and the FMI interface, which is the same for every module
(fmi2_wrapper.c in this package, shipped as sources/fmi2.c). The FMU can get, set and serialise its
state (canGetAndSetFMUstate, canSerializeFMUstate).

Ports (docs/interop.md): an input event is a Boolean input true in the step it occurs, plus one
input per value field; an operation call is a Boolean output plus its arguments; output events
likewise; `state` is the index of the active leaf state. Constants without a value are parameters.
`cycle_period` (s, 0 = one cycle per step) makes a step of size h run round(h / cycle_period)
cycles, the input events present in the first only (one occurrence is taken once); an output flag is
then true if it occurred in any of them, with the values of the last occurrence; an output raised in
two cycles of one step (two occurrences one step cannot carry) is logged once as an fmi2Warning.
"""

from __future__ import annotations

import hashlib
import io
import re
import shlex
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import escape

import fmpy

from .. import __version__
from ..cache import bound, touch
from ..diagnostics import CotwinError
from ..files import Reserved, cache_dir
from . import cnames
from .ccode import generate_c
from .ports import SLOT_ARRAY, PortLayout, Variable
from .program import Program

WRAPPER = Path(__file__).with_name("fmi2_wrapper.c")  # the FMI 2.0 interface, the same for every module
_FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def _start_text(var: Variable) -> str:
    if var.start is None:
        return ""
    if var.fmi_type == "Boolean":
        return f' start="{"true" if var.start else "false"}"'
    if var.fmi_type == "Real":
        return f' start="{float(var.start)!r}"'
    return f' start="{int(var.start)}"'


def _field(path: tuple[str, ...]) -> str:
    return cnames.field_path(path)


def model_identifier(program: Program) -> str:
    return re.sub(r"\W", "_", program.module.name)


def model_description(program: Program, layout: PortLayout, guid: str) -> str:
    ident = model_identifier(program)
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<fmiModelDescription fmiVersion="2.0"',
        f'  modelName="{escape(program.module.name)}"',
        f'  guid="{{{guid}}}"',
        f'  description="RoboSim d-model module {escape(program.module.name)}, one cycle per step by default"',
        '  generationTool="cotwin"',
        '  variableNamingConvention="flat"',
        '  numberOfEventIndicators="0">',
        f'  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"'
        ' canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="true"'
        ' canSerializeFMUstate="true"/>',
        '  <DefaultExperiment startTime="0.0" stepSize="1.0"/>',
        "  <ModelVariables>",
    ]
    for var in layout.variables:
        desc = f' description="{escape(var.description, {chr(34): "&quot;"})}"' if var.description else ""
        initial = ' initial="exact"' if var.causality == "parameter" else ""
        lines.append(f'    <ScalarVariable name="{escape(var.name)}" valueReference="{var.vr}" '
                     f'causality="{var.causality}" variability="{var.variability}"{initial}{desc}>')
        lines.append(f"      <{var.fmi_type}{_start_text(var)}/>")
        lines.append("    </ScalarVariable>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    outputs = [v for v in layout.variables if v.causality == "output"]
    lines.append("    <Outputs>")
    lines.extend(f'      <Unknown index="{v.vr + 1}" dependencies=""/>' for v in outputs)
    lines.append("    </Outputs>")
    lines.append("    <InitialUnknowns>")
    lines.extend(f'      <Unknown index="{v.vr + 1}" dependencies=""/>' for v in outputs)
    lines.append("    </InitialUnknowns>")
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _port_code(layout: PortLayout) -> dict[str, list[str]]:
    """The C statements that move port values between the slot arrays r, i, b and the model M."""
    slot = layout.slot
    code: dict[str, list[str]] = {"start": [], "parameters": [], "to_model": [], "clear_events": [],
                                  "clear_outputs": [], "from_model": []}
    for var in layout.variables:
        if var.start not in (None, 0, False, 0.0):
            code["start"].append(f"{slot(var)} = {_c_start(var)};")
    for par in layout.parameters:
        code["parameters"].append(f"{cnames.parameter(par.machine, par.name)} = {_CAST[par.var.fmi_type].format(slot(par.var))};")
    for ev in layout.inputs:
        code["to_model"].append(f"{cnames.in_flag(ev.name)} = {slot(ev.flag)};")
        code["clear_events"].append(f"{cnames.in_flag(ev.name)} = false;")
        for v in ev.values:
            code["to_model"].append(f"{cnames.in_value(ev.name)}{_field(v.path)} = {_CAST[v.var.fmi_type].format(slot(v.var))};")
    for op in layout.operations:
        code["clear_outputs"].append(f"{slot(op.flag)} = false;")
        copies = [f"{slot(v.var)} = {cnames.call_arg(op.name, pname)}{_field(v.path)};" for pname, values in op.args for v in values]
        code["from_model"].append(f"if ({cnames.call_flag(op.name)}) {{ {' '.join([*_again(slot(op.flag), op.name), *copies])} }}")
    for ev in layout.outputs:
        code["clear_outputs"].append(f"{slot(ev.flag)} = false;")
        copies = [f"{slot(v.var)} = {cnames.out_value(ev.name)}{_field(v.path)};" for v in ev.values]
        code["from_model"].append(f"if ({cnames.out_flag(ev.name)}) {{ {' '.join([*_again(slot(ev.flag), ev.name), *copies])} }}")
    for st in layout.states:
        code["from_model"].append(f"{slot(st.var)} = model_state(M, {st.machine});")
    code["from_model"] = ["const char *again = NULL;", *code["from_model"], "return again;"]
    return code


def _again(flag: str, name: str) -> list[str]:
    """An output flag set by a cycle; `again` names it when an earlier cycle of the step set it already
    (two occurrences the step carries as one: the FMU says so, see fmi2_wrapper.c)."""
    return [f"if ({flag}) again = {_c_string(name)};", f"{flag} = true;"]


_CAST = {"Real": "{}", "Integer": "(int64_t){}", "Boolean": "(bool){}"}
_UNUSED = {"start": "(void)r; (void)i; (void)b;", "parameters": "(void)M; (void)r; (void)i; (void)b;",
           "to_model": "(void)M; (void)r; (void)i; (void)b;", "clear_events": "(void)M;",
           "clear_outputs": "(void)r; (void)i; (void)b;", "from_model": "(void)M; (void)r; (void)i; (void)b;"}
_SIGNATURES = {
    "start": "ports_start_values(double *r, int64_t *i, bool *b)",
    "parameters": "ports_parameters(Model *M, const double *r, const int64_t *i, const bool *b)",
    "to_model": "ports_to_model(Model *M, const double *r, const int64_t *i, const bool *b)",
    "clear_events": "ports_clear_input_events(Model *M)",
    "clear_outputs": "ports_clear_outputs(double *r, int64_t *i, bool *b)",
    "from_model": "ports_from_model(const Model *M, double *r, int64_t *i, bool *b)",
}
_PURPOSE = {
    "start": "start values of the ports (all others are zero)",
    "parameters": "parameters into the model, before model_init",
    "to_model": "input events and their values into the model, before a cycle",
    "clear_events": "no input events in the second and later cycles of a step",
    "clear_outputs": "output flags false at the start of a step",
    "from_model": "operation calls, output events and states out of the model, after a cycle; the name of an "
                  "output an earlier cycle of the step already raised (NULL if none)",
}


def ports_header(program: Program, layout: PortLayout, model_header: str) -> str:
    """sources/ports.h: the module's ports as tables for fmi2_wrapper.c, and the code that moves their
    values in and out of the model. STATE_TAG (from the model's data layout and the ports) marks the
    FMU states of this FMU, so that a state of another module or build is refused."""
    n = layout.counts
    code = _port_code(layout)
    lines = [f"/* Generated by cotwin from module {program.module.name}: the FMU's ports and how their values",
             "   move between the slot arrays (r: reals, i: integers, b: Booleans) and the model. */",
             "#ifndef COTWIN_PORTS_H", "#define COTWIN_PORTS_H", "#include <stdbool.h>", "#include <stdint.h>",
             '#include "model.h"', "",
             f"#define N_REAL {n['Real']}", f"#define N_INTEGER {n['Integer']}", f"#define N_BOOLEAN {n['Boolean']}",
             f"#define N_VARIABLES {len(layout.variables)}",
             f"#define PERIOD_SLOT {layout.period.slot}  /* r[] slot of the parameter {layout.period.name} */",
             "#define STATE_TAG UINT64_C(0x@TAG@)  /* identifies the states of this FMU */", "",
             "/* per value reference: its type (r, i, b), its slot in that array, its name */",
             f"static const char port_kind[] = "
             f"{_c_string(''.join(SLOT_ARRAY[v.fmi_type] for v in layout.variables))};",
             f"static const int port_slot[] = {{{', '.join(str(v.slot) for v in layout.variables) or '0'}}};",
             "static const char *const port_name[] = {"]
    lines.extend(f"    {_c_string(v.name)}," for v in layout.variables)
    lines.append("};")
    for key, signature in _SIGNATURES.items():
        lines.append("")
        lines.append(f"/* {_PURPOSE[key]} */")
        lines.append(f"static {'const char *' if key == 'from_model' else 'void '}{signature} {{")
        lines.extend(f"    {stmt}" for stmt in code[key] or [_UNUSED[key]])
        lines.append("}")
    lines.append("")
    lines.append("#endif")
    text = "\n".join(lines) + "\n"
    tag = hashlib.sha256((model_header + text).encode()).hexdigest()[:16]
    return text.replace("@TAG@", tag)


def _c_start(var: Variable) -> str:
    if var.fmi_type == "Boolean":
        return "true" if var.start else "false"
    if var.fmi_type == "Real":
        return repr(float(var.start))
    return str(int(var.start))


def fmu_sources(program: Program, root: str | Path | None = None) -> dict[str, str]:
    """Every text file of the FMU (deterministic): modelDescription.xml and sources/*. Model locations in
    them (error messages) are relative to `root`, the project's folder (default: the folder holding the
    model files), so that the same models give the same bytes and GUID from any working directory and
    wherever the project lies; the GUID is a digest of the other files."""
    layout = PortLayout(program)
    files = {f"sources/{name}": text for name, text in generate_c(program, root).items()}
    files["sources/ports.h"] = ports_header(program, layout, files["sources/model.h"])
    files["sources/fmi2.c"] = WRAPPER.read_text()
    headers = Path(fmpy.__file__).parent / "c-code"
    for h in _FMI_HEADERS:
        files[f"sources/{h}"] = (headers / h).read_text()
    digest = hashlib.sha256("".join(files[k] for k in sorted(files)).encode()).hexdigest()
    guid = str(uuid.UUID(digest[:32]))
    files["modelDescription.xml"] = model_description(program, layout, guid)
    return files


def compile_binary(sources: dict[str, str], ident: str, folder: Path, cc: str = "cc") -> Path:
    """Compile the sources' .c files into folder/<ident>.so with the C compiler `cc` (a command, possibly with
    arguments, e.g. "ccache gcc"); paths are kept out of the binary so that it does not depend on
    where it was built. A binary compiled before from the same sources by the same compiler (the command and
    the file it runs) is copied from cotwin's cache instead (cotwin.files.cache_dir; COTWIN_CACHE=off: none)."""
    command = shlex.split(cc)
    found = shutil.which(command[0]) if command else None
    if found is None:
        raise CotwinError(f"no C compiler '{cc}' found on PATH (install gcc, or pass --cc)")
    cache = cache_dir()
    if cache is None:
        return _compile(sources, ident, folder, cc)
    compiler = Path(found).resolve()
    info = compiler.stat()
    digest = hashlib.sha256("\0".join((__version__, ident, cc, str(compiler), str(info.st_size),
                                       str(info.st_mtime_ns))).encode())
    for name in sorted(sources):
        digest.update(b"\0" + name.encode() + b"\0" + sources[name].encode())
    kept = cache / "binaries" / f"{digest.hexdigest()}.so"
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{ident}.so"
    if kept.is_file():
        try:
            shutil.copyfile(kept, out)
            touch(kept)  # used now: the last the cache's bound removes (cotwin.cache)
            return out
        except OSError:  # removed since (the cache's bound, `cotwin cache --clear`): compiled again
            pass
    built = _compile(sources, ident, folder, cc)
    try:  # kept whole or not at all (two builds may finish at once); a cache that cannot be written is skipped
        kept.parent.mkdir(parents=True, exist_ok=True)
        spare = kept.with_name(f"{kept.name}.{uuid.uuid4().hex}.part")
        shutil.copyfile(built, spare)
        spare.replace(kept)
        bound(kept)
    except OSError:
        pass
    return built


def _compile(sources: dict[str, str], ident: str, folder: Path, cc: str = "cc") -> Path:
    command = shlex.split(cc)
    with tempfile.TemporaryDirectory(prefix="cotwin-cc-") as tmp:
        src = Path(tmp)
        for name, text in sources.items():
            if name.startswith("sources/"):
                (src / Path(name).name).write_text(text)
        out = folder / f"{ident}.so"
        folder.mkdir(parents=True, exist_ok=True)
        cmd = [*command, "-std=c99", "-O2", "-fPIC", "-shared", "-fvisibility=default", "-Wall", "-Wno-unused-label",
               "-Wno-unused-variable", "-Wno-unused-function", f"-ffile-prefix-map={src}=sources", "-I", str(src),
               "-o", str(out), *sorted(str(src / Path(n).name) for n in sources if n.startswith("sources/")
                                       and n.endswith(".c")), "-lm"]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True)
        except OSError as err:
            raise CotwinError(f"cannot run the C compiler '{cc}': {err.strerror or err}") from None
        if proc.returncode != 0:
            raise CotwinError(f"the C compiler '{cc}' failed on the generated code:\n{proc.stderr}")
        if not out.is_file():
            raise CotwinError(f"the C compiler '{cc}' reported success but wrote no {out.name}")
    return out


def build_fmu(program: Program, output: str | Path, cc: str = "cc", root: str | Path | None = None) -> Path:
    """Write the FMU zip: modelDescription.xml, binaries/linux64/<id>.so (compiled with `cc`) and sources/
    (locations relative to `root`, see fmu_sources)."""
    return package_fmu(fmu_sources(program, root), model_identifier(program), output, cc)


def package_fmu(files: dict[str, str], ident: str, output: str | Path, cc: str = "cc", platform: str = "linux64") -> Path:
    """Compile the sources and zip them with the text files into `output` (`fmu_archive`); a place `output` cannot
    be written is found before the compiler runs."""
    reserved = Reserved(output)
    try:
        return reserved.put(fmu_archive(files, ident, cc, platform))
    finally:
        reserved.discard()


def fmu_archive(files: dict[str, str], ident: str, cc: str = "cc", platform: str = "linux64") -> bytes:
    """The FMU zip of the sources compiled and the text files: binaries/<platform>/<ident>.so (FMI 2.0 names the
    platform linux64, FMI 3.0 x86_64-linux), deterministically (fixed dates, sorted names); bytes, so that a
    build records their digest without reading the file back."""
    archive = io.BytesIO()
    with tempfile.TemporaryDirectory(prefix="cotwin-fmu-") as tmp:
        binary = compile_binary(files, ident, Path(tmp), cc)
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(files):
                info = zipfile.ZipInfo(name, date_time=_ZIP_TIME)
                info.compress_type = zipfile.ZIP_DEFLATED
                zf.writestr(info, files[name])
            info = zipfile.ZipInfo(f"binaries/{platform}/{ident}.so", date_time=_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o755 << 16
            zf.writestr(info, binary.read_bytes())
    return archive.getvalue()
