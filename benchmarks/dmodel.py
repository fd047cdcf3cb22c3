"""d-model FMU: microseconds per FMU step through FMI calls (fmi2Set inputs, fmi2DoStep, fmi2Get
outputs), and through cotwin's in-memory port path, with the reference interpreter's cycle as the peer
in the same run; FMU build time; verifier state space."""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.dmodel.fmu import build_fmu  # noqa: E402
from cotwin.dmodel.interpreter import Interpreter  # noqa: E402
from cotwin.dmodel.program import build_program  # noqa: E402
from cotwin.cosim.driver import FMUDriver  # noqa: E402
from cotwin.dmodel.verify import verify  # noqa: E402
from cotwin.robosim.check import load_checked  # noqa: E402
from figures import figure  # noqa: E402
from fmicalls import FMICallsOnly  # noqa: E402

ARGS = {"target_X": 3, "target_Y": 20, "target_Z": 2}
SCENARIO = [{}, {"moveDiscreteCommand": ARGS}, {"feasibleMoveDiscreteCommand": None}, {}, {},
            {"moveCompleted": None}, {"robotStopped": None}, {}]


def per_step(runner, steps: int) -> float:
    t0 = time.perf_counter()
    for k in range(steps):
        runner.step(SCENARIO[k % len(SCENARIO)])
    return (time.perf_counter() - t0) / steps


def bench(model: Path, steps: int = 10_000, repeats: int = 3) -> None:
    t0 = time.perf_counter()
    program = build_program(load_checked([model]))
    t_model = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        fmu = build_fmu(program, Path(tmp) / "m.fmu")
        t_build = time.perf_counter() - t0
        with FMICallsOnly():
            through_calls = FMUDriver(program, fmu)
        runners = {"FMI calls": through_calls, "in-memory ports": FMUDriver(program, fmu), "interpreter": Interpreter(program)}
        best = dict.fromkeys(runners, 1e9)
        for _ in range(repeats):  # interleaved: the machine's load hits all three alike
            for name, runner in runners.items():
                best[name] = min(best[name], per_step(runner, steps))
        through_calls.close()
        runners["in-memory ports"].close()
    t_interp = best.pop("interpreter")
    t_fmu = best
    report = verify(program)
    print(f"{model.name}: parse+check+program {t_model * 1000:.0f} ms, FMU build (C gen + cc + zip) {t_build * 1000:.0f} ms")
    for path, seconds in t_fmu.items():
        figure(f"{model.name}: d-model FMU step through {path}", seconds * 1e6, "us/step",
               peer="reference interpreter cycle", peer_value=t_interp * 1e6)
        print(f"  FMU step through {path} (set inputs, doStep, get outputs): {seconds * 1e6:.1f} us/step; "
              f"peer, reference interpreter cycle: {t_interp * 1e6:.1f} us/cycle (FMU/interpreter = {seconds / t_interp:.2f})")
    print(f"  verify: {report.states} states, {report.cycles} cycles explored "
          f"({report.input_combinations} input combinations/state) in {report.seconds:.2f} s, "
          f"{len(report.violations)} violation(s)")


def main() -> None:
    shared = ROOT.parent / "shared" / "robosim" / "ur5e" / "ur5e_gripper.rst"
    if shared.is_file():
        bench(shared)
    bench(ROOT / "examples" / "ur5e" / "arm.rst")


if __name__ == "__main__":
    main()
