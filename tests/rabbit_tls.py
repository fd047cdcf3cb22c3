"""Test helpers for the real RabbitMQ: a throwaway PKI made with openssl, a TLS listener started on the
running broker at run time (no restart, nothing written where the broker would have to read it: the
certificates go to it in the call), and a throwaway vhost with one user per role."""

from __future__ import annotations

import os
import re
import secrets
import shutil
import socket
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from cotwin.twin.assembly.broker_access import Role


def broker_up(port: int = 5672) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1):
            return True
    except OSError:
        return False


def tools_missing() -> str | None:
    for tool in ("openssl", "rabbitmqctl"):
        if shutil.which(tool) is None:
            return f"{tool} is not on PATH"
    return None


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


@dataclass
class PKI:
    """A CA, a server certificate for localhost and 127.0.0.1, a client certificate (PEM files)."""

    folder: Path
    names: tuple[str, ...] = ("DNS:localhost", "IP:127.0.0.1")  # the server certificate's subjectAltNames
    ca: Path = field(init=False)
    server: Path = field(init=False)
    server_key: Path = field(init=False)
    client: Path = field(init=False)
    client_key: Path = field(init=False)

    def __post_init__(self) -> None:
        d = self.folder
        d.mkdir(parents=True, exist_ok=True)
        ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
        _openssl("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2",
                 "-subj", "/CN=cotwin test CA", cwd=d)
        for name, subject, ext in [
                ("server", "/CN=localhost", f"subjectAltName={','.join(self.names)}\nextendedKeyUsage=serverAuth\n"),
                ("client", "/CN=cotwin test client", "extendedKeyUsage=clientAuth\n")]:
            _openssl("req", *ec, "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", subject, cwd=d)
            (d / f"{name}.ext").write_text("basicConstraints=CA:FALSE\n" + ext)
            _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
                     "-out", f"{name}.pem", "-days", "2", "-extfile", f"{name}.ext", cwd=d)
        for p in d.iterdir():
            os.chmod(p, 0o600)
        self.ca, self.server, self.server_key = d / "ca.pem", d / "server.pem", d / "server.key"
        self.client, self.client_key = d / "client.pem", d / "client.key"


def _der(pem: Path) -> str:
    """The base64 DER inside a PEM file (one object)."""
    text = pem.read_text()
    body = re.search(r"-----BEGIN ([A-Z ]+)-----(.*?)-----END \1-----", text, re.S)
    return "".join(body.group(2).split())


def _bin(b64: str) -> str:
    return f'base64:decode(<<"{b64}">>)'


def _str(text: str) -> str:
    return "<<\"" + text.replace("\\", "\\\\").replace('"', '\\"') + "\">>"


def rabbitmqctl_eval(expression: str) -> str:
    done = subprocess.run(["rabbitmqctl", "-q", "eval", expression], capture_output=True, text=True, timeout=60)
    if done.returncode != 0:
        raise RuntimeError(f"rabbitmqctl eval failed: {done.stdout}{done.stderr}")
    return done.stdout.strip()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class TLSBroker:
    """A TLS listener on 127.0.0.1:`port` of the running broker (mutual TLS: a client certificate
    signed by the test CA is required), a vhost, and a user per role with a random password."""

    pki: PKI
    roles: list[Role]
    port: int = field(default_factory=free_port)
    vhost: str = field(default_factory=lambda: f"cotwin-test-{secrets.token_hex(4)}")
    passwords: dict[str, str] = field(default_factory=dict)

    def start(self) -> "TLSBroker":
        self.passwords = {r.name: secrets.token_urlsafe(18) for r in self.roles}
        options = (f"[{{cert, {_bin(_der(self.pki.server))}}}, "
                   f"{{key, {{'PrivateKeyInfo', {_bin(_der(self.pki.server_key))}}}}}, "
                   f"{{cacerts, [{_bin(_der(self.pki.ca))}]}}, "
                   "{verify, verify_peer}, {fail_if_no_peer_cert, true}, {versions, ['tlsv1.3', 'tlsv1.2']}]")
        users = "".join(
            f"ok = rabbit_auth_backend_internal:add_user({_str(r.user)}, {_str(self.passwords[r.name])}, <<\"cotwin-test\">>), "
            f"ok = rabbit_auth_backend_internal:set_permissions({_str(r.user)}, V, {_str(r.configure)}, "
            f"{_str(r.write)}, {_str(r.read)}, <<\"cotwin-test\">>), "
            + ("" if r.topic is None else
               f"ok = rabbit_auth_backend_internal:set_topic_permissions({_str(r.user)}, V, {_str(r.topic[0])}, "
               f"{_str(r.topic[1])}, {_str(r.topic[2])}, <<\"cotwin-test\">>), ")
            for r in self.roles)
        rabbitmqctl_eval(f"V = {_str(self.vhost)}, ok = rabbit_vhost:add(V, <<\"cotwin-test\">>), {users}"
                         f"ok = rabbit_networking:start_ssl_listener({{\"127.0.0.1\", {self.port}}}, {options}, 1), ok.")
        return self

    def stop(self) -> None:
        users = "".join(f"catch rabbit_auth_backend_internal:delete_user({_str(r.user)}, <<\"cotwin-test\">>), "
                        for r in self.roles)
        rabbitmqctl_eval(f"catch rabbit_networking:stop_tcp_listener({{\"127.0.0.1\", {self.port}}}), {users}"
                         f"catch rabbit_vhost:delete({_str(self.vhost)}, <<\"cotwin-test\">>), ok.")

    def url(self, host: str = "localhost") -> str:
        return f"amqps://{host}:{self.port}/{self.vhost}"

    def env(self, role: str, **extra: str) -> dict[str, str]:
        """The environment of a process acting in `role` over TLS (credentials, CA, client certificate)."""
        user = next(r.user for r in self.roles if r.name == role)
        return {"COTWIN_AMQP_USER": user, "COTWIN_AMQP_PASSWORD": self.passwords[role],
                "COTWIN_AMQP_CA": str(self.pki.ca), "COTWIN_AMQP_CERT": str(self.pki.client),
                "COTWIN_AMQP_KEY": str(self.pki.client_key), **extra}


def close_connection(name: str) -> bool:
    """Close, from the broker's side, the connections whose name contains `name`."""
    listing = subprocess.run(["rabbitmqctl", "-q", "list_connections", "pid", "client_properties"],
                             capture_output=True, text=True, timeout=30)
    found = False
    for line in listing.stdout.splitlines():
        if name in line:
            pid = line.split("\t", 1)[0]
            subprocess.run(["rabbitmqctl", "-q", "close_connection", pid, "test: closed by the broker"],
                           capture_output=True, timeout=30)
            found = True
    return found
