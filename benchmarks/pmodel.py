"""Platform simulator: microseconds per 1 ms physics step of the Flex-cell scenes (set-points every
2 ms along the paper's four moves), each beside its peers in the same run:
- the scene's physics (bare mj_step on the simulator's model) against a bare mj_step of the same MJCF
  without the Flex-cell (the robot and its gripper): goal scene / robot <= 1.5; and against a
  6-joint capsule arm alone (no gripper, no scene): the physics floor;
- the scene stepped as the twin steps it (PlatformSimulator: set-points by name, checked and clipped)
  against its bare physics: what the simulator adds.
Each figure is the best of several interleaved repetitions (the machine is shared). Also the time to
build the tree, generate the MJCF and load it."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.pmodel import ik  # noqa: E402
from cotwin.pmodel.mjcf import to_mjcf  # noqa: E402
from cotwin_cells.flexcell import Brick, FlexCell  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from cotwin.pmodel.tree import build_tree  # noqa: E402
from cotwin.robosim.check import load_checked  # noqa: E402
from cotwin.robosim.pmodel_elements import Mapping  # noqa: E402
from figures import figure, goal  # noqa: E402

SECONDS = 8.0  # simulated per repetition: the four moves, 2 s each
REPEATS = 5
PERIOD = 2  # physics steps between set-points (the endpoint's CONTROL_PERIOD)

ARM = """<mujoco model="capsule arm">
  <option timestep="0.001" gravity="0 0 -9.81" integrator="implicitfast" cone="elliptic" impratio="10"/>
  <default><geom condim="4" contype="2" conaffinity="1"/><joint armature="0.1" damping="0"/></default>
  <worldbody>
    <body name="l0" gravcomp="1"><geom type="capsule" fromto="0 0 0 0 0 0.16" size="0.06" mass="3.7"/>
      <joint name="j0" axis="0 0 1"/>
      <body name="l1" pos="0 0.13 0.16" gravcomp="1"><joint name="j1" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.425 0 0" size="0.05" mass="8.4"/>
        <body name="l2" pos="0.425 -0.12 0" gravcomp="1"><joint name="j2" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0.39 0 0" size="0.04" mass="2.3"/>
          <body name="l3" pos="0.39 0.1 0" gravcomp="1"><joint name="j3" axis="0 1 0"/>
            <geom type="capsule" fromto="0 0 0 0 0 -0.1" size="0.035" mass="1.2"/>
            <body name="l4" pos="0 0 -0.1" gravcomp="1"><joint name="j4" axis="0 0 1"/>
              <geom type="capsule" fromto="0 0 0 0 0.1 0" size="0.035" mass="1.2"/>
              <body name="l5" pos="0 0.1 0" gravcomp="1"><joint name="j5" axis="0 1 0"/>
                <geom type="cylinder" fromto="0 0 0 0 0.03 0" size="0.04" mass="0.2"/>
              </body></body></body></body></body></body>
  </worldbody>
  <actuator>""" + "".join(f'<position joint="j{i}" kp="2000" kv="150"/>' for i in range(6)) + """</actuator>
