"""The dashboard beyond loopback: refused at start without an access file; with one, every route answers
401 to a client without credentials, a viewer's command 403, an operator's goes to the broker; logins,
sessions, revocation, TLS, and the page in a real browser logging in and commanding as an operator.

"Beyond loopback" is the address the page is bound to (docs/security.md). These tests serve on an
address of this machine that is not loopback and, where the test may make one (root, `ip netns`), send
the requests from another network namespace through a veth pair: a client that reaches the page over
a network, not over loopback. Elsewhere they send them from this machine to that address, and say so."""

from __future__ import annotations

import fcntl
import json
import logging
import os
import random
import shutil
import socket
import struct
import subprocess
import sys
import time
import urllib.error
import urllib.request
import uuid
from dataclasses import dataclass, replace
from pathlib import Path

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.twin.services.dashboard import Dashboard
from cotwin.twin.services.dashboard.access import Person, hash_password, hash_token, new_token, read_access, write_access

ROOT = Path(__file__).resolve().parents[1]
BROKER = "amqp://127.0.0.1:5672/%2F"
CHROMIUM = Path("/usr/bin/chromium")
MOVE = {"event": "moveDiscreteCommand",
        "values": {"MovementArgs_target_X": 2, "MovementArgs_target_Y": 5, "MovementArgs_target_Z": 0}}
PASSWORD = "operator's long password"

CLIENT = r'''
import json, ssl, sys, urllib.error, urllib.request
from websockets.sync.client import connect
from websockets.exceptions import InvalidStatus
out = []
for r in json.load(sys.stdin):
    context = ssl.create_default_context(cafile=r["ca"]) if r.get("ca") else None
    if r["method"] == "WS":
        try:
            with connect(r["url"], additional_headers=r["headers"], open_timeout=10, ssl=context):
                out.append([101, ""])
        except InvalidStatus as err:
            out.append([err.response.status_code, err.response.body.decode("utf-8", "replace")])
        continue
    body = r["body"].encode() if r["body"] is not None else None
    request = urllib.request.Request(r["url"], body, r["headers"], method=r["method"])
    try:
        with urllib.request.urlopen(request, timeout=20, context=context) as answer:
            out.append([answer.status, answer.read(4000).decode("utf-8", "replace")])
    except urllib.error.HTTPError as err:
        out.append([err.code, err.read(4000).decode("utf-8", "replace")])
    except (urllib.error.URLError, OSError) as err:
        out.append([0, str(err)])
print(json.dumps(out))
'''


