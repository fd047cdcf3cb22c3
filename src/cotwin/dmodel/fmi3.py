"""Package a module as an FMI 3.0 co-simulation FMU whose d-model cycle is a clock.

The interface type is Co-Simulation with Event Mode (`hasEventMode`), not Scheduled Execution: the
d-model has no continuous state and runs beside FMUs that do (the platform), under a master that steps
them all; clocks in Co-Simulation need Event Mode, where the master activates the clock at its ticks,
sets the clocked inputs and reads the clocked outputs at the same instant, which is what lets a command
cross the d-model and reach the platform in the same communication step. Scheduled Execution would
hand the master a real-time scheduler's job (model partitions activated by it, no fmi3DoStep) that a
fixed-step co-simulation master does not have (docs/interop.md, FMI 3.0).

The clock `cycle` is a time-based, fixed periodic input clock (intervalVariability="fixed", shift 0)
whose interval is the parameter `cycle_period` (read by the importer with fmi3GetIntervalDecimal in
Initialization Mode); every port but the parameters is clocked by it. The ports are those of the FMI 2.0
FMU (cotwin.dmodel.ports), typed Float64, Int32 and Boolean, with the same value references; the clock
comes after them, then the independent variable `time`. The C is the FMI 2.0 FMU's model and ports with
an FMI 3.0 interface (fmi3_wrapper.c, shipped as sources/fmi3.c); see it for the calling sequences.
"""

from __future__ import annotations

import hashlib
import uuid
from pathlib import Path
from xml.sax.saxutils import escape

import fmpy

from ..diagnostics import CotwinError
from .ccode import generate_c
from .fmu import _start_text, model_identifier, package_fmu, ports_header
from .ports import PortLayout
from .program import Program

WRAPPER = Path(__file__).with_name("fmi3_wrapper.c")
PLATFORM = "x86_64-linux"  # FMI 3.0's name of the binaries' folder
_FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
FMI3_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
CLOCK = "cycle"
DEFAULT_PERIOD = 0.1  # s: the cycle_period an importer gets unless it sets the parameter


def clock_reference(layout: PortLayout) -> int:
    return len(layout.variables)


def model_description(program: Program, layout: PortLayout, token: str, period: float) -> str:
    ident = model_identifier(program)
    clock = clock_reference(layout)
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<fmiModelDescription fmiVersion="3.0"',
        f'  modelName="{escape(program.module.name)}"',
        f'  instantiationToken="{{{token}}}"',
        f'  description="RoboSim d-model module {escape(program.module.name)}: one cycle per tick of the clock {CLOCK} '
        '(interval cycle_period)"',
        '  generationTool="cotwin"',
        '  variableNamingConvention="flat">',
        f'  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"'
        ' canGetAndSetFMUState="true" canSerializeFMUState="true" hasEventMode="true"'
        ' mightReturnEarlyFromDoStep="true"/>',
        f'  <DefaultExperiment startTime="0.0" stepSize="{period!r}"/>',
        "  <ModelVariables>",
    ]
    for var in layout.variables:
        kind = FMI3_TYPE[var.fmi_type]
        desc = f' description="{escape(var.description, {chr(34): "&quot;"})}"' if var.description else ""
        if var.causality == "parameter":
            extra = ' initial="exact"'
        else:
            extra = f' clocks="{clock}"'
        start = f' start="{period!r}"' if var is layout.period else _start_text(var) if var.causality != "output" else ""
        lines.append(f'    <{kind} name="{escape(var.name)}" valueReference="{var.vr}" causality="{var.causality}" '
                     f'variability="{var.variability}"{extra}{start}{desc}/>')
    lines.append(f'    <Clock name="{CLOCK}" valueReference="{clock}" causality="input" variability="discrete" '
                 'intervalVariability="fixed" priority="0" description="one tick per d-model cycle; interval: '
                 'cycle_period"/>')
    lines.append(f'    <Float64 name="time" valueReference="{clock + 1}" causality="independent" variability="continuous" '
                 'description="simulation time"/>')
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    lines.extend(f'    <Output valueReference="{v.vr}"/>' for v in layout.variables if v.causality == "output")
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def clock_header(program: Program, layout: PortLayout, period: float, tag: str) -> str:
    """sources/fmi3ports.h: what FMI 3.0 adds to ports.h (which ports are clocked, the clock's value
    reference, the default period, and how a tick consumes the input events)."""
    clocked = "".join("i" if v.causality == "input" else "o" if v.causality == "output" else "-"
                      for v in layout.variables)
    flags = [layout.slot(ev.flag) for ev in layout.inputs]
    lines = [f"/* Generated by cotwin from module {program.module.name}: the FMI 3.0 clock of its ports. */",
             "#ifndef COTWIN_FMI3PORTS_H", "#define COTWIN_FMI3PORTS_H", "#include <stdbool.h>", "",
             f"#define CLOCK_VR {clock_reference(layout)}u  /* the clock {CLOCK}: one d-model cycle per tick */",
             f"#define DEFAULT_PERIOD {period!r}  /* s: cycle_period's start value */",
             f"#define FMI3_TAG UINT64_C(0x{tag})  /* FMI 3.0 states differ from FMI 2.0 ones */", "",
             "/* per value reference: 'i' clocked input, 'o' clocked output, '-' not clocked (a parameter) */",
             f'static const char port_clocked[] = "{clocked}";', "",
             "/* after a tick: its input events are consumed (the next tick has them only if they are set again) */",
             "static void ports_clear_input_flags(bool *b) {"]
    lines.extend(f"    {slot} = false;" for slot in flags)
    if not flags:
        lines.append("    (void)b;")
    lines += ["}", "", "#endif", ""]
    return "\n".join(lines)


def fmu3_sources(program: Program, period: float = DEFAULT_PERIOD, root: str | Path | None = None) -> dict[str, str]:
    """Every text file of the FMI 3.0 FMU (deterministic): modelDescription.xml and sources/*; model locations
    relative to `root`, as the FMI 2.0 FMU's (cotwin.dmodel.fmu.fmu_sources)."""
    if not period > 0:
        raise CotwinError(f"the cycle period must be a positive number of seconds, not {period!r}")
    layout = PortLayout(program)
    files = {f"sources/{name}": text for name, text in generate_c(program, root).items()}
    files["sources/ports.h"] = ports_header(program, layout, files["sources/model.h"])
    tag = hashlib.sha256(b"fmi3" + files["sources/ports.h"].encode()).hexdigest()[:16]
    files["sources/fmi3ports.h"] = clock_header(program, layout, period, tag)
    files["sources/fmi3.c"] = WRAPPER.read_text()
    headers = Path(fmpy.__file__).parent / "c-code"
    for h in _FMI3_HEADERS:
        files[f"sources/{h}"] = (headers / h).read_text()
    digest = hashlib.sha256("".join(files[k] for k in sorted(files)).encode()).hexdigest()
    files["modelDescription.xml"] = model_description(program, layout, str(uuid.UUID(digest[:32])), period)
    return files


def build_fmu3(program: Program, output: str | Path, cc: str = "cc", period: float = DEFAULT_PERIOD,
               root: str | Path | None = None) -> Path:
    """Write the FMI 3.0 FMU zip: modelDescription.xml, binaries/x86_64-linux/<id>.so and sources/."""
    return package_fmu(fmu3_sources(program, period, root), model_identifier(program), output, cc, PLATFORM)
