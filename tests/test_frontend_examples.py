"""Our own example models check clean, and constants evaluate as written."""

from __future__ import annotations


import pytest

from cotwin.robosim.check import check_paths
from cotwin.robosim.pmodel_scope import PModelScope
from cotwin.robosim.consteval import ConstError
from cotwin.robosim.parser import parse


def test_examples_check_without_findings(ur5e_example):
    result = check_paths([ur5e_example])
    assert result.ok, "\n".join(map(str, result.findings))
    assert [f for f in result.findings] == []
    assert {p.name for p in ur5e_example.iterdir()} >= {"arm.rst", "ur5e.pm", "mapping.pm"}


def test_pmodel_constants_evaluate(ur5e_example):
    result = check_paths([ur5e_example])
    project = result.project
    pmodel = project.lookup("pmodel", "ur5e")
    env = PModelScope(project).pmodel_env(pmodel)
    assert env.value("D1", None) == pytest.approx(0.1625)
    gripper = project.lookup("pmodel", "Gripper2FG7")
    genv = PModelScope(project).pmodel_env(gripper)
    assert genv.value("STROKE", None) == pytest.approx(0.019)
    assert genv.value("HALF_MIN_WIDTH", None) == pytest.approx(0.0175)


def _const(text: str, name: str):
    source = parse(f"pmodel P {{ {text} }}", "c.pm")
    from cotwin.robosim.consteval import const_env

    return const_env(source.elements[0].constants).value(name, None)


def test_constant_arithmetic_like_the_published_pmodel():
    assert _const("const PI: real = 3.1415 const H: real = PI/2", "H") == pytest.approx(3.1415 / 2)
    assert _const("const R: real = 0.15/2", "R") == pytest.approx(0.075)
    assert _const("const A: real = -2*3.0 + 1", "A") == pytest.approx(-5.0)
    assert _const("const Q: real = sqrt(4.0)", "Q") == pytest.approx(2.0)
    assert _const("const V: real = (|0,0,1|)", "V") == (0, 0, 1)
    assert _const("const T: real = 7 / 2", "T") == 3  # integer division between ints, as in C
    assert _const("const N: real = -7 / 2", "N") == -3  # truncates toward zero (not Python's floor)
    assert _const("const M: real = -7 % 2", "M") == -1  # the remainder takes the dividend's sign


def test_cyclic_constants_are_reported():
    with pytest.raises(ConstError, match="in terms of itself"):
        _const("const A: real = B + 1 const B: real = A", "A")


def test_mass_units_and_errors_are_reported_with_places():
    text = """import physmod::joints::*
pmodel P {
	local link a {
		def { inertial information { mass -1.0 kg } }
		local body b { def { box ( length = 1.0 , width = -0.5 , height = 0.0 ) } }
		jref j = Revolute { flexibly connected to c }
	}
	local link c { def { inertial information { mass 2.0 lb } } }
}
"""
    result = _check_text({"p.pm": text})
    messages = {(f.location.line, f.message.split(" (")[0]) for f in result.findings if f.severity.value == "error"}
    assert (4, "mass of link a must be positive, is -1.0") in messages
    assert (5, "box width in body b must be positive, is -0.5") in messages
    # RoboTool accepts flat shapes (its coverage models have boxes of height 0): a warning, not an error
    warnings = {(f.location.line, f.message) for f in result.findings if f.severity.value == "warning"}
    assert (5, "box height in body b is 0: a flat shape") in warnings
    assert any(line == 8 and msg.startswith("unknown unit 'lb'") for line, msg in messages)


def _check_text(files: dict[str, str], tmp=None):
    import tempfile
    from pathlib import Path

    folder = Path(tempfile.mkdtemp(prefix="cotwin-"))
    for name, text in files.items():
        (folder / name).write_text(text)
    return check_paths([folder])
