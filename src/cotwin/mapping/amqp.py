"""Connections to a RabbitMQ broker, the same way for every link of the twin (robot endpoint, command
bridge, alarms): credentials never come from project files nor appear in messages, `amqps://` verifies
the broker's certificate and host name by default, and plain AMQP is kept to the loopback interface.

Credentials, in this order: COTWIN_AMQP_USER and COTWIN_AMQP_PASSWORD; a file named by
COTWIN_AMQP_CREDENTIALS holding `user:password` on its first line (readable by its owner only); else,
for a broker on loopback only, RabbitMQ's guest account (which RabbitMQ itself only admits from there).

TLS (amqps://): COTWIN_AMQP_CA, a CA bundle (default: the system's); COTWIN_AMQP_CERT and
COTWIN_AMQP_KEY (and COTWIN_AMQP_KEY_PASSWORD), a client certificate; COTWIN_AMQP_SERVER_NAME, the name
to expect in the broker's certificate and send as SNI (default: the URL's host); COTWIN_AMQP_VERIFY=0
turns verification off (a test broker only: it is logged at every connection). Plain amqp:// to a host
other than loopback is refused unless COTWIN_AMQP_ALLOW_PLAIN=1.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import re
import ssl
import stat
from dataclasses import dataclass
from typing import Mapping
from urllib.parse import unquote, urlsplit

import pika

from ..diagnostics import CotwinError

log = logging.getLogger("cotwin.amqp")

MAX_SECRET_FILE = 4096  # bytes: a credentials or secret file holds one short line


def url_has_password(url: str) -> bool:
    try:
        return urlsplit(url).password is not None
    except ValueError:
        return False


def url_problem(url: str) -> str | None:
    """Why `url` cannot name a broker (scheme, port, user information), or None. Never quotes the URL
    beyond its scheme, host, port and path (a malformed one may hold a password anywhere)."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return "bad broker URL: malformed"
    if parts.scheme not in ("amqp", "amqps"):
        return f"bad broker URL {redact(url)}: expected amqp:// or amqps://"
    if "@" in url or parts.password is not None or parts.username is not None:
        return (f"the broker URL {redact(url)} holds user information (a user name or password): give credentials "
                "in the environment (COTWIN_AMQP_USER, COTWIN_AMQP_PASSWORD) or a file (COTWIN_AMQP_CREDENTIALS)")
    try:
        parts.port  # noqa: B018 - raises ValueError on a bad port
    except ValueError:
        return "bad broker URL: the port is not a number in 1..65535"
    return None


def redact(url: str) -> str:
    """The URL without user information, for messages (whatever characters a password holds)."""
    scheme, sep, rest = url.partition("://")
    if sep and "@" in rest:
        url = f"{scheme}://{rest.rpartition('@')[2]}"
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:
        return "<malformed url>"
    host = parts.hostname or ""
    if ":" in host:
        host = f"[{host}]"
    if port:
        host = f"{host}:{port}"
    return f"{parts.scheme}://{host}{parts.path}"


