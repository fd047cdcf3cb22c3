"""Calibration: fit the digital twin to a recorded run of the physical twin (an RTDE log).

What is fitted, from what (docs/calibration.md):
- the cell's geometry: the plate's pose in the robot's frame (6 DoF), the tool's orientation at a
  target and, when the targets were reached with different tool orientations, the tool point; from
  the commanded grid points (what the mapping asks its IK for each command of the plan) against the
  joint angles the PT settled at after each move. The fit also finds corrections of the solver's joint
  origins (kept small by a prior) when the PT's IK solves on other link lengths than the arm's;
- the reference posture of the IK (the PT's first settled posture), so the DT keeps the PT's branch;
- the joint-move profile (URScript movej: acceleration a, speed v of the leading joint) and each
  move's onset, from the set-point trajectories (the measured ones if the log has no set-points);
- the servo lag: how far the PT's measured joints trail its set-point, and the DT's own (simulated)
  lag; the DT's profile starts (PT lag - DT lag) after the command;
- each command's latency: its onset minus the time the plan sends it (the log's first row taken as
  co-simulation time `log_start`).
The result is a `Calibration` (TOML, read by a project's `[platform] calibration` key).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, minimize_scalar
from scipy.spatial.transform import Rotation

from .scenario import Command
from ...config import Key, Schema, TomlFile, dumps, is_number, raise_problems
from ...diagnostics import CotwinError, Finding, Location, Severity
from ...files import write_text
from ...dmodel.program import Program
from ...mapping.motion import MOTION, JointMove, MotionProfile, Quintic, profile_from_values
from ...mapping.rtde import ArmLog, Motion
from ...pmodel import ik
from ...pmodel.cell import GEOMETRY, CellGeometry
from ...pmodel.simulator import PlatformSimulator
from ...pmodel.tree import KinematicTree, matrix_rpy
from .replay import DigitalTwin, JointErrors, OperationCall, commanded_points, joint_errors, operation_calls, replay

ROTATION_WEIGHT = 0.1  # m per rad: 0.01 rad of tool orientation weighs like 1 mm of position
PRIOR = 1e-3  # weight of the solver's joint-origin corrections and of moving the tool point
AXIAL = 0.1  # relative weight of a correction along its joint's axis
SETTLE_WINDOW = 1.0  # s of rest after a move averaged into its settled posture
ONSET_SLACK = 0.3  # s: a fitted onset stays this close to the detected one
SAME_ORIENTATION = 0.05  # rad: tool orientations closer than this leave the tool point unobservable
CLEARANCE = 0.005  # m kept between the plate's top and the robot at every recorded posture


# ---- the calibration file ----
@dataclass
class Timing:
    """What the fitted run's clock says: when each move started and how late it was."""

    log: str
    onsets: list[float]  # s since the log's first row
    latencies: list[float]  # s: onset - planned command time
    servo_lag: float  # s: the PT's measured joints behind its set-point
    simulated_servo_lag: float  # s: the DT's simulated joints behind its set-point
    log_start: float = 0.0  # co-simulation time of the log's first row

    def table(self) -> dict:
        return {"log": self.log, "log_start": self.log_start, "onsets": self.onsets, "latencies": self.latencies,
                "servo_lag": self.servo_lag, "simulated_servo_lag": self.simulated_servo_lag}


@dataclass
class Calibration:
    geometry: CellGeometry
    profile: MotionProfile
    timing: Timing | None = None
    fit: dict = field(default_factory=dict)  # figures of the fit, for the reader (not read back)

    def write(self, path: str | Path, header: str = "") -> Path:
        path = Path(path)
        tables = self.geometry.tables()
        tables["motion"] = self.profile.tables()
        if self.timing is not None:
            tables["timing"] = self.timing.table()
        if self.fit:
            tables["fit"] = self.fit
        return write_text(path, dumps(tables, header or "cotwin calibration"))

    @classmethod
    def read(cls, path: str | Path) -> "Calibration":
        """A calibration file: [plate], [tool], [ik], [motion], [timing] (all optional), [fit] (not read)."""
        file = TomlFile(path, "calibration file")
        problems: list[Finding] = []
        if not any(table in file.data for table in FITTED):
            raise CotwinError([Finding(file.location(), Severity.ERROR, "the calibration file sets none of "
                                       f"{', '.join(f'[{t}]' for t in FITTED)}: it would calibrate nothing "
                                       "(write one with cotwin calibrate --pt-log LOG -o FILE)")])
        values = SCHEMA.read(file.data, file, (), problems)
        _check_bounds(values, file, problems)
        profile = profile_from_values(values["motion"], file, problems, Quintic())
        raise_problems(problems)  # before reading the geometry: a wrong value is left as None
        geometry = CellGeometry.from_values(values, file)
        timing = Timing(**values["timing"]) if values["timing"] is not None else None
        return cls(geometry, profile, timing)


