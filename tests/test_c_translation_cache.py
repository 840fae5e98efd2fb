"""What a C translation reuses gives the translation a cold one gives: the kit headers' state the grader hands to a
sandbox, the translation cache, and the translator's quicker paths through pycparser (its lexer, its look-ahead) give
the same Python code for every solution and starter; and a file's own #define or #include order is never overruled by
what the kit made of its headers alone (no stale header cache)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
from workshop import KIT

from appsim.errors import CCompileError
from appsim.firmware import c18
from appsim.firmware.c18.parser import C18_QUALIFIERS, C18Lexer

SOLUTIONS, STARTERS = KIT / "solutions", KIT / "exercises"

# Translates every .c file under the folders with each option set, and prints a fingerprint of each translation: its
# code, compared field by field (bytecode, constants, names, line table), its #define constants and defines. `cold`:
# nothing known ahead; `zygote`: as a grading sandbox, the grader's headers' state adopted and warmed, the files in
# reverse order, then all again (each from the cache, the very same translation); `pycparser`: cold, with pycparser's
# own lexer and look-ahead and pcpp's own lexer instead of the kit's quicker ones.
_FINGERPRINTS = """
import gc, hashlib, json, sys
from pathlib import Path
from types import CodeType
from appsim.firmware import c18

def canonical(code):
    consts = tuple(canonical(c) if isinstance(c, CodeType) else repr(c) for c in code.co_consts)
    return (code.co_name, code.co_code, code.co_names, code.co_varnames, code.co_freevars, code.co_cellvars,
            code.co_flags, code.co_argcount, code.co_firstlineno, code.co_linetable,
            getattr(code, "co_exceptiontable", b""), consts)

mode, folders = sys.argv[1], sys.argv[2:]
if mode == "zygote":
    c18.adopt(sys.stdin.buffer.read())
    c18.warm()
    gc.freeze()
elif mode == "pycparser":
    from pycparser import c_lexer, c_parser
    from appsim.firmware.c18 import parser
    parser.C18Lexer.token = c_lexer.CLexer.token
    parser.C18Parser._peek = c_parser.CParser._peek
    parser.C18Parser._peek_type = c_parser.CParser._peek_type
    from pcpp.parser import lex
    from appsim.firmware.c18 import preprocess
    preprocess._QuickLexer.token = lex.Lexer.token
files = sorted(p for folder in folders for p in Path(folder).rglob("*.c"))
jobs = [(p, options) for options in ((), ("-Oi",), ("-k",)) for p in files]
if mode == "zygote":
    jobs.reverse()
found = {}
for path, options in jobs:
    t = c18.translate(path.name, path.read_bytes(), {}, options)
    code = hashlib.sha256(repr(canonical(t.code)).encode()).hexdigest()
    found[f"{path.parent.name}/{path.name} {' '.join(options)}"] = [code, sorted(t.constants.items()), list(t.defines)]
    if mode == "zygote":
        assert c18.translate(path.name, path.read_bytes(), {}, options) is t
print(json.dumps(found, sort_keys=True))
"""


def _fingerprints(mode: str, state: bytes | None = None) -> dict[str, list[object]]:
    done = subprocess.run([sys.executable, "-c", _FINGERPRINTS, mode, str(SOLUTIONS), str(STARTERS)], input=state,
                          capture_output=True, check=True)
    return json.loads(done.stdout)


def test_every_kit_c_file_translates_the_same_cold_from_the_graders_headers_state_and_with_pycparsers_own_lexer():
    cold = _fingerprints("cold")
    assert len(cold) == 3 * 17, "solutions, interrupts, starters; three option sets each"
    assert _fingerprints("zygote", c18.header_state()) == cold, "a sandbox's translations are cold ones"
    assert _fingerprints("pycparser") == cold, "the kit's quicker lexers and look-ahead change nothing"


def _pcpp_tokens(lexer: object, text: str) -> list[tuple[object, ...]]:
    lexer.input(text)                                                   # type: ignore[attr-defined]
    tokens = []
    while (token := lexer.token()) is not None:                         # type: ignore[attr-defined]
        tokens.append((token.type, token.value, token.lineno, token.lexpos, hasattr(token, "lexer"),
                       lexer.lineno, lexer.lexpos))                     # type: ignore[attr-defined]
    return tokens


def test_the_preprocessors_quicker_lexer_gives_pcpps_own_tokens_on_every_kit_file_and_on_random_text():
    """Token for token (type, text, line, position, and the lexer's own line and position after it): the kit's C
    files, its headers, and 20,000 random strings of what C is written with, with the rules' traps (L'x' is a
    character, not a word; ^= is two tokens to pcpp; a line continuation; a comment)."""
    import random

    from pcpp.parser import default_lexer

    from appsim.firmware.c18 import headers, preprocess

    texts = [p.read_text(errors="replace") for folder in (SOLUTIONS, STARTERS) for p in folder.rglob("*.c")]
    texts += [headers.header_text(name) for name in headers.HEADERS]
    draw = random.Random(1)
    alphabet = [*"  \t\n\nabcLxyz_019'\"/*\\#.^=<>-+|&!(){}[];,:?~%é", "L'a'", "/*", "*/", "//", "\\\n", "0x1F"]
    texts += ["".join(draw.choice(alphabet) for _ in range(draw.randrange(1, 60))) for _ in range(20_000)]
    texts += ["=", "^=", "L'", "L'x", "_L'x'", ""]
    assert len(texts) > 20_000 + 14 + len(headers.HEADERS)
    pcpps = default_lexer()                                             # never used: each text gets a fresh copy
    for text in texts:
        assert _pcpp_tokens(preprocess._quick_lexer(), text) == _pcpp_tokens(pcpps.clone(), text), repr(text)


_TRICKY = r"""
int $dollar = 0x1FUL + 0b101 + 017 + 1.5e3 + .5 + 1. + 'a' + '\n' + L'x' + u'y' + U'z' + u8'q';
char *s = "tab\tquote\"" L"wide" u8"utf" u"16" U"32";
a->b; a >>= 1; a <<= 2; a ... b :: c; x ? y : z; ~a ^ b | c & d && e || !f; a != b == c <= d >= e < f > g;
Lfoo Ufoo ufoo u8foo L u U _x x_ __18CXX rom ram near far
[[deprecated]] int old(void);
#pragma interrupt high_isr
#line 40 "other.c"
	tabs	and formfeeds  vertical  end