def is_loopback(host: str) -> bool:
    if host.lower() in ("localhost", "localhost.", "ip6-localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def read_secret_file(path: str, variable: str) -> str:
    """The first line of a file holding a secret; refused if others than its owner may read it."""
    try:
        info = os.stat(path)
        if stat.S_IMODE(info.st_mode) & 0o077:
            raise CotwinError(f"{path} (named by {variable}) may be read by others than its owner: "
                              f"chmod 600 {path}")
        with open(path, "rb") as f:
            data = f.read(MAX_SECRET_FILE + 1)
    except OSError as err:
        raise CotwinError(f"cannot read {path} (named by {variable}): {err.strerror or err}") from None
    if len(data) > MAX_SECRET_FILE:
        raise CotwinError(f"{path} (named by {variable}): more than {MAX_SECRET_FILE} bytes, expected one line")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise CotwinError(f"{path} (named by {variable}): not UTF-8 text") from None
    return text.split("\n", 1)[0].rstrip("\r")


@dataclass(frozen=True)
class Credentials:
    user: str
    password: str
    source: str  # where they came from, for messages (never the password)


def credentials(environ: Mapping[str, str] = os.environ, host: str = "127.0.0.1") -> Credentials:
    """The broker credentials (see module doc), or CotwinError saying what is missing."""
    user, password = environ.get("COTWIN_AMQP_USER"), environ.get("COTWIN_AMQP_PASSWORD")
    if user or password:
        if not user or password is None:
            raise CotwinError("COTWIN_AMQP_USER and COTWIN_AMQP_PASSWORD go together: set both or neither")
        return Credentials(user, password, "COTWIN_AMQP_USER")
    path = environ.get("COTWIN_AMQP_CREDENTIALS")
    if path:
        user, sep, password = read_secret_file(path, "COTWIN_AMQP_CREDENTIALS").partition(":")
        if not sep or not user:
            raise CotwinError(f"{path} (named by COTWIN_AMQP_CREDENTIALS) must hold 'user:password' on its first line")
        return Credentials(user, password, "COTWIN_AMQP_CREDENTIALS")
    if is_loopback(host):
        return Credentials("guest", "guest", "the default guest account")
    raise CotwinError(f"no credentials for the broker at {host}: set COTWIN_AMQP_USER and COTWIN_AMQP_PASSWORD, "
                      "or COTWIN_AMQP_CREDENTIALS (a file holding 'user:password')")


def tls_context(environ: Mapping[str, str] = os.environ) -> ssl.SSLContext:
    """A client context: TLS 1.2 or newer, the broker's certificate and host name verified."""
    ca = environ.get("COTWIN_AMQP_CA") or None
    try:
        context = ssl.create_default_context(cafile=ca)
    except (OSError, ssl.SSLError) as err:
        raise CotwinError(f"cannot load the CA bundle {ca} (COTWIN_AMQP_CA): {_reason(err)}") from None
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    cert, key = environ.get("COTWIN_AMQP_CERT"), environ.get("COTWIN_AMQP_KEY")
    if key and not cert:
        raise CotwinError("COTWIN_AMQP_KEY is set without COTWIN_AMQP_CERT (the client certificate)")
    if cert:
        try:
            context.load_cert_chain(cert, key or None, password=environ.get("COTWIN_AMQP_KEY_PASSWORD") or None)
        except (OSError, ssl.SSLError) as err:
            raise CotwinError(f"cannot load the client certificate {cert} (COTWIN_AMQP_CERT) with its key "
                              f"{key or '(in the same file)'} (COTWIN_AMQP_KEY): {_reason(err)}") from None
    if environ.get("COTWIN_AMQP_VERIFY", "1") == "0":
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
    return context


def _reason(err: BaseException) -> str:
    if isinstance(err, ssl.SSLError) and err.reason:
        return err.reason.replace("_", " ").lower()
    if isinstance(err, OSError) and err.strerror:
        return err.strerror
    return type(err).__name__


def parameters(url: str, name: str = "cotwin", heartbeat: int = 30,
               environ: Mapping[str, str] = os.environ) -> pika.ConnectionParameters:
    """Connection parameters for an amqp:// or amqps:// URL (host, port, vhost); user information in
    the URL is refused, the connection is named (RabbitMQ shows and can close it by that name)."""
    problem = url_problem(url)
    if problem:
        raise CotwinError(problem)
    parts = urlsplit(url)
    host = parts.hostname or "127.0.0.1"
    tls = parts.scheme == "amqps"
    if not tls and not is_loopback(host) and environ.get("COTWIN_AMQP_ALLOW_PLAIN") != "1":
        raise CotwinError(f"plain AMQP to {redact(url)} would send the credentials and the twin's data in clear: "
                          "use amqps:// (or set COTWIN_AMQP_ALLOW_PLAIN=1 on a trusted network)")
    vhost = unquote(parts.path[1:]) if len(parts.path) > 1 else "/"
    ssl_options = None
    if tls:
        context = tls_context(environ)
        if context.verify_mode == ssl.CERT_NONE:
            log.warning("TLS to %s without certificate verification (COTWIN_AMQP_VERIFY=0)", redact(url))
        ssl_options = pika.SSLOptions(context, environ.get("COTWIN_AMQP_SERVER_NAME") or host)
    creds = credentials(environ, host)
    return pika.ConnectionParameters(
        host=host, port=parts.port or (5671 if tls else 5672), virtual_host=vhost,
        credentials=pika.PlainCredentials(creds.user, creds.password), ssl_options=ssl_options,
        heartbeat=heartbeat, blocked_connection_timeout=30, connection_attempts=1, socket_timeout=5,
        client_properties={"connection_name": name})


def connect(url: str, name: str = "cotwin", environ: Mapping[str, str] | None = None) -> pika.BlockingConnection:
    """A blocking connection, or CotwinError naming the broker (without credentials) and the reason."""
    environ = os.environ if environ is None else environ
    params = parameters(url, name, environ=environ)
    try:
        return pika.BlockingConnection(params)
    except (pika.exceptions.AMQPError, OSError) as err:
        raise CotwinError(scrub(connect_error(url, err, params), environ)) from None


def declare_exchange(channel, name: str, kind: str, url: str, what: str) -> None:
    """Declare `name` as cotwin declares its exchanges (type `kind`, not durable, not auto-deleted), or
    CotwinError naming it and `what` set its name if one of that name exists otherwise (another
    application's exchange, or one declared by hand): the broker refuses the declaration (406)."""
    try:
        channel.exchange_declare(name, exchange_type=kind, durable=False, auto_delete=False)
    except pika.exceptions.ChannelClosedByBroker as err:
        if err.reply_code != 406:
            raise
        found = re.search(r"inequivalent arg '(\w+)'.*received '?([^' ]+)'? but current is '?([^' ]+)'?", err.reply_text)
        why = (f"it is a {found[3]} exchange" if found and found[1] == "type" else
               f"its '{found[1]}' is {found[3]}, not {found[2]}" if found else err.reply_text[:160])
        raise CotwinError(f"RabbitMQ {redact(url)}: the exchange '{name}' exists already and is not the {kind} exchange "
                          f"cotwin uses ({why}; another application's?): name another exchange for {what}, or delete "
                          "that one") from None


def connect_error(url: str, err: BaseException, params: pika.ConnectionParameters | None = None) -> str:
    """What went wrong when connecting, in the user's terms."""
    where = f"the broker at {redact(url)}"
    user = params.credentials.username if params is not None else "?"
    vhost = params.virtual_host if params is not None else "?"
    text = f"{err!r}"
    if isinstance(err, ssl.SSLCertVerificationError):
        return (f"TLS: the certificate of {where} could not be verified ({err.verify_message}): give the CA that "
                "signed it in COTWIN_AMQP_CA, and connect by a name the certificate holds (or set COTWIN_AMQP_SERVER_NAME)")
    if "CERTIFICATE_REQUIRED" in text:
        return f"TLS: {where} requires a client certificate: set COTWIN_AMQP_CERT and COTWIN_AMQP_KEY"
    if any(alert in text for alert in ("UNKNOWN_CA", "BAD_CERTIFICATE", "CERTIFICATE_UNKNOWN", "CERTIFICATE_EXPIRED")):
        return f"TLS: {where} refused the client certificate (COTWIN_AMQP_CERT): {_alert(text)}"
    if "WRONG_VERSION_NUMBER" in text or "RECORD_LAYER_FAILURE" in text:
        return f"TLS: {where} does not speak TLS on this port (amqps:// to a plain AMQP port?)"
    if isinstance(err, ssl.SSLError):
        return f"TLS with {where} failed: {_reason(err)}"
    if isinstance(err, (pika.exceptions.ProbableAuthenticationError, pika.exceptions.AuthenticationError)):
        return f"{where} refused the credentials of user '{user}'"
    if isinstance(err, pika.exceptions.ProbableAccessDeniedError):
        return f"{where}: user '{user}' may not use virtual host '{vhost}' (or does not exist)"
    tls = params is not None and params.ssl_options is not None
    if isinstance(err, pika.exceptions.IncompatibleProtocolError) and tls:
        return (f"{where} closed the connection right after the TLS handshake: it may require a client certificate "
                "(set COTWIN_AMQP_CERT and COTWIN_AMQP_KEY) or refuse the one given")
    if isinstance(err, pika.exceptions.IncompatibleProtocolError):
        return f"{where} closed the connection during the handshake (a TLS port reached with amqp://? then use amqps://)"
    if "ConnectionRefusedError" in text:
        return f"cannot reach {where}: connection refused (is RabbitMQ listening there?)"
    if "gaierror" in text:
        return f"cannot reach {where}: unknown host"
    if "timeout" in text.lower():
        return f"cannot reach {where}: timed out"
    return f"cannot reach {where} ({type(err).__name__}{': ' + str(err) if str(err) else ''})"


def _alert(text: str) -> str:
    for alert in ("UNKNOWN_CA", "BAD_CERTIFICATE", "CERTIFICATE_UNKNOWN", "CERTIFICATE_EXPIRED"):
        if alert in text:
            return alert.replace("_", " ").lower()
    return "refused"


def secrets_of(environ: Mapping[str, str] = os.environ) -> list[str]:
    """Every secret cotwin may hold from this environment (to keep them out of messages)."""
    found = [environ.get(v) for v in ("COTWIN_AMQP_PASSWORD", "COTWIN_AMQP_KEY_PASSWORD", "COTWIN_ROBOT_SECRET")]
    for variable in ("COTWIN_AMQP_CREDENTIALS", "COTWIN_ROBOT_SECRET_FILE"):
        path = environ.get(variable)
        if path:
            try:
                line = read_secret_file(path, variable)
            except CotwinError:
                continue
            found.append(line.partition(":")[2] if variable == "COTWIN_AMQP_CREDENTIALS" else line)
    return [s for s in found if s and len(s) >= 3]


def scrub(text: str, environ: Mapping[str, str] = os.environ) -> str:
    """Remove every known secret from a message (a library's text may quote what it was given)."""
    for secret in sorted(secrets_of(environ), key=len, reverse=True):
        text = text.replace(secret, "***")
    return text
