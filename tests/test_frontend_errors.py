"""Broken inputs give the right message at the right line and column, all findings together."""

from __future__ import annotations

import subprocess
import sys

from conftest import cotwin_in_process
from cotwin.diagnostics import Severity

DMODEL = """interface I {
	event go: int
	event halt
	move(x: int)
}
stm M {
	var n: int
	var flag: boolean
	input context { uses I }
	output context { requires I }
	initial i
	state A { entry $move(n) }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?n }
}
"""

PMODEL = """import physmod::joints::*
import physmod::sensors::*
pmodel P {
	local link base {
		def { inertial information { mass 1.0 kg } }
		jref j = Revolute { flexibly connected to tip }
		sref S = VelocitySensor
	}
	local link tip { def { inertial information { mass 1.0 kg } } }
}
"""

MODULE = """module Mod {
	robotic platform RP { uses I provides I }
}
"""

MAPPING = """map Map dmodel Mod to pmodel P {
	var speed: real
	operation move { action speed = x }
	input event halt { equation P::base::S.output_vel == 0.0 }
	input event go { equation speed > 1.0 }
}
"""


def errors(result):
    return [(f.location.path.rsplit("/", 1)[-1], f.location.line, f.location.column, f.message)
            for f in result.findings if f.severity is Severity.ERROR]


def test_valid_baseline(check_texts):
    result = check_texts({"m.rst": DMODEL + MODULE, "p.pm": PMODEL, "map.pm": MAPPING})
    assert errors(result) == []


def test_missing_brace(check_texts):
    text = DMODEL.replace("\tmove(x: int)\n}", "\tmove(x: int)\n")
    result = check_texts({"m.rst": text})
    [(path, line, col, message)] = errors(result)
    assert (path, line, col) == ("m.rst", 6, 1)
    assert message.startswith("unexpected 'stm'") and "is a '}' missing before it?" in message


def test_missing_final_brace_at_end_of_file(check_texts):
    result = check_texts({"m.rst": DMODEL.rstrip()[:-1]})
    [(path, line, col, message)] = errors(result)
    assert (path, line, col) == ("m.rst", 15, 1)
    assert "end of file" in message and "'}' is missing" in message


def test_unknown_state_in_transition(check_texts):
    text = DMODEL.replace("transition t1 { from A to A exec", "transition t1 { from A to B exec")
    result = check_texts({"m.rst": text})
    assert errors(result) == [("m.rst", 14, 28, "transition t1: unknown target state 'B'")]


def test_undeclared_event(check_texts):
    text = DMODEL.replace("condition $go?n", "condition $went")
    result = check_texts({"m.rst": text})
    assert errors(result) == [("m.rst", 14, 46, "unknown input event 'went'")]


def test_type_mismatch_in_event_binding(check_texts):
    text = DMODEL.replace("condition $go?n", "condition $go?flag")
    result = check_texts({"m.rst": text})
    assert errors(result) == [("m.rst", 14, 45, "event 'go' carries int but 'flag' is boolean")]


def test_type_mismatch_in_operation_argument(check_texts):
    text = DMODEL.replace("entry $move(n)", "entry $move(flag)")
    result = check_texts({"m.rst": text})
    assert errors(result) == [("m.rst", 12, 24, "argument 1 of 'move': expected int, got boolean")]


def test_unknown_sensor_path_in_mapping(check_texts):
    text = MAPPING.replace("P::base::S.output_vel", "P::base::T.output_vel")
    result = check_texts({"m.rst": DMODEL + MODULE, "p.pm": PMODEL, "map.pm": text})
    assert errors(result) == [("map.pm", 4, 30, "link 'base' of p-model 'P' has no sensor or actuator 'T'")]


def test_unknown_sensor_port_in_mapping(check_texts):
    text = MAPPING.replace("S.output_vel", "S.speed")
    result = check_texts({"m.rst": DMODEL + MODULE, "p.pm": PMODEL, "map.pm": text})
    assert errors(result) == [("map.pm", 4, 41, "sensor 'VelocitySensor' has no port 'speed'")]


