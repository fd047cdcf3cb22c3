"""Make docs/dashboard.png: the dashboard during the paper's experiment, the real UR5e's recorded run as
the PT (examples/ur5e/replay.toml) beside the MuJoCo DT, paced in real time, photographed by Debian's
headless Chromium at t = SECONDS (default 17 s, after the fourth command).

    .venv/bin/python docs/dashboard_screenshot.py [SECONDS]
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parents[1]


def main(at: float = 17.0) -> None:
    with tempfile.TemporaryDirectory() as out:
        twin = subprocess.Popen([sys.executable, "-m", "cotwin", "twin", str(ROOT / "examples" / "ur5e" / "replay.toml"),
                                 "-o", out, "--realtime", "--dashboard", "127.0.0.1:0"],
                                stderr=subprocess.PIPE, text=True)
        try:
            url = None
            for line in twin.stderr:
                found = re.search(r"dashboard: (http://\S+)", line)
                if found:
                    url = found.group(1)
                    break
            if url is None:
                raise SystemExit("the twin did not start its dashboard")
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path="/usr/bin/chromium",
                                            args=["--headless", "--no-sandbox", "--disable-gpu",
                                                  "--disable-background-networking"])
                page = browser.new_page(viewport={"width": 1440, "height": 1000}, device_scale_factor=1)
                page.goto(url)
                page.wait_for_selector("body[data-ready=true]")
                page.wait_for_function(f"window.cotwin.status.time >= {at}", timeout=(at + 60) * 1000)
                time.sleep(0.3)  # let the plot and the 3D view draw the last batch
                page.screenshot(path=str(ROOT / "docs" / "dashboard.png"), full_page=True)
                browser.close()
        finally:
            twin.terminate()
            twin.wait(30)
    print(ROOT / "docs" / "dashboard.png")


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
