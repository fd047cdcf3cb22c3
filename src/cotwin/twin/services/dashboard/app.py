"""The dashboard's web server: a Starlette app served by uvicorn on a background thread, started and
stopped with the run.

Routes: `/` (the page), `/static/...` (its scripts, styles and the vendored three.js), `/api/model`
(what describe.py derives from the models), `/api/status`, `/api/command` (POST: a command from the
panel, published on the twin's broker by PagePublisher; answered 200 with the step that applied it, 409
when the twin refused it, or 202 when it is accepted and waits, `/api/command/{id}` saying what became of it), `/api/whatif` (POST: a plan for the twin's
what-if service, when it runs one), `/api/history` and `/api/history/{run}` (the history store), and
`/ws`: the live stream.

Requests are read as a hostile client might send them: a body is at most MAX_BODY bytes (a larger
Content-Length is answered 413 before reading it, a longer body is cut off at the limit and answered
413, a body slower than BODY_SECONDS 408), must be UTF-8 JSON without NaN or Infinity, an object with
only the keys it documents (400 naming what is wrong); at most MAX_WHATIFS what-ifs from the page are
in flight and at most PagePublisher.MAX_WAITING commands wait to leave (429 beyond); commands to a twin
that has ended are refused (409), while the page keeps its last figure and state.

Who may use the page (access.py): on loopback anyone on this machine, unless an access file is given;
beyond loopback (server.py says what that is) only those in the access file, or the page refuses to
start: every request without a valid token or session is answered 401, a viewer's command or what-if
403. Request heads must arrive within HEADER_SECONDS (408 and closed otherwise); TLS is uvicorn's.

A command moves a robot, so another site open in the same browser must not send one: a POST must say
`Content-Type: application/json` (415 otherwise; a browser cannot send that across sites without a
preflight, which is never answered), its `Origin`, when sent, must be this server (403), and, on a page
without login, its `Host` must name this machine's loopback (403: a DNS-rebound name, or another
machine's address, is none of these). A stream (`/ws`) from a page of another origin is closed (1008).

A client gets a `hello` (recent samples, the newest events, the status) and then, every `period` seconds, a `batch` of what is new: samples (at most
`max_rate` per second, evenly thinned beyond that), events and the status. Each client reads the
feed from its own cursor on the server's event loop, so one that is slow to take its messages only
falls behind (and is told how many samples it skipped), never the twin or the other clients.
"""

from __future__ import annotations

import asyncio
import json
import logging
import queue
import socket
import threading
import time as wallclock
from pathlib import Path

from .... import safejson
from ....diagnostics import CotwinError, PicklableError
from ...assembly.cell import CellSystem
from ...assembly.system import MAPPING, RABBITMQ, TwinSystem
from ..whatif import finite as _finite
from .access import Access, Gate
from .describe import describe, describe_cell
from .feed import CellFeed, DashboardFeed
from .server import (HEADER_SECONDS, beyond_loopback, bound_socket, check_tls, protocol, serve_in_thread,
                     ws_protocol)

log = logging.getLogger("cotwin.dashboard")
STATIC = Path(__file__).resolve().parent / "static"
MAX_BODY = 1 << 20  # bytes of a request body (a command or a what-if plan is a few hundred)
BODY_SECONDS = 10.0  # to send it
MAX_CONNECTIONS = 128  # open at once, pages, streams and requests together
MAX_CLIENTS = 32  # live streams at once (more are closed with 1013, try again later)
MAX_WHATIFS = 2  # what-ifs from the page in flight (each waits for a fork of the twin)
MAX_HISTORY_READS = 2  # runs read from the history store at once (more wait their turn)
MAX_EVENTS = 10_000  # commands, state changes and alarms of a run sent to the page (the first; `counts` has all)
COMMAND_SECONDS = 5.0  # a command's answer waits this long for the twin to apply it (else 202: it will be)
ENDED = ("done", "stopped", "failed")


