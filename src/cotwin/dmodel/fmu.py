"""Package a module as an FMI 2.0 co-simulation FMU: modelDescription.xml, C sources, linux64 binary.

Ports (docs/interop.md): an input event is a Boolean input true in the step it occurs, plus one
input per value field; an operation call is a Boolean output plus its arguments; output events
likewise; `state` is the index of the active leaf state. Constants without a value are parameters.
`cycle_period` (s, 0 = one cycle per step) makes a step of size h run round(h / cycle_period)
cycles, the inputs present in the first; an output flag is then true if it occurred in any of them.
"""

from __future__ import annotations

import hashlib
import re
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import escape

import fmpy

from ..diagnostics import CotwinError
from .ccode import generate_c
from .ports import PortLayout, Variable
from .program import Program

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


_CAST = {"Real": "{}", "Integer": "(int64_t){}", "Boolean": "(bool){}"}


def _field(path: tuple[str, ...]) -> str:
    return "".join(f".{f}" for f in path)


def _wrapper_code(layout: PortLayout) -> dict[str, list[str]]:
    """The wrapper's C statements that move port values in and out of the model, from the layout."""
    slot = layout.slot
    code: dict[str, list[str]] = {"params": [], "to_model": [], "flags": [], "clear": [], "from_model": []}
    for par in layout.parameters:
        code["params"].append(f"M->m{par.machine}.p_{par.name} = "
                              f"{_CAST[par.var.fmi_type].format('inst->' + slot(par.var))};")
    for ev in layout.inputs:
        code["to_model"].append(f"M->in_{ev.name} = inst->{slot(ev.flag)};")
        code["flags"].append(f"M->in_{ev.name}")
        for v in ev.values:
            code["to_model"].append(f"M->in_{ev.name}_v{_field(v.path)} = "
                                    f"{_CAST[v.var.fmi_type].format('inst->' + slot(v.var))};")
    for op in layout.operations:
        code["clear"].append(f"inst->{slot(op.flag)} = false;")
        copies = [f"inst->{slot(v.var)} = M->arg_{op.name}_{pname}{_field(v.path)};"
                  for pname, values in op.args for v in values]
        code["from_model"].append(f"if (M->op_{op.name}) {{ inst->{slot(op.flag)} = true; {' '.join(copies)} }}")
    for ev in layout.outputs:
        code["clear"].append(f"inst->{slot(ev.flag)} = false;")
        copies = [f"inst->{slot(v.var)} = M->out_{ev.name}_v{_field(v.path)};" for v in ev.values]
        code["from_model"].append(f"if (M->out_{ev.name}) {{ inst->{slot(ev.flag)} = true; {' '.join(copies)} }}")
    for st in layout.states:
        code["from_model"].append(f"inst->{slot(st.var)} = model_state(M, {st.machine});")
    return code


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
        ' canNotUseMemoryManagementFunctions="true"/>',
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


