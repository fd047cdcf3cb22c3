"""The fleet's overview page: every twin's state, simulated time, pace (real-time factor, lag behind the
wall clock), deviation, alarms and restarts, with a link to the twin's own page where it serves one.

Served by Starlette and uvicorn like the twin's dashboard (cotwin.twin.services.dashboard), read-only, on
loopback only (the fleet page has no login: it commands nothing, but shows every twin), with the
dashboard's request-head timeout and its Host check against DNS rebinding. `GET /` is the page (it
refreshes itself from `GET /api/fleet`, the overview as JSON).
"""

from __future__ import annotations

import html
from typing import Callable

from ....diagnostics import CotwinError

PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>cotwin fleet {name}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 1.5em; }}
table {{ border-collapse: collapse; }} td, th {{ padding: 0.3em 0.8em; border-bottom: 1px solid #ddd; text-align: left; }}
.failed, .behind {{ color: #b00; font-weight: bold; }} .restarting {{ color: #b60; }} .done {{ color: #070; }}
</style></head>
<body><h1>fleet {name}</h1><p id="where">{where}</p>
<table><thead><tr><th>twin</th><th>state</th><th>t [s]</th><th>real-time factor</th><th>lag [s]</th>
<th>deviation</th><th>alarms</th><th>restarts</th><th>page</th><th>message</th></tr></thead>
<tbody id="twins">{rows}</tbody></table>
<script>
function cell(text, cls) {{ const td = document.createElement("td"); td.textContent = text; if (cls) td.className = cls; return td; }}
function num(v, d) {{ return v === null || v === undefined ? "" : Number(v).toFixed(d); }}
async function refresh() {{
  try {{
    const r = await fetch("api/fleet"); if (!r.ok) return;
    const fleet = await r.json(); const body = document.getElementById("twins"); body.replaceChildren();
    for (const t of fleet.twins) {{
      const tr = document.createElement("tr"); tr.dataset.twin = t.name;
      tr.append(cell(t.name), cell(t.state, t.state), cell(num(t.time, 1) + (t.end ? " / " + t.end : "")),
                cell(num(t.real_time_factor, 2), t.behind ? "behind" : ""), cell(num(t.lag, 2), t.behind ? "behind" : ""),
                cell(num(t.deviation, 4)), cell(String(t.alarms || 0) + (t.deviating && t.deviating.length ? " (" + t.deviating.join(", ") + ")" : "")),
                cell(String(t.restarts || 0)));
      const page = document.createElement("td");
      if (t.page) {{ const a = document.createElement("a"); a.href = t.page; a.textContent = "open"; page.append(a); }}
      tr.append(page, cell(t.message || ""));
      body.append(tr);
    }}
  }} catch (e) {{}}
}}
setInterval(refresh, 1000);
</script></body></html>
"""


def rows(overview: dict) -> str:
    """The table's rows as HTML (the page's first paint, before its script refreshes them)."""
    out = []
    for t in overview["twins"]:
        page = f'<a href="{html.escape(t["page"])}">open</a>' if t.get("page") else ""
        rtf = "" if t.get("real_time_factor") is None else f'{t["real_time_factor"]:.2f}'
        dev = "" if t.get("deviation") is None else f'{t["deviation"]:.4f}'
        behind = ' class="behind"' if t.get("behind") else ""
        out.append(f'<tr data-twin="{html.escape(t["name"])}"><td>{html.escape(t["name"])}</td>'
                   f'<td class="{html.escape(t["state"])}">{html.escape(t["state"])}</td>'
                   f'<td>{(t.get("time") or 0.0):.1f}</td><td{behind}>{rtf}</td><td{behind}>{(t.get("lag") or 0.0):.2f}</td>'
                   f'<td>{dev}</td><td>{t.get("alarms") or 0}</td><td>{t.get("restarts") or 0}</td><td>{page}</td>'
                   f'<td>{html.escape(t.get("message") or "")}</td></tr>')
    return "\n".join(out)


def app(overview: Callable[[], dict], host: str):
    """The Starlette app of the page, showing `overview()`."""
    from starlette.applications import Starlette
    from starlette.responses import HTMLResponse, JSONResponse, PlainTextResponse
    from starlette.routing import Route

    from ...services.dashboard.app import same_site

    def refused(request):
        why = same_site(request.headers, host)
        return PlainTextResponse(f"refused: {why}", status_code=403) if why else None

    async def page(request):
        no = refused(request)
        if no is not None:
            return no
        o = overview()
        return HTMLResponse(PAGE.format(name=html.escape(o["fleet"]), rows=rows(o),
                                        where=html.escape(f"{len(o['twins'])} twin(s) on {o['hosts'] or '...'}; "
                                                          f"history: {o['history']}")))

    async def api(request):
        no = refused(request)
        return no if no is not None else JSONResponse(overview())

    return Starlette(routes=[Route("/", page), Route("/api/fleet", api)])


class FleetPage:
    """The page served on HOST:PORT (loopback) in a thread until `stop()`."""

    def __init__(self, overview: Callable[[], dict], host: str = "127.0.0.1", port: int = 8060):
        from ...services.dashboard.server import beyond_loopback

        if beyond_loopback(host):
            raise CotwinError(f"--page {host}:{port}: the fleet page is served on loopback only (it has no login); "
                              "serve it on 127.0.0.1 and reach it through an SSH tunnel or a proxy with "
                              "authentication")
        self.overview, self.host, self.port = overview, host, port
        self._served = None  # cotwin.twin.services.dashboard.server.ServedPage

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def start(self) -> "FleetPage":
        import uvicorn

        from ...services.dashboard.server import bound_socket, protocol, serve_in_thread

        sock = bound_socket(self.host, self.port, "fleet page")
        self.port = sock.getsockname()[1]
        config = uvicorn.Config(app(self.overview, self.host), log_level="warning", access_log=False, lifespan="off",
                                http=protocol(), proxy_headers=False, limit_concurrency=64, timeout_graceful_shutdown=2)
        self._served = serve_in_thread(config, sock, "fleet page")
        return self

    def stop(self) -> None:
        if self._served is not None:
            self._served.stop(5)
            self._served = None
