"""Connections to a RabbitMQ broker, the same way for every link of the twin (robot endpoint, command
bridge, alarms): credentials never come from project files nor appear in messages, and `amqps://`
verifies the broker's certificate by default.

Credentials, in this order: COTWIN_AMQP_USER and COTWIN_AMQP_PASSWORD; a file named by
COTWIN_AMQP_CREDENTIALS holding `user:password` on its first line; else RabbitMQ's guest account,
which RabbitMQ itself only admits from loopback. TLS: COTWIN_AMQP_CA (a CA bundle; default: the
system's), COTWIN_AMQP_CERT / COTWIN_AMQP_KEY (a client certificate), COTWIN_AMQP_VERIFY=0 to turn
verification off (for a test broker only).
"""

from __future__ import annotations

import os
import ssl
from urllib.parse import unquote, urlsplit

import pika

from ..diagnostics import CotwinError


def url_has_password(url: str) -> bool:
    try:
        return urlsplit(url).password is not None
    except ValueError:
        return False


def redact(url: str) -> str:
    """The URL without user information, for messages."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return "<malformed url>"
    host = parts.hostname or ""
    if parts.port:
        host = f"{host}:{parts.port}"
    return f"{parts.scheme}://{host}{parts.path}"


def credentials(environ=os.environ) -> pika.PlainCredentials:
    user, password = environ.get("COTWIN_AMQP_USER"), environ.get("COTWIN_AMQP_PASSWORD")
    if user and password is not None:
        return pika.PlainCredentials(user, password)
    path = environ.get("COTWIN_AMQP_CREDENTIALS")
    if path:
        try:
            with open(path, encoding="utf-8") as f:
                first = f.readline().strip()
        except (OSError, UnicodeDecodeError) as err:
            raise CotwinError(f"cannot read the broker credentials file named by COTWIN_AMQP_CREDENTIALS: {err}") from None
        user, sep, password = first.partition(":")
        if not sep or not user:
            raise CotwinError("the broker credentials file (COTWIN_AMQP_CREDENTIALS) must hold 'user:password' "
                              "on its first line")
        return pika.PlainCredentials(user, password)
    return pika.PlainCredentials("guest", "guest")


def tls_context(environ=os.environ) -> ssl.SSLContext:
    context = ssl.create_default_context(cafile=environ.get("COTWIN_AMQP_CA") or None)
    if environ.get("COTWIN_AMQP_CERT"):
        context.load_cert_chain(environ["COTWIN_AMQP_CERT"], environ.get("COTWIN_AMQP_KEY") or None)
    if environ.get("COTWIN_AMQP_VERIFY", "1") == "0":
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
    return context


def parameters(url: str, name: str = "cotwin", heartbeat: int = 30, environ=os.environ) -> pika.ConnectionParameters:
    """Connection parameters for an amqp:// or amqps:// URL (host, port, vhost); user information in
    the URL is refused, the connection is named (RabbitMQ shows and can close it by that name)."""
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as err:
        raise CotwinError(f"bad broker URL {redact(url)}: {err}") from None
    if parts.scheme not in ("amqp", "amqps"):
        raise CotwinError(f"bad broker URL {redact(url)}: expected amqp:// or amqps://")
    if parts.password is not None:
        raise CotwinError(f"the broker URL {redact(url)} holds a password: give credentials in the environment "
                          "(COTWIN_AMQP_USER, COTWIN_AMQP_PASSWORD) or a file (COTWIN_AMQP_CREDENTIALS)")
    tls = parts.scheme == "amqps"
    vhost = unquote(parts.path[1:]) if len(parts.path) > 1 else "/"
    ssl_options = None
    if tls:
        try:
            ssl_options = pika.SSLOptions(tls_context(environ), parts.hostname or "localhost")
        except (OSError, ssl.SSLError) as err:
            raise CotwinError(f"cannot set up TLS for {redact(url)}: {err}") from None
    return pika.ConnectionParameters(
        host=parts.hostname or "127.0.0.1", port=port or (5671 if tls else 5672), virtual_host=vhost,
        credentials=credentials(environ), ssl_options=ssl_options, heartbeat=heartbeat,
        blocked_connection_timeout=30, connection_attempts=1, socket_timeout=5,
        client_properties={"connection_name": name})


def connect(url: str, name: str = "cotwin") -> pika.BlockingConnection:
    """A blocking connection, or CotwinError naming the broker (without credentials) and the reason."""
    params = parameters(url, name)
    try:
        return pika.BlockingConnection(params)
    except pika.exceptions.ProbableAuthenticationError:
        raise CotwinError(f"the broker at {redact(url)} refused the credentials") from None
    except pika.exceptions.AMQPError as err:
        reason = type(err).__name__ + (f": {err}" if str(err) else "")
        raise CotwinError(f"cannot reach the broker at {redact(url)} ({_scrub(reason)})") from None


def _scrub(text: str) -> str:
    """Remove anything that looks like a credential from a library's message."""
    secret = os.environ.get("COTWIN_AMQP_PASSWORD")
    return text.replace(secret, "***") if secret else text