def wrapper_source(program: Program, layout: PortLayout) -> str:
    n = layout.counts
    code = _wrapper_code(layout)
    ind = "\n    "
    text = f"""/* Generated by cotwin: the FMI 2.0 co-simulation interface of module {program.module.name}. */
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
#include "model.h"

typedef struct {{
    Model model;
    double r[{max(n['Real'], 1)}];
    int64_t i[{max(n['Integer'], 1)}];
    bool b[{max(n['Boolean'], 1)}];
    fmi2CallbackFunctions functions;
    char *name;
    int initialised;
}} Instance;

static const char kind_of[] = "{''.join({'Real': 'r', 'Integer': 'i', 'Boolean': 'b'}[v.fmi_type] for v in layout.variables)}";
static const int slot_of[] = {{{', '.join(str(v.slot) for v in layout.variables) or '0'}}};
#define NVARS {len(layout.variables)}

static void log_error(Instance *inst, const char *message) {{
    if (inst->functions.logger)
        inst->functions.logger(inst->functions.componentEnvironment, inst->name, fmi2Error, "error", "%s", message);
}}

static void defaults(Instance *inst) {{
    memset(inst->r, 0, sizeof inst->r);
    memset(inst->i, 0, sizeof inst->i);
    memset(inst->b, 0, sizeof inst->b);
    {ind.join(f"inst->{layout.slot(v)} = {_c_start(v)};" for v in layout.variables if v.start not in (None, 0, False, 0.0))}
    memset(&inst->model, 0, sizeof inst->model);
}}

static void start_model(Instance *inst) {{
    Model *M = &inst->model;
    {ind.join(code['params'])}
    model_init(M);
    inst->initialised = 1;
}}

static int run_cycle(Instance *inst, int first) {{
    Model *M = &inst->model;
    {ind.join(code['to_model'])}
    if (!first) {{  /* input events are present in the first cycle of a step only */
        {(ind + '    ').join(f"{flag} = false;" for flag in code['flags'])}
    }}
    if (model_step(M)) return 1;
    {ind.join(code['from_model'])}
    return 0;
}}

const char *fmi2GetTypesPlatform(void) {{ return fmi2TypesPlatform; }}
const char *fmi2GetVersion(void) {{ return fmi2Version; }}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {{
    (void)fmuResourceLocation; (void)visible; (void)loggingOn; (void)fmuGUID;
    if (fmuType != fmi2CoSimulation) return NULL;
    Instance *inst = calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    if (functions) inst->functions = *functions;
    inst->name = malloc(strlen(instanceName ? instanceName : "") + 1);
    strcpy(inst->name, instanceName ? instanceName : "");
    defaults(inst);
    return inst;
}}

void fmi2FreeInstance(fmi2Component c) {{
    Instance *inst = (Instance *)c;
    if (!inst) return;
    free(inst->name);
    free(inst);
}}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {{
    (void)c; (void)on; (void)n; (void)cats; return fmi2OK;
}}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDef, fmi2Real stop) {{
    (void)c; (void)tolDef; (void)tol; (void)start; (void)stopDef; (void)stop; return fmi2OK;
}}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {{ (void)c; return fmi2OK; }}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {{ start_model((Instance *)c); return fmi2OK; }}
fmi2Status fmi2Terminate(fmi2Component c) {{ (void)c; return fmi2OK; }}
fmi2Status fmi2Reset(fmi2Component c) {{ Instance *inst = (Instance *)c; defaults(inst); inst->initialised = 0; return fmi2OK; }}

#define CHECK_VR(k) if ((k) >= NVARS) return fmi2Error
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {{
    Instance *inst = (Instance *)c;
    for (size_t k = 0; k < n; k++) {{ CHECK_VR(vr[k]); if (kind_of[vr[k]] != 'r') return fmi2Error; v[k] = inst->r[slot_of[vr[k]]]; }}
    return fmi2OK;
}}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {{
    Instance *inst = (Instance *)c;
    for (size_t k = 0; k < n; k++) {{ CHECK_VR(vr[k]); if (kind_of[vr[k]] != 'i') return fmi2Error; v[k] = (fmi2Integer)inst->i[slot_of[vr[k]]]; }}
    return fmi2OK;
}}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {{
    Instance *inst = (Instance *)c;
    for (size_t k = 0; k < n; k++) {{ CHECK_VR(vr[k]); if (kind_of[vr[k]] != 'b') return fmi2Error; v[k] = inst->b[slot_of[vr[k]]] ? fmi2True : fmi2False; }}
    return fmi2OK;
}}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {{
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {{
    Instance *inst = (Instance *)c;
    for (size_t k = 0; k < n; k++) {{ CHECK_VR(vr[k]); if (kind_of[vr[k]] != 'r') return fmi2Error; inst->r[slot_of[vr[k]]] = v[k]; }}
    return fmi2OK;
}}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {{
    Instance *inst = (Instance *)c;
    for (size_t k = 0; k < n; k++) {{ CHECK_VR(vr[k]); if (kind_of[vr[k]] != 'i') return fmi2Error; inst->i[slot_of[vr[k]]] = v[k]; }}
    return fmi2OK;
}}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {{
    Instance *inst = (Instance *)c;
    for (size_t k = 0; k < n; k++) {{ CHECK_VR(vr[k]); if (kind_of[vr[k]] != 'b') return fmi2Error; inst->b[slot_of[vr[k]]] = v[k] != fmi2False; }}
    return fmi2OK;
}}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {{
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {{
    Instance *inst = (Instance *)c;
    (void)t; (void)noSetPrior;
    if (!inst->initialised) start_model(inst);
    double period = inst->{layout.slot(layout.period)};
    long cycles = period > 0.0 ? lround(h / period) : 1;
    {ind.join(code['clear'])}
    for (long k = 0; k < cycles; k++) {{
        if (run_cycle(inst, k == 0)) {{ log_error(inst, inst->model.message); return fmi2Error; }}
    }}
    return fmi2OK;
}}

fmi2Status fmi2CancelStep(fmi2Component c) {{ (void)c; return fmi2Error; }}
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {{ (void)c; (void)s; (void)v; return fmi2Discard; }}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {{ (void)c; (void)s; (void)v; return fmi2Discard; }}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {{ (void)c; (void)s; (void)v; return fmi2Discard; }}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {{ (void)c; (void)s; (void)v; return fmi2Discard; }}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {{ (void)c; (void)s; (void)v; return fmi2Discard; }}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]) {{ (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error; }}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]) {{ (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error; }}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {{ (void)c; (void)s; return fmi2Error; }}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {{ (void)c; (void)s; return fmi2Error; }}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {{ (void)c; (void)s; return fmi2Error; }}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {{ (void)c; (void)s; (void)n; return fmi2Error; }}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {{ (void)c; (void)s; (void)b; (void)n; return fmi2Error; }}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {{ (void)c; (void)b; (void)n; (void)s; return fmi2Error; }}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {{ (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz; return fmi2Error; }}
"""
    return text


