"""pycparser taught MPLAB C18's words: the qualifiers `rom`, `ram`, `near`, `far` (kept in each declaration's quals),
and typedef names that the kit's headers declared before the file is parsed.

`short long` needs nothing: pycparser keeps a declaration's type specifiers as written, the translator reads them.
"""
from __future__ import annotations

from collections.abc import Iterable

import pycparser
from pycparser import c_ast, c_lexer, c_parser

C18_QUALIFIERS = {"rom": "ROM", "ram": "RAM", "near": "NEAR", "far": "FAR"}


def _teach_pycparser() -> None:
    """Make the parser take C18's qualifier tokens where C's take theirs. No other lexer emits these token types, so
    other users of pycparser in the process (cffi) see no change (from pycparser 3.12, each lexer has its own
    keywords)."""
    if tuple(int(part) for part in pycparser.__version__.split(".")[:2]) < (3, 12):
        raise RuntimeError(f"this pycparser ({pycparser.__version__}, {c_parser.__file__}) is older than 3.12, which "
                           "the kit's C translator needs: pip install --upgrade 'pycparser>=3.12,<4'")
    for table in ("_TYPE_QUALIFIER", "_DECL_START"):
        tokens = getattr(c_parser, table, None)
        if not isinstance(tokens, set):
            raise RuntimeError(f"this pycparser ({c_parser.__file__}) has no {table}: the kit needs pycparser 3")
        tokens.update(C18_QUALIFIERS.values())


_teach_pycparser()


class C18Lexer(c_lexer.CLexer):
    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._keyword_map.update(C18_QUALIFIERS)


class C18Parser(c_parser.CParser):
    """A C parser for one translation unit, which starts knowing the typedef names `typedefs`."""

    def __init__(self, typedefs: Iterable[str] = ()) -> None:
        super().__init__(lexer=C18Lexer)
        self._typedefs = dict.fromkeys(typedefs, True)

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
