"""The C preprocessor of a firmware file (pcpp), walled in: #include finds the kit's headers and nothing else, and
every way to make it run away (a macro bomb, a huge expansion, deep includes) ends in a named error within limits.

A kit header is preprocessed once per process; a file that includes it gets its macros and nothing of its text (the
translator knows its declarations already). `-D` names replace the file's own #define of them.
"""
from __future__ import annotations

import io
import re
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, NoReturn

from pcpp import preprocessor as pcpp
from pcpp.parser import LexToken, default_lexer, lex

from appsim.errors import CCompileError
from appsim.firmware.c18 import headers

MAX_OUTPUT_CHARS = 1_000_000        # the preprocessed file (the workshop's biggest, Demo1, is about 20 kB)
MAX_EXPANDED_TOKENS = 200_000       # tokens the file's macro expansions add, in all
MAX_MACRO_DEPTH = 64                # macros expanding macros
MAX_INCLUDE_DEPTH = 8
# C18's predefined macros (its User's Guide, 2.10), and fixed __DATE__/__TIME__: the kit is deterministic.
PREDEFINED = {"__18CXX": "1", "__18F8680": "1", "__SMALL__": "1", "__TRADITIONAL18__": "1",
              "__DATE__": '"Jan  1 2026"', "__TIME__": '"00:00:00"'}


_BLANKS = re.compile(r"[ \t]+")
_WORD = re.compile(r"[A-Za-z_][\w_]*")           # pcpp's t_CPP_ID
_WORD_START = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz_")
# Punctuation that is a token by itself in pcpp's rules (no longer token starts with it).
_SINGLE = {"(": "CPP_LPAREN", ")": "CPP_RPAREN", ",": "CPP_COMMA", ";": "CPP_SEMICOLON", "{": "CPP_LCURLY",
           "}": "CPP_RCURLY", "[": "CPP_LBRACKET", "]": "CPP_RBRACKET", "~": "CPP_TILDE", "?": "CPP_QUESTION",
           ":": "CPP_COLON"}


class _QuickLexer(lex.Lexer):
    """pcpp's lexer (ply's, with pcpp's rules), quicker at what a firmware is mostly made of (blanks, newlines, words,
    brackets and separators): each gives the very token ply's rules give (tests/test_c_translation_cache.py compares
    their tokens on every C file of the kit and on random text), the rest is ply's."""

    lexdata: str                        # ply's Lexer's, set in its input()
    lexpos: int
    lexlen: int
    lineno: int

    def token(self) -> Any:
        data, pos = self.lexdata, self.lexpos
        if pos >= self.lexlen:
            return super().token()
        c = data[pos]
        tok = LexToken()
        tok.lineno, tok.lexpos = self.lineno, pos
        if c == " " or c == "\t":
            match = _BLANKS.match(data, pos)
            tok.type, tok.value, tok.lexer = "CPP_WS", match.group(), self     # type: ignore[union-attr]
            self.lexmatch, self.lexpos = match, match.end()                    # type: ignore[union-attr]
        elif c == "\n":
            tok.type, tok.value, tok.lexer = "CPP_WS", c, self
            self.lexpos, self.lineno = pos + 1, self.lineno + 1
        elif c in _WORD_START and not (c == "L" and data.startswith("'", pos + 1)):     # L'x' is a character
            value = tok.value = _WORD.match(data, pos).group()                 # type: ignore[union-attr]
            tok.type, self.lexpos = "CPP_ID", pos + len(value)
        elif c in _SINGLE:
            tok.type, tok.value, self.lexpos = _SINGLE[c], c, pos + 1
        else:
            return super().token()
        return tok


def _quick_lexer() -> _QuickLexer:
    """pcpp's own lexer as a `_QuickLexer`, made once (ply builds it from pcpp's rules), a copy for each use."""
    global _LEXER
    if _LEXER is None:
        made = default_lexer()
        if made.lexignore or len(made.lexstatere) != 1:
            raise RuntimeError(f"this pcpp's lexer ({pcpp.__file__}) ignores characters or has states, which the "
                               "kit's quicker lexer does not know: install pcpp 1.30")
        made.__class__ = _QuickLexer
        _LEXER = made
    return _LEXER.clone()


_LEXER: _QuickLexer | None = None


@dataclass
class Preprocessed:
    """A file preprocessed: its text (line markers included), the kit headers it included, and its own object-like
    #defines (name -> replacement text, line) in the order it made them."""

    text: str
    headers: list[str]
    defines: dict[str, tuple[str, int]] = field(default_factory=dict)
    expanded: dict[str, str] = field(default_factory=dict)      # each of `defines`, fully expanded at the end


