"""What the faster paths must keep: the simulated model drops only what shows, an unstable simulation
stops instead of resetting itself, CSV rows are spelt as Maestro's, ports move in bound groups."""

from __future__ import annotations

import csv

import mujoco
import numpy as np
import pytest

from cotwin.cosim.algorithm import GaussSeidel, Jacobi
from cotwin.cosim.execution import Execution
from cotwin.cosim.observers import CSVWriter
from cotwin.cosim.system import Connection, System
from cotwin.cosim.units import Port, PythonUnit
from cotwin.diagnostics import CotwinError
from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.simulator import PlatformSimulator


@pytest.fixture(scope="module")
def twin():
    from conftest import EXAMPLES

    from cotwin.twin.assembly.run import load

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


def test_the_simulator_steps_the_scene_without_its_markers(twin):
    tree, scene = twin.models.tree, twin.models.scene
    shown = mujoco.MjModel.from_xml_string(to_mjcf(tree, scene))
    sim = PlatformSimulator(tree, scene)
    holes = [shown.geom(i).name for i in range(shown.ngeom) if shown.geom(i).name.startswith("hole_")]
    assert len(holes) == (scene.xmax + 1) * (scene.ymax + 1)
    assert not any(sim.model.geom(i).name.startswith("hole_") for i in range(sim.model.ngeom))
    assert sim.model.ngeom == shown.ngeom - len(holes)
    assert (sim.model.nbody, sim.model.njnt, sim.model.nu, sim.model.nsensor) == \
        (shown.nbody, shown.njnt, shown.nu, shown.nsensor)


def test_unstable_physics_stops_with_an_error(twin, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs its warning to MUJOCO_LOG.TXT in the working folder
    sim = PlatformSimulator(twin.models.tree, twin.models.scene)
    sim.data.qvel[:] = 1e200
    with pytest.raises(CotwinError, match="physics became unstable"):
        sim.advance(0.01)


def _unit(name, ports, step):
    unit = PythonUnit(name, ports)
    unit.step = step
    return unit


def test_csv_rows_are_spelt_as_maestro_spells_them(tmp_path):
    ports = [Port("r", "Real", "output"), Port("b", "Boolean", "output"), Port("i", "Integer", "output"),
             Port("odd", "Real", "output")]
    values = iter([(0.1, True, -3, None), (1e-300, False, 2 ** 31 - 1, np.float64(2.5)), (float("inf"), True, 0, 7)])

    def step(t, h):
        unit.values.update(zip(("r", "b", "i", "odd"), next(values)))

    unit = _unit("{u}.u", ports, step)
    system = System.of([unit], [], log={"{u}.u": ["r", "b", "i", "odd"]})
    Execution(system, Jacobi(), 0.5, observers=[CSVWriter(tmp_path / "out.csv")]).run(1.5)
    rows = list(csv.reader(open(tmp_path / "out.csv")))
    assert rows == [["time", "{u}.u.r", "{u}.u.b", "{u}.u.i", "{u}.u.odd"], ["0.0", "0", "false", "0", "0"],
                    ["0.5", "0.1", "true", "-3", ""], ["1.0", "1e-300", "false", "2147483647", "2.5"],
                    ["1.5", "inf", "true", "0", "7"]]


@pytest.mark.parametrize("algorithm", [Jacobi, GaussSeidel])
def test_values_cross_connections_of_every_type_in_bound_groups(algorithm):
    """Ports declared in mixed type order reach their targets (the master groups them by type)."""
    out = [Port("b", "Boolean", "output"), Port("r", "Real", "output"), Port("i", "Integer", "output"),
           Port("r2", "Real", "output")]
    into = [Port(p.name, p.type, "input") for p in out]
    seen = []

    def produce(t, h):
        source.values.update(b=int(t * 10) % 2 == 0, r=t, i=int(round(t * 10)), r2=-t)

    def consume(t, h):
        seen.append(tuple(sink.values[p] for p in ("b", "r", "i", "r2")))

    source, sink = _unit("a", out, produce), _unit("z", into, consume)
    system = System.of([sink, source], [Connection("a", p.name, "z", p.name) for p in out])
    Execution(system, algorithm(), 0.1).run(0.3)
    f = [(int(t * 10) % 2 == 0, t, int(round(t * 10)), -t) for t in (0.0, 0.1, 0.2)]  # the outputs of each step
    if algorithm is Jacobi:  # the sink sees the previous step's outputs (first the start values)
        assert seen == [(False, 0, 0, 0), f[0], f[1]]
    else:  # the same step's
        assert seen == f


def test_a_result_file_being_written_is_refused_to_a_second_run(tmp_path):
    """Two runs into one CSV (cotwin simulate -o f.csv twice) interleaved rows of different widths: the
    second is refused with a clear error while the first writes, and the first's result is whole."""
    def execution(names):
        unit = _unit("{u}.u", [Port(n, "Real", "output") for n in names], lambda t, h: None)
        system = System.of([unit], [], log={"{u}.u": names})
        return Execution(system, Jacobi(), 0.5, observers=[CSVWriter(tmp_path / "out.csv")])

    first = execution(["a", "b", "c"])
    first.initialize()  # writing out.csv.part
    with pytest.raises(CotwinError, match="out.csv is being written by another run"):
        execution(["a"]).run(1.0)
    first.run(2.0)
    rows = list(csv.reader(open(tmp_path / "out.csv")))
    assert rows[0] == ["time", "{u}.u.a", "{u}.u.b", "{u}.u.c"] and len(rows) == 6  # t = 0 .. 2
    assert {len(r) for r in rows} == {4}
    execution(["a"]).run(1.0)  # released once the first has finished
    assert list(csv.reader(open(tmp_path / "out.csv")))[0] == ["time", "{u}.u.a"]
