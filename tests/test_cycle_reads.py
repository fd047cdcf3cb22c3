"""cotwin.dmodel.waits.CycleReads against the interpreter: a command the d-model read on the way of a state
change (or that made it call an operation) is among the events the change may have read, or the ledger
(cotwin.twin.assembly.outcomes) calls a command that was taken 'not taken'."""

from __future__ import annotations

from cotwin.dmodel.interpreter import Interpreter
from cotwin.dmodel.program import build_program
from cotwin.dmodel.waits import CycleReads
from cotwin.robosim.check import load_checked

WRAP = """interface Cmds {
	event cmd
	event finished
}
interface Ops {
	go()
}
%(extra)s
stm M {
	cycleDef cycle == 1
	%(requires)s
	input context { uses Cmds }
	output context { requires Ops }
	initial i0
%(body)s
}
controller C {
	cycleDef cycle == 1
	uses Cmds
	requires Ops
	sref m = M
	%(opref)s
	connection C on cmd to m on cmd (_async)
	connection C on finished to m on finished (_async)
}
module Mod {
	cycleDef cycle == 1
	robotic platform P {
		provides Ops
		uses Cmds
	}
	cref c = C
	connection P on cmd to c on cmd (_async)
	connection P on finished to c on finished (_async)
}
"""

# Idle reads cmd on an exec transition: in the cycle Work -> Done -> Idle it is chosen (Work -> Idle on the
# state port), and the next cycle enters Work because of it.
EXEC_GUARD = """	state Idle { }
	state Work { entry $go() }
	state Done { }
	transition t0 { from i0 to Idle }
	transition wait { from Idle to Idle exec condition not $cmd }
	transition take { from Idle to Work exec condition $cmd }
	transition busy { from Work to Work exec condition not $finished }
	transition work { from Work to Done exec condition $finished }
	transition back { from Done to Idle }"""

# Check's entry action reads cmd: Idle -> Check calls go() because of it.
ENTRY_READ = """	state Idle { }
	state Check { entry if $cmd then $go() end }
	transition t0 { from i0 to Idle }
	transition wait { from Idle to Idle exec condition not $finished }
	transition take { from Idle to Check condition $finished }
	transition checked { from Check to Idle exec }"""

OPERATION = """interface Soft { check() }
operation check() {
	uses Cmds
	requires Ops
	initial a
	junction j
	final f
	transition t { from a to j }
	transition ta { from j to f condition $cmd action $go() }
	transition tb { from j to f condition not $cmd }
}"""


def program(tmp_path, body: str, operation: bool = False):
    path = tmp_path / "m.rst"
    path.write_text(WRAP % {"extra": OPERATION if operation else "", "requires": "requires Soft" if operation else "",
                            "opref": "opref o = check" if operation else "",
                            "body": body.replace("entry if $cmd then $go() end", "entry check()") if operation
                            else body})
    return build_program(load_checked([path]), None)


def test_a_command_read_on_the_exec_transition_chosen_where_the_cycle_ends_may_be_read(tmp_path):
    p = program(tmp_path, EXEC_GUARD)
    it = Interpreter(p)
    it.step({})  # Idle
    it.step({"cmd": None})  # take chosen: Idle still
    it.step({})  # Work
    before = it.state_index(0)
    it.step({"finished": None, "cmd": None})  # work chosen; next cycle Done -> Idle, take chosen again
    it.step({"cmd": None})
    after = it.state_index(0)
    names = p.leaf_names(p.machines[0])
    assert (names[before], names[after]) == ("Work", "Idle")
    assert "cmd" in CycleReads(p).between(0, before, after)


def test_a_command_read_by_an_action_or_a_software_operation_may_be_read(tmp_path):
    for operation in (False, True):
        p = program(tmp_path, ENTRY_READ, operation)
        it = Interpreter(p)
        it.step({})
        it.step({})
        before = it.state_index(0)
        calls = it.step({"cmd": None, "finished": None})
        after = it.state_index(0)
        assert [c.name for c in calls] == ["go"]  # because of cmd
        assert "cmd" in CycleReads(p).between(0, before, after), operation


def test_several_cycles_a_step_follow_paths_past_exec_and_one_cycle_keeps_its_precision():
    """The UR5e example's d-model: one cycle from Requested to Moving reads the feasibility answer only (a
    gripper command read then was not taken); a step of several cycles (cycle_period shorter than the step)
    goes from Idle to AwaitFeasibility having read the move, on a path past Requested's exec."""
    from conftest import EXAMPLES

    p = build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"]), None)
    names = p.leaf_names(p.machines[0])
    reads = CycleReads(p)
    assert reads.between(0, names.index("Requested"), names.index("Moving")) == {"feasibleMoveDiscreteCommand"}
    assert "moveDiscreteCommand" in reads.between(0, names.index("Idle"), names.index("AwaitFeasibility"),
                                                  several=True)
