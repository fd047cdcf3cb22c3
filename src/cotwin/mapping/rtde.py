"""UR RTDE logs: space-separated, one header row of RTDE output fields (vectors expanded `_0`..`_5`),
one row per sample. Read strictly: every problem is an error at its line and column (a missing or
repeated column, a short or long row, a cell that is not a finite number, an oversized field, bytes
that are not text, a joint angle, speed or TCP coordinate beyond any UR arm's (RANGES), time that does
not increase or jumps by more than MAX_GAP), up to MAX_ERRORS of them at once.

Two views of a log:
- `RTDELog`: the fields as logged (the controller's convention): `column`, `vector`, `times`, `q`, `qd`;
- `ArmLog`: the arm in the p-model's convention (a `Convention` read from the project's robot profile,
  cotwin.mapping.profile: joint offsets and the controller's base frame in the model frame; by default
  the identity): time since the first row, measured and set-point joints, TCP poses, and
  the moves found in the log (`motions()`: a move starts when a joint's speed leaves rest, its onset
  placed between samples by extrapolating the leading joint's speed back to zero, and settles when
  every joint is back at rest).
"""

from __future__ import annotations

import math
import stat
from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..diagnostics import CotwinError, Diagnostics, Finding, Location, Severity
from ..files import write_text
from .profile import IDENTITY, Convention

JOINTS = 6
MAX_FIELD = 64  # characters: a number needs fewer; anything longer is reported, not parsed
MAX_BYTES = 1 << 29  # a log is read into memory (about 30 s a 512 MiB): cut longer runs to what is needed
MAX_ERRORS = 20  # findings reported from one file before giving up
REST_SPEED = 0.01  # rad/s: below this on every joint, the arm is at rest
MAX_GAP = 10.0  # s between two samples: an RTDE recording is continuous (2-125 ms); a longer jump is corruption
# The largest magnitude of the fields cotwin reads: UR joints turn +-360 deg at up to 360 deg/s, in a reach of
# a few metres; two turns, twice that speed and 100 m leave room for every UR and flag what no arm could do.
RANGES = {"actual_q": (4 * math.pi, "rad"), "target_q": (4 * math.pi, "rad"), "actual_qd": (4 * math.pi, "rad/s"),
          "target_qd": (4 * math.pi, "rad/s"), "actual_TCP_pose": (100.0, "m or rad")}
ARM = ("timestamp", *(f"actual_q_{k}" for k in range(JOINTS)))
LIVE = (*ARM, *(f"actual_qd_{k}" for k in range(JOINTS)))


@dataclass
class RTDELog:
    """The fields of a log as written (UR convention)."""

    path: str
    columns: list[str]
    data: np.ndarray  # (rows, columns)

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.columns.index(name)]

    def has(self, field_name: str, n: int = JOINTS) -> bool:
        return all(f"{field_name}_{k}" in self.columns for k in range(n))

    def vector(self, field_name: str, n: int = JOINTS) -> np.ndarray:
        return np.column_stack([self.column(f"{field_name}_{k}") for k in range(n)])

    @property
    def times(self) -> np.ndarray:
        return self.column("timestamp")

    @property
    def q(self) -> np.ndarray:
        return self.vector("actual_q")

    @property
    def qd(self) -> np.ndarray:
        return self.vector("actual_qd")


@dataclass
class Motion:
    """One move of the arm in a log (times on the log's clock, seconds since its first row)."""

    onset: float  # when the set-point started to move (between samples)
    settled: float  # the first sample at rest again
    first: int  # row of the first moving sample
    last: int  # row of the last moving sample
    start_q: np.ndarray  # joints at rest before (p-model convention)
    end_q: np.ndarray  # joints at rest after

    @property
    def duration(self) -> float:
        return self.settled - self.onset


