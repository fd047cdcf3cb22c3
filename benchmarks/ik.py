"""Inverse kinematics: cotwin's deterministic solver (cotwin.pmodel.ik) against mink (differential IK on
MuJoCo: a frame task, a posture task towards the same reference posture, configuration limits; daqp),
each figure beside the other's in the same run, on
- the UR5e example (6 joints) in its calibrated cell (examples/ur5e/calibration.toml: plate pose, tool,
  reference posture, joint-origin corrections): its plate's holes, the targets the twin solves;
- the Franka Panda imported from example-robot-data (7 joints, redundant): a workspace grid in front of
  it, tool down, and random reachable poses (forward kinematics of random joints within limits).
Figures: success rate (within 0.1 mm and 1 mrad), time per solve (median, and the slowest), the error
reached, and determinism: the spread of the joints found for one target from 20 random start postures
(cotwin solves from any start; mink from the start, its natural use, and from the reference posture).
Goals (exit 1 if missed): the kept solver (cotwin's) reaches every target mink reaches, and gives the
same joints from every start. Needs example-robot-data and mink (the test extra); the Panda is skipped, saying so,
without them.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.pmodel import ik  # noqa: E402
from cotwin.pmodel.mjcf import to_mjcf  # noqa: E402
from cotwin_cells.flexcell import FlexCell  # noqa: E402
from cotwin.pmodel.tree import build_tree, transform  # noqa: E402
from cotwin.pmodel.xmltext import quat  # noqa: E402
from cotwin.robosim.check import load_checked  # noqa: E402
from cotwin.robosim.pmodel_elements import Mapping  # noqa: E402
from cotwin.twin.assembly.calibration import Calibration  # noqa: E402

POSITION_TOL, ANGLE_TOL = 1e-4, 1e-3  # m, rad: success
STARTS = 20


class MinkSolver:
    """mink's differential IK run to convergence: a FrameTask on a site at the tool frame, a PostureTask
    (cost 1e-5, next to the frame task's 1) towards the reference posture, ConfigurationLimit; joint-origin
    corrections applied to the MuJoCo model's bodies as cotwin's Chain applies them."""

    def __init__(self, tree, tool, reference: np.ndarray, offsets: dict | None = None, iterations: int = 200):
        import mink
        import mujoco

        self.mink = mink
        spec = mujoco.MjSpec.from_string(to_mjcf(tree, None, visual=False))
        spec.body(tool.link).add_site(name="ik_tool", pos=tool.offset[:3, 3], quat=quat(tool.offset[:3, :3]))
        for joint, d in (offsets or {}).items():  # the joint's origin and all beyond it, by d (model frame)
            j = next(x for x in tree.joints if x.name == joint)
            body = spec.body(j.child)
            body.pos = np.asarray(body.pos) + tree.link(j.parent).pose[:3, :3].T @ np.asarray(d, float)
        self.model = spec.compile()
        self.arm = ik.arm_joints(tree, tool)
        self.adr = [int(self.model.jnt_qposadr[self.model.joint(j).id]) for j in self.arm]
        self.configuration = mink.Configuration(self.model)
        self.frame = mink.FrameTask("ik_tool", "site", position_cost=1.0, orientation_cost=1.0)
        self.posture = mink.PostureTask(self.model, cost=1e-5)
        self.home = self.model.qpos0.copy()
        self.home[self.adr] = reference
        self.posture.set_target(self.home)
        self.limits = [mink.ConfigurationLimit(self.model)]
        self.iterations = iterations

    def solve(self, target: np.ndarray, start: np.ndarray | None = None):
        """(arm joints, position error, angle error, iterations) from `start` (default: the reference)."""
        q = self.home.copy()
        if start is not None:
            q[self.adr] = start
        self.configuration.update(q)
        self.frame.set_target(self.mink.SE3.from_matrix(target))
        for k in range(1, self.iterations + 1):
            v = self.mink.solve_ik(self.configuration, [self.frame, self.posture], 1.0, "daqp", damping=1e-9,
                                   limits=self.limits)
            self.configuration.integrate_inplace(v, 1.0)
            e = self.frame.compute_error(self.configuration)
            if np.linalg.norm(e[:3]) < 1e-9 and np.linalg.norm(e[3:]) < 1e-9:
                break
        e = self.frame.compute_error(self.configuration)
        return self.configuration.q[self.adr].copy(), float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])), k


def pose_error(chain: ik.Chain, q: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """Errors of joints q judged by cotwin's chain (the same kinematics for both solvers)."""
    T = chain.pose(q)
    return float(np.linalg.norm(T[:3, 3] - target[:3, 3])), float(np.linalg.norm(ik.rotation_error(target[:3, :3], T[:3, :3])))


def run_cotwin(solver: ik.Solver, targets):
    rows = []
    for T in targets:
        t0 = time.perf_counter()
        r = solver.branch(T)
        rows.append((time.perf_counter() - t0, np.array([r.q[j] for j in solver.joints])))
    return rows


def run_mink(solver: MinkSolver, targets):
    rows = []
    for T in targets:
        t0 = time.perf_counter()
        q = solver.solve(T)[0]
        rows.append((time.perf_counter() - t0, q))
    return rows


def summary(name: str, rows, chain, targets, reference: np.ndarray) -> dict:
    times = [t for t, _ in rows]
    errors = [pose_error(chain, q, T) for (_, q), T in zip(rows, targets)]
    reached = [p <= POSITION_TOL and a <= ANGLE_TOL for p, a in errors]
    distance = [float(np.linalg.norm((q - reference + np.pi) % (2 * np.pi) - np.pi)) for (_, q), r in zip(rows, reached) if r]
    return {"name": name, "reached": reached, "ok": sum(reached), "n": len(rows),
            "median_ms": 1000 * statistics.median(times), "max_ms": 1000 * max(times),
            "worst_ok_error": max((p for p, a in errors if p <= POSITION_TOL), default=0.0),
            "distance": statistics.mean(distance) if distance else float("nan")}


def determinism(chain, cotwin: ik.Solver, minker: MinkSolver, targets, seed: int = 11) -> dict:
    """Largest spread (rad) of the joints found for one target from STARTS random start postures."""
    rng = np.random.default_rng(seed)
    lo, hi = np.maximum(chain.lower, -np.pi), np.minimum(chain.upper, np.pi)
    spread = {"cotwin": 0.0, "mink from the start": 0.0, "mink from the reference": 0.0}
    for T in targets:
        found = {k: [] for k in spread}
        for _ in range(STARTS):
            start = lo + (hi - lo) * rng.random(len(lo))
            found["cotwin"].append(np.array(list(cotwin.solve(T, dict(zip(cotwin.joints, start))).q.values())))
            found["mink from the start"].append(minker.solve(T, start)[0])
            found["mink from the reference"].append(minker.solve(T)[0])
        for k, qs in found.items():  # the base joint modulo a turn (cotwin keeps it on the turn nearest the start)
            d = np.array(qs) - qs[0]
            d[:, 0] = (d[:, 0] + np.pi) % (2 * np.pi) - np.pi
            spread[k] = max(spread[k], float(np.abs(d).max()))
    return spread


def compare(label: str, tree, tool, reference, offsets, grid, extra=()) -> bool:
    solver = ik.Solver(tree, tool, dict(zip(ik.arm_joints(tree, tool), reference)), offsets)
    minker = MinkSolver(tree, tool, np.asarray(reference, float), offsets)
    chain = solver.chain
    sets = [("grid", grid)] + ([("random reachable poses", list(extra))] if len(extra) else [])
    good = True
    print(f"{label}: {len(chain.joints)} joints, tool {tool.link}; machine shared (figures side by side, same run)")
    reference = np.asarray(reference, float)
    for set_name, targets in sets:
        ours = summary("cotwin", run_cotwin(solver, targets), chain, targets, reference)
        theirs = summary("mink", run_mink(minker, targets), chain, targets, reference)
        for s in (ours, theirs):
            print(f"  {set_name}: {s['name']:<7} success {s['ok']}/{s['n']}, {s['median_ms']:.1f} ms per solve "
                  f"(slowest {s['max_ms']:.0f} ms), worst error of a success {s['worst_ok_error']:.1e} m, "
                  f"mean distance of a success from the reference posture {s['distance']:.2f} rad")
        neither = sum(not a and not b for a, b in zip(ours["reached"], theirs["reached"]))
        if neither:
            print(f"  {set_name}: {neither} target(s) neither solver reaches (out of the arm's reach)")
        missed = sum(b and not a for a, b in zip(ours["reached"], theirs["reached"]))
        if missed:
            print(f"  GOAL MISSED: {missed} target(s) mink reaches and cotwin's solver does not")
            good = False
    spread = determinism(chain, solver, minker, grid[:: max(1, len(grid) // 3)][:3])
    print("  determinism, largest spread of the joints over 20 random start postures (3 targets): "
          + "; ".join(f"{k} {v:.2g} rad" for k, v in spread.items()))
    if spread["cotwin"] != 0.0:
        print("  GOAL MISSED: cotwin's solver gives different joints from different starts")
        good = False
    return good


def ur5e() -> bool:
    project = load_checked([ROOT / "examples" / "ur5e"])
    tree = build_tree(project)
    geometry = Calibration.read(ROOT / "examples" / "ur5e" / "calibration.toml").geometry
    cell = FlexCell.from_mapping(project.elements(Mapping)[0], geometry=geometry)
    holes = [geometry.target_pose(cell.hole(X, Y, Z)) for X in range(0, 16, 3) for Y in range(0, 24, 5) for Z in (0, 2)]
    tool = ik.find_tool(tree, geometry.tool)
    return compare("UR5e example, calibrated cell's holes", tree, tool, geometry.reference, geometry.joint_offsets, holes)


def panda() -> bool:
    try:
        import importlib.metadata

        import mink  # noqa: F401

        share = Path(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data"))
    except (ImportError, importlib.metadata.PackageNotFoundError):
        print("Panda skipped: example-robot-data or mink is not installed (pip install -e '.[test]')")
        return True
    from cotwin.pmodel.urdf_import import import_urdf

    with tempfile.TemporaryDirectory() as folder:  # the meshes stay there while MuJoCo loads them
        result = import_urdf(share / "robots/panda_description/urdf/panda.urdf", folder, check=False)
        tree = build_tree(load_checked([result.file]))
        tool = ik.find_tool(tree)
        chain = ik.Chain(tree, tool)
        reference = np.clip((chain.lower + chain.upper) / 2, chain.lower, chain.upper)  # mid-range: a neutral posture
        grid = [transform((x, y, z), (np.pi, 0.0, 0.0)) for x in (0.3, 0.4, 0.5, 0.6) for y in (-0.3, -0.1, 0.1, 0.3)
                for z in (0.1, 0.3, 0.5)]
        rng = np.random.default_rng(3)
        reachable = [chain.pose(chain.lower + (chain.upper - chain.lower) * rng.random(len(chain.joints)))
                     for _ in range(24)]
        return compare("Franka Panda (example-robot-data), grid in front, tool down", tree, tool, reference, {}, grid,
                       reachable)


def main() -> None:
    results = [ur5e(), panda()]
    if not all(results):
        sys.exit(1)


if __name__ == "__main__":
    main()
