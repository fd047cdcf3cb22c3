"""Run a multimodel in libcosim (through libcosimpy), a third-party FMI 2.0 master, for comparison.

libcosim steps all units at the same time and passes outputs to inputs after each step, as Maestro's
Jacobi does. Returns the time series of the requested variables.
"""

from __future__ import annotations

from .multimodel import MultiModel, unit_name


def run_libcosim(mm: MultiModel, watch: dict[str, list[str]], step: float | None = None,
                 end: float | None = None, log_level: str = "WARNING") -> dict[str, list[float]]:
    """`log_level` is libcosim's own (TRACE ... FATAL); below WARNING it prints every FMI call."""
    from libcosimpy.CosimObserver import CosimObserver

    step = step or mm.step
    end = end or mm.end
    ex, index, refs = libcosim_execution(mm, step, log_level)
    observer = CosimObserver.create_last_value()
    ex.add_observer(observer)
    series: dict[str, list[float]] = {"time": []}
    for unit, names in watch.items():
        for n in names:
            series[f"{unit}.{n}"] = []
    n_steps = int(round((end - mm.start) / step))
    for k in range(n_steps):
        ex.step()
        series["time"].append(mm.start + (k + 1) * step)
        for unit, names in watch.items():
            for n in names:
                vr, kind = refs[unit][n]
                getter = {"Real": observer.last_real_values, "Integer": observer.last_integer_values,
                          "Boolean": observer.last_boolean_values}[kind]
                series[f"{unit}.{n}"].append(getter(index[unit], [vr])[0])
    return series


def libcosim_execution(mm: MultiModel, step: float | None = None, log_level: str = "WARNING"):
    """The multimodel as a libcosim execution (its instances added and connected, no observer):
    (execution, slave index by unit name, (value reference, type) by unit and variable name)."""
    from fmpy import read_model_description
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel[log_level])
    ex = CosimExecution.from_step_size(step_size=int(round((step or mm.step) * 1e9)))
    index, refs = {}, {}
    for inst in mm.instances:
        name = unit_name(inst)
        index[name] = ex.add_local_slave(CosimLocalSlave(fmu_path=str(mm.fmus[inst[0]]), instance_name=inst[1]))
        md = read_model_description(str(mm.fmus[inst[0]]))
        refs[name] = {v.name: (v.valueReference, v.type) for v in md.modelVariables}
    for c in mm.connections:
        src, dst = unit_name(c[:2]), unit_name(c[3:5])
        vr_out, kind = refs[src][c[2]]
        vr_in, _ = refs[dst][c[5]]
        _connect(ex, kind, index[src], vr_out, index[dst], vr_in)
    return ex, index, refs


def _connect(ex, kind: str, src: int, vr_out: int, dst: int, vr_in: int) -> None:
    """libcosimpy 0.0.6's connect_integer_variables calls a misspelt private wrapper
    (`__connect_integer_variables`, defined as `__connect_int_variables`); call the defined one."""
    if kind == "Integer":
        status = ex._CosimExecution__connect_int_variables(ex._CosimExecution__ptr, src, vr_out, dst, vr_in)
    else:
        status = getattr(ex, f"connect_{kind.lower()}_variables")(src, vr_out, dst, vr_in)
    if status not in (0, True, None):
        from ..diagnostics import CotwinError

        raise CotwinError(f"libcosim refused to connect {kind} variables ({src}:{vr_out} -> {dst}:{vr_in})")