@dataclass(frozen=True)
class _Header:
    macros: dict[str, Any]
    includes: tuple[str, ...]       # itself and the kit headers it includes
    text: str                       # its declarations, preprocessed (those of the headers it includes are theirs)
    tested: frozenset[str] = frozenset()    # the names its own #if, #ifdef, #ifndef and #elif test
    words: frozenset[str] = frozenset()     # the names its own declarations are written with


_HEADERS: dict[tuple[str, bool], _Header] = {}


class _Walled(pcpp.Preprocessor):
    """pcpp with its includes, errors and growth under the kit's control."""

    def __init__(self, filename: str, deadline: float, locked: Mapping[str, int] = {}):
        super().__init__(lexer=_quick_lexer())
        self.filename = filename
        self.deadline = deadline
        self.locked = dict(locked)
        self.included: list[str] = []
        self.own_defines: dict[str, tuple[str, int]] = {}
        self.touched = set(locked)      # the names the file's own #define and #undef (and -D) gave a meaning
        self.expanded = 0
        self.nesting, self.line = 0, 0  # expand_macros calls within calls; the line expanded
        self.written = 0                # characters of tokens given out (the preprocessed file's size, near enough)
        self.text, self.last_line = "", 1   # the file, and the line of the last token given out
        self.line_directive = "#line"
        self.rewrite_paths: list[tuple[str, str]] = []      # pcpp shortens paths under the working folder
        for name in ("__PCPP__", "__DATE__", "__TIME__"):
            self.macros.pop(name, None)
        for name, text in PREDEFINED.items():
            self.define(f"{name} {text}")
        for name, value in locked.items():
            self.define(f"{name} {_literal(value)}")

    def fail(self, line: int, message: str) -> NoReturn:
        raise CCompileError(message, self.filename, line)

    def parse(self, input: str, source: str | None = None, ignore: Any = None) -> None:
        """As pcpp's, but the file keeps the name it is given (pcpp would make it absolute): tokens, #line markers
        and every message name it so."""
        self.ignore = ignore or {}
        self.text = input
        self.parser = self.parsegen(input, source, source)

    def token(self) -> Any:
        """As pcpp's (the next token not ignored), the file's size limited as its tokens go out: one call a token,
        where a writer of its own would add another. A directive pcpp cannot read (`#ifdef` with no name: it fails
        on it) is refused in words, at its line."""
        parser, ignore = self.parser, self.ignore
        try:
            while True:
                tok = next(parser)
                if tok.type not in ignore:
                    self.written += len(tok.value)
                    if self.written > MAX_OUTPUT_CHARS:
                        self.fail(0, f"the preprocessed file passed {MAX_OUTPUT_CHARS:,} characters: a firmware "
                                     "file is a few thousand lines at most")
                    self.last_line = tok.lineno
                    return tok
        except StopIteration:
            self.parser = None
            return None
        except IndexError:              # pcpp's, on a directive with nothing after it
            line, text = _unreadable_directive(self.text, self.last_line)
            self.fail(line, f"the preprocessor cannot read `{text}`: #define, #undef, #ifdef and #ifndef need a "
                            "name after them, #if and #elif an expression, #pragma what it sets (such as #ifdef DEBUG, "
                            "#if RATE == 125, #pragma config WDT = OFF)")

    # -------------------------------------------------------------- pcpp's hooks
    def on_error(self, file: str, line: int, msg: str) -> None:
        evaluated = re.match(r"Could not evaluate expression due to (\w+)\(.*\(passed to evaluator: '(.*)'\)", msg,
                             re.DOTALL)
        if evaluated:
            why = ("it divides by zero" if evaluated.group(1) == "ZeroDivisionError" else
                   "#if and #elif take an integer expression of numbers and macros, such as #if RATE == 125")
            self.fail(line, f"the preprocessor cannot evaluate #if {evaluated.group(2)}: {why}")
        self.fail(line, f"{msg} (the preprocessor)")

    def on_directive_unknown(self, directive: Any, toks: Any, ifpassthru: Any, precedingtoks: Any) -> Any:
        name = directive.value
        text = "".join(t.value for t in toks).strip()
        if name == "error":
            self.fail(directive.lineno, f"#error {text}")
        if name == "warning":
            return True
        if name == "pragma":
            return None                 # the translator reads it
        if name == "line":
            self.fail(directive.lineno, "#line is not supported: the kit keeps the file's own line numbers, so that "
                                        "every message points where you look")
        self.fail(directive.lineno, f"#{name} is not a preprocessor directive")

    def on_comment(self, tok: Any) -> bool:
        return False

    def on_include_not_found(self, is_malformed: bool, is_system_include: bool, curdir: str,
                             includepath: str) -> None:
        self.fail(0, f"#include {includepath}: not found")

    # -------------------------------------------------------------- includes: the kit's headers only
    def include(self, tokens: Any, original_line: Any) -> Any:
        line = tokens[0].lineno if tokens else 0
        if not tokens:
            self.fail(line, "#include names no file: #include <p18f8680.h> or #include \"CAN18XX8.h\"")
        if tokens[0].value == "<":
            name = "".join(t.value for t in tokens[1:]).rstrip()
            name = name[:-1] if name.endswith(">") else name
        elif tokens[0].type == self.t_STRING:
            name = tokens[0].value[1:-1]
        else:
            name = "".join(t.value for t in tokens)
        known = headers.canonical(name)
        if known is None:
            self.fail(line, f"#include {name!r}: the kit's C includes only its own headers "
                            f"({', '.join(headers.HEADERS)}); a firmware is one .c file, and no other file of this "
                            "computer is read")
        assert known is not None
        if len(self.included) >= MAX_INCLUDE_DEPTH * 4:
            self.fail(line, "too many #includes")
        if known in self.included:
            return iter(())
        header = kit_header(known, declarations=False)
        new = [kit_header(each, declarations=False) for each in header.includes if each not in self.included]
        if self.touched:                # the file defined names before this #include: do they change the header?
            names = [(each.includes[-1], sorted(self.touched & each.words)) for each in new]
            for included, rewritten in names:
                if rewritten:
                    self.fail(line, f"{', '.join(rewritten)} is #defined before #include {included}, whose "
                                    "declarations are written with it: C18 would read them with your macro in "
                                    "them. Put the #define after the #includes, or give it a name of its own")
            if any(self.touched & each.tested for each in new):
                return self._in_context(known)
        self.included += [each.includes[-1] for each in new]
        self.macros.update((n, m) for n, m in header.macros.items() if n not in self.locked)
        return iter(())

    def _in_context(self, name: str) -> Any:
        """A kit header whose #if, #ifdef or #ifndef test a name the file defined before including it (its own NULL
        before <stdio.h>): its directives read here, in the file's context, as C's preprocessor reads them (the macros
        the kit made of the header alone would not hold); its declarations are the kit's, as always."""
        for _ in self.parsegen(headers.header_text(name), name, name):
            pass
        self.included.append(name)
        return iter(())

    def undef(self, tokens: Any) -> None:
        if not isinstance(tokens, str) and tokens and getattr(tokens[0], "source", None) == self.filename:
            self.touched.add(tokens[0].value)
        super().undef(tokens)

    # -------------------------------------------------------------- defines: -D wins; the file's own are kept
    def define(self, tokens: Any) -> None:
        if isinstance(tokens, str):
            super().define(tokens)
            return
        words = [t for t in tokens if t.type not in self.t_WS]
        name = words[0].value if words else ""
        source = getattr(words[0], "source", None) if words else None
        if words and words[0].type != self.t_ID:
            self.fail(words[0].lineno, f"#define {name}: a macro's name is an identifier (a letter or _ first), "
                                       "such as #define RX_Mask0 0x7FF")
        if source == self.filename:
            self.touched.add(name)
        if name in self.locked and source == self.filename:
            self.own_defines[name] = (_literal(self.locked[name]), words[0].lineno)
            return
        super().define(tokens)
        arguments = getattr(self.macros.get(name), "arglist", None) or []
        if len(set(arguments)) != len(arguments):
            self.fail(words[0].lineno, f"#define {name}(...) names a parameter twice: each needs a name of its own")
        if name in self.macros and self._expanded_size(name, set()) > MAX_EXPANDED_TOKENS:
            self.fail(words[0].lineno, f"#define {name} expands to more than {MAX_EXPANDED_TOKENS:,} tokens: a macro "
                                       "bomb (a macro that uses another several times, over and over)")
        if source == self.filename and name in self.macros and self.macros[name].arglist is None:
            self.own_defines[name] = ("".join(t.value for t in self.macros[name].value).strip(), words[0].lineno)

    def _expanded_size(self, name: str, seen: set[str]) -> int:
        """How many tokens macro `name` expands to, its macros expanded (each counted once per use), bounded."""
        sizes = self.__dict__.setdefault("_sizes", {})
        macro = self.macros[name]
        if sizes.get(name, (None,))[0] is macro:
            return int(sizes[name][1])
        total = 0
        for token in macro.value:
            word = token.value
            if word in self.macros and word != name and word not in seen:
                total += self._expanded_size(word, seen | {name})
            else:
                total += 1
            if total > MAX_EXPANDED_TOKENS:
                break
        sizes[name] = (macro, total)
        return total

    def macro_expand_args(self, macro: Any, args: Any) -> Any:
        """A function-like macro's body with its arguments in place, refused as soon as it passes the limit, before
        pcpp rescans it (`F(x) x x x x` nested: each level is 4 times the last, and the first one past the limit
        is the last one made)."""
        body = super().macro_expand_args(macro, args)
        if len(body) > MAX_EXPANDED_TOKENS:
            self.fail(self.line, f"the macro {macro.name}() expands to more than {MAX_EXPANDED_TOKENS:,} tokens: a "
                                 "macro bomb (a macro whose argument is used several times, nested over and over)")
        return body

    def expand_macros(self, tokens: Any, expanding_from: Any = []) -> Any:   # noqa: B006 (pcpp's own signature)
        if len(expanding_from) > MAX_MACRO_DEPTH:
            self.fail(tokens[0].lineno if tokens else 0,
                      f"macros expand more than {MAX_MACRO_DEPTH} deep ({' -> '.join(expanding_from[:4])} ...)")
        if self.nesting == 0 and tokens:
            self.line = tokens[0].lineno                # the line being expanded, for what its macros do
        self.nesting += 1
        try:
            result = super().expand_macros(tokens, expanding_from)
        finally:
            self.nesting -= 1
        self.expanded += max(0, len(result) - len(tokens))
        if self.expanded > MAX_EXPANDED_TOKENS:
            self.fail(result[0].lineno if result else 0,
                      f"the macros add more than {MAX_EXPANDED_TOKENS:,} tokens: a macro bomb (a macro "
                      "that uses another several times, over and over)?")
        if time.process_time() > self.deadline:
            self.fail(result[0].lineno if result else 0, "the preprocessor ran out of its time")
        return result