</mujoco>"""


def quintic(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    s = min(max(s, 0.0), 1.0)
    return a + (b - a) * s ** 3 * (10 - 15 * s + 6 * s * s)


def setpoints(tree, cell, joints: list[str]) -> np.ndarray:
    """Arm set-points every PERIOD ms along the paper's four moves (holes from the plan, 1.5 s each
    and then holding 0.5 s), as the endpoint would send them."""
    tool = ik.find_tool(tree)
    postures, q = [np.zeros(len(joints))], {}
    for hole in ((0, 23, 1), (3, 20, 2), (8, 10, 0), (1, 13, 0)):
        q = ik.solve(tree, np.array(cell.hole(*hole)), tool=tool, current=q or None).q
        postures.append(np.array([q[j] for j in joints]))
    rows = []
    for a, b in zip(postures, postures[1:]):
        for k in range(int(2.0 / (PERIOD * 1e-3))):
            rows.append(quintic(a, b, k * PERIOD * 1e-3 / 1.5))
    return np.array(rows)


def through_simulator(sim: PlatformSimulator, joints: list[str], points: np.ndarray) -> float:
    sim.reset()
    t0 = time.perf_counter()
    for row in points:
        sim.write_actuators(dict(zip(joints, row.tolist())))
        sim.step(PERIOD)
    return (time.perf_counter() - t0) / (len(points) * PERIOD)


def bare(model: mujoco.MjModel, points: np.ndarray) -> float:
    data = mujoco.MjData(model)
    ctrl = data.ctrl
    n = points.shape[1]
    t0 = time.perf_counter()
    for row in points:
        ctrl[:n] = row
        mujoco.mj_step(model, data, PERIOD)
    return (time.perf_counter() - t0) / (len(points) * PERIOD)


def main() -> None:
    t0 = time.perf_counter()
    project = load_checked([ROOT / "examples" / "ur5e"])
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    tree = build_tree(project)
    mapping = project.elements(Mapping)[0]
    experiment = FlexCell.from_mapping(mapping)
    pick_place = FlexCell.from_mapping(mapping, [Brick("brick1", (8, 10))])
    xml = to_mjcf(tree, experiment)
    t_gen = time.perf_counter() - t0
    t0 = time.perf_counter()
    sims = {"paper's experiment (plate, 384 hole markers)": PlatformSimulator(tree, experiment),
            "pick-and-place (plate, markers, a brick)": PlatformSimulator(tree, pick_place)}
    t_mj = (time.perf_counter() - t0) / len(sims)
    shown = mujoco.MjModel.from_xml_string(xml)
    sim = next(iter(sims.values()))
    print(f"models -> checked project {t_load * 1000:.0f} ms; tree + MJCF text {t_gen * 1000:.1f} ms "
          f"({len(xml) // 1024} KiB); simulator (MuJoCo compile) {t_mj * 1000:.1f} ms")
    print(f"scene as shown: {shown.nbody} bodies, {shown.ngeom} geoms; as simulated (visual markers discarded): "
          f"{sim.model.ngeom} geoms, {sim.model.nu} servos, {len(sim.sensor_names)} sensor ports, "
          f"physics step {sim.timestep * 1000:g} ms")

    arm = ik.arm_joints(tree, ik.find_tool(tree))
    points = setpoints(tree, experiment, arm)
    robot = mujoco.MjModel.from_xml_string(to_mjcf(tree, None, visual=False))
    capsules = mujoco.MjModel.from_xml_string(ARM)
    best: dict[str, float] = {}
    for _ in range(REPEATS):  # interleaved, so that every figure sees the same machine
        for name, s in sims.items():
            best[name] = min(best.get(name, 1e9), through_simulator(s, arm, points))
            best["bare " + name] = min(best.get("bare " + name, 1e9), bare(s.model, points))
        for name, model in (("robot", robot), ("arm", capsules)):
            best[name] = min(best.get(name, 1e9), bare(model, points))
    robot_us, arm_us = best["robot"] * 1e6, best["arm"] * 1e6
    print(f"peer: bare mj_step, the same MJCF without the Flex-cell (robot and gripper): {robot_us:.2f} us/step")
    print(f"peer: bare mj_step, a 6-joint capsule arm alone: {arm_us:.2f} us/step")
    for name in sims:
        physics, us = best["bare " + name] * 1e6, best[name] * 1e6
        figure(f"scene of the {name}: physics", physics, "us/step", peer="the robot alone", peer_value=robot_us,
               arm_us=arm_us, stepped_as_the_twin_does_us=us)
        print(f"scene of the {name}: physics {physics:.2f} us/step; scene/robot = {physics / robot_us:.2f} "
              f"({goal(f'scene/robot, {name}', physics / robot_us, 1.5, at_most=True)}), scene/arm = {physics / arm_us:.2f}; stepped as the twin does {us:.2f} us/step "
              f"(real-time factor {1e3 / us:.0f}x, simulator/bare = {us / physics:.2f})")


if __name__ == "__main__":
    main()