@dataclass
class Away:
    """An address of this machine beyond loopback to serve on, and a way to send requests to it from
    another network namespace (`elsewhere`) or, where none can be made, from this machine."""

    address: str
    namespace: str | None

    @property
    def elsewhere(self) -> bool:
        return self.namespace is not None

    def send(self, requests: list[dict]) -> list[tuple[int, str]]:
        prefix = ["ip", "netns", "exec", self.namespace] if self.namespace else []
        proc = subprocess.run([*prefix, sys.executable, "-c", CLIENT], input=json.dumps(requests), capture_output=True,
                              text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return [tuple(r) for r in json.loads(proc.stdout)]


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


def _local_addresses() -> list[str]:
    """This machine's IPv4 addresses that are not loopback (from its interfaces)."""
    found = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for _, name in socket.if_nameindex():
            try:
                packed = fcntl.ioctl(s.fileno(), 0x8915, struct.pack("256s", name[:15].encode()))  # SIOCGIFADDR
            except OSError:
                continue
            address = socket.inet_ntoa(packed[20:24])
            if not address.startswith("127."):
                found.append(address)
    return found


@pytest.fixture(scope="module")
def away():
    tag = uuid.uuid4().hex[:8]
    namespace, outside, inside = f"cotwin{tag}", f"cw{tag}a", f"cw{tag}b"
    subnet = f"10.{random.randrange(200, 250)}.{random.randrange(256)}.{4 * random.randrange(64)}"
    base = subnet.rsplit(".", 1)
    host, peer = f"{base[0]}.{int(base[1]) + 1}", f"{base[0]}.{int(base[1]) + 2}"
    made = shutil.which("ip") is not None and os.geteuid() == 0 and _ip("netns", "add", namespace).returncode == 0
    if made:
        steps = [("link", "add", outside, "type", "veth", "peer", "name", inside),
                 ("link", "set", inside, "netns", namespace), ("addr", "add", f"{host}/30", "dev", outside),
                 ("link", "set", outside, "up"), ("-n", namespace, "addr", "add", f"{peer}/30", "dev", inside),
                 ("-n", namespace, "link", "set", inside, "up"), ("-n", namespace, "link", "set", "lo", "up")]
        made = all(_ip(*step).returncode == 0 for step in steps)
    try:
        if made:
            yield Away(host, namespace)
        else:
            addresses = _local_addresses()
            if not addresses:
                pytest.skip("this machine has no address beyond loopback to serve the page on")
            yield Away(addresses[0], None)
    finally:
        _ip("link", "del", outside)
        _ip("netns", "del", namespace)


@pytest.fixture(scope="module")
def access(tmp_path_factory):
    """An access file: an operator with a password, a viewer with a token, an operator with a token."""
    folder = tmp_path_factory.mktemp("access")
    tokens = {"viewer": new_token(), "operator": new_token()}
    path = folder / "access"
    write_access(path, [Person("alice", "operator", hash_password(PASSWORD)),
                        Person("kiosk", "viewer", hash_token(tokens["viewer"])),
                        Person("robot-script", "operator", hash_token(tokens["operator"]))])
    return path, tokens


@pytest.fixture(scope="module")
def live(broker):
    from cotwin.twin.assembly.run import load

    system = load(ROOT / "examples" / "ur5e" / "live.toml")
    name = f"cotwin_access_{uuid.uuid4().hex[:8]}"
    system.spec.rabbitmq = replace(system.spec.rabbitmq, exchange=name)
    system.spec.deviation = replace(system.spec.deviation, exchange=name + ".events")
    return system


def _history(folder: Path) -> str:
    from cotwin.twin.services.history import HistoryRecorder

    url = f"sqlite:///{folder / 'history.sqlite'}"
    recorder = HistoryRecorder(url, "p.toml", "twin", 0.1, "jacobi", {"dt": ["{mapping}.mapping.q0"]}, batch_seconds=0.05)
    recorder.record_sample("dt", 0, 0.0, [0.5])
    recorder.close()
    return url


def _routes(dash: Dashboard) -> list[tuple[str, str]]:
    """Every route of the page's app (method, path), a file of its static folder for the mount."""
    from starlette.routing import Mount, Route, WebSocketRoute

    out = []
    for route in dash.app().routes:
        if isinstance(route, Route):
            out += [(m, route.path.replace("{run_id}", "1")) for m in sorted(route.methods - {"HEAD"})]
        elif isinstance(route, WebSocketRoute):
            out.append(("WS", route.path))
        elif isinstance(route, Mount):
            out.append(("GET", route.path + "/js/main.js"))
    return out + [("GET", "/nowhere"), ("POST", "/api/nowhere")]


def _request(dash: Dashboard, method: str, path: str, headers: dict | None = None, body=None, ca=None) -> dict:
    scheme = "wss" if dash.tls else "ws"
    url = (dash.url.replace("https", scheme).replace("http", scheme) if method == "WS" else dash.url).rstrip("/") + path
    headers = dict(headers or {})
    if body is not None:
        headers.setdefault("Content-Type", "application/json")
    return {"method": method, "url": url, "headers": headers, "ca": str(ca) if ca else None,
            "body": json.dumps(body) if isinstance(body, dict) else body}


def test_a_page_bound_beyond_loopback_without_an_access_file_is_refused_at_start(away, tmp_path):
    url = _history(tmp_path)
    for host in (away.address, "0.0.0.0", "::"):
        with pytest.raises(CotwinError, match="can be reached from other machines"):
            Dashboard(None, host, 0, mode="history", history_url=url).start()
    proc = subprocess.run([sys.executable, "-m", "cotwin", "dashboard", "--dir", str(tmp_path), "--at", "0.0.0.0:0"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and "--dashboard-access FILE" in proc.stderr and "Traceback" not in proc.stderr
    for host in ("127.0.0.1", "localhost", "127.0.0.2"):  # loopback: served, as before
        Dashboard(None, host, 0, mode="history", history_url=url).start().stop()


def test_on_loopback_a_request_naming_another_host_is_refused(live):
    """The hostile case of the issue: a POST with `Host: 198.51.100.7:PORT` moved the robot."""
    with Dashboard(live, port=0, mode="twin") as dash:
        for host in (f"198.51.100.7:{dash.port}", f"[2001:db8::1]:{dash.port}", f"192.0.2.2:{dash.port}"):
            request = urllib.request.Request(dash.url + "api/command", json.dumps(MOVE).encode(),
                                             {"Content-Type": "application/json", "Host": host})
            with pytest.raises(urllib.error.HTTPError) as refused:
                urllib.request.urlopen(request, timeout=10)
            assert refused.value.code == 403 and "is not this server's address" in json.loads(refused.value.read())["error"]
        assert dash.publisher._pending.qsize() == 0
        for host in (f"127.0.0.1:{dash.port}", f"localhost:{dash.port}", f"[::1]:{dash.port}"):
            request = urllib.request.Request(dash.url + "api/command", json.dumps(MOVE).encode(),
                                             {"Content-Type": "application/json", "Host": host})
            with urllib.request.urlopen(request, timeout=10) as answer:
                assert answer.status == 202  # accepted: no twin steps here to apply it


def test_beyond_loopback_every_route_answers_401_without_credentials_and_a_viewer_may_not_command(
        away, access, live, tmp_path, caplog):
    path, tokens = access
    with caplog.at_level(logging.WARNING, logger="cotwin.dashboard"), \
            Dashboard(live, away.address, 0, mode="twin", history_url=_history(tmp_path), whatif_url=BROKER,
                      access=path) as dash:
        routes = _routes(dash)
        assert ("POST", "/api/command") in routes and ("WS", "/ws") in routes and len(routes) >= 12
        anonymous = [_request(dash, m, p, body=MOVE if m == "POST" else None) for m, p in routes]
        wrong = [_request(dash, m, p, {"Authorization": "Bearer " + new_token()}) for m, p in routes]
        browser = [_request(dash, "GET", "/", {"Accept": "text/html"})]
        answers = away.send(anonymous + wrong + browser)
        for (method, route), (code, body) in zip(routes + routes, answers):
            assert code == 401, (method, route, code, body)
        assert answers[-1][0] == 401 and 'action="/login"' in answers[-1][1]  # a browser gets the login form
        viewer = {"Authorization": "Bearer " + tokens["viewer"]}
        operator = {"Authorization": "Bearer " + tokens["operator"]}
        plan = {"plan": [{"time": 0.5, "event": "moveDiscreteCommand", "args": {"target_X": 1, "target_Y": 1,
                                                                                  "target_Z": 0}}], "horizon": 2}
        answers = away.send([_request(dash, "GET", "/api/status", viewer), _request(dash, "GET", "/", viewer),
                             _request(dash, "GET", "/api/history/1", viewer), _request(dash, "WS", "/ws", viewer),
                             _request(dash, "POST", "/api/command", viewer, MOVE),
                             _request(dash, "POST", "/api/whatif", viewer, plan),
                             _request(dash, "POST", "/api/command", operator, MOVE)])
        assert [code for code, _ in answers[:4]] == [200, 200, 200, 101], answers
        assert answers[4][0] == answers[5][0] == 403 and "kiosk is a viewer" in answers[4][1]
        assert answers[6][0] == 202 and '"queued"' in answers[6][1]  # accepted; no twin steps to apply it
        assert dash.publisher._pending.qsize() == 1  # the operator's command, and only it
        assert dash.gate.refusals.count == 2 * len(routes) + 3  # every refusal counted
    refusals = [r.getMessage() for r in caplog.records if r.getMessage().startswith("dashboard refused")]
    assert len(refusals) == 2 * len(routes) + 3  # and, below the flood cap, logged
    assert any("403 kiosk is a viewer" in r and "(kiosk)" in r for r in refusals)
    assert any(f"from {'10.' if away.elsewhere else away.address}" in r for r in refusals)
    assert tokens["viewer"] not in caplog.text and tokens["operator"] not in caplog.text  # no secret in the log


def test_logins_open_sessions_that_end_when_the_access_file_drops_the_person(away, access, tmp_path, caplog):
    import http.cookiejar

    path, _ = access
    mine = tmp_path / "access"
    shutil.copy(path, mine)
    os.chmod(mine, 0o600)
    dash = Dashboard(None, away.address, 0, mode="history", history_url=_history(tmp_path), access=mine)
    dash.body_seconds = 2.0
    dash.start()
    try:
        jar = http.cookiejar.CookieJar()
        opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(jar))

        def call(path: str, form: dict | None = None) -> int:
            data = "&".join(f"{k}={urllib.request.quote(v)}" for k, v in form.items()).encode() if form else None
            try:
                with opener.open(urllib.request.Request(dash.url.rstrip("/") + path, data), timeout=20) as r:
                    return r.status
            except urllib.error.HTTPError as err:
                return err.code

        assert call("/api/status") == 401
        # a login form that never finishes arriving holds nothing for long
        with socket.create_connection((away.address, dash.port), timeout=10) as sock:
            started = time.monotonic()
            sock.sendall(b"POST /login HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\nname=")
            assert sock.recv(100).startswith(b"HTTP/1.1 408") and time.monotonic() - started < 8
        assert call("/login", {"name": "alice", "secret": "not the password"}) == 401
        assert call("/login", {"name": "nobody", "secret": PASSWORD}) == 401
        assert call("/login", {"name": "alice", "secret": PASSWORD}) == 200  # 303 to the page, then the page
        cookie = next(c for c in jar if c.name.startswith("cotwin_session_"))
        assert cookie.has_nonstandard_attr("HttpOnly") and not cookie.secure
        assert call("/api/status") == 200 and call("/api/history") == 200
        # alice's line removed from the file: her session ends within a second or two
        write_access(mine, [p for p in read_access(mine) if p.name != "alice"])
        deadline = time.monotonic() + 5
        while call("/api/status") == 200 and time.monotonic() < deadline:
            time.sleep(0.2)
        assert call("/api/status") == 401
        # guessing: throttled per address after MAX_FAILURES failures, each logged
        from cotwin.twin.services.dashboard.access import MAX_FAILURES

        codes = [call("/login", {"name": "alice", "secret": f"guess {k}"}) for k in range(MAX_FAILURES + 2)]
        assert codes[-1] == 429 and codes.count(401) <= MAX_FAILURES
    finally:
        dash.stop()
    assert "login failed for 'alice'" in caplog.text and "failed logins from" in caplog.text


def test_the_page_is_served_over_tls_with_a_secure_cookie(away, access, tmp_path):
    from rabbit_tls import PKI

    if shutil.which("openssl") is None:
        pytest.skip("openssl is not on PATH")
    path, tokens = access
    pki = PKI(tmp_path / "pki", names=("DNS:localhost", f"IP:{away.address}"))
    dash = Dashboard(None, away.address, 0, mode="history", history_url=_history(tmp_path), access=path,
                     tls=(pki.server, pki.server_key)).start()
    try:
        assert dash.url.startswith("https://")
        viewer = {"Authorization": "Bearer " + tokens["viewer"]}
        answers = away.send([_request(dash, "GET", "/api/status", viewer, ca=pki.ca),
                             _request(dash, "GET", "/api/status", ca=pki.ca),
                             _request(dash, "WS", "/ws", viewer, ca=pki.ca),
                             {**_request(dash, "GET", "/api/status", viewer), "url": dash.url.replace("https", "http")
                              + "api/status"}])
        assert [code for code, _ in answers[:3]] == [200, 401, 101], answers
        assert answers[3][0] != 200  # plain HTTP to the TLS port gets nothing
    finally:
        dash.stop()
    with pytest.raises(CotwinError, match="--tls-cert .* not a certificate"):
        Dashboard(None, "127.0.0.1", 0, mode="history", history_url=_history(tmp_path),
                  tls=(pki.ca.with_name("ca.key"), pki.server_key)).start()


def test_a_browser_logs_in_as_operator_and_commands_the_twin(away, access, live, tmp_path):
    if not CHROMIUM.is_file():
        if os.environ.get("CI"):
            pytest.fail(f"no Debian chromium at {CHROMIUM} (.ci/run should install it)")
        pytest.skip(f"no Debian chromium at {CHROMIUM}")
    from playwright.sync_api import sync_playwright

    from cotwin.mapping.amqp import connect
    from cotwin.twin.assembly.rabbitmq import READY

    path, tokens = access
    exchange = live.spec.rabbitmq.exchange
    link = connect(BROKER, "cotwin test twin side")
    channel = link.channel()
    channel.exchange_declare(exchange, exchange_type="direct", durable=False, auto_delete=False)
    inbox = channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
    channel.queue_bind(inbox, exchange, routing_key="data.to_cosim")

    def commands_received() -> list[dict]:
        out = []
        while True:
            body = channel.basic_get(inbox, auto_ack=True)[2]
            if body is None:
                return out
            message = json.loads(body)
            if message.get("moveDiscreteCommand") is True:
                out.append(message)

    try:
        with Dashboard(live, away.address, 0, mode="twin", access=path) as dash, sync_playwright() as p:
            channel.basic_publish(exchange, "data.from_cosim", json.dumps(READY).encode())  # the twin is ready
            chromium = p.chromium.launch(executable_path=str(CHROMIUM),
                                         args=["--headless", "--no-sandbox", "--disable-gpu"])
            try:
                for who, name, secret in (("operator", "alice", PASSWORD), ("viewer", "", tokens["viewer"])):
                    page = chromium.new_context().new_page()
                    errors = []
                    page.on("pageerror", lambda err: errors.append(str(err)))
                    answer = page.goto(dash.url)
                    assert answer.status == 401 and page.locator('form[action="/login"]').count() == 1
                    page.fill('input[name="name"]', name)
                    page.fill('input[name="secret"]', secret)
                    page.click('button[type="submit"]')
                    page.wait_for_selector("body[data-ready=true]", timeout=15_000)
                    form = page.locator('form[data-event="moveDiscreteCommand"]')
                    for port, value in MOVE["values"].items():
                        form.locator(f'input[name="{port}"]').fill(str(value))
                    form.locator("button").click()
                    if who == "operator":
                        page.wait_for_selector("#sent li.queued", timeout=10_000)
                        assert "accepted, not applied yet" in page.inner_text("#sent li.queued")
                        deadline = time.monotonic() + 10
                        received = []
                        while not received and time.monotonic() < deadline:
                            received = commands_received()
                            time.sleep(0.1)
                        assert len(received) == 1 and all(received[0][k] == v for k, v in MOVE["values"].items())
                    else:
                        page.wait_for_selector("#sent li.error", timeout=10_000)
                        assert "kiosk is a viewer" in page.inner_text("#sent li.error")
                        time.sleep(0.5)
                        assert commands_received() == []
                    assert errors == []
                    page.context.close()
            finally:
                chromium.close()
    finally:
        channel.exchange_delete(exchange)
        link.close()