_DIRECTIVE = re.compile(r"\s*#\s*(\w*)(.*)")


def _unreadable_directive(text: str, from_line: int) -> tuple[int, str]:
    """The first directive from line `from_line` on that lacks what it needs (a name, an expression), with its line;
    else the first directive there."""
    lines = text.splitlines()
    first: tuple[int, str] | None = None
    for number in range(max(from_line, 1), len(lines) + 1):
        found = _DIRECTIVE.match(lines[number - 1])
        if not found:
            continue
        first = first or (number, lines[number - 1].strip())
        argument = _COMMENT.sub(" ", found.group(2)).strip()
        if found.group(1) in ("define", "undef", "ifdef", "ifndef", "if", "elif", "pragma") and (
                not argument or not re.search(r"\w", argument)):
            return number, lines[number - 1].strip()
    return first or (from_line, "")


def _literal(value: int) -> str:
    """A -D value as C writes it: hexadecimal (the workshop's identifiers are), so that it has the type the file's
    own hexadecimal #define would give it."""
    return f"{value:#x}" if value >= 0 else str(value)


def kit_header(name: str, declarations: bool = True) -> _Header:
    """A kit header's macros (and, with `declarations`, its preprocessed text), preprocessed once per process. The
    device header's declarations come from the register map it was written from (see c18.header_symbols): only its
    directives are preprocessed."""
    declarations = declarations or name != headers.DEVICE_HEADER
    found = _HEADERS.get((name, declarations))
    if found is None:
        walled = _Walled(name, time.process_time() + 60)
        text = headers.header_text(name)
        if name == headers.DEVICE_HEADER and not declarations:
            text = "\n".join(line if line.lstrip().startswith("#") else "" for line in text.splitlines())
        walled.parse(text, name)
        out = io.StringIO()
        walled.write(out)
        tested, words = _names(headers.header_text(name))
        found = _HEADERS[name, declarations] = _Header(dict(walled.macros), (*walled.included, name), out.getvalue(),
                                                       tested, words)
    return found


_COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.DOTALL)
_CONDITION = re.compile(r"\s*#\s*(?:if|ifdef|ifndef|elif)\b(.*)")
_NAME = re.compile(r"[A-Za-z_]\w*")


def _names(text: str) -> tuple[frozenset[str], frozenset[str]]:
    """The names a header's conditional directives test, and the names its declarations are written with."""
    tested: set[str] = set()
    words: set[str] = set()
    for line in _COMMENT.sub(" ", text).splitlines():
        condition = _CONDITION.match(line)
        if condition:
            tested.update(_NAME.findall(condition.group(1)))
        elif not line.lstrip().startswith("#"):
            words.update(_NAME.findall(line))
    return frozenset(tested - {"defined"}), frozenset(words)


def header_macros() -> dict[tuple[str, bool], tuple[Any, ...]]:
    """The kit headers preprocessed so far, as plain data (a macro's attributes, its tokens as tuples): what
    `adopt_headers` takes in another process of this kit."""
    return {key: ({name: {**vars(macro), "value": [(t.type, t.value, t.lineno, t.lexpos, getattr(t, "source", ""))
                                                   for t in macro.value]}
                   for name, macro in header.macros.items()}, header.includes, header.text, header.tested, header.words)
            for key, header in _HEADERS.items()}


