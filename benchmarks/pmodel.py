"""Platform simulator: microseconds per 1 ms physics step and real-time factor of the UR5e Flex-cell
scene (arm, gripper, plate, bricks) while the arm moves; peer: a bare mujoco.mj_step loop on the same
model in the same run. Also the time to build the tree, generate the MJCF and load it."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.pmodel.mjcf import to_mjcf  # noqa: E402
from cotwin.pmodel.scene import Brick, FlexCell  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from cotwin.pmodel.tree import build_tree  # noqa: E402
from cotwin.robosim.check import load_checked  # noqa: E402
from cotwin.robosim.pmodel_elements import Mapping  # noqa: E402


def main(seconds: float = 10.0) -> None:
    t0 = time.perf_counter()
    project = load_checked([ROOT / "examples" / "ur5e"])
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    tree = build_tree(project)
    cell = FlexCell.from_mapping(project.elements(Mapping)[0],
                                 [Brick(f"brick{i}", hole) for i, hole in enumerate([(8, 10), (4, 12), (10, 6), (2, 14)])])
    xml = to_mjcf(tree, cell)
    t_gen = time.perf_counter() - t0
    t0 = time.perf_counter()
    sim = PlatformSimulator(tree, cell)
    t_mj = time.perf_counter() - t0
    print(f"models -> checked project {t_load * 1000:.0f} ms; tree + MJCF text {t_gen * 1000:.1f} ms "
          f"({len(xml) // 1024} KiB); simulator (MuJoCo compile) {t_mj * 1000:.1f} ms")
    print(f"scene: {sim.model.nbody} bodies, {sim.model.ngeom} geoms, {sim.model.nu} servos, "
          f"{len(sim.sensor_names)} sensor ports, physics step {sim.timestep * 1000:g} ms")

    targets = [{j: 0.5 * np.sin(k + i) for i, j in enumerate(sim.joint_names) if "finger" not in j} for k in range(10)]
    steps = int(seconds / sim.timestep)
    t0 = time.perf_counter()
    for k in range(10):
        sim.write_actuators(targets[k])
        sim.advance(seconds / 10)
        sim.read_sensors()
    ours = time.perf_counter() - t0
    model, data = mujoco.MjModel.from_xml_string(xml), None
    data = mujoco.MjData(model)
    t0 = time.perf_counter()
    for k in range(10):
        data.ctrl[:6] = list(targets[k].values())
        for _ in range(steps // 10):
            mujoco.mj_step(model, data)
    bare = time.perf_counter() - t0
    print(f"{seconds:g} s simulated: PlatformSimulator {ours / steps * 1e6:.1f} us/step, real-time factor {seconds / ours:.0f}x")
    print(f"peer, bare mj_step loop on the same model: {bare / steps * 1e6:.1f} us/step "
          f"(ours/bare = {ours / bare:.2f})")


if __name__ == "__main__":
    main()
