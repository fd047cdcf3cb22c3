"""How the dashboard is served: where it may listen, its TLS certificate, and an HTTP protocol that gives a
client HEADER_SECONDS to send each request's head (uvicorn gives any time: 128 sockets that never finish
a request held every connection the server allows, and the page was answered 503 until they went).

"Beyond loopback" is decided by the address the page is bound to, never by who connects: a loopback
address (127.0.0.0/8, ::1, localhost) is reachable from this machine only, anything else (an interface's
address, 0.0.0.0 or :: for all of them, a name resolving to one) from other machines too. A page bound
beyond loopback needs an access file (cotwin.twin.services.dashboard.access), or it is refused at start.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import ssl
from pathlib import Path

from ....diagnostics import CotwinError
from ....logcap import CappedLog
from ....mapping.amqp import is_loopback
from ....service import BackgroundService, reason

log = logging.getLogger("cotwin.dashboard")
HEADER_SECONDS = 10.0  # to send a request's line and headers (every request of a kept-alive connection)


def beyond_loopback(host: str) -> bool:
    """Whether a server bound to `host` can be reached from other machines (see module doc): every address
    the name resolves to must be a loopback one for it not to be."""
    if is_loopback(host.strip("[]")):
        return False
    try:
        found = {info[4][0] for info in socket.getaddrinfo(host.strip("[]"), None, type=socket.SOCK_STREAM)}
    except (socket.gaierror, UnicodeError):
        return True  # cannot tell; binding will say what is wrong with it
    for address in found:
        ip = ipaddress.ip_address(address.split("%")[0])
        mapped = getattr(ip, "ipv4_mapped", None)
        if not (ip.is_loopback or (mapped is not None and mapped.is_loopback)):
            return True
    return False


def check_tls(cert: str | Path, key: str | Path) -> None:
    """CotwinError naming the option if the certificate and key cannot serve TLS."""
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    for option, path in (("--tls-cert", cert), ("--tls-key", key)):
        if not Path(path).is_file():
            raise CotwinError(f"{option} {path}: no such file")
    try:
        context.load_cert_chain(str(cert), str(key))
    except ssl.SSLError as err:
        raise CotwinError(f"--tls-cert {cert} / --tls-key {key}: not a certificate and its private key "
                          f"({err.reason or err})") from None
    except OSError as err:
        raise CotwinError(f"--tls-cert {cert} / --tls-key {key}: {err.strerror or err}") from None


def protocol(header_seconds: float = HEADER_SECONDS):
    """uvicorn's h11 protocol, closing a connection whose request head does not arrive in `header_seconds`
    (answered 408, logged as a refusal)."""
    import h11
    from uvicorn.protocols.http.h11_impl import H11Protocol

    late = CappedLog(log, "connections closed for slow request headers")

    class TimelyH11(H11Protocol):
        def connection_made(self, transport) -> None:
            super().connection_made(transport)
            self._head_timer = None
            self._await_head()

        def _await_head(self) -> None:
            self._head_done()
            self._head_timer = self.loop.call_later(header_seconds, self._head_late)

        def _head_done(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
                self._head_timer = None

        def handle_events(self) -> None:
            super().handle_events()
            if self.conn.their_state is not h11.IDLE:  # a request's head is in (or the connection is over)
                self._head_done()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            if not self.transport.is_closing():
                self._await_head()  # the next request on this connection gets the same time

        def connection_lost(self, exc) -> None:
            self._head_done()
            super().connection_lost(exc)

        def _head_late(self) -> None:
            self._head_timer = None
            if self.transport.is_closing() or self.conn.their_state is not h11.IDLE:
                return
            client = self.client[0] if self.client else "?"
            late.warning("dashboard refused a connection from %s: 408 no request head within %g s", client,
                         header_seconds)
            self.transport.write(b"HTTP/1.1 408 Request Timeout\r\nconnection: close\r\ncontent-length: 0\r\n\r\n")
            self.transport.close()

    return TimelyH11


def ws_protocol():
    """uvicorn's websockets protocol, counting a denial response (a 401 to a stream without credentials) as
    a finished handshake: uvicorn answers it, then logs "ASGI callable returned without completing
    handshake" as an error for each one (a flood of refused streams would flood the log with errors)."""
    from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

    class DenyingProtocol(WebSocketsSansIOProtocol):
        async def send(self, message) -> None:
            await super().send(message)
            if message["type"] == "websocket.http.response.body" and not message.get("more_body", False):
                self.handshake_complete = True

    return DenyingProtocol


def bound_socket(host: str, port: int, what: str) -> socket.socket:
    """A TCP socket bound to HOST:PORT for a page of ours (PORT 0: a free one); a port that cannot be had is a
    readable error naming the page."""
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as err:
        sock.close()
        raise CotwinError(f"{what}: cannot serve on {host}:{port}: {err.strerror or err}") from None
    return sock


class ServedPage(BackgroundService):
    """A uvicorn server for a page of ours on a bound socket, in its own thread (cotwin.service): ready once it
    serves; one that does not start within the timeout is stopped and a readable error naming the page."""

    def __init__(self, config, sock: socket.socket, what: str):
        import uvicorn

        BackgroundService.__init__(self, f"cotwin {what}")
        self.what, self.sock = what, sock
        page = self

        class Server(uvicorn.Server):
            async def startup(self, sockets=None) -> None:
                await super().startup(sockets=sockets)
                if self.started:
                    page.ready()

        self.server = Server(config)

    def serve(self) -> None:
        self.server.run(sockets=[self.sock])

    def interrupt(self) -> None:
        self.server.should_exit = True

    def late(self, timeout: float) -> CotwinError:
        host, port = self.sock.getsockname()[:2]
        return CotwinError(f"{self.what}: the server did not start on {host}:{port}")

    def error_of(self, err: BaseException) -> CotwinError:
        host, port = self.sock.getsockname()[:2]
        return CotwinError(f"{self.what}: the server did not start on {host}:{port} ({reason(err)})")


def serve_in_thread(config, sock: socket.socket, what: str, timeout: float = 10.0) -> ServedPage:
    """A uvicorn server for `config` on `sock` in a daemon thread (a ServedPage), returned once it is serving;
    one that does not start within `timeout` s is stopped and a readable error."""
    return ServedPage(config, sock, what).start(timeout)