FITTED = ("plate", "tool", "ik", "motion", "timing")  # the tables a calibration sets ([fit] is only read)
METRES, RADIANS, SECONDS = 10.0, 4 * np.pi, 3600.0  # what a fitted cell's values can sensibly be, at most
BOUNDS = {  # key path -> (lowest, highest, unit); lists are checked value by value, "*" is every key of a table
    ("plate", "xyz"): (-METRES, METRES, "m"), ("plate", "rpy"): (-RADIANS, RADIANS, "rad"),
    ("plate", "surface"): (-METRES, METRES, "m"), ("tool", "point"): (-METRES, METRES, "m"),
    ("tool", "rpy"): (-RADIANS, RADIANS, "rad"), ("ik", "reference"): (-RADIANS, RADIANS, "rad"),
    ("ik", "joint_offsets", "*"): (-METRES, METRES, "m"), ("motion", "a"): (0.0, 1000.0, "rad/s^2"),
    ("motion", "v"): (0.0, 100.0, "rad/s"), ("motion", "delay"): (-SECONDS, SECONDS, "s"),
    ("timing", "log_start"): (-1e9, 1e9, "s"), ("timing", "onsets"): (-1e9, 1e9, "s"),
    ("timing", "latencies"): (-SECONDS, SECONDS, "s"), ("timing", "servo_lag"): (-SECONDS, SECONDS, "s"),
    ("timing", "simulated_servo_lag"): (-SECONDS, SECONDS, "s"),
}


def _check_bounds(values: dict, file: TomlFile, problems: list[Finding]) -> None:
    """Every number the calibration gives within BOUNDS (finite is not enough: 1e300 m is no plate pose)."""
    for path, (low, high, unit) in BOUNDS.items():
        table = values.get(path[0]) or {}
        keys = list(table.get(path[1]) or {}) if path[-1] == "*" else [path[1]]
        for key in keys:
            value = table.get(key) if path[-1] != "*" else table[path[1]][key]
            at = path[:1] + ((path[1], key) if path[-1] == "*" else (key,))
            numbers = value if isinstance(value, list) else [value]
            bad = [v for v in numbers if isinstance(v, (int, float)) and not isinstance(v, bool) and not low <= v <= high]
            if bad:
                problems.append(Finding(file.location(at), Severity.ERROR, f"[{path[0]}] {' '.join(at[1:])} must be "
                                        f"within [{low:g}, {high:g}] {unit}, got {bad[0]!r}"))


def _seconds(value) -> str | None:
    if not all(is_number(v) for v in value):
        return f"must be a list of times in seconds, got {value!r}"
    return None


SCHEMA = Schema({
    **GEOMETRY,
    "motion": Key("table", table=MOTION),
    "timing": Key("table", table=Schema({
        "log": Key("str", ""), "log_start": Key("number", 0.0), "onsets": Key("list", [], check=_seconds),
        "latencies": Key("list", [], check=_seconds), "servo_lag": Key("number", 0.0),
        "simulated_servo_lag": Key("number", 0.0)})),
    "fit": Key("table", table=Schema(open=True, values=Key("any"))),
})


# ---- the pieces of the fit ----
def settled_postures(log: ArmLog, motions: list[Motion]) -> np.ndarray:
    """Per move, the mean measured posture over the first SETTLE_WINDOW s at rest after it."""
    t, q, out = log.t, log.q, []
    for m, following in zip(motions, motions[1:] + [None]):
        until = min(m.settled + SETTLE_WINDOW, following.onset if following else np.inf)
        rows = (t >= m.settled) & (t <= until)
        out.append(q[rows].mean(axis=0) if rows.any() else q[min(m.last + 1, len(t) - 1)])
    return np.array(out)


