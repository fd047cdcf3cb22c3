"""Mutated model text never makes the front end raise anything but its own findings."""

from __future__ import annotations

from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cotwin.diagnostics import Diagnostics
from cotwin.robosim.check import check_project
from cotwin.robosim.parser import parse_text
from cotwin.robosim.project import build_project

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "ur5e"
TEXTS = {p.name: p.read_text() for p in sorted(EXAMPLES.iterdir()) if p.suffix in (".rst", ".pm")}
TOKENS = ["{", "}", "(", ")", "$", "?", "::", ";", "exec", "state", "transition", "from", "to", "==", "/\\",
          "not", "0.5", "x", "pose", "link", "jref", "equation", "action", "condition", "//", "/*", "*/", "@", "|)"]


@st.composite
def mutated(draw):
    name = draw(st.sampled_from(sorted(TEXTS)))
    text = TEXTS[name]
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(text)))
        kind = draw(st.sampled_from(["delete", "insert", "duplicate", "token"]))
        if kind == "delete":
            end = min(len(text), pos + draw(st.integers(1, 12)))
            text = text[:pos] + text[end:]
        elif kind == "insert":
            text = text[:pos] + draw(st.text(min_size=1, max_size=4)) + text[pos:]
        elif kind == "duplicate":
            end = min(len(text), pos + draw(st.integers(1, 40)))
            text = text[:end] + text[pos:end] + text[end:]
        else:
            text = text[:pos] + " " + draw(st.sampled_from(TOKENS)) + " " + text[pos:]
    return name, text


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_text_gives_findings_not_exceptions(case):
    name, text = case
    source, findings = parse_text(text, name)
    for f in findings:
        assert f.location.line >= 1 and f.location.column >= 1 and f.message
    others = [parse_text(t, n)[0] for n, t in TEXTS.items() if n != name]
    diag = Diagnostics()
    diag.extend(findings)
    project = build_project([s for s in [source, *others] if s is not None], diag)
    check_project(project, diag)  # must not raise
    for f in diag.findings:
        assert str(f).startswith(f"{f.location.path}:{f.location.line}:{f.location.column}: ")
