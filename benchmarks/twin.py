"""The UR5e twin end to end, each figure beside its peer measured in this run:
- the paper's 20 s experiment at communication steps 0.1, 0.01 and 0.001 s (physics at 1 ms):
  real-time factor of the stepping (goals >= 200x, >= 50x, >= 5x), judged both cold (the cell's IK
  solved in the run: a user's first run) and warm (IK solutions cached by an earlier run), beside the
  physics alone (the same scene's 20 000 mj_steps in one MuJoCo call: the limit the twin cannot beat);
  the share of the run's time spent in MuJoCo is timed inside the very run it describes;
- the mapping step against the interpreted mapping it replaces;
- the master against libcosim like for like: the same FMUs, cotwin through FMI calls only (its
  in-memory port path switched off) against libcosim's own simulate_until, neither logging, for a chain
  of three C d-model FMUs (overhead per step per unit) and for the whole twin as FMUs.
Figures are the best of a few repetitions: the machine is shared; ratios are taken within one run.
"""

from __future__ import annotations

import gc
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

from cotwin.cosim.libcosim import libcosim_execution  # noqa: E402
from cotwin.cosim.multimodel import execution_for, read_multimodel  # noqa: E402
from cotwin.cosim.observers import Observer  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from cotwin.twin.assembly.build import build  # noqa: E402
from cotwin.twin.assembly.run import load, run_twin  # noqa: E402
from figures import figure, goal  # noqa: E402
from fmicalls import FMICallsOnly  # noqa: E402

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
    gc.collect()
    t0 = time.perf_counter()
    mujoco.mj_step(sim.model, sim.data, steps)
    return time.perf_counter() - t0


class PhysicsClock:
    """Seconds spent inside MuJoCo's mj_step called through the module during a run (the C loops of
    cotwin.mapping.native and cotwin.cosim.native call it directly: not counted)."""

    def __init__(self):
        self.seconds = 0.0
        self._step = mujoco.mj_step

    def __enter__(self):
        def timed(*args, _step=self._step):
            t0 = time.perf_counter()
            _step(*args)
            self.seconds += time.perf_counter() - t0

        mujoco.mj_step = timed
        return self

    def __exit__(self, *exc):
        mujoco.mj_step = self._step


def experiment(twin, build_dir: Path, folder: Path, step: float) -> tuple[float, float, float]:
    """(stepping seconds, whole run seconds, seconds in mj_step) of the 20 s experiment at this step."""
    folder.mkdir(exist_ok=True)
    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(build_dir / name, folder / name)
    watch = Stopwatch()
    with PhysicsClock() as physics:
        t0 = time.perf_counter()
        run_twin(twin, folder, step=step, plot=False, observers=[watch])
        whole = time.perf_counter() - t0
    return watch.seconds, whole, physics.seconds


def mapping_step() -> None:
    """The mapping's event evaluation, compiled closures beside the interpreting evaluator it replaces."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import mapping

    mapping.main()


def masters(mm, repeats: int) -> dict[str, float]:
    """Best seconds of cotwin and libcosim running the multimodel to its end, interleaved, no logging:
    the stepping alone (cotwin: from the end of initialisation; libcosim: simulate_until) and the whole
    run with set-up (instantiating and connecting the FMUs)."""
    best = {"cotwin": 1e9, "libcosim": 1e9, "cotwin whole": 1e9, "libcosim whole": 1e9}
    for _ in range(repeats):
        with FMICallsOnly():
            watch = Stopwatch()
            t0 = time.perf_counter()
            execution_for(mm, observers=[watch]).run(mm.end)
            best["cotwin whole"] = min(best["cotwin whole"], time.perf_counter() - t0)
            best["cotwin"] = min(best["cotwin"], watch.seconds)
        t0 = time.perf_counter()
        ex, _, _ = libcosim_execution(mm)
        t1 = time.perf_counter()
        if not ex.simulate_until(int(round(mm.end * 1e9))):
            raise RuntimeError("libcosim's simulate_until failed")
        t2 = time.perf_counter()
        best["libcosim whole"] = min(best["libcosim whole"], t2 - t0)
        best["libcosim"] = min(best["libcosim"], t2 - t1)
    return best


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
    best = masters(read_multimodel(path), 3)
    ours, theirs = best["cotwin"], best["libcosim"]
    per = lambda seconds: seconds / steps / 3 * 1e6  # noqa: E731
    figure("master stepping, 3 C FMUs chained, FMI calls only", per(ours), "us/step/unit",
           peer="libcosim simulate_until", peer_value=per(theirs),
           whole_run_s=best["cotwin whole"], peer_whole_run_s=best["libcosim whole"])
    print(f"master, 3 C FMUs x {steps} steps, both through FMI calls, no logging: stepping cotwin {ours:.3f} s "
          f"({per(ours):.1f} us/step/unit), peer libcosim simulate_until {theirs:.3f} s ({per(theirs):.1f} us/step/unit); "
          f"cotwin/libcosim = {ours / theirs:.2f}; "
          f"with set-up {best['cotwin whole']:.3f} s against {best['libcosim whole']:.3f} s")


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
        figure("the scene's physics alone, 20 s in one mj_step call", END / limit, "x (real-time factor)")
        print(f"peer: the scene's physics alone, {END:g} s in one mj_step call: {limit:.3f} s, "
              f"real-time factor {END / limit:.0f}x (the limit)")
        os.environ["COTWIN_CACHE"] = str(out / "cache")  # IK solutions: none at first, then this run's
        for step, target in GOALS.items():
            shutil.rmtree(out / "cache", ignore_errors=True)
            cold = experiment(twin, out / "build", out / f"run{step}", step)
            runs = [experiment(twin, out / "build", out / f"run{step}", step) for _ in range(3 if step > 0.001 else 2)]
            warm = min(runs)
            for label, (stepping, whole, physics) in (("cold", cold), ("warm", warm)):
                figure(f"20 s experiment, step {step:g} s, {label}: real-time factor", END / stepping, "x",
                       peer="physics alone", peer_value=END / limit, python_mj_step_share=physics / stepping,
                       whole_run_rtf=END / whole)
                print(f"20 s experiment, step {step:g} s, physics 1 ms, {label} "
                      f"({'IK solved in the run' if label == 'cold' else 'IK solutions cached by an earlier run'}): "
                      f"real-time factor {END / stepping:.1f}x "
                      f"({goal(f'real-time factor at step {step:g} s, {label}', END / stepping, target, unit='x')}); "
                      f"{100 * physics / stepping:.0f}% of this run's stepping in mj_step called from Python (the "
                      f"native loops' physics is not seen here: benchmarks/fused.py profiles it); whole run with set-up "
                      f"{END / whole:.1f}x")
        mapping_step()
        best = masters(read_multimodel(out / "build" / "multimodel.json"), 2)
        figure("20 s experiment, step 0.1 s, all three as FMUs, FMI calls only: stepping", best["cotwin"], "s",
               peer="libcosim simulate_until", peer_value=best["libcosim"],
               whole_run_s=best["cotwin whole"], peer_whole_run_s=best["libcosim whole"])
        print(f"20 s experiment, step 0.1 s, all three as FMUs, both through FMI calls, no logging: stepping cotwin "
              f"{best['cotwin']:.2f} s, peer libcosim simulate_until {best['libcosim']:.2f} s (cotwin/libcosim = "
              f"{best['cotwin'] / best['libcosim']:.2f}); with set-up {best['cotwin whole']:.2f} s against "
              f"{best['libcosim whole']:.2f} s")
        overhead(out / "build" / "dmodel.fmu", out)


if __name__ == "__main__":
    main()
