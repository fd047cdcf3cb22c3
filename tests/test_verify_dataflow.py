"""The verifier follows a value from one machine to another: an input's value that a machine passes on with an event
(`$fwd!n`) steers the control of the machine that binds it (`$fwd?k`, a guard reading k) or compares it (`$fwd.2`),
in the same controller or in another one of the module, so the input's domain is explored, not one value."""

from __future__ import annotations

import pytest

from cotwin.dmodel.program import build_program
from cotwin.dmodel.verify import event_values, format_report, verify
from cotwin.robosim.check import load_checked

RELAY = """interface I { event go: int }
interface Link { event fwd: int }
interface O { act() other() }
stm Relay {
	var n: int
	input context { uses I }
	output context { uses Link }
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?n action $fwd!(n + 1) }
	transition t2 { from A to A exec condition not $go }
}
stm Sink {
	var k: int
	input context { uses Link }
	output context { requires O }
	initial i
	state W { }
	state B { }
	state Yes { entry $act() }
	state No { entry $other() }
	transition t0 { from i to W }
	transition t1 { from W to %(receive)s }
	transition t3 { from W to W exec condition not $fwd }
	transition t4 { from Yes to W exec }
	transition t5 { from No to W exec }
	transition t6 { from B to Yes exec condition k == 2 }
	transition t7 { from B to No exec condition k != 2 }
}
"""

# the receiver binds the value and a later guard reads it; or a guard compares the value itself
BINDS = "B condition $fwd?k"
COMPARES = "Yes condition $fwd.2 } transition t2 { from W to No condition $fwd /\\ not $fwd.2"

ONE_CONTROLLER = """controller C { uses I requires O sref r = Relay sref k = Sink
	connection C on go to r on go (_async) connection r on fwd to k on fwd (_async) }
module Mod { robotic platform P { uses I provides O } cref c = C
	connection P on go to c on go (_async) }
"""

TWO_CONTROLLERS = """controller Front { uses I uses Link sref r = Relay
	connection Front on go to r on go (_async) connection r on fwd to Front on fwd (_async) }
controller Back { uses Link requires O sref k = Sink
	connection Back on fwd to k on fwd (_async) }
module Mod { robotic platform P { uses I provides O } cref f = Front cref b = Back
	connection P on go to f on go (_async) connection f on fwd to b on fwd (_async) }
"""


@pytest.mark.parametrize("receive", [BINDS, COMPARES], ids=["binds", "compares"])
@pytest.mark.parametrize("wiring", [ONE_CONTROLLER, TWO_CONTROLLERS], ids=["one-controller", "two-controllers"])
def test_a_value_sent_to_another_machine_steers_its_control(tmp_path, receive, wiring):
    """verify called go's value 'read by no condition' (only Relay's conditions were looked at), explored go = 0
    alone, so Sink only ever received 1 and state Yes was reported unreachable: a false FAIL."""
    text = RELAY % {"receive": receive} + wiring
    if receive == COMPARES:
        text = text.replace("\ttransition t6 { from B to Yes exec condition k == 2 }\n", "") \
                   .replace("\ttransition t7 { from B to No exec condition k != 2 }\n", "") \
                   .replace("\tstate B { }\n", "")
    (tmp_path / "relay.rst").write_text(text)
    program = build_program(load_checked([tmp_path / "relay.rst"]))
    _, notes = event_values(program, {})
    assert notes == ["go: 2 value(s) from its domain"]
    report = verify(program)
    assert report.complete and report.ok, format_report(program, report)
