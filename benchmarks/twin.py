"""The UR5e twin end to end: build time, the 20 s experiment's wall time and real-time factor at
steps 0.1 s and 0.01 s (physics 1 ms), and master overhead per step per unit against libcosim
(the peer) on the same FMUs in the same run."""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.cosim.libcosim import run_libcosim  # noqa: E402
from cotwin.cosim.multimodel import execution_for, read_multimodel  # noqa: E402
from cotwin.twin.build import build  # noqa: E402
from cotwin.twin.run import load, run_twin  # noqa: E402


def overhead(dmodel_fmu: Path, folder: Path, steps: int = 20_000) -> None:
    """Three instances of the (cheap, C) d-model FMU chained: what each master adds per step per unit."""
    mm = {"fmus": {"{d}": str(dmodel_fmu)},
          "connections": {"{d}.a.movediscrete": ["{d}.b.moveDiscreteCommand"],
                          "{d}.b.movediscrete": ["{d}.c.moveDiscreteCommand"],
                          "{d}.a.target_X": ["{d}.b.MovementArgs_target_X"]},
          "logVariables": {"{d}.c": ["state"]},
          "algorithm": {"type": "fixed-step", "size": 0.001}, "startTime": 0.0, "endTime": steps * 0.001}
    path = folder / "overhead.json"
    path.write_text(json.dumps(mm))
    model = read_multimodel(path)
    t0 = time.perf_counter()
    execution_for(model).run(model.end)
    ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_libcosim(model, {"{d}.c": ["state"]})
    theirs = time.perf_counter() - t0
    per = lambda seconds: seconds / steps / 3 * 1e6  # noqa: E731
    print(f"master overhead, 3 C FMUs x {steps} steps: cotwin {per(ours):.1f} us/step/unit, "
          f"libcosim {per(theirs):.1f} us/step/unit (cotwin/libcosim = {ours / theirs:.2f})")


def main() -> None:
    project = ROOT / "examples" / "ur5e" / "cotwin.toml"
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        t0 = time.perf_counter()
        twin = load(project)
        t_models = time.perf_counter() - t0
        t0 = time.perf_counter()
        build(twin, out / "build")
        t_build = time.perf_counter() - t0
        print(f"models -> checked, flattened, tree: {t_models:.2f} s; build (C FMU, 2 Python FMUs, SDF/URDF/MJCF, "
              f"multimodel): {t_build:.2f} s")
        for step in (0.1, 0.01):
            run = out / f"run{step}"
            run.mkdir()
            for name in ("dmodel.fmu", "build.json"):
                shutil.copy(out / "build" / name, run / name)
            result = run_twin(twin, run, step=step, plot=False).result
            print(f"20 s experiment, step {step:g} s, physics 1 ms (in-process mapping): wall {result.wall_seconds:.2f} s, "
                  f"real-time factor {20 / result.wall_seconds:.1f}x")
        mm = read_multimodel(out / "build" / "multimodel.json")
        t0 = time.perf_counter()
        execution_for(mm, out / "fmus.csv").run(mm.end)
        ours = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_libcosim(mm, {"{mapping}.mapping": ["q0"]})
        theirs = time.perf_counter() - t0
        print(f"20 s experiment, step 0.1 s, all three as FMUs: cotwin simulate {ours:.2f} s, libcosim {theirs:.2f} s "
              f"(cotwin/libcosim = {ours / theirs:.2f})")
        overhead(out / "build" / "dmodel.fmu", out)


if __name__ == "__main__":
    main()
