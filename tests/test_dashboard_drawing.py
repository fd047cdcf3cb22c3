"""The page's state-machine drawing, as Debian's headless Chromium renders it: no two labels (state
names, transition names) overlap, and every label stays inside the drawing. Bounding boxes come from
the DOM (getBBox of every SVG text, in the drawing's units)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from cotwin.twin.services.dashboard import Dashboard
from cotwin.twin.assembly.run import load

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = Path("/usr/bin/chromium")
SHARED = ROOT.parent / "shared" / "robosim"

LABELS = """() => [...document.querySelectorAll('svg[aria-label^="state machine"]')].map((svg) => {
  const view = svg.viewBox.baseVal;
  return {
    machine: svg.getAttribute('aria-label'),
    view: [view.x, view.y, view.x + view.width, view.y + view.height],
    labels: [...svg.querySelectorAll('text')].filter((t) => t.textContent).map((t) => {
      const b = t.getBBox();
      return [t.textContent, b.x, b.y, b.x + b.width, b.y + b.height];
    }),
  };
})"""


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.is_file():
        if os.environ.get("CI"):
            pytest.fail(f"no Debian chromium at {CHROMIUM} (.ci/run should install it)")
        pytest.skip(f"no Debian chromium at {CHROMIUM} (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=str(CHROMIUM),
                                     args=["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"])
        yield chromium
        chromium.close()


def projects():
    yield "ur5e", ROOT / "examples" / "ur5e" / "cotwin.toml"
    yield "turtlebot", ROOT / "examples" / "turtlebot" / "cotwin.toml"
    if (SHARED / "mobile" / "OA_mapping.pm").is_file():
        yield "turtlebot-published", ROOT / "examples" / "turtlebot" / "published.toml"


@pytest.mark.parametrize("name, project", list(projects()), ids=[n for n, _ in projects()])
def test_no_two_labels_of_a_state_machine_overlap(browser, name, project):
    system = load(project)
    with Dashboard(system, port=0, mode="run") as dash:
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        errors = []
        page.on("pageerror", lambda err: errors.append(str(err)))
        page.goto(dash.url)
        page.wait_for_selector("body[data-ready=true]", timeout=30_000)
        drawings = page.evaluate(LABELS)
        page.close()
    assert not errors, errors
    assert drawings and all(d["labels"] for d in drawings)
    for drawing in drawings:
        labels = drawing["labels"]
        clashes = [(a[0], b[0]) for i, a in enumerate(labels) for b in labels[i + 1:]
                   if a[1] < b[3] and b[1] < a[3] and a[2] < b[4] and b[2] < a[4]]
        assert not clashes, f"{drawing['machine']}: overlapping labels {clashes}"
        x0, y0, x1, y1 = drawing["view"]
        outside = [t for t, *box in labels if box[0] < x0 - 0.5 or box[1] < y0 - 0.5 or box[2] > x1 + 0.5
                   or box[3] > y1 + 0.5]
        assert not outside, f"{drawing['machine']}: labels outside the drawing {outside}"
