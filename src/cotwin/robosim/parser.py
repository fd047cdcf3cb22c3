"""Parse RoboSim text into a typed SourceFile, turning every syntax problem into a located Finding."""

from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources
from pathlib import Path

import lark
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken, VisitError

from ..diagnostics import CotwinError, Diagnostics, Finding, Location, Severity
from ..files import CAPS, read_text
from .builder import Builder
from .declarations import SourceFile

NOTATIONS = {".rst": "rst", ".rct": "rct", ".pm": "pm"}
_START = {"rst": "rst_file", "rct": "rst_file", "pm": "pm_file"}
_GRAMMAR = {"rst": "dmodel.lark", "rct": "dmodel.lark", "pm": "pmodel.lark"}

# Terminal names shown to a user as the text they stand for.
_TERMINAL_TEXT = {
    "ID": "a name", "INT": "an integer", "FLOAT": "a real number", "STRING": "a string",
    "LBRACE": "'{'", "RBRACE": "'}'", "LPAR": "'('", "RPAR": "')'", "COLON": "':'", "COMMA": "','",
    "EQUAL": "'='", "DOLLAR": "'$'", "SEMICOLON": "';'", "$END": "end of file",
}


def _grammar_text(name: str) -> str:
    """The shared rules first, then the notation's own (which may `%extend` shared rules)."""
    folder = resources.files("cotwin.robosim") / "grammar"
    return (folder / "common.lark").read_text(encoding="utf-8") + "\n" + (folder / name).read_text(encoding="utf-8")


def lark_parser(notation: str) -> lark.Lark:
    """The LALR parser of one notation ("rst", "rct" or "pm"), built once per process."""
    return _lark_parser(_GRAMMAR[notation])


@lru_cache(maxsize=None)
def _lark_parser(grammar: str) -> lark.Lark:
    start = "pm_file" if grammar == "pmodel.lark" else "rst_file"
    return lark.Lark(
        _grammar_text(grammar),
        start=start,
        parser="lalr",
        lexer="contextual",
        propagate_positions=True,
        maybe_placeholders=False,
        cache=True,
    )


_NAME = re.compile(r"\^?[a-zA-Z_][a-zA-Z0-9_]*")


def _keyword_as_name(err: UnexpectedInput) -> bool:
    """A word of the grammar where only a name fits is that name (`record PID { output : real }` in a
    RoboChart file, where `output` is no keyword): LALR lookahead merging can lex it as the keyword one
    token early; the parser takes it again as a name and goes on."""
    token = getattr(err, "token", None)
    if not isinstance(err, UnexpectedToken) or token is None or token.type in ("ID", "$END"):
        return False
    if "ID" not in err.expected or not _NAME.fullmatch(str(token)):
        return False
    err.interactive_parser.feed_token(lark.Token.new_borrow_pos("ID", str(token), token))
    return True


def notation_of(path: str | Path) -> str | None:
    return NOTATIONS.get(Path(path).suffix)


def _describe_expected(expected: set[str], parser: lark.Lark) -> str:
    names = []
    for term in sorted(expected):
        if term in _TERMINAL_TEXT:
            names.append(_TERMINAL_TEXT[term])
            continue
        try:
            pattern = parser.get_terminal(term).pattern
        except KeyError:
            names.append(term)
            continue
        names.append(f"'{pattern.value}'" if pattern.type == "str" else term.lower())
    names = sorted(set(names))
    if len(names) > 8:
        return ", ".join(names[:8]) + ", ..."
    return ", ".join(names)


# Words that open a declaration or a block item; seen as a plain name just before a syntax error,
# they usually mean an earlier block was not closed.
_OPENERS = frozenset(
    "interface stm state transition controller module robotic datatype record enumeration function "
    "operation connection initial junction final entry during exit pmodel local sensor actuator joint "
    "map jref sref aref part import opref cref rref probabilistic".split())


def _keyword_before(err: UnexpectedToken, text: str) -> tuple[int, int, str] | None:
    """A block keyword that the lexer read as a name right before the unexpected token."""
    found = _word_before(err, text)
    return found if found is not None and found[2] in _OPENERS else None


def _binder_word_before(err: UnexpectedToken, text: str) -> tuple[int, int, str] | None:
    """`let` or `the` right before the unexpected token, where the lexer read it as a name: written as an
    operand of arithmetic (`1 + let ...`), of unary minus, or as a let's body (`let x == 1 @ the ...`)."""
    found = _word_before(err, text)
    return found if found is not None and found[2] in ("let", "the") else None


def _word_before(err: UnexpectedToken, text: str) -> tuple[int, int, str] | None:
    """The word right before the unexpected token, with its line and column."""
    start = getattr(err.token, "start_pos", None)
    if start is None or err.token.type == "$END":
        return None
    end = start
    while end > 0 and text[end - 1].isspace():
        end -= 1
    begin = end
    while begin > 0 and (text[begin - 1].isalnum() or text[begin - 1] == "_"):
        begin -= 1
    if begin == end:
        return None
    line = text.count("\n", 0, begin) + 1
    column = begin - (text.rfind("\n", 0, begin) + 1) + 1
    return line, column, text[begin:end]


