"""d-model FMU: microseconds per FMU step through FMPy (set inputs, doStep, get outputs), with the
reference interpreter's cycle as the peer in the same run; FMU build time; verifier state space."""

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
from cotwin.dmodel.runner import FMUDriver  # noqa: E402
from cotwin.dmodel.verify import verify  # noqa: E402
from cotwin.robosim.check import load_checked  # noqa: E402

ARGS = {"target_X": 3, "target_Y": 20, "target_Z": 2}
SCENARIO = [{}, {"moveDiscreteCommand": ARGS}, {"feasibleMoveDiscreteCommand": None}, {}, {},
            {"moveCompleted": None}, {"robotStopped": None}, {}]


def bench(model: Path, steps: int = 20_000) -> None:
    t0 = time.perf_counter()
    program = build_program(load_checked([model]))
    t_model = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        fmu = build_fmu(program, Path(tmp) / "m.fmu")
        t_build = time.perf_counter() - t0
        driver = FMUDriver(program, fmu)
        t0 = time.perf_counter()
        for k in range(steps):
            driver.step(SCENARIO[k % len(SCENARIO)])
        t_fmu = (time.perf_counter() - t0) / steps
        driver.close()
    interp = Interpreter(program)
    t0 = time.perf_counter()
    for k in range(steps):
        interp.step(SCENARIO[k % len(SCENARIO)])
    t_interp = (time.perf_counter() - t0) / steps
    report = verify(program)
    print(f"{model.name}: parse+check+program {t_model * 1000:.0f} ms, FMU build (C gen + cc + zip) {t_build * 1000:.0f} ms")
    print(f"  FMU step through FMPy (set inputs, doStep, get outputs): {t_fmu * 1e6:.1f} us/step")
    print(f"  peer, reference interpreter cycle: {t_interp * 1e6:.1f} us/cycle  (FMU/interpreter = {t_fmu / t_interp:.2f})")
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