def adopt_headers(plain: Mapping[tuple[str, bool], tuple[Any, ...]]) -> None:
    """Take the kit headers preprocessed elsewhere (see `header_macros`), as if preprocessed here."""
    lexer = _quick_lexer()
    for key, (macros, includes, text, tested, words) in plain.items():
        rebuilt = {}
        for name, attributes in macros.items():
            macro = pcpp.Macro.__new__(pcpp.Macro)
            macro.__dict__.update(attributes, value=[_token(lexer, *token)
                                                           for token in attributes["value"]])
            rebuilt[name] = macro
        _HEADERS.setdefault(key, _Header(rebuilt, tuple(includes), text, frozenset(tested), frozenset(words)))


def _token(lexer: Any, kind: str, value: str, lineno: int, lexpos: int, source: str) -> Any:
    token = LexToken()                  # pcpp's own copy of PLY's
    token.type, token.value, token.lineno, token.lexpos, token.source, token.lexer = (kind, value, lineno, lexpos,
                                                                                      source, lexer)
    return token


_CONDITIONAL = re.compile(r'"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'|/\*.*?\*/|//[^\n]*|'
                          r"(?<!\\)(?<!\\\r)\n[ \t\f\v]*#[ \t\f\v]*(if|ifdef|ifndef|elif|else|endif)\b", re.DOTALL)


def check_conditionals(text: str, filename: str) -> None:
    """Refuse a file whose #if ... #endif groups do not pair up, each case in its own words at its line (pcpp takes
    an #elif or an #else after the #else, and tells the rest in words of its own); comments, strings and a line
    continued from the one before (`\\` at its end) are not read for directives."""
    line, counted = 1, 0
    groups: list[tuple[str, int, int]] = []         # each open group: its #if, #ifdef or #ifndef, its line, its #else's
    for found in _CONDITIONAL.finditer("\n" + text):
        directive = found.group(1)
        if directive is None:
            continue
        line += text.count("\n", counted, found.start())
        counted = found.start()
        if directive.startswith("if"):
            groups.append((directive, line, 0))
        elif not groups:
            raise CCompileError(f"#{directive} with no #if before it: #else, #elif and #endif each belong to an "
                                "#if, #ifdef or #ifndef above them (one too many, or its #if deleted?)", filename, line)
        elif directive == "endif":
            groups.pop()
        elif groups[-1][2]:
            opened, at, else_at = groups[-1]
            raise CCompileError(f"#{directive} after the #else of line {else_at}: the #else is the last choice of the "
                                f"#{opened} at line {at}; put every #elif before it, and one #else at most (or close "
                                "the group with #endif first)", filename, line)
        elif directive == "else":
            groups[-1] = (groups[-1][0], groups[-1][1], line)
    if groups:
        opened, at, _ = groups[-1]
        more = f" ({len(groups)} groups are open at the end)" if len(groups) > 1 else ""
        raise CCompileError(f"this #{opened} has no #endif: each #if, #ifdef and #ifndef needs an #endif that ends "
                            f"its group{more}", filename, at)


def preprocess(text: str, filename: str, locked: Mapping[str, int], deadline: float) -> Preprocessed:
    """The file's text preprocessed, with the -D names `locked` to their values."""
    check_conditionals(text, filename)
    walled = _Walled(filename, deadline, locked)
    walled.parse(text, filename)
    out = io.StringIO()
    walled.write(out)
    expanded = {}
    for name in walled.own_defines:
        macro = walled.macros.get(name)
        if macro is not None and macro.arglist is None:
            tokens = walled.expand_macros(walled.tokenize(name))
            expanded[name] = "".join(t.value for t in tokens).strip()
    return Preprocessed(out.getvalue(), walled.included, walled.own_defines, expanded)
