"""Who may use the dashboard: an access file of viewers and operators, their login sessions, and the
gate every request passes (an ASGI middleware around the page's app).

The access file (`cotwin dashboard-access FILE add NAME --role viewer|operator [--token]`) holds one
line per person or client, `ROLE NAME HASH`: a password as `scrypt:N:r:p:SALT:HASH` (hashlib.scrypt,
salted, 16 MiB per try) or a generated token as `sha256:HEX` (32 random bytes: nothing to guess, so a
plain hash suffices). Only its owner may read or write it (mode 600), it holds no secret in clear, and
it is read again when it changes, so removing a line revokes that person at once, sessions included.

A client proves who it is with `Authorization: Bearer TOKEN` (scripts) or a login (the page): the
login form is the body of every 401 a browser gets, it posts NAME and a password (or a token and no
name) to /login, and the answer sets an HttpOnly, SameSite=Strict session cookie (Secure under TLS)
valid for SESSION_HOURS. Viewers see everything the page shows; operators may also command the robot
and run what-ifs (`OPERATOR_ONLY`). A request without valid credentials is answered 401, a viewer's
command 403, and every refusal is logged (logger `cotwin.dashboard`, capped against floods).
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import hmac
import logging
import os
import re
import secrets
import stat
import threading
import time as wallclock
from collections import OrderedDict, deque
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import parse_qs

from .... import files
from ....diagnostics import CotwinError
from ....logcap import CappedLog

log = logging.getLogger("cotwin.dashboard")
ROLES = ("viewer", "operator")
OPERATOR_ONLY = {("POST", "/api/command"), ("POST", "/api/whatif")}
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._@+-]{0,63}$")
SCRYPT = (1 << 14, 8, 1)  # N, r, p: 16 MiB and about 50 ms a try
SESSION_HOURS = 12.0
MAX_SESSIONS = 1024  # the oldest is dropped beyond (a login flood cannot grow memory)
MAX_FAILURES = 10  # failed logins from one address within FAILURE_WINDOW, then 429 until it passes
FAILURE_WINDOW = 300.0  # s
MAX_LOGIN_BODY = 4096  # bytes of a login form
MAX_HASHING = 2  # password checks at once (each costs 16 MiB and a core for ~50 ms)


@dataclass(frozen=True)
class Person:
    name: str
    role: str
    secret: str  # the stored hash, never the password


def hash_password(password: str) -> str:
    n, r, p = SCRYPT
    salt = os.urandom(16)
    digest = hashlib.scrypt(password.encode("utf-8"), salt=salt, n=n, r=r, p=p, dklen=32)
    return f"scrypt:{n}:{r}:{p}:{_b64(salt)}:{_b64(digest)}"


def hash_token(token: str) -> str:
    return "sha256:" + hashlib.sha256(token.encode("utf-8")).hexdigest()


def new_token() -> str:
    return secrets.token_urlsafe(32)


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def check_password(password: str, stored: str) -> bool:
    kind, n, r, p, salt, digest = stored.split(":")
    try:
        found = hashlib.scrypt(password.encode("utf-8", "replace"), salt=base64.b64decode(salt), n=int(n), r=int(r),
                               p=int(p), dklen=len(base64.b64decode(digest)), maxmem=64 << 20)
    except ValueError:
        return False
    return hmac.compare_digest(found, base64.b64decode(digest))


_DECOY: list[str] = []


def _decoy() -> str:
    if not _DECOY:
        _DECOY.append(hash_password(new_token()))
    return _DECOY[0]


_HASH = re.compile(r"^(scrypt:(\d{1,7}):(\d{1,2}):(\d{1,2}):[A-Za-z0-9+/=]{8,100}:[A-Za-z0-9+/=]{16,100}"
                   r"|sha256:[0-9a-f]{64})$")


def read_access(path: str | Path) -> list[Person]:
    """The people of an access file, or a CotwinError naming the line (and the file's mode, if others may
    read or write it)."""
    path = Path(path)
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except OSError as err:
        raise files.error(path, f"cannot read the access file: {err.strerror or err}") from None
    if mode & 0o077:
        raise files.error(path, f"the access file may be read or changed by others than its owner (mode "
                                f"{mode:03o}): chmod 600 {path}")
    text = files.read_text(path, "access file")
    people: dict[str, Person] = {}
    problems = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = line.split()
        if len(fields) != 3:
            problems.append((number, 1, "expected ROLE NAME HASH (cotwin dashboard-access FILE add NAME --role ROLE)"))
            continue
        role, name, secret = fields
        column = line.index(name) + 1
        if role not in ROLES:
            problems.append((number, 1, f"unknown role {role[:40]!r} (viewer or operator)"))
        elif not NAME.match(name):
            problems.append((number, column, f"{name[:40]!r} is not a name (letters, digits, . _ @ + -, at most 64)"))
        elif name in people:
            problems.append((number, column, f"{name} is named twice"))
        elif not _HASH.match(secret) or (secret.startswith("scrypt:") and not _sane_scrypt(secret)):
            problems.append((number, line.index(secret) + 1, "not a hash cotwin wrote (scrypt:... or sha256:...)"))
        else:
            people[name] = Person(name, role, secret)
    if problems:
        raise CotwinError([files.error(path, message, line, column).findings[0] for line, column, message in problems])
    return list(people.values())


def _sane_scrypt(stored: str) -> bool:
    """Parameters cotwin can check without being made to spend more than 64 MiB or a second on a try."""
    _, n, r, p, _, _ = stored.split(":")
    n, r, p = int(n), int(r), int(p)
    return 2 <= n <= 1 << 17 and n & (n - 1) == 0 and 1 <= r <= 16 and 1 <= p <= 4 and 128 * n * r <= 64 << 20


def write_access(path: str | Path, people: list[Person]) -> None:
    lines = ["# cotwin dashboard access: ROLE NAME HASH, one a line (cotwin dashboard-access FILE add|remove|list)"]
    lines += [f"{p.role} {p.name} {p.secret}" for p in people]
    files.write_text(path, "\n".join(lines) + "\n", mode=0o600)


@dataclass
class Session:
    name: str
    expires: float  # time.monotonic()


class Access:
    """The access file of a running dashboard (re-read when it changes) and its login sessions."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._people = read_access(self.path)  # refused at start if unreadable
        self._stamp = self._file_stamp()
        self._checked = wallclock.monotonic()
        self._sessions: OrderedDict[str, Session] = OrderedDict()
        self._failures: dict[str, deque] = {}
        self._lock = threading.Lock()
        self.hashing = threading.BoundedSemaphore(MAX_HASHING)

    def _file_stamp(self):
        try:
            info = os.stat(self.path)
            return info.st_mtime_ns, info.st_size, info.st_ino
        except OSError:
            return None

    def people(self) -> dict[str, Person]:
        """Who may come in now: the file as it is (checked at most once a second; a file that became
        unreadable or wrong keeps the last good list and says so in the log)."""
        now = wallclock.monotonic()
        if now - self._checked >= 1.0:
            self._checked = now
            stamp = self._file_stamp()
            if stamp != self._stamp:
                self._stamp = stamp
                try:
                    self._people = read_access(self.path)
                    log.warning("dashboard: access file %s re-read: %d people", self.path, len(self._people))
                except CotwinError as err:
                    log.warning("dashboard: access file changed but cannot be read, keeping the last good one: %s",
                                "; ".join(f.message for f in err.findings))
        return {p.name: p for p in self._people}

    # ---- credentials ----
    def bearer(self, token: str) -> Person | None:
        digest = hash_token(token)
        found = None
        for person in self.people().values():
            if person.secret.startswith("sha256:") and hmac.compare_digest(person.secret, digest):
                found = person
        return found

    def login(self, name: str, secret: str) -> Person | None:
        """The person `name` whose password is `secret`, or (no name) whose token it is; None otherwise."""
        if not name:
            return self.bearer(secret)
        person = self.people().get(name)
        if person is None:
            check_password(secret, _decoy())  # as long as a real check: the time taken says nobody exists
            return None
        if person.secret.startswith("sha256:"):
            return person if hmac.compare_digest(person.secret, hash_token(secret)) else None
        return person if check_password(secret, person.secret) else None

    # ---- sessions ----
    def open_session(self, person: Person) -> str:
        key = secrets.token_urlsafe(32)
        with self._lock:
            self._sessions[key] = Session(person.name, wallclock.monotonic() + SESSION_HOURS * 3600)
            while len(self._sessions) > MAX_SESSIONS:
                self._sessions.popitem(last=False)
        return key

    def session(self, key: str) -> Person | None:
        with self._lock:
            session = self._sessions.get(key)
            if session is None:
                return None
            if session.expires < wallclock.monotonic():
                del self._sessions[key]
                return None
        return self.people().get(session.name)  # removed from the file: no longer anyone

    def close_session(self, key: str) -> None:
        with self._lock:
            self._sessions.pop(key, None)

    # ---- failed logins ----
    def throttled(self, client: str) -> bool:
        now = wallclock.monotonic()
        with self._lock:
            recent = self._failures.get(client)
            while recent and now - recent[0] > FAILURE_WINDOW:
                recent.popleft()
            return bool(recent) and len(recent) >= MAX_FAILURES

    def failed(self, client: str) -> None:
        with self._lock:
            if len(self._failures) > 10_000:  # many addresses: forget the quiet ones
                self._failures = {k: v for k, v in self._failures.items() if v}
            self._failures.setdefault(client, deque(maxlen=MAX_FAILURES)).append(wallclock.monotonic())


