"""Mutated p-model text (RoboTool's current notation) never makes the front end or the exporters raise
anything but their own findings."""

from __future__ import annotations

from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cotwin.diagnostics import CotwinError, Diagnostics
from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.sdf import to_sdf
from cotwin.pmodel.tree import build_tree
from cotwin.robosim.check import check_project
from cotwin.robosim.parser import parse_text
from cotwin.robosim.pmodel_elements import PModel
from cotwin.robosim.project import build_project

MODELS = Path(__file__).resolve().parent / "models" / "pmodel"
TEXTS = {p.name: p.read_text() for p in sorted(MODELS.glob("*.pm"))}
TOKENS = ["{", "}", "(", ")", "(|", "|)", "[|", "|]", ";", "<", ">", "^", "m", "cm", "1e-3", "0.5", "-", "index",
          "i", ":", "[0,", "3)", "4]", "lref", "bref", "local", "link", "body", "joint", "sensor", "actuator", "def",
          "relation", "fixed to", "in", "flexibly connected to", "package", "endpackage", "InOut", "Constraint",
          "mesh", "shape", '"x.stl"', "scaling", "bounce", "friction", "laser retro", "fragment", "solution", "end",
          "primitive unit", "metre", "degree", "derivative("]


@st.composite
def mutated(draw):
    name = draw(st.sampled_from(sorted(TEXTS)))
    text = TEXTS[name]
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(text)))
        kind = draw(st.sampled_from(["delete", "insert", "duplicate", "token"]))
        if kind == "delete":
            text = text[:pos] + text[min(len(text), pos + draw(st.integers(1, 12))):]
        elif kind == "insert":
            text = text[:pos] + draw(st.text(min_size=1, max_size=4)) + text[pos:]
        elif kind == "duplicate":
            end = min(len(text), pos + draw(st.integers(1, 40)))
            text = text[:end] + text[pos:end] + text[end:]
        else:
            text = text[:pos] + " " + draw(st.sampled_from(TOKENS)) + " " + text[pos:]
    return name, text


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_pmodel_text_gives_findings_not_exceptions(case):
    name, text = case
    source, findings = parse_text(text, str(MODELS / name))
    for f in findings:
        assert f.location.line >= 1 and f.location.column >= 1 and f.message
    diag = Diagnostics()
    diag.extend(findings)
    sources = [] if source is None else [source, *source.siblings]
    project = build_project(sources, diag)
    check_project(project, diag)  # must not raise
    for f in diag.findings:
        assert str(f).startswith(f"{f.location.path}:{f.location.line}:{f.location.column}: ")
    if source is None or any(f.severity.value == "error" for f in diag.findings):
        return
    for pmodel in [e for s in sources for e in s.elements if isinstance(e, PModel)]:
        try:  # an accepted model exports, or says why not
            tree = build_tree(project, pmodel.name)
        except CotwinError:
            continue
        to_sdf(tree)
        to_mjcf(tree)