@dataclass
class ArmLog:
    """The arm's series of an RTDE log in the p-model's convention."""

    raw: RTDELog
    convention: Convention = IDENTITY

    @property
    def path(self) -> Path:
        return Path(self.raw.path)

    @property
    def timestamp(self) -> np.ndarray:
        """s, the controller's clock."""
        return self.raw.times

    @property
    def t(self) -> np.ndarray:
        """Seconds since the log's first row."""
        return self.raw.times - self.raw.times[0]

    @property
    def q(self) -> np.ndarray:
        """Measured joint angles (n x 6)."""
        return self.convention.to_model(self.raw.q)

    @property
    def qd(self) -> np.ndarray:
        """Measured joint speeds (n x 6); differentiated from q when the log has none."""
        return self.raw.qd if self.raw.has("actual_qd") else np.gradient(self.q, self.t, axis=0)

    @property
    def target_q(self) -> np.ndarray | None:
        """The controller's set-points (n x 6), if logged."""
        return self.convention.to_model(self.raw.vector("target_q")) if self.raw.has("target_q") else None

    @property
    def target_qd(self) -> np.ndarray | None:
        return self.raw.vector("target_qd") if self.raw.has("target_qd") else None

    @property
    def tcp(self) -> np.ndarray | None:
        """The measured TCP pose per row (n x 4 x 4) in the model frame, if logged."""
        if not self.raw.has("actual_TCP_pose"):
            return None
        return np.array([self.convention.pose_to_model(pose_matrix(row)) for row in self.raw.vector("actual_TCP_pose")])

    def sample(self, time: float) -> dict[str, np.ndarray]:
        """q and qd at a time since the first row, linearly interpolated."""
        t = self.t
        return {"q": np.array([np.interp(time, t, col) for col in self.q.T]),
                "qd": np.array([np.interp(time, t, col) for col in self.qd.T])}

    # ---- moves ----
    def moving(self, rest_speed: float = REST_SPEED) -> np.ndarray:
        """Rows where some joint moves: the set-point's speed if logged, else the measured one."""
        speed = self.target_qd if self.target_qd is not None else self.qd
        return np.abs(speed).max(axis=1) > rest_speed

    def motions(self, rest_speed: float = REST_SPEED) -> list[Motion]:
        moving = self.moving(rest_speed)
        speed = np.abs(self.target_qd if self.target_qd is not None else self.qd)
        reference = self.target_q if self.target_q is not None else self.q
        t, out, row, n = self.t, [], 0, len(moving)
        while row < n:
            if not moving[row]:
                row += 1
                continue
            first = row
            while row < n and moving[row]:
                row += 1
            last = row - 1
            before, after = reference[max(first - 1, 0)], reference[min(row, n - 1)]
            lead = int(np.argmax(np.abs(after - before)))
            onset = t[first]
            if first > 0:
                onset = t[first - 1]
                if first + 1 <= last and speed[first + 1, lead] > speed[first, lead]:
                    slope = (speed[first + 1, lead] - speed[first, lead]) / (t[first + 1] - t[first])
                    onset = float(np.clip(t[first] - speed[first, lead] / slope, t[first - 1], t[first]))
            out.append(Motion(float(onset), float(t[min(row, n - 1)]), first, last, before.copy(), after.copy()))
        return out


def pose_matrix(pose) -> np.ndarray:
    """4x4 of a UR pose (x, y, z, rx, ry, rz): position and rotation vector."""
    x, y, z, rx, ry, rz = (float(v) for v in pose)
    T = np.eye(4)
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle > 1e-12:
        k = np.array([rx, ry, rz]) / angle
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        T[:3, :3] = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    T[:3, 3] = (x, y, z)
    return T


def pose_vector(T: np.ndarray) -> np.ndarray:
    """(x, y, z, rx, ry, rz) of a 4x4: position and rotation vector (inverse of pose_matrix)."""
    R = T[:3, :3]
    angle = math.acos(max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0)))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-12:
        rot = v / 2.0
    elif math.pi - angle < 1e-6:
        w, V = np.linalg.eigh((R + R.T) / 2.0)
        rot = V[:, int(np.argmax(w))] * angle
    else:
        rot = v * angle / (2.0 * math.sin(angle))
    return np.concatenate([T[:3, 3], rot])


def read_arm_log(path: str | Path, convention: Convention = IDENTITY) -> ArmLog:
    """An RTDE log's arm series in the p-model's convention (needs timestamp and actual_q_0..5)."""
    return ArmLog(read_rtde(path, ARM), convention)