class Refused(PicklableError):
    """A request the server answers with `status` and `message` (what is wrong with it)."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


async def read_json(request, foreign: str | None, limit: int = MAX_BODY, seconds: float = BODY_SECONDS):
    """The request's body as JSON (see module doc), or Refused saying why not (`foreign`: why the request
    may come from another site, see same_site)."""
    if foreign is not None:
        raise Refused(403, f"refused: {foreign}")
    kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if kind != "application/json":
        raise Refused(415, f"the body must be sent as application/json, not {kind[:80] or 'without a type'!r}")
    length = request.headers.get("content-length")
    if length is not None:
        if not length.strip().isdigit():
            raise Refused(400, f"Content-Length {length[:40]!r} is not a number of bytes")
        if int(length) > limit:
            raise Refused(413, f"the body of {int(length)} bytes is larger than the {limit} bytes accepted")

    async def collect() -> bytes:
        body = bytearray()
        async for chunk in request.stream():
            body += chunk
            if len(body) > limit:
                raise Refused(413, f"the body is larger than the {limit} bytes accepted")
        return bytes(body)

    try:
        body = await asyncio.wait_for(collect(), seconds)
    except asyncio.TimeoutError:
        raise Refused(408, f"the body did not arrive within {seconds:g} s") from None
    try:
        return safejson.loads(body, limit)
    except safejson.Refused as err:
        raise Refused(400, f"the request is not JSON cotwin reads: {err}") from None


def same_site(headers, served: str, checked_host: bool = True) -> str | None:
    """Why a request with these headers may come from another site (see module doc), or None. With
    `checked_host` (a page on loopback without authentication) its Host must name this machine's loopback:
    `localhost`, a loopback address, the served host or this machine's name."""
    from urllib.parse import urlsplit

    from ....mapping.amqp import is_loopback

    host = headers.get("host", "")
    try:
        name = urlsplit("//" + host).hostname or ""
    except ValueError:  # e.g. an unclosed [
        return f"Host {host[:80]!r} is not an address"
    if checked_host and not (is_loopback(name) or name in (served.strip("[]"), socket.gethostname())):
        return f"Host {host[:80]!r} is not this server's address"
    origin = headers.get("origin")
    if origin is not None and origin not in (f"http://{host}", f"https://{host}"):
        return f"Origin {origin[:80]!r} is not this server (Host {host[:80]!r})"
    return None


def parse_run_id(text: str) -> int:
    """A history run id from a URL, or Refused (400 not a run id, 404 out of the ids a store can hold)."""
    from ..history import MAX_RUN_ID

    if not text.isascii() or not text.isdigit() or len(text) > 30:
        raise Refused(400, f"'{text[:40]}' is not a run id (a positive whole number)")
    number = int(text)
    if not 0 < number <= MAX_RUN_ID:
        raise Refused(404, f"no run {number} (run ids are 1, 2, ...)")
    return number


def parse_address(text: str) -> tuple[str, int]:
    """HOST:PORT (e.g. 127.0.0.1:8050; port 0 picks a free one), or ValueError saying what is wrong."""
    host, sep, port = str(text).rpartition(":")
    host = host.strip("[]")
    if not sep or not host:
        raise ValueError(f"'{text}' is not HOST:PORT (e.g. 127.0.0.1:8050)")
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"'{text}': the port '{port}' is not a number") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"'{text}': the port {number} is not within 0..65535")
    return host, number


def thin(rows: list, limit: int) -> list:
    """At most `limit` of `rows`, evenly spaced, always keeping the last."""
    if len(rows) <= limit:
        return rows
    if limit <= 1:
        return rows[-1:]
    stride = (len(rows) - 1) / (limit - 1)
    return [rows[round(i * stride)] for i in range(limit)]