def _kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t minimising |R P + t - Q| (rows are points)."""
    pc, qc = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((P - pc).T @ (Q - qc))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, qc - R @ pc


@dataclass
class GeometryFit:
    geometry: CellGeometry
    position_residuals: np.ndarray  # m, per target: solver tool point vs the fitted hole
    angle_residuals: np.ndarray  # rad, per target
    ik_errors: np.ndarray  # rad, per target and joint: the DT's IK at the hole vs the PT's posture
    tool_observable: bool  # the targets were reached with different tool orientations
    rigid_residuals: np.ndarray  # m, per target, of the plate alone (no solver corrections)


def fit_geometry(tree: KinematicTree, points: np.ndarray, postures: np.ndarray, start: CellGeometry,
                 kinematics: bool = True, reference_name: str = "") -> GeometryFit:
    """The plate's pose, the tool orientation (and the tool point when observable) and, with
    `kinematics`, the solver's joint-origin corrections that make the DT's IK give the PT's postures."""
    points, postures = np.asarray(points, float), np.asarray(postures, float)
    if len(points) < 3 or np.linalg.matrix_rank(points[1:] - points[0], tol=1e-6) < 2:
        raise CotwinError(f"fitting the plate's pose needs at least three commanded targets not on one line; "
                          f"got {len(points)}")
    base_tool = start.find_tool(tree)  # its [tool] link too: the arm the mapping's IK takes
    arm = ik.arm_joints(tree, base_tool)
    n = len(arm)
    tool0 = base_tool.offset[:3, 3].copy()

    def chain(point, offsets) -> ik.Chain:
        T = base_tool.offset.copy()
        T[:3, 3] = point
        return ik.Chain(tree, ik.Tool(base_tool.link, T, base_tool.fingers), dict(zip(arm, offsets.reshape(n, 3))))

    reached = [chain(tool0, np.zeros(3 * n)).pose(q) for q in postures]
    R0, t0 = _kabsch(points, np.array([T[:3, 3] for T in reached]))
    rigid = np.linalg.norm(points @ R0.T + t0 - np.array([T[:3, 3] for T in reached]), axis=1)
    tools = [R0.T @ T[:3, :3] for T in reached]
    spread = max(Rotation.from_matrix(a.T @ b).magnitude() for a in tools for b in tools)
    observable = spread > SAME_ORIENTATION
    free = 3 * n if kinematics else 0
    # corrections along a joint's own axis (link offsets, the usual mismatch) cost less than across it
    joints = {j.name: j for j in tree.joints}
    axes = [joints[name].pose[:3, :3] @ joints[name].axis / np.linalg.norm(joints[name].axis) for name in arm]

    def prior(offsets: np.ndarray) -> list[float]:
        out = []
        for a, d in zip(axes, offsets.reshape(n, 3)):
            along = float(d @ a)
            out.extend(PRIOR * (d - along * a))
            out.append(PRIOR * AXIAL * along)
        return out

    def unpack(x):
        R = Rotation.from_rotvec(x[3:6]).as_matrix()
        Rt = Rotation.from_rotvec(x[6:9]).as_matrix()
        point = x[9:12] if observable else tool0
        offsets = np.concatenate([x[12:12 + free], np.zeros(3 * n - free)])
        return x[:3], R, Rt, point, offsets

    def residuals(x):
        t, R, Rt, point, offsets = unpack(x)
        c = chain(point, offsets)
        out = []
        for p, q in zip(points, postures):
            T = c.pose(q)
            out.extend(T[:3, 3] - (R @ p + t))
            out.extend(ROTATION_WEIGHT * ik.rotation_error(R @ Rt, T[:3, :3]))
        out.extend(PRIOR * (point - tool0))
        out.extend(prior(offsets))
        return np.array(out)

    x0 = np.concatenate([t0, Rotation.from_matrix(R0).as_rotvec(), Rotation.from_matrix(tools[0]).as_rotvec(),
                         tool0, np.zeros(free)])
    solution = least_squares(residuals, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
    t, R, Rt, point, offsets = unpack(solution.x)
    plate = np.eye(4)
    plate[:3, :3], plate[:3, 3] = R, t
    tool = start.tool if not observable or np.allclose(point, tool0, atol=1e-7) else tuple(map(float, point))
    joint_offsets = {j: tuple(float(v) + 0.0 for v in d) for j, d in zip(arm, offsets.reshape(n, 3))
                     if np.abs(d).max() > 1e-7}
    geometry = CellGeometry(tool=tool, tool_rpy=tuple(map(float, matrix_rpy(Rt))), reference=tuple(map(float, postures[0])),
                            reference_name=reference_name, joint_offsets=joint_offsets,
                            tool_link=start.tool_link).with_plate(plate)
    r = residuals(solution.x)[: 6 * len(points)].reshape(len(points), 6)
    solver = ik.Solver(tree, geometry.find_tool(tree), dict(zip(arm, postures[0])), geometry.joint_offsets)
    errors, current = [], postures[0]
    for p, q in zip(points, postures):
        result = solver.solve(geometry.target_pose(p), dict(zip(arm, current)))
        errors.append(np.array([result.q[j] for j in arm]) - q)
        current = q
    return GeometryFit(geometry, np.linalg.norm(r[:, :3], axis=1), np.linalg.norm(r[:, 3:], axis=1) / ROTATION_WEIGHT,
                       np.array(errors), observable, rigid)


def robot_touches_plate(twin: DigitalTwin, geometry: CellGeometry, postures: np.ndarray) -> bool:
    """Whether any moving part of the robot comes within CLEARANCE of the plate at any posture."""
    if twin.scene is None:
        return False
    scene = twin.scene.with_geometry(geometry, payloads=False)
    sim = PlatformSimulator(twin.tree, scene)
    try:
        plate = sim.model.geom("plate").id
    except KeyError:
        return False
    sim.model.geom_margin[plate] = CLEARANCE  # contacts are reported this far out
    arm = twin.arm(geometry)
    for q in postures:
        sim.reset(dict(zip(arm, map(float, q))))
        data = sim.data
        if any(plate in (data.contact[i].geom1, data.contact[i].geom2) for i in range(data.ncon)):
            return True
    return False


def fit_surface(twin: DigitalTwin, geometry: CellGeometry, postures: np.ndarray, lowest: float = -1.0) -> float:
    """The highest plate top (<= 0 in the grid frame) that no recorded posture of the PT touches: the
    PT moved freely, so the plate cannot be where the DT's robot would run into it."""
    def touches(surface):
        return robot_touches_plate(twin, replace_surface(geometry, surface), postures)

    if not touches(0.0):
        return 0.0
    if touches(lowest):
        raise CotwinError(f"the recorded postures touch the plate even with its top {-lowest:g} m below the targets: "
                          "is the plate's fitted pose plausible?")
    low, high = lowest, 0.0  # low is free, high touches
    while high - low > 1e-3:
        middle = (low + high) / 2
        low, high = (low, middle) if touches(middle) else (middle, high)
    return float(low)


def replace_surface(geometry: CellGeometry, surface: float) -> CellGeometry:
    copy = geometry.with_plate(geometry.plate_pose())
    copy.surface = float(surface)
    return copy


@dataclass
class ProfileFit:
    a: float
    v: float
    onsets: list[float]
    rms: float  # rad, set-point model vs the logged series
    v_reached: bool  # some move cruised at v (else v is only bounded below)


def _series(log: ArmLog) -> np.ndarray:
    return log.target_q if log.target_q is not None else log.q


def _model(profile: JointMove, motion: Motion, onset: float, t: np.ndarray) -> np.ndarray:
    delta = motion.end_q - motion.start_q
    distance = float(np.abs(delta).max())
    if distance <= 0:
        return np.tile(motion.start_q, (len(t), 1))
    fraction = np.array([profile.travelled(distance, max(x - onset, 0.0)) / distance for x in t])
    return motion.start_q + fraction[:, None] * delta


def _window(log: ArmLog, motion: Motion, margin: int = 3) -> np.ndarray:
    return np.arange(max(motion.first - margin, 0), min(motion.last + margin + 1, len(log.t)))


def fit_joint_move(log: ArmLog, motions: list[Motion], a: float | None = None, v: float | None = None) -> ProfileFit:
    """movej's a and v (unless given) and every move's onset, fitted to the logged set-points."""
    series, t = _series(log), log.t
    fixed = a is not None and v is not None
    speed = np.abs(np.gradient(series, t, axis=0))
    if not fixed:
        peaks = [speed[_window(log, m)].max() for m in motions]
        v0 = float(max(peaks))
        accel = np.abs(np.gradient(speed, t, axis=0))
        a0 = float(max(accel[_window(log, m)].max() for m in motions))
    onsets0 = np.array([m.onset for m in motions])

    def unpack(x):
        return (a, v, x) if fixed else (x[0], x[1], x[2:])

    def residuals(x):
        aa, vv, onsets = unpack(x)
        profile = JointMove(aa, vv)
        out = []
        for m, onset in zip(motions, onsets):
            rows = _window(log, m)
            out.append((_model(profile, m, onset, t[rows]) - series[rows]).ravel())
        return np.concatenate(out)

    x0 = onsets0.copy() if fixed else np.concatenate([[a0, v0], onsets0])
    lower = onsets0 - ONSET_SLACK if fixed else np.concatenate([[1e-3, 1e-3], onsets0 - ONSET_SLACK])
    upper = onsets0 + ONSET_SLACK if fixed else np.concatenate([[1e3, 1e2], onsets0 + ONSET_SLACK])
    solution = least_squares(residuals, np.clip(x0, lower, upper), bounds=(lower, upper), x_scale="jac",
                             xtol=1e-12, ftol=1e-12, gtol=1e-12)
    aa, vv, onsets = unpack(solution.x)
    reached = any(float(np.abs(m.end_q - m.start_q).max()) > vv * vv / aa for m in motions)
    if not reached:  # no move cruised: v is at least the fastest peak reached
        vv = max(float(np.sqrt(aa * np.abs(m.end_q - m.start_q).max())) for m in motions)
    rms = float(np.sqrt(np.mean(residuals(solution.x) ** 2)))
    return ProfileFit(float(aa), float(vv), [float(o) for o in onsets], rms, reached)


def pt_servo_lag(log: ArmLog, motions: list[Motion], fit: ProfileFit) -> float:
    """The shift (s) that best aligns the PT's measured joints with its fitted set-point trajectory."""
    if log.target_q is None:
        return 0.0  # the set-point was fitted to the measured joints: no lag to see
    profile, t, q = JointMove(fit.a, fit.v), log.t, log.q

    def cost(lag):
        return sum(float(np.sum((_model(profile, m, onset + lag, t[_window(log, m)]) - q[_window(log, m)]) ** 2))
                   for m, onset in zip(motions, fit.onsets))

    return float(minimize_scalar(cost, bounds=(-0.1, 0.3), method="bounded", options={"xatol": 1e-5}).x)


def simulated_servo_lag(twin: DigitalTwin, profile: JointMove, start_q: np.ndarray, end_q: np.ndarray,
                        geometry: CellGeometry | None = None) -> float:
    """The shift (s) that best aligns the DT's simulated joints with its set-point over one move."""
    mapping = twin.mapping(geometry, JointMove(profile.a, profile.v))
    endpoint, arm = mapping.endpoint, mapping.registry.arm
    endpoint.place(dict(zip(arm, map(float, start_q))))
    endpoint.start()
    endpoint.command(dict(zip(arm, map(float, end_q))))
    segment = endpoint.segment
    times, measured = [], []
    while endpoint.time < segment.end + 0.3:
        endpoint.advance(0.005)
        q = endpoint.joint_positions()
        times.append(endpoint.time)
        measured.append([q[j] for j in arm])
    times, measured = np.array(times), np.array(measured)

    def cost(lag):
        setpoint = np.array([[segment.at(x - lag)[j] for j in arm] for x in times])
        return float(np.sum((setpoint - measured) ** 2))

    return float(minimize_scalar(cost, bounds=(-0.1, 0.3), method="bounded", options={"xatol": 1e-5}).x)


# ---- the whole calibration ----
@dataclass
class Move:
    """A command of the plan that moves the arm, with what it asks of the mapping."""

    command: Command
    calls: list[OperationCall]
    point: tuple[float, float, float]  # the grid point asked of the IK


def plan_moves(twin: DigitalTwin, program: Program, commands: list[Command]) -> list[Move]:
    """The commands that move the arm (their operations ask the IK for a grid point), in plan order."""
    calls = [operation_calls(program, c) for c in commands]
    points = commanded_points(twin, calls)
    return [Move(c, group, asked[-1]) for c, group, asked in zip(commands, calls, points) if asked]


def paired(log: ArmLog, moves: list[Move], where: str) -> list[Motion]:
    motions = log.motions()
    if len(motions) != len(moves):
        raise CotwinError([Finding(Location(str(log.path), 1, 1), Severity.ERROR,
                                   f"the log has {len(motions)} move(s) but {where} commands {len(moves)}: "
                                   "is this a recording of that plan?")])
    return motions


@dataclass
class CalibrationReport:
    calibration: Calibration
    before: JointErrors
    after: JointErrors
    geometry_fit: GeometryFit
    profile_fit: ProfileFit
    pt_lag: float
    dt_lag: float
    moves: list[Move]

    def lines(self) -> list[str]:
        g, p = self.calibration.geometry, self.profile_fit
        deg = np.degrees
        out = [f"fitted on {self.calibration.timing.log}: {len(self.moves)} moves",
               f"plate in the robot's frame: xyz = ({', '.join(f'{v:.4f}' for v in g.plate_xyz)}) m, "
               f"rpy = ({', '.join(f'{v:.2f}' for v in deg(g.plate_rpy))}) deg",
               f"tool point: {g.tool if isinstance(g.tool, str) else tuple(round(v, 5) for v in g.tool)}"
               + ("" if self.geometry_fit.tool_observable else " (not observable: the tool kept one orientation)")
               + f"; tool orientation in the plate frame: rpy = ({', '.join(f'{v:.2f}' for v in deg(g.tool_rpy))}) deg",
               f"plate's top {1000 * g.surface:.0f} mm along the plate's normal from the targets' grid frame "
               "(as high as the recorded postures allow)",
               f"plate alone (rigid) misses the PT's targets by up to {1000 * self.geometry_fit.rigid_residuals.max():.1f} mm",
               "solver joint-origin corrections (mm): " + (", ".join(
                   f"{j} ({', '.join(f'{1000 * v:.1f}' for v in d)})" for j, d in g.joint_offsets.items()) or "none"),
               f"fit residual: {1000 * self.geometry_fit.position_residuals.max():.3f} mm, "
               f"{deg(self.geometry_fit.angle_residuals.max()):.4f} deg; DT IK vs PT postures: "
               f"{np.abs(self.geometry_fit.ik_errors).max():.2e} rad",
               f"joint move (movej): a = {p.a:.3f} rad/s^2, v = {p.v:.3f} rad/s"
               + ("" if p.v_reached else " (no move cruised: v is a lower bound)") + f", set-point fit RMS {p.rms:.4f} rad",
               f"onsets (s since the log's first row): {', '.join(f'{o:.3f}' for o in p.onsets)}",
               f"latencies (s after the plan's command): {', '.join(f'{x:.3f}' for x in self.calibration.timing.latencies)}",
               f"servo lag: PT {1000 * self.pt_lag:.1f} ms, DT {1000 * self.dt_lag:.1f} ms -> set-point delay "
               f"{1000 * self.calibration.profile.delay:.1f} ms"]
        out += self.before.lines("before (the project's DT):")
        out += self.after.lines("after (calibrated):")
        return out


CALIBRATION_STAGES = ("planning the moves", "fitting the geometry", "fitting the plate's surface",
                      "fitting the motion profile", "measuring the servo lags", "replaying before and after")


def calibrate(twin: DigitalTwin, program: Program, commands: list[Command], log: ArmLog,
              start: CellGeometry | None = None, log_start: float = 0.0, kinematics: bool = True,
              progress=None) -> CalibrationReport:
    """Fit the DT to the PT's recorded run of `commands` (see the module's docstring); `progress(k, n,
    stage)` is told as each of CALIBRATION_STAGES begins."""
    stage = iter(enumerate(CALIBRATION_STAGES))

    def next_stage() -> None:
        if progress is not None:
            k, what = next(stage)
            progress(k, len(CALIBRATION_STAGES), what)

    start = start or CellGeometry(tool="flange")
    next_stage()
    moves = plan_moves(twin, program, commands)
    motions = paired(log, moves, "the plan")
    postures = settled_postures(log, motions)
    name = f"settled posture after move 1 of {Path(log.path).name}"
    next_stage()
    geometry_fit = fit_geometry(twin.tree, np.array([m.point for m in moves]), postures, start, kinematics, name)
    next_stage()
    geometry_fit.geometry.surface = fit_surface(twin, geometry_fit.geometry, log.q)
    next_stage()
    profile_fit = fit_joint_move(log, motions)
    next_stage()
    pt_lag = pt_servo_lag(log, motions, profile_fit)
    first = motions[0]
    dt_lag = simulated_servo_lag(twin, JointMove(profile_fit.a, profile_fit.v), first.start_q, first.end_q,
                                 geometry_fit.geometry)
    profile = JointMove(profile_fit.a, profile_fit.v, pt_lag - dt_lag)
    latencies = [log_start + onset - move.command.time for onset, move in zip(profile_fit.onsets, moves)]
    timing = Timing(Path(log.path).name, profile_fit.onsets, latencies, pt_lag, dt_lag, log_start)
    calibration = Calibration(geometry_fit.geometry, profile, timing)
    schedule = [(onset, call) for onset, move in zip(profile_fit.onsets, moves) for call in move.calls]
    next_stage()
    before_q = replay(twin, schedule, log.t, log.q[0])  # the DT as it is
    after_q = replay(twin, schedule, log.t, log.q[0], calibration.geometry, calibration.profile)
    joints = twin.arm()
    before = joint_errors(log, before_q, joints, motions)
    after = joint_errors(log, after_q, joints, motions)
    calibration.fit = {"rmse_motion_before": [float(v) for v in before.motion],
                       "rmse_motion_after": [float(v) for v in after.motion],
                       "settled_error_after": [float(v) for v in after.settled],
                       "plate_rigid_residual_mm": float(1000 * geometry_fit.rigid_residuals.max()),
                       "setpoint_rms": profile_fit.rms}
    if progress is not None:
        progress(len(CALIBRATION_STAGES), len(CALIBRATION_STAGES), "done")
    return CalibrationReport(calibration, before, after, geometry_fit, profile_fit, pt_lag, dt_lag, moves)


@dataclass
class CheckReport:
    log: str
    onsets: list[float]
    errors: JointErrors

    def lines(self) -> list[str]:
        return [f"replayed {len(self.onsets)} moves of {self.log} at its onsets "
                f"({', '.join(f'{o:.3f}' for o in self.onsets)} s)"] + self.errors.lines("calibrated DT vs the log:")


def check(twin: DigitalTwin, program: Program, commands: list[Command], log: ArmLog,
          calibration: Calibration) -> CheckReport:
    """Replay another recorded run of the plan on the calibrated DT, at that log's onsets."""
    moves = plan_moves(twin, program, commands)
    motions = paired(log, moves, "the plan")
    profile = calibration.profile
    if isinstance(profile, JointMove):
        onsets = fit_joint_move(log, motions, profile.a, profile.v).onsets
    else:
        onsets = [m.onset for m in motions]
    schedule = [(onset, call) for onset, move in zip(onsets, moves) for call in move.calls]
    q = replay(twin, schedule, log.t, log.q[0], calibration.geometry, profile)
    joints = twin.arm()
    return CheckReport(Path(log.path).name, onsets, joint_errors(log, q, joints, motions))


# ---- a twin project's calibration (what `cotwin calibrate` runs) ----
def project_twin(system) -> tuple[DigitalTwin, Program, list[Command]]:
    """The DT parts, d-model and plan of a TwinSystem (cotwin.twin.assembly.system), as the fit takes them."""
    models = system.models
    if not system.commands:
        raise CotwinError([Finding(Location(str(system.spec.path), 1, 1), Severity.ERROR,
                                   "calibration replays the plan the PT ran: the project needs [scenario] plan "
                                   "or commands")])
    calibration = models.calibration  # the project's own, if it names one
    twin = DigitalTwin(models.project, models.tree, models.scene, calibration and calibration.profile,
                       calibration and calibration.geometry)
    return twin, models.program, system.commands
