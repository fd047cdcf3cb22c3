"""Who may drive the plant over OPC UA: operator credentials shared by the plant and its clients, and
the loopback rule for where a plant listens.

Anonymous OPC UA sessions may browse, read and subscribe (watch the cell), never call a method or
write. Driving the cell (Command, Advance, Reset) takes an operator login (user name and password).
Credentials, in this order: COTWIN_OPCUA_USER and COTWIN_OPCUA_PASSWORD; a file named by
COTWIN_OPCUA_CREDENTIALS holding `user:password` on its first line; else the plant makes a random
password at start and writes `cotwin:<password>` to a file only its user can read,
`<runtime dir>/opcua-<host>-<port>.credentials` (runtime dir: $XDG_RUNTIME_DIR/cotwin, else
/tmp/cotwin-<uid>, mode 0700), which clients of the same user on the same machine find by the URL.
Credentials never come from project files and never appear in messages.
"""

from __future__ import annotations

import hmac
import ipaddress
import os
import secrets
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from ..diagnostics import CotwinError

DEFAULT_USER = "cotwin"


@dataclass(frozen=True)
class Credentials:
    user: str
    password: str = ""

    def matches(self, user: str | None, password: str | None) -> bool:
        return (user is not None and password is not None and hmac.compare_digest(user.encode(), self.user.encode())
                and hmac.compare_digest(password.encode(), self.password.encode()))

    def __repr__(self) -> str:  # never print the password
        return f"Credentials(user={self.user!r})"


def parse_url(url: str) -> tuple[str, int]:
    """(host, port) of an opc.tcp:// URL, or CotwinError saying what is wrong."""
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as err:
        raise CotwinError(f"bad OPC UA URL '{url}': {err}") from None
    if parts.scheme != "opc.tcp":
        raise CotwinError(f"bad OPC UA URL '{url}': expected opc.tcp://HOST:PORT")
    if parts.username is not None or parts.password is not None:
        raise CotwinError("an OPC UA URL with user information is refused: give credentials in the environment "
                          "(COTWIN_OPCUA_USER, COTWIN_OPCUA_PASSWORD) or a file (COTWIN_OPCUA_CREDENTIALS)")
    if not parts.hostname:
        raise CotwinError(f"bad OPC UA URL '{url}': no host")
    return parts.hostname, 4840 if port is None else port


def opc_url(host: str, port: int) -> str:
    """The opc.tcp:// URL of (host, port), an IPv6 address in brackets (what parse_url reads back)."""
    return f"opc.tcp://[{host}]:{port}" if ":" in host else f"opc.tcp://{host}:{port}"


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def runtime_dir(environ=os.environ) -> Path:
    """A folder only this user can enter, for the plant's generated credentials."""
    base = environ.get("XDG_RUNTIME_DIR")
    folder = Path(base) / "cotwin" if base else Path(tempfile.gettempdir()) / f"cotwin-{os.getuid()}"
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    info = folder.lstat()
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid() or info.st_mode & 0o077:
        raise CotwinError(f"{folder} must be a folder of this user that no one else can enter (mode 0700)")
    return folder


def default_credentials_file(url: str, environ=os.environ) -> Path:
    host, port = parse_url(url)
    return runtime_dir(environ) / f"opcua-{host.replace(':', '_')}-{port}.credentials"


def _read_file(path: str | Path, what: str) -> Credentials:
    try:
        with open(path, encoding="utf-8") as f:
            first = f.readline().strip()
    except (OSError, UnicodeDecodeError) as err:
        raise CotwinError(f"cannot read {what}: {getattr(err, 'strerror', None) or err}") from None
    user, sep, password = first.partition(":")
    if not sep or not user:
        raise CotwinError(f"{what} must hold 'user:password' on its first line")
    return Credentials(user, password)


def configured_credentials(environ=os.environ) -> Credentials | None:
    """Credentials from the environment or the file it names, if any."""
    user, password = environ.get("COTWIN_OPCUA_USER"), environ.get("COTWIN_OPCUA_PASSWORD")
    if user and password is not None:
        return Credentials(user, password)
    path = environ.get("COTWIN_OPCUA_CREDENTIALS")
    if path:
        return _read_file(path, "the plant credentials file named by COTWIN_OPCUA_CREDENTIALS")
    return None


def client_credentials(url: str, environ=os.environ) -> Credentials:
    """What a client logs in with: configured credentials, else those the plant wrote for this URL."""
    configured = configured_credentials(environ)
    if configured is not None:
        return configured
    path = default_credentials_file(url, environ)
    if not path.is_file():
        raise CotwinError(f"no operator credentials for the plant at {url}: set COTWIN_OPCUA_USER and "
                          f"COTWIN_OPCUA_PASSWORD or COTWIN_OPCUA_CREDENTIALS, or run the plant as this user "
                          f"on this machine (it writes {path})")
    return _read_file(path, f"the plant's credentials file {path}")


class PlantCredentials:
    """The plant's operator account: configured, or generated. A generated one is written for local
    clients by `publish(url)`, which the plant calls only once it listens on that URL's port: a plant that
    fails to start (a busy port) never writes, and so never replaces or removes, another plant's file.
    `close` removes the file if it still holds this account."""

    def __init__(self, environ=os.environ):
        configured = configured_credentials(environ)
        self._environ = environ
        self.file: Path | None = None
        self.generated = configured is None
        self.credentials = configured or Credentials(DEFAULT_USER, secrets.token_urlsafe(24))

    def publish(self, url: str) -> None:
        if not self.generated:
            return
        self.close()
        self.file = default_credentials_file(url, self._environ)
        partial = self.file.with_suffix(f".{os.getpid()}.tmp")
        fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(f"{self.credentials.user}:{self.credentials.password}\n")
        os.replace(partial, self.file)

    def close(self) -> None:
        if self.file is not None:
            try:
                if self.file.read_text(encoding="utf-8").strip() == f"{self.credentials.user}:{self.credentials.password}":
                    self.file.unlink()
            except OSError:
                pass
            self.file = None