def history_run(url: str, run_id: int, max_points: int = 4000) -> dict:
    """A run of the history store shaped for the page: per side the times and the mapping's variables
    (thinned to `max_points`), the d-model's states, the commands and the alarms."""
    from ..history import read_run

    data = read_run(url, run_id, max_points=max_points, max_events=MAX_EVENTS)  # bounded, whatever the run's length
    prefix = MAPPING.name + "."
    sides = {}
    try:
        for side, columns in data["columns"].items():
            rows = thin(data["samples"].get(side, []), max_points)
            picked = [(i, c[len(prefix):]) for i, c in enumerate(columns) if c.startswith(prefix)
                      and all(isinstance(values[i], (int, float)) and not isinstance(values[i], bool)
                              for _, values in rows if values[i] is not None)]  # numbers, not the events
            sides[side] = {"time": [t for t, _ in rows],
                           "values": {name: [values[i] for _, values in rows] for i, name in picked}}
    except (IndexError, TypeError):  # a sample of another width than the run's columns
        raise CotwinError(f"run {run_id}: its samples do not match its columns (the store is damaged)") from None
    run = dict(data["run"])
    return {"run": run, "sides": sides, "states": data["states"], "alarms": data["alarms"],
            "commands": data["commands"], "counts": data["counts"],
            "corrections": [{k: c[k] for k in ("time", "kind", "reason", "size")} for c in data.get("corrections", [])]}


def page_publishers(system, events: list[dict], heartbeat) -> dict:
    """The page's command publishers: one for a twin whose commands come from the broker (key None), one per
    robot for such a cell (by robot, each on its robot's routing, cotwin.twin.assembly.cell.routed), none
    when the commands come from a plan."""
    from ...assembly.cell import routed
    from ...assembly.rabbitmq import port_scalars, port_types
    from .commands import PagePublisher

    if isinstance(system, CellSystem):
        program = system.program
        return {robot.name: PagePublisher(routed(system.spec.rabbitmq, robot.name),
                                          port_types(program, robot.system.source_ports), events, heartbeat=heartbeat,
                                          scalars=port_scalars(program))
                for robot in system.robots if robot.system.source is RABBITMQ}
    if system.source is not RABBITMQ:
        return {}
    program = system.models.program
    return {None: PagePublisher(system.spec.rabbitmq, port_types(program, system.source_ports), events,
                                heartbeat=heartbeat, scalars=port_scalars(program))}


