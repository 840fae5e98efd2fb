"""pycparser taught MPLAB C18's words: the qualifiers `rom`, `ram`, `near`, `far` (kept in each declaration's quals),
and typedef names that the kit's headers declared before the file is parsed.

`short long` needs nothing: pycparser keeps a declaration's type specifiers as written, the translator reads them.
"""
from __future__ import annotations

import re
from collections.abc import Iterable

import pycparser
from pycparser import c_ast, c_lexer, c_parser

C18_QUALIFIERS = {"rom": "ROM", "ram": "RAM", "near": "NEAR", "far": "FAR"}


def _teach_pycparser() -> None:
    """Make the parser take C18's qualifier tokens where C's take theirs. No other lexer emits these token types, so
    other users of pycparser in the process (cffi) see no change (from pycparser 3.12, each lexer has its own
    keywords)."""
    if "_keyword_map" not in c_lexer.CLexer.__init__.__code__.co_names:     # a lexer's own keywords: pycparser 3.12
        raise RuntimeError(f"this pycparser ({pycparser.__version__}, {c_parser.__file__}) is older than 3.12, which "
                           "the kit's C translator needs: pip install --upgrade 'pycparser>=3.12,<4'")
    for table in ("_TYPE_QUALIFIER", "_DECL_START"):
        tokens = getattr(c_parser, table, None)
        if not isinstance(tokens, set):
            raise RuntimeError(f"this pycparser ({c_parser.__file__}) has no {table}: the kit needs pycparser 3")
        tokens.update(C18_QUALIFIERS.values())


_teach_pycparser()


_BLANKS = re.compile(r"[ \t\f\v]+")
_WORD = re.compile(r"[a-zA-Z_$][0-9a-zA-Z_$]*")       # pycparser's _identifier
# A word starting with one of these is an identifier and nothing else: L, u and U may start a wide or Unicode literal.
_WORD_START = frozenset("abcdefghijklmnopqrstvwxyzABCDEFGHIJKMNOPQRSTVWXYZ_$")
# Punctuation only pycparser's fixed tokens start (no literal, comment or attribute does: not / . [), longest first.
_PUNCTUATION = {first: [(entry.literal, entry.tok_type) for entry in bucket]
                for first, bucket in c_lexer._fixed_tokens_by_first.items() if first not in "/.["}


class C18Lexer(c_lexer.CLexer):
    """pycparser's lexer with C18's qualifiers, and quicker at what a firmware is made of (runs of blanks, words,
    punctuation): each gives the very token pycparser's own rules give (tests/test_c_translation_cache.py compares
    every translation with pycparser's own lexer's)."""

    _pos: int                           # CLexer's, set in its _init_state

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._keyword_map.update(C18_QUALIFIERS)

    def token(self) -> c_lexer.Token | None:
        """As CLexer.token: blanks skipped a run at a time, a word or punctuation made at once, the rest (#line,
        #pragma, literals, errors) pycparser's."""
        text = self._lexdata
        n = len(text)
        while self._pending_tok is None and self._pos < n:
            pos = self._pos
            c = text[pos]
            if c in " \t\f\v":
                self._pos = _BLANKS.match(text, pos).end()      # type: ignore[union-attr]
            elif c == "\n":
                self._lineno += 1
                self._pos = self._line_start = pos + 1
            elif self._in_attribute or c == "#":
                break
            elif c in _WORD_START:
                value = _WORD.match(text, pos).group()          # type: ignore[union-attr]
                self._pos = pos + len(value)
                return c_lexer.Token(self._keyword_map.get(value, "ID"), value, self._lineno,
                                     pos - self._line_start + 1, self._filename)
            elif c in _PUNCTUATION:
                for literal, kind in _PUNCTUATION[c]:
                    if text.startswith(literal, pos):
                        self._pos = pos + len(literal)
                        return c_lexer.Token(kind, literal, self._lineno, pos - self._line_start + 1, self._filename)
                break
            else:
                break
        return super().token()


class C18Parser(c_parser.CParser):
    """A C parser for one translation unit, which starts knowing the typedef names `typedefs`."""

    def __init__(self, typedefs: Iterable[str] = ()) -> None:
        super().__init__(lexer=C18Lexer)
        self._typedefs = dict.fromkeys(typedefs, True)

    def _peek(self, k: int = 1) -> c_lexer.Token | None:
        """As CParser._peek, the token read ahead taken from the stream's buffer without a call (it is called
        several times a token)."""
        stream = self._tokens
        position = stream._index + k - 1
        buffer = stream._buffer
        tok = buffer[position] if 0 < k and position < len(buffer) else stream.peek(k)
        if tok is not self._typedef_checked_token:
            self._classify_identifier(tok)
        return tok

    def _peek_type(self, k: int = 1) -> str | None:
        tok = self._peek(k)
        return tok.type if tok is not None else None

    def parse(self, text: str, filename: str = "", debug: bool = False) -> c_ast.FileAST:
        self._scope_stack = [dict(self._typedefs)]
        self._typedef_checked_token = None
        self.clex.input(text, filename)
        self._tokens = c_parser._TokenStream(self.clex.token)
        ast = self._parse_translation_unit_or_empty()
        tok = self._peek()
        if tok is not None:
            self._parse_error(f"before: {tok.value}", self._tok_coord(tok))
        return ast