def test_mapping_operation_must_exist_on_platform(check_texts):
    text = MAPPING.replace("operation move {", "operation jump {")
    result = check_texts({"m.rst": DMODEL + MODULE, "p.pm": PMODEL, "map.pm": text})
    found = errors(result)
    assert ("map.pm", 3, 12, "operation 'jump' is not an operation of robotic platform 'RP'") in found
    # `x` is a parameter of `move` only, so inside `jump` it is unknown: reported too, not hidden
    assert ("map.pm", 3, 34, "unknown name 'x'") in found


def test_duplicate_names(check_texts):
    text = DMODEL.replace("\tvar flag: boolean\n", "\tvar flag: boolean\n\tvar n: real\n")
    result = check_texts({"m.rst": text, "other.rst": "interface I { event e }\n"})
    found = errors(result)
    assert ("m.rst", 9, 6, "duplicate variable 'n' in state machine M (first at line 7)") in found
    # two top-level elements of one qualified name: RoboTool's validator warns ("more than one element
    # with name"), and so does cotwin, using the first
    warned = [(f.location.path.rsplit("/", 1)[-1], f.location.line, f.location.column, f.message)
              for f in result.findings if f.severity is Severity.WARNING]
    assert not any(m.startswith("duplicate interface") for _, _, _, m in found)
    assert any(p == "other.rst" and (l, c) == (1, 11) and m.startswith("duplicate interface 'I' (first declared at")
               and m.endswith("RoboTool warns too): the first one is used") for p, l, c, m in warned)


def test_all_findings_reported_together(check_texts):
    text = (DMODEL.replace("to A exec", "to B exec").replace("$go?n", "$go?flag")
            .replace("entry $move(n)", "entry $move(flag)"))
    result = check_texts({"m.rst": text})
    assert len(errors(result)) == 3


def test_cli_reports_findings_on_stderr_and_exits_1(tmp_path):
    (tmp_path / "m.rst").write_text(DMODEL.replace("to A exec", "to B exec"))
    proc = cotwin_in_process("check", tmp_path)  # what it says and its status: no process needed
    assert proc.returncode == 1
    assert f"{tmp_path / 'm.rst'}:14:28: error: transition t1: unknown target state 'B'" in proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""


def test_cli_missing_path_is_a_finding(tmp_path):
    proc = cotwin_in_process("check", tmp_path / "nope.rst")
    assert proc.returncode == 1 and "no such file or folder" in proc.stderr and "Traceback" not in proc.stderr