class Dashboard:
    """The page of one twin (see module doc). `mode`: twin (a LiveTwin: pass `feed` to it as an
    observer), run (one twin: pass `feed` to run_twin's observers) or history (no live run)."""

    def __init__(self, system: TwinSystem | None, host: str = "127.0.0.1", port: int = 8050, mode: str = "twin",
                 history_url: str | None = None, period: float = 0.1, max_rate: float = 100.0,
                 backlog: int = 4000, heartbeat: bool = True, whatif_url: str | None = None,
                 access: str | Path | None = None, tls: tuple[str | Path, str | Path] | None = None):
        if mode not in ("twin", "run", "history"):
            raise ValueError(f"unknown dashboard mode {mode!r}")
        if system is None and mode != "history":
            raise ValueError("a live dashboard needs the twin's system")
        self.system = system
        self.host, self.port = host, port
        self.access_file, self.tls = access, tls  # see access.py and server.py
        self.access = None
        self.gate: Gate | None = None
        self.header_seconds = HEADER_SECONDS
        self.mode = mode
        self.history_url = history_url
        self.period = period
        self.max_rate = max_rate
        self.backlog = backlog
        cell = isinstance(system, CellSystem)  # a cell of several robots: its own description and feed
        self.feed = (CellFeed if cell else DashboardFeed)(system) if system is not None and mode != "history" else None
        sides = ["pt", "dt"] if mode == "twin" else ["twin"]
        self.whatif_url = whatif_url if system is not None and mode == "twin" and not cell else None  # what-if
        self.model = None if system is None else describe_cell(system, sides, mode) if cell else \
            describe(system, sides, mode, {"whatif": self.whatif_url is not None})
        self.publishers = page_publishers(system, self.model["commands"]["events"], heartbeat) \
            if system is not None and mode != "history" else {}
        self._history_reads = asyncio.Semaphore(MAX_HISTORY_READS)
        self.whatifs = 0  # what-ifs from the page in flight
        self.whatif_timeout = 120.0  # s to wait for the twin's answer
        self.body_seconds = BODY_SECONDS
        self.command_seconds = COMMAND_SECONDS
        self._closing = threading.Event()  # ends the what-ifs the page waits for
        self.clients = 0
        self.skipped = 0  # samples clients skipped because they fell behind
        self._served = None  # cotwin.twin.services.dashboard.server.ServedPage
        self._socket: socket.socket | None = None

    @property
    def publisher(self):
        """A single twin's command publisher (None when its commands come from a plan, or for a cell: `publishers`)."""
        return self.publishers.get(None)

    # ---- lifecycle ----
    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls else 'http'}://{host}:{self.port}/"

    def start(self) -> "Dashboard":
        """Serve the page (and start the command publisher, bound before this returns, so the twin's ready
        message reaches it); CotwinError if the address cannot be served, or is beyond loopback without an
        access file (server.py), or the access file or the TLS certificate cannot be used."""
        import uvicorn

        if self.access_file is not None:
            self.access = Access(self.access_file)
        elif beyond_loopback(self.host):
            raise CotwinError(f"dashboard: {self.host} can be reached from other machines (it is not a loopback "
                              "address), and anyone who reaches the page could command the robot: give it an access "
                              "file (--dashboard-access FILE, made with cotwin dashboard-access; see docs/security.md) "
                              "or serve it on 127.0.0.1")
        if self.tls is not None:
            check_tls(*self.tls)
        elif beyond_loopback(self.host):
            log.warning("dashboard: served on %s without TLS: passwords, tokens and the session cookie cross the "
                        "network in clear text (give --tls-cert and --tls-key)", self.host)
        sock = bound_socket(self.host, self.port, "dashboard")
        self._socket = sock
        self.port = sock.getsockname()[1]
        tls = {"ssl_certfile": str(self.tls[0]), "ssl_keyfile": str(self.tls[1])} if self.tls else {}
        self.gate = Gate(self.app(), self.access, self.tls is not None, str(self.port), self.body_seconds)
        config = uvicorn.Config(self.gate, log_level="warning",
                                access_log=False, lifespan="off", ws=ws_protocol(), timeout_graceful_shutdown=2,
                                http=protocol(self.header_seconds), proxy_headers=False,  # clients are who connects
                                limit_concurrency=MAX_CONNECTIONS, **tls)  # more at once are answered 503
        _cap_server_log()
        try:
            self._served = serve_in_thread(config, sock, "dashboard")
        except CotwinError:
            self.stop()
            raise
        try:
            for publisher in self.publishers.values():
                publisher.start()
        except CotwinError:
            self.stop()
            raise
        return self

    def finish(self, state: str, message: str | None = None) -> None:
        if self.feed is not None:
            self.feed.finish(state, message)

    def stop(self) -> None:
        """Tell the page the run is over, close the streams and stop serving."""
        if self.feed is not None:
            self.feed.finish("stopped")
        self._closing.set()
        for publisher in self.publishers.values():
            publisher.stop()
        if self._served is not None:
            if self._served.running:
                wallclock.sleep(min(2 * self.period, 0.2))  # let the streams send the final status
            self._served.stop(10)
            self._served = None
        if self._socket is not None:
            self._socket.close()
            self._socket = None
        if self.gate is not None:
            self.gate.refusals.close()  # how many refusals were not logged

    def __enter__(self) -> "Dashboard":
        return self.start()

    def __exit__(self, kind, error, tb) -> None:
        if error is not None:
            self.finish("failed" if not isinstance(error, KeyboardInterrupt) else "stopped", str(error))
        self.stop()

    # ---- the app ----
    def app(self):
        from starlette.applications import Starlette
        from starlette.concurrency import run_in_threadpool
        from starlette.responses import FileResponse, JSONResponse, Response
        from starlette.routing import Mount, Route, WebSocketRoute
        from starlette.staticfiles import StaticFiles

        async def index(request):
            return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

        async def favicon(request):
            return Response(status_code=204)

        async def model(request):
            return JSONResponse({"model": self.model, "history": self.history_url is not None, "mode": self.mode})

        async def status(request):
            return JSONResponse(self._status())

        def refused(err: Refused) -> JSONResponse:
            return JSONResponse({"error": err.message}, status_code=err.status)

        async def command(request):
            if not self.publishers:
                commands = self.model["commands"] if self.model else {"source": "history"}
                why = {"plan": f"this twin's commands come from its plan ({commands.get('plan')}), not from the page",
                       "none": "this twin takes no commands"}.get(commands["source"], "no live twin to command")
                return JSONResponse({"error": why}, status_code=409)
            try:
                body = await read_json(request, self._foreign(request.headers), seconds=self.body_seconds)
            except Refused as err:
                return refused(err)
            robots = [name for name in self.publishers if name is not None]  # a cell's: the command names its robot
            shape = ("expected {\"robot\": NAME, \"event\": NAME, \"values\": {PORT: VALUE, ...}}" if robots else
                     "expected {\"event\": NAME, \"values\": {PORT: VALUE, ...}}")
            if not isinstance(body, dict):
                return JSONResponse({"error": shape}, status_code=400)
            unknown = sorted(set(body) - {"event", "values", *(["robot"] if robots else [])})
            if unknown or not isinstance(body.get("event"), str) or not isinstance(body.get("values", {}), dict):
                why = f"unknown key {', '.join(repr(k[:40]) for k in unknown)}" if unknown \
                    else "'event' must be a name" if not isinstance(body.get("event"), str) else "'values' must be an object"
                return JSONResponse({"error": f"{why}: {shape}"}, status_code=400)
            robot = body.get("robot")
            if robots and robot not in robots:
                named = f"no robot {str(robot)[:40]!r} in this cell" if robot is not None else "the command names no robot"
                return JSONResponse({"error": f"{named} (its robots: {', '.join(robots)}): {shape}"}, status_code=400)
            publisher = self.publishers[robot]
            if self._ended():
                return JSONResponse({"error": f"{self._ended()}; it takes no more commands"}, status_code=409)
            try:
                message = publisher.command(body["event"], body.get("values", {}))
            except ValueError as err:
                return JSONResponse({"error": str(err)}, status_code=422)
            except CotwinError as err:  # the link thread stopped: nothing would leave
                return JSONResponse({"error": "; ".join(f.message for f in err.findings)}, status_code=503)
            except queue.Full:
                return JSONResponse({"error": f"{publisher.MAX_WAITING} commands are waiting to be published; "
                                              "try again later"}, status_code=429, headers={"Retry-After": "1"})
            if publisher.error:
                return JSONResponse({"error": publisher.error}, status_code=503)
            return await command_answer(publisher, message)

        async def command_answer(publisher, message: dict) -> JSONResponse:
            """Wait (up to command_seconds, while the twin is there) for the twin to apply or refuse the
            command: 200 with the step that applied it, 409 with the twin's refusal, else 202 (accepted:
            it will be applied; GET /api/command/{id} says when)."""
            ident, ready = message["internal_id"], publisher.twin_ready.is_set()
            deadline = wallclock.monotonic() + (self.command_seconds if ready else 0.0)
            ticket = publisher.ticket(ident)
            while ticket["status"] not in ("applied", "refused") and wallclock.monotonic() < deadline \
                    and not self._closing.is_set():
                await asyncio.sleep(0.02)
                ticket = publisher.ticket(ident)
            if ticket["status"] == "refused":
                return JSONResponse({"error": f"the twin refused the command: {ticket.get('internal_message')}",
                                     "id": ident}, status_code=409)
            if ticket["status"] == "applied":
                return JSONResponse({"applied": {"time": ticket["applied_at"]}, "id": ident, "message": message,
                                     "twin_ready": True})
            return JSONResponse({"queued": message, "id": ident, "status": ticket["status"],
                                 **({"place": ticket["place"]} if "place" in ticket else {}),
                                 "twin_ready": publisher.twin_ready.is_set()}, status_code=202)

        async def command_status(request):
            ident = request.path_params["ident"]
            ticket = next((t for t in (p.ticket(ident) for p in self.publishers.values()) if t is not None), None)
            if ticket is None:
                return JSONResponse({"error": "no such command (or it is too old to be remembered)"}, status_code=404)
            return JSONResponse(ticket)

        async def whatif(request):
            if self.whatif_url is None:
                return JSONResponse({"error": "this twin does not answer what-if requests (cotwin twin --whatif)"},
                                    status_code=409)
            from .whatif import ask, check_request

            try:
                body = await read_json(request, self._foreign(request.headers), seconds=self.body_seconds)
            except Refused as err:
                return refused(err)
            try:
                checked = check_request(body, self.system.models.program)
            except CotwinError as err:
                return JSONResponse({"error": "; ".join(f.message for f in err.findings)}, status_code=422)
            if self._ended():
                return JSONResponse({"error": f"{self._ended()}; there is no live state to fork"}, status_code=409)
            if self.whatifs >= MAX_WHATIFS:  # the server's one event loop: no lock needed
                return JSONResponse({"error": f"{MAX_WHATIFS} what-ifs are already running; try again when one is "
                                              "answered"}, status_code=429, headers={"Retry-After": "5"})
            self.whatifs += 1
            try:
                answer = await run_in_threadpool(ask, self.whatif_url, self.system.spec.deviation.exchange, checked,
                                                 self.whatif_timeout, cancel=self._closing)
            except CotwinError as err:
                return JSONResponse({"error": "; ".join(f.message for f in err.findings)},
                                    status_code=503 if self._closing.is_set() else 504)
            finally:
                self.whatifs -= 1
            return JSONResponse(_finite(answer), status_code=422 if "error" in answer else 200)

        async def runs(request):
            if self.history_url is None:
                return JSONResponse({"runs": [], "error": "no history store"})
            try:
                found = await run_in_threadpool(_list_runs, self.history_url)
            except CotwinError as err:
                return JSONResponse({"runs": [], "error": "; ".join(f.message for f in err.findings)})
            return JSONResponse({"runs": found})

        async def run(request):
            if self.history_url is None:
                return JSONResponse({"error": "no history store"}, status_code=404)
            try:
                run_id = parse_run_id(request.path_params["run_id"])
            except Refused as err:
                return refused(err)
            try:
                async with self._history_reads:  # each read is bounded; so is how many run at once
                    data = await run_in_threadpool(history_run, self.history_url, run_id)
            except CotwinError as err:
                return JSONResponse({"error": "; ".join(f.message for f in err.findings)}, status_code=404)
            return JSONResponse(data)

        routes = [
            Route("/", index),
            Route("/favicon.ico", favicon),
            Route("/api/model", model),
            Route("/api/status", status),
            Route("/api/command", command, methods=["POST"]),
            Route("/api/command/{ident}", command_status),
            Route("/api/whatif", whatif, methods=["POST"]),
            Route("/api/history", runs),
            Route("/api/history/{run_id}", run),
            WebSocketRoute("/ws", self._stream),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
        ]
        return Starlette(routes=routes)

    def _foreign(self, headers) -> str | None:
        """Why a request may come from another site's page (same_site); the Host is checked only where no
        login protects the page (on loopback without an access file)."""
        return same_site(headers, self.host, checked_host=self.access is None)

    def _ended(self) -> str | None:
        """How the live twin ended ("the twin has stopped"), or None while it runs or waits."""
        if self.feed is None or self.feed.state not in ENDED:
            return None
        return f"the twin has {'ended' if self.feed.state == 'done' else self.feed.state}"

    def _status(self) -> dict:
        out = self.feed.status() if self.feed is not None else {"state": "history"}
        out["clients"] = self.clients
        out["skipped"] = self.skipped
        links = {name: {"twin_ready": p.twin_ready.is_set(), "sent": p.sent_count, "running": not p.stopped,
                        "echoes_refused": p.echoes.refused, "error": p.error or ("its link ended" if p.stopped else None)}
                 for name, p in self.publishers.items()}
        if None in links:
            out["broker"] = links[None]
        elif links:  # a cell's: one link per robot
            out["brokers"] = links
        return out

    async def _stream(self, websocket) -> None:
        from starlette.websockets import WebSocketDisconnect

        if self.clients >= MAX_CLIENTS:  # each stream costs the server's loop a task and a copy per batch
            await websocket.accept()  # then closed with a reason the page can show
            await websocket.close(code=1013, reason=f"{MAX_CLIENTS} pages are already following this twin")
            return
        foreign = self._foreign(websocket.headers)
        if foreign is not None:  # another site's page would read the twin's stream
            await websocket.accept()
            await websocket.close(code=1008, reason=foreign[:120])
            return
        await websocket.accept()
        self.clients += 1
        closed = asyncio.Event()

        async def listen():  # the page sends nothing we need; this notices it going away
            try:
                while True:
                    message = await websocket.receive()
                    if message["type"] == "websocket.disconnect":
                        break
            except (WebSocketDisconnect, RuntimeError):
                pass
            closed.set()

        listener = asyncio.create_task(listen())
        feed = self.feed
        try:
            if feed is None:
                await websocket.send_text(_json({"type": "hello", "samples": [], "events": [],
                                                 "status": self._status()}))
                await closed.wait()
                return
            cursor = max(0, feed.samples.count - self.backlog)
            rows, cursor, _ = feed.samples.since(cursor)
            events, seen, events_skipped = feed.events.since(0)
            await websocket.send_text(_json({"type": "hello", "sides": feed.sides, "samples": _rows(rows),
                                             "events": events, "events_skipped": events_skipped,
                                             "status": self._status()}))
            limit = max(1, int(self.max_rate * self.period))
            last_state = None
            while not closed.is_set():
                try:
                    await asyncio.wait_for(closed.wait(), self.period)
                    break
                except asyncio.TimeoutError:
                    pass
                rows, cursor, skipped = feed.samples.since(cursor)
                self.skipped += skipped
                events, seen, events_skipped = feed.events.since(seen)
                status = self._status()
                if not rows and not events and status["state"] == last_state:
                    continue
                last_state = status["state"]
                await websocket.send_text(_json({"type": "batch", "sides": feed.sides,
                                                 "samples": _rows(thin(rows, limit)), "skipped": skipped,
                                                 "events": events, "events_skipped": events_skipped,
                                                 "status": status}))
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        finally:
            self.clients -= 1
            listener.cancel()


def _cap_server_log() -> None:
    """uvicorn warns once per malformed request: a client sending thousands must not fill the log."""
    from ....logcap import CappedFilter

    server_log = logging.getLogger("uvicorn.error")
    if not any(isinstance(f, CappedFilter) for f in server_log.filters):
        server_log.addFilter(CappedFilter("warnings about bad requests"))


def _json(message: dict) -> str:
    """JSON a browser can parse: NaN and infinities (which JSON lacks) become null."""
    try:
        return json.dumps(message, allow_nan=False, default=str)
    except ValueError:
        return json.dumps(_finite(message), allow_nan=False, default=str)


def _rows(rows: list) -> list:
    """Samples on the wire: [time, [values, states] per side]."""
    return [[t, row] for t, _, row in rows]


def _list_runs(url: str) -> list[dict]:
    from ..history import list_runs

    return list_runs(url)
