"""The UR5e twin end to end, each figure beside its peer measured in this run:
- the paper's 20 s experiment at communication steps 0.1, 0.01 and 0.001 s (physics at 1 ms):
  real-time factor of the stepping (goals >= 200x, >= 50x, >= 5x) beside the physics alone (the same
  scene's 20 000 mj_steps in one MuJoCo call: the limit the twin cannot beat);
- the mapping step against the interpreted mapping it replaces (the expression-core work: a marked
  place below);
- the master's overhead per step per unit against libcosim on the same FMUs, and the whole twin as
  FMUs (d-model in C, mapping and controller through pythonfmu) in both masters.
Figures are the best of a few repetitions: the machine is shared."""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import mujoco

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.cosim.libcosim import run_libcosim  # noqa: E402
from cotwin.cosim.multimodel import execution_for, read_multimodel  # noqa: E402
from cotwin.cosim.observers import Observer  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from cotwin.twin.build import build  # noqa: E402
from cotwin.twin.run import load, run_twin  # noqa: E402

GOALS = {0.1: 200.0, 0.01: 50.0, 0.001: 5.0}
END = 20.0


class Stopwatch(Observer):
    """Wall time of the stepping alone (from the end of initialisation to the end of the run)."""

    def simulation_initialized(self, execution) -> None:
        self.started = time.perf_counter()

    def simulation_ended(self, execution, error) -> None:
        self.seconds = time.perf_counter() - self.started


def physics_alone(twin) -> float:
    """Seconds for END s of the twin's scene physics: the simulator's model, one mj_step call."""
    sim = PlatformSimulator(twin.models.tree, twin.models.scene)
    steps = int(round(END / sim.timestep))
    t0 = time.perf_counter()
    mujoco.mj_step(sim.model, sim.data, steps)
    return time.perf_counter() - t0


def experiment(twin, build_dir: Path, folder: Path, step: float) -> tuple[float, float]:
    """(stepping seconds, whole run seconds) of the 20 s experiment at this communication step."""
    folder.mkdir(exist_ok=True)
    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(build_dir / name, folder / name)
    watch = Stopwatch()
    t0 = time.perf_counter()
    run_twin(twin, folder, step=step, plot=False, observers=[watch])
    return watch.seconds, time.perf_counter() - t0


def mapping_step() -> None:
    """The mapping's event evaluation, compiled closures beside the interpreting evaluator it replaces."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import mapping

    mapping.main()


def overhead(dmodel_fmu: Path, folder: Path, steps: int = 20_000) -> None:
    """Three instances of the (cheap, C) d-model FMU chained: what each master adds per step per unit."""
    mm = {"fmus": {"{d}": str(dmodel_fmu)},
          "connections": {"{d}.a.movediscrete": ["{d}.b.moveDiscreteCommand"],
                          "{d}.b.movediscrete": ["{d}.c.moveDiscreteCommand"],
                          "{d}.a.target_X": ["{d}.b.MovementArgs_target_X"]},
          # the chain's head is logged too: an unlogged instance that only sends, beside instances of the same
          # FMU that take inputs, is refused as a probable misspelling
          "logVariables": {"{d}.a": ["state"], "{d}.c": ["state"]},
          "algorithm": {"type": "fixed-step", "size": 0.001}, "startTime": 0.0, "endTime": steps * 0.001}
    path = folder / "overhead.json"
    path.write_text(json.dumps(mm))
    model = read_multimodel(path)
    ours = theirs = 1e9
    for _ in range(3):
        t0 = time.perf_counter()
        execution_for(model).run(model.end)
        ours = min(ours, time.perf_counter() - t0)
        t0 = time.perf_counter()
        run_libcosim(model, mm["logVariables"])
        theirs = min(theirs, time.perf_counter() - t0)
    per = lambda seconds: seconds / steps / 3 * 1e6  # noqa: E731
    print(f"master overhead, 3 C FMUs x {steps} steps: cotwin {per(ours):.1f} us/step/unit, "
          f"peer libcosim {per(theirs):.1f} us/step/unit (cotwin/libcosim = {ours / theirs:.2f})")


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
        limit = min(physics_alone(twin) for _ in range(3))
        print(f"peer: the scene's physics alone, {END:g} s in one mj_step call: {limit:.3f} s, "
              f"real-time factor {END / limit:.0f}x (the limit)")
        os.environ["COTWIN_CACHE"] = str(out / "cache")  # IK solutions: none at first, then this run's
        for step, goal in GOALS.items():
            shutil.rmtree(out / "cache", ignore_errors=True)
            cold, _ = experiment(twin, out / "build", out / f"run{step}", step)
            runs = [experiment(twin, out / "build", out / f"run{step}", step) for _ in range(3 if step > 0.001 else 2)]
            stepping, whole = min(runs)
            print(f"20 s experiment, step {step:g} s, physics 1 ms (in-process: d-model FMU, mapping, MuJoCo, CSV): "
                  f"real-time factor {END / stepping:.1f}x with the cell's IK solutions cached from an earlier run "
                  f"(goal >= {goal:g}x{', met' if END / stepping >= goal else ''}; {100 * limit / stepping:.0f}% of the "
                  f"time is physics), {END / cold:.1f}x solving the IK in the run; whole run with set-up {END / whole:.1f}x")
        mapping_step()
        mm = read_multimodel(out / "build" / "multimodel.json")
        ours = theirs = 1e9
        for _ in range(2):
            t0 = time.perf_counter()
            execution_for(mm, out / "fmus.csv").run(mm.end)
            ours = min(ours, time.perf_counter() - t0)
            t0 = time.perf_counter()
            run_libcosim(mm, {"{mapping}.mapping": ["q0"]})
            theirs = min(theirs, time.perf_counter() - t0)
        print(f"20 s experiment, step 0.1 s, all three as FMUs: cotwin simulate {ours:.2f} s, peer libcosim "
              f"{theirs:.2f} s (cotwin/libcosim = {ours / theirs:.2f})")
        overhead(out / "build" / "dmodel.fmu", out)


if __name__ == "__main__":
    main()