'unterminated
"bad \q escape"
'ab' '' 08 @ `
/* a comment */ // another
"""


def _tokens(lexer_class: type, text: str) -> list[tuple[object, ...]]:
    seen: list[tuple[object, ...]] = []
    lexer = lexer_class(lambda message, line, column: seen.append(("error", message, line, column)))
    lexer.input(text, "t.c")
    while (token := lexer.token()) is not None:
        seen.append((token.type, token.value, token.lineno, token.column, token.filename))
    return seen


class _PycparsersLexer(C18Lexer):
    """The C18 lexer as pycparser's lexer reads: C18's qualifiers, and pycparser's own token()."""

    token = C18Lexer.__mro__[1].token       # type: ignore[assignment]


def test_the_kits_lexer_gives_pycparsers_tokens_columns_and_errors():
    texts = [_TRICKY]
    for path in sorted([*SOLUTIONS.rglob("*.c"), *STARTERS.glob("*.c")]):
        done = c18.preprocess.preprocess(path.read_text(encoding="utf-8"), path.name, {}, float("inf"))
        texts.append(done.text)
    for text in texts:
        ours = _tokens(C18Lexer, text)
        assert ours == _tokens(_PycparsersLexer, text)
    tricky = _tokens(C18Lexer, _TRICKY)
    assert {"rom", "near"} & {t[1] for t in tricky} and sum(t[0] == "error" for t in tricky) >= 4
    assert ("ROM", "rom") in {t[:2] for t in tricky} and set(C18_QUALIFIERS.values()) <= {t[0] for t in tricky}


# ====================================================================== no stale header cache

_NULL_USER = b"""%s
void main(void) { int count = NULL; char *none = NULL; while (1) { count = count + 1; } }
"""


@pytest.mark.parametrize("before", [
    b"#define NULL 0\n#include <stdio.h>",
    b"#define NULL 0\n#include \"CAN18XX8.h\"\n#include <string.h>\n#include <stdio.h>",
    b"#include <stdio.h>\n#undef NULL\n#define NULL 0",
])
def test_a_files_own_define_of_a_header_macro_holds_as_cs_preprocessor_has_it(before):
    """stdio.h defines NULL only #ifndef NULL: the file's own NULL, defined before the #include, is the one that
    holds (the kit's headers preprocessed alone would give ((void *)0), and `int count = NULL` would be refused)."""
    c18.warm()                          # the headers known ahead, as in a sandbox
    source = _NULL_USER % before
    c18.translate("own_null.c", source, {}, ())
    assert "NULL" in c18.constants("own_null.c", source), "the file's own #define, with its value"
    classmate = _NULL_USER % b"#include <stdio.h>"
    with pytest.raises(CCompileError, match="this is a pointer"):
        c18.translate("classmate.c", classmate, {}, ())     # the header's own NULL: nothing of the first file stayed


def test_a_files_own_null_holds_in_a_sandbox_booted_with_the_graders_headers_state():
    script = ("import sys; from appsim.firmware import c18; c18.adopt(sys.stdin.buffer.read()); c18.warm(); "
              "c18.translate('own_null.c', sys.argv[1].encode(), {}, ()); print('translated')")
    source = (_NULL_USER % b"#define NULL 0\n#include <stdio.h>").decode()
    done = subprocess.run([sys.executable, "-c", script, source], input=c18.header_state(), capture_output=True)
    assert done.stdout.strip() == b"translated", done.stderr.decode()[-600:]


def test_a_files_include_order_does_not_change_its_translation():
    source = (SOLUTIONS / "ex6.c").read_text(encoding="utf-8")
    lines = source.splitlines(keepends=True)
    includes = [n for n, line in enumerate(lines) if line.startswith("#include")]
    assert len(includes) >= 3
    reordered = list(lines)
    for n, m in zip(includes, reversed(includes), strict=True):
        reordered[n] = lines[m]
    assert reordered != lines
    first = c18.translate("order.c", source.encode(), {}, ())
    again = c18.translate("order.c", "".join(reordered).encode(), {}, ())
    assert again is not first and again.code == first.code and again.constants == first.constants


def test_a_define_that_would_rewrite_a_kit_headers_declarations_is_refused_at_its_include():
    """`#define BYTE int` before "CAN18XX8.h": C18 would read the header's declarations with the macro in them; the
    kit knows them as the header has them, so it says so, at the #include, instead of translating something else."""
    source = b"#include <p18f8680.h>\n#define BYTE int\n#include \"CAN18XX8.h\"\nvoid main(void) { while (1) ; }\n"
    with pytest.raises(CCompileError) as caught:
        c18.translate("rewrite.c", source, {}, ())
    assert caught.value.line == 3 and "BYTE is #defined before #include CAN18XX8.h" in str(caught.value)
    after = source.replace(b"#define BYTE int\n#include \"CAN18XX8.h\"\n", b"#include \"CAN18XX8.h\"\n#define NEW 1\n")
    c18.translate("rewrite.c", after, {}, ())
