"""The robot link's wire protocol (see `broker`): what a request and a reply may hold, and who sent them.

Messages are JSON objects of bounded size. Both directions are authenticated with HMAC-SHA256 under a
secret the twin and the robot server share (COTWIN_ROBOT_SECRET, or the first line of the file named
by COTWIN_ROBOT_SECRET_FILE): the MAC covers the direction, the request queue, the correlation id, the
reply queue and send time (requests) and the body, so a message cannot be forged, moved to another
robot or direction, nor (within the freshness window, by its correlation id) replayed. Every request
and every reply is checked field by field (types, finite numbers, known names, the time advancing) and
refused with a message naming the field; nothing is taken silently.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import os
import re
import time as wallclock
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Mapping

from .. import safejson
from ..config import is_number
from ..diagnostics import CotwinError
from .amqp import read_secret_file

MAX_REQUEST = 64 * 1024  # bytes: a request names a few actuators
MAX_REPLY = 1024 * 1024  # bytes: a state holds every sensor and joint
MAX_NAME = 512  # characters of an actuator, sensor or joint name
MAX_NAMES = 10_000
MAX_ERROR = 2000  # characters of an error text shown from a reply
MAX_DT = 10.0  # s: one advance
FRESHNESS = 120.0  # s: a request older (or newer) than this is refused; its correlation id is kept as long
MIN_SECRET = 16  # characters
MAC_HEADER, SENT_HEADER = "cotwin-mac", "cotwin-sent"
REPLY_QUEUE = re.compile(r"^amq\.gen-[A-Za-z0-9_-]{1,200}$")  # a broker-named exclusive queue, nothing else
_DOMAIN = b"cotwin robot link v1"

OPS = {"describe": set(), "command": {"goals"}, "advance": {"dt"}, "state": set()}  # `stop` is a local call


def load_secret(environ: Mapping[str, str] = os.environ) -> bytes:
    """The shared secret of the robot link, or CotwinError saying how to give one."""
    text = environ.get("COTWIN_ROBOT_SECRET")
    source = "COTWIN_ROBOT_SECRET"
    if not text and environ.get("COTWIN_ROBOT_SECRET_FILE"):
        source = "COTWIN_ROBOT_SECRET_FILE"
        text = read_secret_file(environ["COTWIN_ROBOT_SECRET_FILE"], source)
    if not text:
        raise CotwinError("the robot link needs a shared secret on both sides (the twin and the robot server): set "
                          "COTWIN_ROBOT_SECRET, or COTWIN_ROBOT_SECRET_FILE naming a file that holds it "
                          "(e.g. made with: openssl rand -hex 32)")
    if len(text) < MIN_SECRET:
        raise CotwinError(f"the robot link's secret ({source}) is too short: at least {MIN_SECRET} characters")
    return text.encode("utf-8")


def _mac(secret: bytes, *parts: str | bytes) -> str:
    h = hmac.new(secret, _DOMAIN, hashlib.sha256)
    for part in parts:
        data = part if isinstance(part, bytes) else part.encode("utf-8")
        h.update(len(data).to_bytes(8, "big"))  # length-prefixed: no two splits of the same bytes agree
        h.update(data)
    return h.hexdigest()


def request_headers(secret: bytes, queue: str, cid: str, reply_to: str, body: bytes, now: float | None = None) -> dict:
    sent = repr(wallclock.time() if now is None else now)
    return {SENT_HEADER: sent, MAC_HEADER: _mac(secret, "request", queue, cid, reply_to, sent, body)}


def reply_headers(secret: bytes, queue: str, cid: str, body: bytes) -> dict:
    return {MAC_HEADER: _mac(secret, "reply", queue, cid, body)}


def _header(headers, key: str) -> str | None:
    value = headers.get(key) if isinstance(headers, dict) else None
    if isinstance(value, bytes):
        try:
            value = value.decode("ascii")
        except UnicodeDecodeError:
            return None
    return value if isinstance(value, str) and len(value) <= 128 else None


@dataclass
class ReplayGuard:
    """Correlation ids seen within the freshness window (a request is taken once)."""

    window: float = FRESHNESS
    seen: OrderedDict = field(default_factory=OrderedDict)

    def fresh(self, cid: str, now: float) -> bool:
        while self.seen and next(iter(self.seen.values())) < now - 2 * self.window:
            self.seen.popitem(last=False)
        if cid in self.seen:
            return False
        self.seen[cid] = now
        return True


def check_request(secret: bytes, queue: str, cid, reply_to, headers, body: bytes, guard: ReplayGuard,
                  now: float | None = None) -> str | None:
    """Why a request is not authentic (None if it is): MAC, freshness, replay."""
    now = wallclock.time() if now is None else now
    sent, mac = _header(headers, SENT_HEADER), _header(headers, MAC_HEADER)
    if mac is None or sent is None or not isinstance(cid, str) or not isinstance(reply_to, str):
        return "request not authenticated (no MAC): is COTWIN_ROBOT_SECRET set on the twin's side?"
    if not hmac.compare_digest(mac, _mac(secret, "request", queue, cid, reply_to, sent, body)):
        return "request not authenticated (wrong MAC): the twin and the robot server must share COTWIN_ROBOT_SECRET"
    try:
        at = float(sent)
    except ValueError:
        return "request not authenticated (bad send time)"
    if not math.isfinite(at) or abs(now - at) > FRESHNESS:
        return f"request refused: sent {now - at:+.0f} s from now (more than {FRESHNESS:g} s: a replay, or clocks apart)"
    if not guard.fresh(cid, now):
        return "request refused: correlation id already used (a replay)"
    return None


def check_reply(secret: bytes, queue: str, cid: str, headers, body: bytes) -> bool:
    mac = _header(headers, MAC_HEADER)
    return mac is not None and hmac.compare_digest(mac, _mac(secret, "reply", queue, cid, body))


# ---- message bodies --------------------------------------------------------------------------------

def decode(body: bytes, limit: int, what: str) -> dict:
    """A JSON object from a message body (cotwin.safejson's policy), or CotwinError saying what is wrong."""
    if not isinstance(body, (bytes, bytearray)):
        raise CotwinError(f"{what}: no body")
    try:
        return safejson.loads_object(body, limit)
    except safejson.Refused as err:
        raise CotwinError(f"{what}: {err}") from None


def _show(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def validate_request(message: object, actuators: set[str] | None = None) -> dict:
    """A request, or CotwinError naming the unknown or ill-typed field (and unknown actuators if known)."""
    if not isinstance(message, dict):
        raise CotwinError("request: expected a JSON object")
    op = message.get("op")
    if not isinstance(op, str) or op not in OPS:
        raise CotwinError(f"request: unknown op {_show(op)} (known: {', '.join(OPS)})")
    extra = set(message) - OPS[op] - {"op"}
    if extra:
        raise CotwinError(f"request {op}: unknown field(s) {', '.join(_show(k) for k in sorted(extra)[:5])}")
    missing = OPS[op] - set(message)
    if missing:
        raise CotwinError(f"request {op}: missing field(s) {', '.join(sorted(missing))}")
    if op == "advance":
        dt = message["dt"]
        if not is_number(dt) or not 0 <= dt <= MAX_DT:
            raise CotwinError(f"request advance: dt must be a number of seconds in [0, {MAX_DT:g}], got {_show(dt)}")
    if op == "command":
        goals = message["goals"]
        if not isinstance(goals, dict) or not goals:
            raise CotwinError("request command: goals must be a non-empty object {actuator: value}")
        for name, value in goals.items():
            if not is_number(value):
                raise CotwinError(f"request command: goal {_show(name)} must be a finite number, got {_show(value)}")
            if actuators is not None and name not in actuators:
                raise CotwinError(f"request command: unknown actuator {_show(name)}")
    return message


@dataclass
class RobotView:
    """What the twin knows of the robot from its replies: the described names and the last time."""

    actuators: set[str] = field(default_factory=set)
    sensors: set[str] = field(default_factory=set)
    joints: set[str] | None = None  # the joints a state may name (the p-model's), if known
    stated_joints: frozenset[str] | None = None  # the joints of the first state: every state names them
    time: float | None = None


def _names(reply: dict, key: str, what: str) -> list[str]:
    names = reply.get(key)
    if not isinstance(names, list) or len(names) > MAX_NAMES:
        raise CotwinError(f"{what}: '{key}' must be a list of names")
    for n in names:
        if not isinstance(n, str) or not 0 < len(n) <= MAX_NAME:
            raise CotwinError(f"{what}: '{key}' holds {_show(n)}, not a name")
    if len(set(names)) != len(names):
        raise CotwinError(f"{what}: '{key}' names some twice")
    return names


def _values(reply: dict, key: str, what: str) -> dict[str, float]:
    values = reply.get(key)
    if not isinstance(values, dict) or len(values) > MAX_NAMES:
        raise CotwinError(f"{what}: '{key}' must be an object {{name: number}}")
    for name, v in values.items():
        if not is_number(v):
            raise CotwinError(f"{what}: {key} {_show(name)} is {_show(v)}, not a finite number")
    return {n: float(v) for n, v in values.items()}


def validate_reply(op: str, reply: dict, view: RobotView, dt: float = 0.0) -> dict:
    """A reply to `op`, checked against what the robot said before; updates `view`. CotwinError
    naming the field otherwise; a refusal (`ok: false`) is a CotwinError carrying the robot's reason."""
    what = f"reply to {op}"
    ok = reply.get("ok")
    if ok is False:
        error = reply.get("error")
        if set(reply) != {"ok", "error"} or not isinstance(error, str):
            raise CotwinError(f"{what}: a refusal must hold exactly 'ok': false and 'error': text")
        text = "".join(c if c.isprintable() else "?" for c in error[:MAX_ERROR])
        raise CotwinError(f"the robot refused {op}: {text}")
    if ok is not True:
        raise CotwinError(f"{what}: 'ok' must be true or false, got {_show(ok)}")
    if op == "describe":
        if set(reply) != {"ok", "actuators", "sensors"}:
            raise CotwinError(f"{what}: expected exactly ok, actuators, sensors; got {', '.join(sorted(map(str, reply))[:8])}")
        actuators = _names(reply, "actuators", what)
        if not actuators:
            raise CotwinError(f"{what}: the robot has no actuator")
        view.actuators, view.sensors = set(actuators), set(_names(reply, "sensors", what))
        return reply
    if set(reply) != {"ok", "time", "sensors", "joints", "velocities"}:
        raise CotwinError(f"{what}: expected exactly ok, time, sensors, joints, velocities; "
                          f"got {', '.join(sorted(map(str, reply))[:8])}")
    t = reply["time"]
    if not is_number(t):
        raise CotwinError(f"{what}: time {_show(t)} is not a finite number")
    sensors, joints, velocities = (_values(reply, k, what) for k in ("sensors", "joints", "velocities"))
    if set(sensors) != view.sensors:
        odd = sorted(set(sensors) ^ view.sensors)[:3]
        raise CotwinError(f"{what}: the sensors are not those the robot described ({', '.join(map(_show, odd))})")
    if view.joints is not None and not set(joints) <= view.joints:
        raise CotwinError(f"{what}: unknown joint(s) {', '.join(map(_show, sorted(set(joints) - view.joints)[:3]))}")
    if set(velocities) != set(joints):
        raise CotwinError(f"{what}: 'velocities' must name the same joints as 'joints'")
    if view.stated_joints is None:
        view.stated_joints = frozenset(joints)
    elif set(joints) != view.stated_joints:
        raise CotwinError(f"{what}: the joints changed from one state to the next")
    if view.time is not None:
        expected = view.time + (dt if op == "advance" else 0.0)
        tolerance = max(1e-6, dt / 2) if op == "advance" else 1e-6
        if abs(t - expected) > tolerance:
            raise CotwinError(f"{what}: the robot's time went from {view.time:.6g} s to {t:.6g} s "
                              f"(expected {expected:.6g} s{f' after advancing {dt:g} s' if op == 'advance' else ''})")
    view.time = float(t)
    return reply