def write_rtde(path: str | Path, timestamp, q, qd=None, target_q=None, target_qd=None, tcp=None,
               convention: Convention = IDENTITY) -> Path:
    """Write p-model-convention series as an RTDE log (the columns given; TCP poses as 4x4s in the
    model frame), e.g. to record a DT run in the PT's format."""
    path = Path(path)
    columns: dict[str, np.ndarray] = {"timestamp": np.asarray(timestamp, float)}

    def put(name, matrix):
        for i in range(JOINTS):
            columns[f"{name}_{i}"] = np.asarray(matrix, float)[:, i]

    for name, series, angles in (("target_q", target_q, True), ("target_qd", target_qd, False),
                                 ("actual_q", q, True), ("actual_qd", qd, False)):
        if series is not None:
            put(name, convention.to_controller(series) if angles else series)
    if tcp is not None:
        to_controller = np.linalg.inv(np.asarray(convention.base))
        put("actual_TCP_pose", [pose_vector(to_controller @ T) for T in tcp])
    names = list(columns)
    rows = zip(*(columns[n] for n in names))
    return write_text(path, " ".join(names) + "\n" + "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows))


def _partial_vectors(columns, reported) -> list[tuple[str, list[int]]]:
    """(field, its missing indices) of every vector field cotwin reads (RANGES) that the header has only
    some elements of (those `reported` missing already aside): read as absent, it would silently give way to
    another field (the measured joints)."""
    out = []
    for field_name in RANGES:
        absent = [k for k in range(JOINTS) if f"{field_name}_{k}" not in columns]
        if 0 < len(absent) < JOINTS and not any(f"{field_name}_{k}" in reported for k in absent):
            out.append((field_name, absent))
    return out


def read_rtde(path: str | Path, required=LIVE) -> RTDELog:
    """Read an RTDE log strictly; `required` columns must be present. The file is read line by line
    into one array (8 bytes a value), so a long log costs its size, not several times it."""
    path = Path(path)
    diag = Diagnostics()
    where = str(path)
    lines = _lines(path)
    header_row, header_line = next(((k, line) for k, line in lines if line.strip()), (None, ""))
    if header_row is None:
        raise CotwinError([_finding(where, 1, 1, "the log is empty: an RTDE log needs a header row and samples")])
    header, header_cols = _fields(header_line)
    seen: dict[str, int] = {}
    for name, col in zip(header, header_cols):
        if len(diag.findings) >= MAX_ERRORS:
            diag.error(Location(where, header_row, col), f"stopped after {MAX_ERRORS} errors")
            break
        if len(name) > MAX_FIELD:
            diag.error(Location(where, header_row, col), f"a header name of {len(name)} characters: "
                       "the first row must name RTDE fields")
        elif name in seen:
            diag.error(Location(where, header_row, col), f"column '{name}' appears twice (also column {seen[name]})")
        seen.setdefault(name, col)
    missing = [c for c in required if c not in seen]
    if missing:
        diag.error(Location(where, header_row, 1), f"the log has no column(s) {', '.join(missing)} (an RTDE log "
                   f"with {_names(required)} is needed; is the file space-separated?)")
    for field_name, absent in _partial_vectors(seen, missing):
        diag.error(Location(where, header_row, seen[f"{field_name}_{min(set(range(JOINTS)) - set(absent))}"]),
                   f"the field {field_name} lacks column(s) {', '.join(f'{field_name}_{k}' for k in absent)}: a "
                   f"vector read by cotwin has all of {field_name}_0..{field_name}_{JOINTS - 1}, or none")
    diag.raise_if_errors()
    bounds = [RANGES.get(name.rsplit("_", 1)[0]) if name[-1:].isdigit() else None for name in header]
    values, numbers, errors, last = array("d"), array("q"), 0, header_row
    for k, line in lines:
        last = k
        row = _row(line.split(), len(header))
        if row is not None:
            values.extend(row)
            numbers.append(k)
            continue
        fields, cols = _fields(line)
        if not fields:
            continue
        if len(fields) != len(header):
            diag.error(Location(where, k, cols[len(header)] if len(fields) > len(header) else len(line) + 1),
                       f"{len(fields)} values for {len(header)} columns")
            errors += 1
        else:
            for name, cell, col, bound in zip(header, fields, cols, bounds):
                problem = _problem(cell, bound)
                if problem is not None:
                    diag.error(Location(where, k, col), f"column '{name}': {problem}")
                    errors += 1
        if errors >= MAX_ERRORS:
            diag.error(Location(where, k, 1), f"stopped after {MAX_ERRORS} errors")
            break
    limit = np.array([b[0] if b is not None else np.inf for b in bounds])
    data = np.frombuffer(values, dtype=float).reshape(len(numbers), len(header))
    outside = np.nonzero(~np.all(np.isfinite(data) & (np.abs(data) <= limit), axis=1))[0]
    if len(outside) and errors < MAX_ERRORS:
        _cell_problems(path, header, bounds, {numbers[r] for r in outside[:MAX_ERRORS - errors]}, diag)
    diag.raise_if_errors()
    if len(numbers) < 2:
        raise CotwinError([_finding(where, last, 1, f"the log has {len(numbers)} sample(s): at least two are needed")])
    stamps = data[:, header.index("timestamp")] if "timestamp" in header else None
    if stamps is not None:
        steps = np.diff(stamps)
        bad_steps = np.nonzero((steps <= 0) | (steps > MAX_GAP))[0]
        if len(bad_steps):
            bad = int(bad_steps[0]) + 1
            now, before = float(stamps[bad]), float(stamps[bad - 1])
            problem = (f"timestamps must increase: {now!r} after {before!r}" if now <= before else
                       f"a jump of {now - before:g} s after {before!r} (at most {MAX_GAP:g} s between samples: "
                       "is the timestamp column corrupt?)")
            raise CotwinError([_finding(where, numbers[bad], seen["timestamp"], problem)])
    return RTDELog(str(path), header, data)


def _lines(path: Path):
    """(line number, text) of a log, read as it goes; a log over MAX_BYTES or bytes that are not UTF-8
    text end it with an error at the place."""
    where = str(path)
    try:
        info = path.stat()
        size = info.st_size
        if not stat.S_ISREG(info.st_mode):  # a FIFO or a device would be read without end
            raise CotwinError([_finding(where, 1, 1, "cannot read the log: not a regular file")])
        if size > MAX_BYTES:
            raise CotwinError([_finding(where, 1, 1, f"the log is {size / 2**20:.0f} MiB, over the {MAX_BYTES // 2**20} "
                                        "MiB cotwin reads: cut it to the run you need")])
        with path.open("rb") as f:
            for k, raw in enumerate(f, 1):
                try:
                    yield k, raw.decode("utf-8").rstrip("\r\n")
                except UnicodeDecodeError as err:
                    raise CotwinError([_finding(where, k, err.start + 1,
                                                "the log is not UTF-8 text (is this an RTDE CSV log?)")]) from None
    except OSError as err:
        raise CotwinError([_finding(where, 1, 1, f"cannot read the log: {err.strerror or err}")]) from None


def _row(fields: list[str], width: int) -> list[float] | None:
    """The numbers of a row, or None when it has the wrong width or a cell is not a number (the caller
    then says which); their ranges are checked on the whole array at the end."""
    if len(fields) != width or max(map(len, fields)) > MAX_FIELD:
        return None
    try:
        return list(map(float, fields))
    except ValueError:
        return None


def _cell_problems(path: Path, header: list[str], bounds, rows: set[int], diag: Diagnostics) -> None:
    """Locate the cells out of range on the given lines (a second pass: rare, and at most MAX_ERRORS lines)."""
    for k, line in _lines(path):
        if k in rows:
            fields, cols = _fields(line)
            for name, cell, col, bound in zip(header, fields, cols, bounds):
                problem = _problem(cell, bound)
                if problem is not None:
                    diag.error(Location(str(path), k, col), f"column '{name}': {problem}")
            if k >= max(rows):
                break


def _problem(cell: str, bound: tuple[float, str] | None) -> str | None:
    """What is wrong with a cell of a column of range `bound`, if anything."""
    value = _number(cell)
    if value is None:
        return (f"{cell!r} is not a finite number" if len(cell) <= 20
                else f"a field of {len(cell)} characters is not a number")
    if bound is not None and abs(value) > bound[0]:
        return f"{value:g} {bound[1]} is beyond any UR arm's (at most {bound[0]:g} {bound[1]})"
    return None


def _names(required) -> str:
    fields = list(dict.fromkeys(name.rsplit("_", 1)[0] if name[-1].isdigit() else name for name in required))
    return ", ".join(f"{f}_0..5" if f != "timestamp" else f for f in fields)


def _fields(line: str) -> tuple[list[str], list[int]]:
    """Whitespace-separated fields and their 1-based columns."""
    fields, cols, k, n = [], [], 0, len(line)
    while k < n:
        while k < n and line[k] in " \t\r":
            k += 1
        if k >= n:
            break
        start = k
        while k < n and line[k] not in " \t\r":
            k += 1
        fields.append(line[start:k])
        cols.append(start + 1)
    return fields, cols


def _number(text: str) -> float | None:
    if len(text) > MAX_FIELD:
        return None
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _finding(path: str, line: int, column: int, message: str) -> Finding:
    return Finding(Location(path, line, column), Severity.ERROR, message)