# ---- the gate --------------------------------------------------------------------------------------

LOGIN_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>cotwin: log in</title>
<style>body{{font:15px system-ui,sans-serif;background:#e9edf2;display:grid;place-items:center;height:100vh;margin:0}}
form{{background:#fff;padding:24px 28px;border-radius:8px;box-shadow:0 1px 4px #0002;display:grid;gap:10px;min-width:280px}}
h1{{font-size:18px;margin:0 0 6px}} input{{font:inherit;padding:6px}} .why{{color:#b00020}} .muted{{color:#666;font-size:13px}}</style>
</head><body><form method="post" action="/login">
<h1>cotwin dashboard</h1><p class="why" id="why">{why}</p>
<label>name <input name="name" autocomplete="username"></label>
<label>password or token <input name="secret" type="password" autocomplete="current-password" required></label>
<button type="submit">Log in</button><p class="muted">A token needs no name.</p></form></body></html>
"""


class Gate:
    """ASGI middleware: authenticates every HTTP request and stream of `app` against `access` (see module
    doc), serves /login and /logout, and logs every refusal of the app's too (any answer of 400 and up)."""

    def __init__(self, app, access: Access | None, tls: bool, port_name: str, body_seconds: float = 10.0):
        self.app, self.access, self.tls, self.body_seconds = app, access, tls, body_seconds
        self.cookie = f"cotwin_session_{port_name}"  # cookies are per host, not per port: one per dashboard
        self.refusals = CappedLog(log, "refused requests", burst=100)  # all counted; a flood logs 10 lines a second

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        method = scope.get("method", "GET") if scope["type"] == "http" else "WS"
        where = f"{method} {scope['path'][:100]} from {_client(scope)}"
        person = None
        if self.access is not None:
            if scope["type"] == "http" and scope["path"] in ("/login", "/logout") and method == "POST":
                return await self._login(scope, receive, send, where)
            person = self._who(scope)
            if person is None:
                return await self._refuse(scope, send, 401, "log in first: no valid token or session", where)
            if (method, scope["path"]) in OPERATOR_ONLY and person.role != "operator":
                return await self._refuse(scope, send, 403, f"{person.name} is a viewer: only operators command the "
                                                            "twin and run what-ifs", where, person)
            scope = dict(scope, cotwin_person=person)
        await self.app(scope, receive, self._watching(send, where, person))

    def _who(self, scope) -> Person | None:
        headers = _headers(scope)
        authorization = headers.get("authorization", "")
        if authorization[:7].lower() == "bearer ":
            return self.access.bearer(authorization[7:].strip())
        key = _cookies(headers.get("cookie", "")).get(self.cookie)
        return self.access.session(key) if key else None

    def _watching(self, send, where: str, person: Person | None):
        """`send`, logging the app's own refusals (status >= 400) with the reason it gave."""
        status = {}

        async def watched(message):
            kind = message["type"]
            if kind in ("http.response.start", "websocket.http.response.start"):
                status["code"] = message["status"]
            elif kind in ("http.response.body", "websocket.http.response.body") and status.get("code", 0) >= 400 \
                    and not status.get("logged"):
                status["logged"] = True
                self._log(status["code"], _reason(message.get("body", b"")), where, person)
            elif kind == "websocket.close" and message.get("code", 1000) in (1008, 1013):
                self._log(message["code"], message.get("reason", ""), where, person)
            await send(message)

        return watched

    def _log(self, code: int, reason: str, where: str, person: Person | None) -> None:
        self.refusals.warning("dashboard refused %s%s: %s %s", where, f" ({person.name})" if person else "", code,
                              reason[:200])

    async def _refuse(self, scope, send, code: int, reason: str, where: str, person: Person | None = None) -> None:
        self._log(code, reason, where, person)
        browser = "text/html" in _headers(scope).get("accept", "") and scope["type"] == "http"
        if browser and code == 401:
            body, kind = LOGIN_PAGE.format(why="").encode(), b"text/html; charset=utf-8"
        else:
            body, kind = _json_error(reason), b"application/json"
        headers = [(b"content-type", kind), (b"content-length", str(len(body)).encode()),
                   (b"cache-control", b"no-store")]
        if code == 401:
            headers.append((b"www-authenticate", b'Bearer realm="cotwin"'))
        prefix = "websocket.http" if scope["type"] == "websocket" else "http"
        await send({"type": f"{prefix}.response.start", "status": code, "headers": headers})
        await send({"type": f"{prefix}.response.body", "body": body})

    async def _login(self, scope, receive, send, where: str) -> None:
        from starlette.concurrency import run_in_threadpool

        from .app import same_site

        headers = _headers(scope)
        foreign = same_site(headers, "", checked_host=False)
        if foreign is not None:
            return await self._refuse(scope, send, 403, f"refused: {foreign}", where)
        if scope["path"] == "/logout":
            key = _cookies(headers.get("cookie", "")).get(self.cookie)
            if key:
                self.access.close_session(key)
            return await self._redirect(send, f"{self.cookie}=; Max-Age=0; Path=/; HttpOnly; SameSite=Strict")
        client = _client(scope)
        if self.access.throttled(client):
            return await self._refuse(scope, send, 429, f"more than {MAX_FAILURES} failed logins from {client} within "
                                                        f"{FAILURE_WINDOW:g} s: try again later", where)
        async def collect() -> bytes | None:
            body = b""
            while True:
                message = await receive()
                body += message.get("body", b"")
                if len(body) > MAX_LOGIN_BODY:
                    return None
                if not message.get("more_body"):
                    return body

        try:
            body = await asyncio.wait_for(collect(), self.body_seconds)
        except asyncio.TimeoutError:
            return await self._refuse(scope, send, 408, f"the login form did not arrive within {self.body_seconds:g} s",
                                      where)
        if body is None:
            return await self._refuse(scope, send, 413, f"a login form of more than {MAX_LOGIN_BODY} bytes", where)
        try:
            form = parse_qs(body.decode("utf-8"), max_num_fields=4, strict_parsing=False)
        except (UnicodeDecodeError, ValueError):
            form = {}
        name, secret = (form.get(k, [""])[0][:200] for k in ("name", "secret"))
        if not self.access.hashing.acquire(blocking=False):
            return await self._refuse(scope, send, 429, "too many logins at once: try again", where)
        try:
            person = await run_in_threadpool(self.access.login, name.strip(), secret) if secret else None
        finally:
            self.access.hashing.release()
        if person is None:
            self.access.failed(client)
            self._log(401, f"login failed for {name[:64]!r}" if name else "login failed (token)", where, None)
            page = LOGIN_PAGE.format(why="That name and password (or token) do not match.").encode()
            return await self._answer(send, 401, page, b"text/html; charset=utf-8")
        key = self.access.open_session(person)
        log.info("dashboard: %s logged in as %s from %s", person.name, person.role, client)
        secure = "; Secure" if self.tls else ""
        await self._redirect(send, f"{self.cookie}={key}; Max-Age={int(SESSION_HOURS * 3600)}; Path=/; HttpOnly; "
                                   f"SameSite=Strict{secure}")

    async def _redirect(self, send, cookie: str) -> None:
        await send({"type": "http.response.start", "status": 303,
                    "headers": [(b"location", b"/"), (b"set-cookie", cookie.encode()), (b"content-length", b"0"),
                                (b"cache-control", b"no-store")]})
        await send({"type": "http.response.body", "body": b""})

    @staticmethod
    async def _answer(send, code: int, body: bytes, kind: bytes) -> None:
        await send({"type": "http.response.start", "status": code,
                    "headers": [(b"content-type", kind), (b"content-length", str(len(body)).encode()),
                                (b"cache-control", b"no-store")]})
        await send({"type": "http.response.body", "body": body})


def _headers(scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def _cookies(text: str) -> dict[str, str]:
    out = {}
    for part in text.split(";")[:50]:
        name, sep, value = part.strip().partition("=")
        if sep:
            out.setdefault(name, value)
    return out


def _client(scope) -> str:
    client = scope.get("client")
    return client[0] if client else "?"


def _reason(body: bytes) -> str:
    from .... import safejson

    try:
        found = safejson.loads(body, 4096)
    except ValueError:
        return body[:200].decode("utf-8", "replace")
    return str(found.get("error", found)) if isinstance(found, dict) else str(found)


def _json_error(reason: str) -> bytes:
    import json

    return json.dumps({"error": reason}).encode()