def _c_start(var: Variable) -> str:
    if var.fmi_type == "Boolean":
        return "true" if var.start else "false"
    if var.fmi_type == "Real":
        return repr(float(var.start))
    return str(int(var.start))


def fmu_sources(program: Program) -> dict[str, str]:
    """Every text file of the FMU (deterministic): modelDescription.xml and sources/*."""
    layout = PortLayout(program)
    files = {f"sources/{name}": text for name, text in generate_c(program).items()}
    files["sources/fmi2.c"] = wrapper_source(program, layout)
    headers = Path(fmpy.__file__).parent / "c-code"
    for h in _FMI_HEADERS:
        files[f"sources/{h}"] = (headers / h).read_text()
    digest = hashlib.sha256("".join(files[k] for k in sorted(files)).encode()).hexdigest()
    guid = str(uuid.UUID(digest[:32]))
    files["modelDescription.xml"] = model_description(program, layout, guid)
    return files


def compile_binary(sources: dict[str, str], ident: str, folder: Path, cc: str = "cc") -> Path:
    """Compile the sources into folder/<ident>.so with the system C compiler."""
    if shutil.which(cc) is None:
        raise CotwinError(f"no C compiler '{cc}' found on PATH (install gcc, or pass --cc)")
    with tempfile.TemporaryDirectory(prefix="cotwin-cc-") as tmp:
        src = Path(tmp)
        for name, text in sources.items():
            if name.startswith("sources/"):
                (src / Path(name).name).write_text(text)
        out = folder / f"{ident}.so"
        folder.mkdir(parents=True, exist_ok=True)
        cmd = [cc, "-std=c99", "-O2", "-fPIC", "-shared", "-fvisibility=default", "-Wall", "-Wno-unused-label",
               "-Wno-unused-variable", "-I", str(src), "-o", str(out), str(src / "model.c"), str(src / "fmi2.c"), "-lm"]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise CotwinError(f"the C compiler failed on the generated code:\n{proc.stderr}")
    return out


def build_fmu(program: Program, output: str | Path, cc: str = "cc") -> Path:
    """Write the FMU zip: modelDescription.xml, binaries/linux64/<id>.so and sources/."""
    output = Path(output)
    files = fmu_sources(program)
    ident = model_identifier(program)
    with tempfile.TemporaryDirectory(prefix="cotwin-fmu-") as tmp:
        binary = compile_binary(files, ident, Path(tmp))
        output.parent.mkdir(parents=True, exist_ok=True)
        partial = output.with_suffix(output.suffix + ".part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(files):
                info = zipfile.ZipInfo(name, date_time=_ZIP_TIME)
                info.compress_type = zipfile.ZIP_DEFLATED
                zf.writestr(info, files[name])
            info = zipfile.ZipInfo(f"binaries/linux64/{ident}.so", date_time=_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o755 << 16
            zf.writestr(info, binary.read_bytes())
        partial.replace(output)
    return output
