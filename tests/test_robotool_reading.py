"""RoboTool parity, reading: each rule of RoboSim.xtext/RoboChart.xtext, their scope providers and validators
that cotwin follows (docs/robosim-notation.md section 1, docs/pmodel-notation.md), on small models of our own.

Each test names the rule; a model RoboTool accepts must be accepted, one it refuses refused, and where cotwin
reads a model RoboTool would not (or is stricter on purpose) a warning says so."""

from __future__ import annotations

from cotwin.diagnostics import Severity


def _by(result, severity):
    return [(f.location.path.rsplit("/", 1)[-1], f.location.line, f.message) for f in result.findings
            if f.severity is severity]


def errors(result):
    return _by(result, Severity.ERROR)


def warnings(result):
    return _by(result, Severity.WARNING)


MACHINE = """package robot
import types::*
interface Sensing { event seen: Pos }
stm Watch {
	input context { uses Sensing }
	output context { }
	var last: Pos
	initial i
	state S { }
	transition t0 { from i to S }
	transition t1 { from S to S exec condition $seen?last }
}
"""

CONTROLLER = """package app
controller Ctrl {
	uses robot::Sensing
	sref w = robot::Watch
	connection Ctrl on seen to w on seen
}
module Mod {
	robotic platform RP { uses robot::Sensing }
	cref c = Ctrl
	connection RP on seen to c on seen (_async)
}
"""


def test_a_type_is_resolved_in_the_file_that_writes_it(check_texts):
    # `Pos` is written in robot.rst, which imports types::*; the controller's file does not import it, and
    # RoboTool resolves the reference where it is written (the event's type in the interface's file)
    result = check_texts({"types.rst": "package types\ntype Pos\n", "robot.rst": MACHINE, "app.rst": CONTROLLER})
    assert errors(result) == []


def test_a_name_of_another_package_needs_an_import_or_a_qualified_name(check_texts):
    result = check_texts({"types.rst": "package types\ntype Pos\n",
                          "robot.rst": MACHINE.replace("import types::*\n", ""), "app.rst": CONTROLLER})
    assert ("robot.rst", 2, "unknown type 'Pos' (there is types::Pos: import its package or qualify the name)") \
        in errors(result)
    qualified = MACHINE.replace("import types::*\n", "").replace(": Pos", ": types::Pos")
    assert errors(check_texts({"robot.rst": qualified})) == []


def test_a_name_two_imports_bring_is_ambiguous_as_for_robotool(check_texts):
    # Xtext's ImportScope finds no element when two imports resolve a name to different elements:
    # RoboTool reports an unresolved reference
    result = check_texts({"types.rst": "package types\ntype Pos\n", "geo.rst": "package geo\ntype Pos\n",
                          "robot.rst": MACHINE.replace("import types::*\n", "import types::*\nimport geo::*\n"),
                          "app.rst": CONTROLLER})
    [ambiguous] = [m for p, line, m in errors(result) if p == "robot.rst" and line == 4]
    assert ambiguous.startswith("'Pos' is ambiguous: the imports bring types::Pos (import types::*, line 2), "
                                "geo::Pos (import geo::*, line 3)")


def test_a_name_of_the_same_package_in_another_file_is_read_with_a_warning(check_texts):
    # RoboTool's local scope sees the file's own elements by simple name, not those of other files of its
    # package (those need an import or a qualified name): cotwin reads them and says so
    result = check_texts({"a.rst": "package p\ntype Pos\n",
                          "b.rst": "package p\ninterface I { event e: Pos }\n"})
    assert errors(result) == []
    assert any(f == "b.rst" and line == 2 and m.startswith("'Pos' is the type p::Pos of another file")
               for f, line, m in warnings(result))


def test_duplicates_and_unknown_imports_are_warnings_as_in_robotool(check_texts):
    result = check_texts({"a.rst": "package p\ntype Pos\n", "b.rst": "package p\ntype Pos\nimport nowhere::*\n"})
    assert errors(result) == []
    found = warnings(result)
    assert any(f == "b.rst" and m.startswith("duplicate type 'p::Pos'") and "RoboTool warns too" in m
               for f, _, m in found)
    assert ("b.rst", 3, "unknown import 'nowhere::*': nothing is imported") in found


def test_a_controller_need_not_declare_the_interfaces_its_machines_use(check_texts):
    # RoboSim's missingDeclaredInterface check is disabled in RoboTool: the connection names an event the
    # machine gets through an interface declared in another package
    result = check_texts({"types.rst": "package types\ntype Pos\n", "robot.rst": MACHINE,
                          "app.rst": CONTROLLER.replace("\tuses robot::Sensing\n\tsref", "\tevent seen: types::Pos\n\tsref")})
    assert errors(result) == []


def test_words_of_robosim_are_names_in_robochart_files(check_texts):
    # `output`, `input`, `context`, `exec` are RoboSim keywords, not RoboChart ones: a record field may be one
    result = check_texts({"pid.rct": "record PID {\n\terror : real\n\toutput : real\n\tinput : real\n}\n"
                                     "function out(p: PID): real { postcondition result == p.output }\n"})
    assert errors(result) == []


def test_a_module_may_declare_constants(check_texts):
    # RoboSim's ConstCycle: `const` in a module is read, its type resolved and its value checked
    module = CONTROLLER.replace("module Mod {\n", "module Mod {\n\tconst PERIOD: real = 0.1\n")
    result = check_texts({"types.rst": "package types\ntype Pos\n", "robot.rst": MACHINE, "app.rst": module})
    assert errors(result) == []
    broken = module.replace("0.1", "1 / 0")
    assert ("app.rst", 8, "division by zero (in constant PERIOD)") in errors(
        check_texts({"types.rst": "package types\ntype Pos\n", "robot.rst": MACHINE, "app.rst": broken}))


def test_link_is_a_physmod_type(check_texts):
    result = check_texts({"lib.pm": "joint Screwed {\n\tconst parent: LINK, child: LINK\n\tconst AXIS: vector(real, 3)\n}\n"})
    assert errors(result) == []
    # in a d-model it is an ordinary (unknown) name
    assert errors(check_texts({"d.rst": "interface I { event e: LINK }\n"}))[0][2].startswith("unknown type 'LINK'")