def _syntax_finding(err: UnexpectedInput, path: str, parser: lark.Lark, text: str = "") -> Finding:
    line = getattr(err, "line", 0) or 0
    column = getattr(err, "column", 0) or 0
    position = err.pos_in_stream if isinstance(err, UnexpectedCharacters) else getattr(
        getattr(err, "token", None), "start_pos", None)
    if position is not None and text.startswith("/*", position):
        return Finding(Location(path, max(line, 1), max(column, 1)), Severity.ERROR,
                       "unterminated comment: '/*' without a closing '*/'")
    if isinstance(err, UnexpectedCharacters) and err.char in "\"'":
        return Finding(Location(path, max(line, 1), max(column, 1)), Severity.ERROR,
                       f"unterminated string: {err.char} without a closing {err.char} on its line "
                       "(a line break in a string is written \\n)")
    if isinstance(err, UnexpectedToken) and (binder := _binder_word_before(err, text)) is not None:
        line, column, word = binder
        return Finding(Location(path, line, column), Severity.ERROR,
                       f"'{word}' cannot start here: as in RoboChart, '{word} ... @ ...' is an operand of a comparison "
                       f"or of a logical operator, not of arithmetic, and a let's body is a let, an 'if' or arithmetic: "
                       f"put it in parentheses, '({word} ... @ ...)'")
    if isinstance(err, UnexpectedToken) and (opener := _keyword_before(err, text)) is not None:
        line, column, word = opener
        return Finding(Location(path, line, column), Severity.ERROR,
                       f"unexpected '{word}' (is a '}}' missing before it?)")
    if isinstance(err, UnexpectedToken):
        token = err.token
        found = "end of file" if token.type == "$END" else f"'{token}'"
        message = f"unexpected {found}, expected {_describe_expected(err.expected, parser)}"
        if "RBRACE" in err.expected:
            message += " (a '}' is missing)" if token.type == "$END" else " (is a '}' missing before it?)"
    elif isinstance(err, UnexpectedCharacters):
        message = f"unexpected character '{err.char}'"
        if err.allowed:
            message += f", expected {_describe_expected(err.allowed, parser)}"
    elif isinstance(err, UnexpectedEOF):
        message = f"unexpected end of file, expected {_describe_expected(set(err.expected), parser)}"
    else:  # pragma: no cover - lark has no other kinds today
        message = "syntax error"
    return Finding(Location(path, max(line, 1), max(column, 1)), Severity.ERROR, message)


def parse_text(text: str, path: str, notation: str | None = None) -> tuple[SourceFile | None, list[Finding]]:
    """Parse one file's text. Returns the file (None on a syntax error) and every finding."""
    notation = notation or notation_of(path)
    if notation not in _START:
        return None, [Finding(Location(path, 1, 1), Severity.ERROR,
                              "unknown file kind: expected a .rst d-model, a .rct RoboChart file or a .pm p-model/mapping")]
    parser = lark_parser(notation)
    try:
        tree = parser.parse(text, on_error=_keyword_as_name)
    except UnexpectedInput as err:
        if isinstance(err, UnexpectedToken) and err.token.type == "$END":
            line, column = _last_position(text)
            f = _syntax_finding(err, path, parser)
            return None, [Finding(Location(path, line, column), f.severity, f.message)]
        return None, [_syntax_finding(err, path, parser, text)]
    diagnostics = Diagnostics()
    try:
        source = Builder(path, notation, diagnostics, text).transform(tree)
    except VisitError as err:  # a builder bug must still not escape as a traceback
        inner = err.orig_exc
        if isinstance(inner, RecursionError):
            message = "expression nested too deeply"
        else:
            message = f"internal error while reading the model: {type(inner).__name__}: {inner}"
        return None, [Finding(Location(path, 1, 1), Severity.ERROR, message)]
    except RecursionError:
        return None, [Finding(Location(path, 1, 1), Severity.ERROR, "expression nested too deeply")]
    return source, diagnostics.findings


def _last_position(text: str) -> tuple[int, int]:
    lines = text.split("\n")
    return len(lines), len(lines[-1]) + 1


def parse_file(path: str | Path) -> tuple[SourceFile | None, list[Finding]]:
    """Read and parse a file; unreadable files are findings too."""
    path = Path(path)
    try:  # capped (an 8 GB model is refused before it is read), UTF-8 errors located at the byte
        text = read_text(path, "file", CAPS["model"])
    except CotwinError as err:
        return None, err.findings
    return parse_text(text, str(path))


def parse(text: str, path: str = "<text>", notation: str | None = None) -> SourceFile:
    """Parse text or raise CotwinError with the findings."""
    source, findings = parse_text(text, path, notation)
    errors = [f for f in findings if f.severity is Severity.ERROR]
    if source is None or errors:
        raise CotwinError(findings)
    return source
