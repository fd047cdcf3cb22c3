"""FMI 2.0 co-simulation FMUs built in the tests (C compiled with cc, zipped with a modelDescription.xml)
that misbehave at a chosen point: a memory fault, an abort, a loop that never returns, a corrupted heap,
or an fmi2Error.

`fault_fmu` is a small unit of its own: y integrates its input u (y += u h), n counts its steps. Its
parameters choose the fault: `fault` (0 none, 1 segfault, 2 abort, 3 hang, 4 heap corruption, 5
fmi2Error), `fault_at` (the first step starting at or after this time faults) and `fault_call` (the
n-th fmi2DoStep of the process faults, whatever the time: a transient fault a restarted process does
not meet again). Its state (y, n) can be saved and serialised unless `can_save=False`.

`faulty_dmodel_fmu` is a cotwin d-model FMU (the same sources and modelDescription) whose n-th
fmi2DoStep in a process faults: a d-model FMU "built by another tool" that crashes now and then.
"""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

FAULTS = {"segfault": 1, "abort": 2, "hang": 3, "heap": 4, "error": 5}

# What each fault does, as C statements (ends the step one way or another).
FAULT_CODE = r"""
static void cotwin_test_fault(int kind) {
    if (kind == 1) { volatile int *p = (volatile int *)16; *p = 1; }
    if (kind == 2) abort();
    if (kind == 3) { volatile int forever = 1; while (forever) { } }
    if (kind == 4) {  /* write past a heap block over the top chunk's header: glibc's next malloc aborts */
        volatile unsigned char *a = malloc(40000);
        for (size_t k = 0; a && k < 40000 + 32; k++) a[k] = 0xff;
        char *volatile b = malloc(80000);
        free(b);
    }
}
"""

SOURCE = r"""
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
""" + FAULT_CODE + r"""
typedef struct { double y, u, fault_at; int fault, fault_call, n; } State;
typedef struct { State s; fmi2CallbackFunctions cb; } Inst;
static long calls = 0;  /* fmi2DoStep calls in this process */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String k[]) { return fmi2OK; }
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Inst *i = calloc(1, sizeof(Inst));
    if (i && cb) i->cb = *cb;
    if (i) i->s.fault_at = 1e300;
    return i;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t, fmi2Boolean d, fmi2Real e) { return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    State *s = &((Inst *)c)->s;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == 0) v[k] = s->u; else if (vr[k] == 1) v[k] = s->y; else if (vr[k] == 2) v[k] = s->fault_at;
        else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    State *s = &((Inst *)c)->s;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == 0) s->u = v[k]; else if (vr[k] == 2) s->fault_at = v[k]; else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    State *s = &((Inst *)c)->s;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == 3) v[k] = s->fault; else if (vr[k] == 4) v[k] = s->fault_call; else if (vr[k] == 5) v[k] = s->n;
        else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    State *s = &((Inst *)c)->s;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == 3) s->fault = v[k]; else if (vr[k] == 4) s->fault_call = v[k]; else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean x) {
    Inst *i = (Inst *)c;
    State *s = &i->s;
    calls++;
    if (s->fault && (t >= s->fault_at - 1e-9 || (s->fault_call > 0 && calls == s->fault_call))) {
        if (s->fault == 5) {
            if (i->cb.logger) i->cb.logger(i->cb.componentEnvironment, "fault", fmi2Error, "logStatusError", "the test FMU refuses this step");
            return fmi2Error;
        }
        cotwin_test_fault(s->fault);
    }
    s->y += s->u * h;
    s->n++;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) { return fmi2Discard; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) { return fmi2Discard; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) { return fmi2Discard; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) { return fmi2Discard; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) { return fmi2Discard; }
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]) { return fmi2Error; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]) { return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference a[], size_t na, const fmi2ValueReference b[], size_t nb, const fmi2Real d[], fmi2Real e[]) { return fmi2Error; }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *st) {
    State *copy = *st ? (State *)*st : malloc(sizeof(State));
    if (!copy) return fmi2Error;
    *copy = ((Inst *)c)->s;
    *st = copy;
    return fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate st) { ((Inst *)c)->s = *(State *)st; return fmi2OK; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *st) { free(*st); *st = NULL; return fmi2OK; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate st, size_t *size) { *size = sizeof(State); return fmi2OK; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate st, fmi2Byte b[], size_t size) {
    if (size < sizeof(State)) return fmi2Error;
    memcpy(b, st, sizeof(State));
    return fmi2OK;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *st) {
    if (size != sizeof(State)) return fmi2Error;
    State *copy = *st ? (State *)*st : malloc(sizeof(State));
    if (!copy) return fmi2Error;
    memcpy(copy, b, sizeof(State));
    *st = copy;
    return fmi2OK;
}
"""

DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{6f1c8a52-1f4e-4a8e-9a4e-0c0ffee{n:05d}}}"
  generationTool="a test of cotwin (not cotwin)" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true"
    canGetAndSetFMUstate="{save}" canSerializeFMUstate="{save}"/>
  <ModelVariables>
    <ScalarVariable name="u" valueReference="0" causality="input" variability="continuous"><Real start="0.0"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="1" causality="output" variability="continuous" initial="exact"><Real start="0.0"/></ScalarVariable>
    <ScalarVariable name="fault_at" valueReference="2" causality="parameter" variability="fixed" initial="exact"><Real start="1e300"/></ScalarVariable>
    <ScalarVariable name="fault" valueReference="3" causality="parameter" variability="fixed" initial="exact"><Integer start="0"/></ScalarVariable>
    <ScalarVariable name="fault_call" valueReference="4" causality="parameter" variability="fixed" initial="exact"><Integer start="0"/></ScalarVariable>
    <ScalarVariable name="n" valueReference="5" causality="output" variability="discrete" initial="exact"><Integer start="0"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="2"/><Unknown index="6"/></Outputs>
  </ModelStructure>
</fmiModelDescription>
"""


def _headers() -> dict[str, str]:
    import fmpy

    folder = Path(fmpy.__file__).parent / "c-code"
    return {f"sources/{h}": (folder / h).read_text()
            for h in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")}


def _package(files: dict[str, str], ident: str, output: Path) -> Path:
    """Compile the sources (cotwin's compile_binary: sources/model.c and sources/fmi2.c) and zip the FMU."""
    from cotwin.dmodel.fmu import compile_binary

    work = output.parent / f".{output.name}.build"
    binary = compile_binary(files, ident, work)
    with zipfile.ZipFile(output, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(files):
            zf.writestr(name, files[name])
        zf.writestr(f"binaries/linux64/{ident}.so", binary.read_bytes())
    shutil.rmtree(work, ignore_errors=True)
    return output


def fault_fmu(folder: Path, name: str = "faulty", can_save: bool = True, number: int = 1) -> Path:
    """The test FMU above at folder/<name>.fmu."""
    files = {"modelDescription.xml": DESCRIPTION.format(name=name, n=number, save="true" if can_save else "false"),
             "sources/fmi2.c": SOURCE, "sources/model.c": "/* the test FMU is all in fmi2.c */\n", **_headers()}
    return _package(files, name, folder / f"{name}.fmu")


def faulty_dmodel_fmu(program, root: Path, output: Path, fault: str, call: int) -> Path:
    """A cotwin d-model FMU (its sources and modelDescription unchanged) whose `call`-th fmi2DoStep in a
    process does `fault` (see FAULTS)."""
    from cotwin.dmodel.fmu import fmu_sources, model_identifier

    files = fmu_sources(program, root)
    wrapper = files["sources/fmi2.c"]
    marker = "fmi2Status fmi2DoStep("
    head, tail = wrapper.split(marker, 1)
    body_at = tail.index("{") + 1
    injected = ("\n    static long cotwin_test_calls = 0;\n"
                f"    if (++cotwin_test_calls == {int(call)}) cotwin_test_fault({FAULTS[fault]});\n")
    files["sources/fmi2.c"] = head + FAULT_CODE + marker + tail[:body_at] + injected + tail[body_at:]
    return _package(files, model_identifier(program), output)