def test_unterminated_comment_is_reported_without_blowing_up(tmp_path):
    # an unterminated /* once made the comment regex backtrack exponentially; run it in a child
    # process with a generous limit so a regression fails instead of hanging the suite
    (tmp_path / "m.rst").write_text(DMODEL + "/* never closed\n" + "x\n" * 2000)
    proc = subprocess.run([sys.executable, "-m", "cotwin", "check", str(tmp_path)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 1
    assert f"{tmp_path / 'm.rst'}:16:1: error: unterminated comment" in proc.stderr


def test_a_model_that_is_not_utf8_is_located_at_the_byte(tmp_path):
    lines = DMODEL.split("\n")
    lines[5] = lines[5] + " // caf\xe9"
    (tmp_path / "m.rst").write_bytes("\n".join(lines).encode("latin-1"))
    proc = cotwin_in_process("check", tmp_path)  # what it says and its status: no process needed
    column = len(lines[5].encode("latin-1"))
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert f"{tmp_path / 'm.rst'}:6:{column}: error: the file is not UTF-8 text (byte 0xe9)" in proc.stderr


REPORTING = """interface Ops { move(x: int) }
interface Cmd { event go: int }
interface Out { event done }
stm R {
	var n: int
	input context { uses Cmd }
	output context { requires Ops uses Out }
	initial i
	state A { }
	state B { entry $move(n); $done }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition not $go }
	transition t2 { from A to B condition $go?n }
	transition t3 { from B to A exec }
}
controller C { uses Cmd uses Out requires Ops sref r = R
	connection C on go to r on go (_async)
	connection r on done to C on done (_async) }
module Mod { robotic platform RP { provides Ops uses Cmd uses Out } cref c = C
	connection RP on go to c on go (_async)
	connection c on done to RP on done (_async) }
"""


def test_an_event_the_d_model_sends_to_its_platform_is_no_unmapped_event(check_texts):
    """A sorter's report `$sorted!count`, sent to the platform, drew 'platform event 'sorted' is not mapped': the
    mapping notation maps input events only, so nothing could silence it. Its commands still may be unmapped."""
    mapping = "map Map dmodel Mod to pmodel P {\n\tvar m: real\n\toperation move { action m = x }\n}\n"
    result = check_texts({"m.rst": REPORTING, "p.pm": PMODEL, "map.pm": mapping})
    assert errors(result) == []
    unmapped = [f.message for f in result.findings if "is not mapped by" in f.message]
    assert unmapped == ["platform event 'go' is not mapped by Map"]


def test_duplicate_pmodel_names_are_located_errors(check_texts):
    """Two elements of one p-model scope (p-model, link, joint, fragment, device) with one name are each an
    error at the second declaration naming the first; one name in two scopes (a joint j in two links) is not."""
    text = """import physmod::joints::*
import physmod::sensors::*
import physmod::actuators::*
pmodel P {
	const k: real = 1
	const k: real = 2
	local link base {
		def { inertial information { mass 1.0 kg } }
		jref j = Revolute { flexibly connected to tip }
		jref j = Revolute { flexibly connected to tip2 }
		sref S = VelocitySensor
		sref S = VelocitySensor
		local body B { def { box ( length = 1 , width = 1 , height = 1 ) } }
		local body B { def { box ( length = 1 , width = 1 , height = 1 ) } }
	}
	local link tip { def { inertial information { mass 1.0 kg } }
		jref j = Revolute { flexibly connected to tip2 }
		sref j = VelocitySensor
	}
	local link tip2 { def { inertial information { mass 1.0 kg } } }
	local link tip2 { def { inertial information { mass 2.0 kg } } }
}
"""
    found = errors(check_texts({"p.pm": text}))
    assert sorted(found) == [
        ("p.pm", 6, 8, "duplicate constant 'k' in p-model P (first declared at line 5, column 8)"),
        ("p.pm", 10, 8, "duplicate joint 'j' in link base (first declared at line 9, column 8)"),
        ("p.pm", 12, 8, "duplicate sensor 'S' in link base (first declared at line 11, column 8)"),
        ("p.pm", 14, 14, "duplicate body 'B' in link base (first declared at line 13, column 14)"),
        ("p.pm", 18, 8, "duplicate sensor 'j' in link tip (first declared as a joint at line 17, column 8)"),
        ("p.pm", 21, 13, "duplicate link 'tip2' in p-model P (first declared at line 20, column 13)"),
    ]


def test_duplicate_names_in_a_joint_and_in_a_fragment_are_located_errors(check_texts):
    """The scopes the test above leaves out: a joint's actuators, a fragment's links (each checked by its own
    call, so each needs its own case)."""
    text = """import physmod::joints::*
import physmod::sensors::*
import physmod::actuators::*
pmodel P {
	local link base {
		def { inertial information { mass 1.0 kg } }
		jref j = Revolute { flexibly connected to tip
			aref M = ControlledMotor { }
			aref M = ControlledMotor { }
		}
	}
	local link tip { def { inertial information { mass 1.0 kg } } }
}
fragment F {
	local link L { def { inertial information { mass 1.0 kg } } }
	local link L { def { inertial information { mass 1.0 kg } } }
}
"""
    found = [e for e in errors(check_texts({"p.pm": text})) if "duplicate" in e[3]]
    assert sorted(found) == [
        ("p.pm", 9, 9, "duplicate actuator 'M' in joint j (first declared at line 8, column 9)"),
        ("p.pm", 16, 13, "duplicate link 'L' in fragment F (first declared at line 15, column 13)"),
    ]
