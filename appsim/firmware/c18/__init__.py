"""MPLAB C18's C on the simulated board: a .c firmware file translated into a Python module that runs where Python
firmware runs (see docs/c-firmware.md for the route, the C18 semantics modelled and what is refused).

`load(path, source, defines, options)` gives the module; `constants(path, source)` the file's #define constants;
`warm()` parses the kit's headers ahead (the grader's zygote does, before it forks).
"""
from __future__ import annotations

import ast
import contextlib
import gc
import pickle
import re
import signal
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import CodeType, ModuleType
from typing import Any

from pycparser import c_ast
from pycparser.c_parser import ParseError

from appsim.chip.sfr import HIGH_VECTOR, LOW_VECTOR, current_mcu
from appsim.errors import CCompileError, CRuntimeError
from appsim.firmware.c18 import compiler, headers, preprocess, runtime
from appsim.firmware.c18.compiler import GOTO, MCU, ROUTINE_MARKS, RT, Sym, Translator, library_name
from appsim.firmware.c18.library import BINDINGS, Restart
from appsim.firmware.c18.parser import C18Parser
from appsim.firmware.interrupts import idle, interrupt, interruptlow, routines
from appsim.firmware.loader import IDLE, waits_for_interrupts

OPTIONS = {"-Oi": "integer promotions, as ISO C has them (C18's default has none)",
           "-k": "plain char is unsigned (C18's default: signed)"}
TRANSLATION_SECONDS = 5.0           # within every exercise's budget (a translation takes 10 to 50 ms)
MAX_NESTING = 60                    # ( [ { nested in the file
MAX_LINES = 10_000                  # of the preprocessed file (the workshop's biggest, Demo1's, has 500)
_CACHE_SIZE = 64


@dataclass(frozen=True)
class Translated:
    """A file translated: the code of its module, the values it puts in the module before that code runs, and its
    #define constants."""

    code: CodeType
    namespace: dict[str, Any]
    constants: dict[str, int]
    defines: tuple[str, ...]


_translated: dict[tuple[str, int, int, tuple[tuple[str, int], ...], tuple[str, ...]], Translated] = {}
_symbols: dict[tuple[str, tuple[str, ...]], dict[str, Sym]] = {}
_C_FILES: set[str] = set()


def is_c_file(filename: str | None) -> bool:
    """Whether code of `filename` was translated from C (its errors are told in C's words)."""
    return filename in _C_FILES


def describe(error: BaseException) -> str | None:
    """What a C firmware's run-time error means, in C's words (None: the error says it well enough)."""
    if isinstance(error, CRuntimeError):
        return str(error)
    if isinstance(error, (UnboundLocalError, NameError)):     # a local never set: Python looks for a global
        found = re.search(r"'(\w+)'", str(error))
        name = (found.group(1) if found else "a local variable").split("__")[0]
        return (f"{name} is read before anything was stored in it: C18 leaves a local variable's value undefined "
                "until it is assigned (give it an initial value where it is declared)")
    if isinstance(error, RecursionError):
        return ("the calls nest without end (a function that calls itself, and never stops?): the PIC18's return "
                "stack holds 31 calls")
    return None


def check_options(options: Sequence[str]) -> tuple[str, ...]:
    for option in options:
        if option not in OPTIONS:
            raise CCompileError(f"{option} is not a C18 option the kit knows: "
                                + "; ".join(f"{name} ({what})" for name, what in OPTIONS.items()))
    return tuple(sorted(set(options)))


def decode(source: bytes, name: str) -> str:
    """The file's text: UTF-8 (with Notepad's BOM or without), else Big5 (the workshop's Traditional Chinese
    comments), else Latin-1."""
    if source.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise CCompileError(f"{name} is saved as UTF-16 (Unicode): save it as UTF-8 or ANSI, as MPLAB's editor does")
    if b"\0" in source:
        raise CCompileError(f"{name} holds NUL bytes: it is not a C source file")
    for encoding in ("utf-8-sig", "cp950"):
        try:
            return source.decode(encoding)
        except UnicodeDecodeError:
            continue
    return source.decode("latin-1")


def load(path: str | Path, source: bytes, defines: Mapping[str, int] | None = None,
         options: Sequence[str] = ()) -> ModuleType:
    """A fresh module of the C file `path` (named so in messages and tracebacks) holding `source`."""
    path = Path(path)
    translated = translate(str(path), source, defines or {}, options)
    module = ModuleType(f"firmware_{_identifier(path.stem)}_{next(_loads)}")
    module.__file__ = str(path)
    namespace = vars(module)
    namespace.update(translated.namespace)
    namespace.update(translated.constants)
    exec(translated.code, namespace)
    routines(module)                    # the translation checked them: two at one vector cannot be
    return module


def constants(path: str | Path, source: bytes) -> list[str]:
    """The object-like #defines of the file that are integer constants: the names `defines` can replace."""
    return list(translate(str(Path(path)), source, {}, ()).constants)


def translate(filename: str, source: bytes, defines: Mapping[str, int], options: Sequence[str]) -> Translated:
    """The file translated (cached by its content, defines and options)."""
    options = check_options(options)
    for name, value in defines.items():
        if not isinstance(value, int) or isinstance(value, bool):
            raise CCompileError(f"-D {name}={value!r}: a define is an integer, such as {name}=0x110")
    # The source by its length and hash: the cache is one process's (in a grading sandbox, one student's firmware),
    # so no other student's file meets it; keeping the 64 sources could hold 64 MB, and hashlib costs a sandbox 4 ms.
    key = (filename, len(source), hash(source), tuple(sorted(defines.items())), options)
    found = _translated.get(key)
    if found is None:
        with _cpu_deadline(filename), _no_collection():
            found = _translate(filename, source, defines, options)
        if len(_translated) >= _CACHE_SIZE:
            _translated.pop(next(iter(_translated)))
        _translated[key] = found
    import linecache
    text = decode(source, Path(filename).name)
    linecache.cache[filename] = (len(text), None, text.splitlines(True), filename)
    _C_FILES.add(filename)
    return found


_loads = iter(range(1, 1 << 62))


class _OutOfTime(Exception):
    pass


@contextlib.contextmanager
def _no_collection() -> Iterator[None]:
    """The cyclic garbage collector off while a file is translated: the translation makes tens of thousands of
    short-lived objects and few cycles, and the collector's passes over them cost a tenth of its time. (Its time and
    memory are limited as before: TRANSLATION_SECONDS, and a sandbox's memory limit.)"""
    if not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


@contextlib.contextmanager
def _cpu_deadline(filename: str) -> Iterator[None]:
    """Stop a translation that runs away (a macro bomb's arguments, a monstrous expression) after
    TRANSLATION_SECONDS of CPU time, wherever it is: a CPU-time timer (SIGVTALRM), in the main thread. Elsewhere the
    translator's own checks of the time stop it, between its steps."""
    if (not hasattr(signal, "setitimer") or threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGVTALRM) not in (signal.SIG_DFL, None)):
        try:
            yield
        except MemoryError:
            raise CCompileError("the translation ran out of memory: a macro that expands without end (a macro "
                                "bomb)?", filename) from None
        return

    def expired(signum: int, frame: object) -> None:
        raise _OutOfTime

    signal.signal(signal.SIGVTALRM, expired)
    try:
        signal.setitimer(signal.ITIMER_VIRTUAL, TRANSLATION_SECONDS)
    except OSError:                     # no CPU-time timer here: the translator's own checks remain
        signal.signal(signal.SIGVTALRM, signal.SIG_DFL)
        yield
        return
    try:
        yield
    except MemoryError:
        raise CCompileError("the translation ran out of memory: a macro that expands without end (a macro bomb)?",
                            filename) from None
    except _OutOfTime:
        raise CCompileError(f"the translation ran out of its time ({TRANSLATION_SECONDS:g} s of CPU; a firmware takes "
                            "a few hundredths): a macro that expands without end (a macro bomb), or an expression "
                            "thousands of terms long?", filename) from None
    finally:
        signal.setitimer(signal.ITIMER_VIRTUAL, 0)
        signal.signal(signal.SIGVTALRM, signal.SIG_DFL)


def _identifier(text: str) -> str:
    return re.sub(r"\W", "_", text)


def _translate(filename: str, source: bytes, defines: Mapping[str, int], options: tuple[str, ...]) -> Translated:
    deadline = time.process_time() + TRANSLATION_SECONDS
    name = Path(filename).name
    text = decode(source, name)
    if len(text) > preprocess.MAX_OUTPUT_CHARS:
        raise CCompileError(f"the file has {len(text):,} characters: a firmware is a few thousand lines at most "
                            f"(the kit takes {preprocess.MAX_OUTPUT_CHARS:,})", filename)
    if text.count("\n") > MAX_LINES:
        raise CCompileError(f"the file has more than {MAX_LINES:,} lines: a firmware has a few hundred", filename)
    done = preprocess.preprocess(text, filename, defines, deadline)
    for define in defines:
        if define not in done.defines:
            raise CCompileError(f"-D {define}: {name} has no #define {define} to replace. It defines "
                                f"{', '.join(done.defines) or 'no constants'}; a -D replaces one of those, as the "
                                "C18 command line's -D replaces a #define.")
    if done.text.count("\n") > MAX_LINES:
        raise CCompileError(f"the file has more than {MAX_LINES:,} lines of C (after the preprocessor): a firmware "
                            "has a few hundred", filename)
    parsed_text = _refuse_what_cannot_parse(done.text, filename)
    symbols: dict[str, Sym] = {}
    for header in done.headers:
        symbols.update(header_symbols(header, options))
    typedefs = [s.name for s in symbols.values() if s.kind == "typedef"]
    try:
        tree = C18Parser(typedefs).parse(parsed_text, filename)
    except ParseError as error:
        raise _parse_error(error, filename, text) from None
    except RecursionError:
        raise CCompileError("the file is nested too deep for the kit's C", filename) from None
    lines = text.splitlines()
    translator = Translator(filename, lines, options, deadline)
    translator.scopes[0].update(symbols)
    translator.translation_unit(tree)
    if not translator.main_seen:
        raise CCompileError("there is no main(): a firmware defines void main(void) that loops forever, as EX1.C "
                            "does", filename)
    constants_ = _define_values(done.expanded, translator, filename)
    module, namespace = _module(translator, filename)
    waits_for_interrupts(module, Path(filename), lines)
    try:
        try:
            code = compile(module, filename, "exec")
        except TypeError:               # a node the translator left without a line: its parent's (a safety net)
            code = compile(ast.fix_missing_locations(module), filename, "exec")
    except SyntaxError as error:
        raise CCompileError(f"the kit could not translate this ({error.msg}): nest fewer blocks or simplify it",
                            filename, error.lineno or 0) from None
    except RecursionError:
        raise CCompileError("the file is nested too deep for the kit's C", filename) from None
    return Translated(code, namespace, constants_, tuple(done.defines))


_ASM = re.compile(r'#line (\d+)[^\n]*\n|#\s*pragma\b|#|\n|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'|[(\[{]|[)\]}]|'
                  r'\b_asm\s+goto\s+([A-Za-z_]\w*)\s+_endasm\b|\b_asm\b|\b__asm\b|\basm\b', re.IGNORECASE)


def _refuse_what_cannot_parse(text: str, filename: str) -> str:
    """The preprocessed text as the parser takes it: inline assembly refused, but for C18's interrupt vector,
    `_asm GOTO high_isr _endasm`, which becomes a call the translator knows (on as many lines as it had); and nesting
    deeper than the parser should go refused, by line."""
    line, depth = 1, 0
    pieces: list[str] = []
    done = 0
    for match in _ASM.finditer(text):
        token = match.group(0)
        if token[0] == "#":             # pcpp has read every directive but #pragma, and left its #line markers
            before = text[text.rfind("\n", 0, match.start()) + 1:match.start()]
            if token == "#" or before.strip(" \t\f\v"):
                raise CCompileError("a stray '#' in the code: # begins a preprocessor directive (#define, #include "
                                    "...), which stands at the start of its own line", filename, line)
            if not match.group(1):
                continue                # #pragma: the translator reads it
        if match.group(1):
            line = int(match.group(1))
        elif token == "\n":
            line += 1
        elif match.group(2):
            pieces += [text[done:match.start()], f"{GOTO}({match.group(2)});", "\n" * token.count("\n")]
            done = match.end()
            line += token.count("\n")
        elif token in "([{":
            depth += 1
            if depth > MAX_NESTING:
                raise CCompileError(f"parentheses, brackets and braces nest more than {MAX_NESTING} deep here: no "
                                    "firmware needs that; simplify the expression", filename, line)
        elif token in ")]}":
            depth -= 1
        elif token[0] not in "\"'":
            raise CCompileError(f"inline assembly ({token} ... _endasm) is not supported: the kit runs C, not PIC18 "
                                "instructions. For a NOP call Nop(); for CLRWDT, ClrWdt(). The one assembly it takes "
                                "is C18's interrupt vector, `_asm GOTO high_isr _endasm` (docs/interrupts.md)",
                                filename, line)
    return "".join(pieces) + text[done:]


def _parse_error(error: ParseError, filename: str, text: str) -> CCompileError:
    message = str(error)
    match = re.match(r"(?:(.*?):)?(\d+):(\d+): (.*)", message)
    if not match:
        if message.endswith("At end of input"):
            opened = _unclosed_brace(text)
            where = f" (the last '{{' not closed is at line {opened})" if opened else ""
            return CCompileError(f"the file ends inside a function or a declaration: a '}}' or a ';' is missing"
                                 f"{where}", filename, opened or 0)
        return CCompileError(f"syntax error: {message.split(': ', 1)[-1]}", filename)
    line, column, what = int(match.group(2)), int(match.group(3)), match.group(4)
    if what.startswith("Comments are not supported"):
        return CCompileError("a comment that is never closed: each /* needs its */", filename, line, column)
    if what == "Illegal character '\"'":
        return CCompileError("a string with no closing quote: a \" needs its closing \" on the same line", filename,
                             line, column)
    what = what.replace("before: ", "syntax error before '") + ("'" if what.startswith("before: ") else "")
    lines = text.splitlines()
    source_line = lines[line - 1] if 0 < line <= len(lines) else ""
    hint = ""
    if "before" in what and 1 < line <= len(lines) + 1:
        previous = lines[line - 2].rstrip()
        ends = (";", "{", "}", ",", "/", "*", "(", "&&", "||", "&", "|", "+", "-", "=", "?", ":")
        control = previous.lstrip().split("(")[0].strip() in ("if", "while", "for", "switch", "else if")
        if what == "syntax error before '{'" and previous.endswith(")") and not control:
            hint = " (a function's body where C still expects code: is the '}' that ends the function above missing?)"
        elif (previous and not previous.endswith(ends) and not previous.lstrip().startswith("#")
                and not (previous.endswith(")") and control)):
            hint = " (is a ';' missing at the end of the line before?)"
    shown = f": `{source_line.strip()}`" if source_line.strip() else ""
    return CCompileError(f"{what}{hint}{shown}", filename, line, column)


_BRACES = re.compile(r'/\*.*?\*/|//[^\n]*|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'|[{}\n]', re.DOTALL)


def _unclosed_brace(text: str) -> int | None:
    """The line of the last '{' of the file that no '}' closes (comments, strings and characters skipped)."""
    line, opened = 1, []
    for match in _BRACES.finditer(text):
        token = match.group(0)
        if token == "{":
            opened.append(line)
        elif token == "}" and opened:
            opened.pop()
        line += token.count("\n")
    return opened[-1] if opened else None


def header_symbols(header: str, options: tuple[str, ...], *, parsed: bool = False) -> dict[str, Sym]:
    """A kit header's declarations, known once per process (and per option set). The device header's come from the
    register map it is written from (every SFR at its address, its NAMEbits, the instruction functions), unless
    `parsed`: then from its text, as every other header's (a test checks that both agree)."""
    key = (header, options)
    found = None if parsed else _symbols.get(key)
    if found is None and header == headers.DEVICE_HEADER and not parsed:
        found = _symbols[key] = compiler.device_symbols()
    if found is None:
        kit = preprocess.kit_header(header)
        inner: dict[str, Sym] = {}
        for included in kit.includes[:-1]:
            inner.update(header_symbols(included, options))
        typedefs = [s.name for s in inner.values() if s.kind == "typedef"]
        tree = C18Parser(typedefs).parse(kit.text, header)
        found = dict(compiler.header_symbols(tree, header, options))
        if not parsed:
            _symbols[key] = found
    return found


def warm(options: Sequence[str] = ()) -> None:
    """Preprocess and parse every kit header now (once per process), with C18's `options` too."""
    for option_set in {(), check_options(options)}:
        for header in headers.HEADERS:
            header_symbols(header, option_set)
            preprocess.kit_header(header, declarations=False)


STATE_FORMAT = 2


def header_state(options: Sequence[str] = ()) -> bytes:
    """The kit's headers preprocessed and parsed (`warm`), as bytes for another process of this same kit: the grader
    makes them once and hands them to every sandbox, which `adopt`s them instead of parsing the headers itself. They are
    made from the kit's own headers, never from a firmware, and only ever go into a sandbox, never out of one."""
    warm(options)
    return pickle.dumps((STATE_FORMAT, _symbols, preprocess.header_macros()), protocol=pickle.HIGHEST_PROTOCOL)


def adopt(state: bytes) -> None:
    """Know the kit's headers as `header_state` made them in the grader (ValueError if they are not of this format)."""
    found = pickle.loads(state)
    if not (isinstance(found, tuple) and len(found) == 3 and found[0] == STATE_FORMAT):
        raise ValueError("the kit headers' state is not one this kit made")
    _, symbols, macros = found
    for key, value in symbols.items():
        _symbols.setdefault(key, value)
    preprocess.adopt_headers(macros)


_PLAIN_NUMBER = re.compile(r"0[xX][0-9a-fA-F]+|[1-9][0-9]*|0")


def _define_values(expanded: Mapping[str, str], translator: Translator, filename: str) -> dict[str, int]:
    """The file's object-like #defines whose replacement is an integer constant, with their values."""
    values: dict[str, int] = {}
    typedefs = [s.name for s in translator.scopes[0].values() if s.kind == "typedef"]
    for name, text in expanded.items():
        if not text:
            continue
        if _PLAIN_NUMBER.fullmatch(text):       # 0x100, 125: the value C gives it, without a parse
            values[name] = int(text, 0)
            continue
        try:
            tree = C18Parser(typedefs).parse(f"int __value = ({text});", filename)
            decl = tree.ext[0]
            assert isinstance(decl, c_ast.Decl)
            e = translator.rvalue(decl.init)
        except (ParseError, compiler._Refused, AssertionError, RecursionError):
            continue
        if e.const is not None:
            values[name] = e.const
    return values


def _module(tr: Translator, filename: str) -> tuple[ast.Module, dict[str, Any]]:
    """The module's code: the functions, the C startup (globals' initial values) and main(), which runs it."""
    namespace: dict[str, Any] = {RT: runtime, "__current_mcu": current_mcu, "__Restart": Restart, MCU: None,
                                 "__c18__": True}
    for name, binding in BINDINGS.items():
        namespace[library_name(name)] = binding
    namespace.update({IDLE: idle, ROUTINE_MARKS[HIGH_VECTOR]: interrupt, ROUTINE_MARKS[LOW_VECTOR]: interruptlow})
    for name, value in tr.constants.items():
        if isinstance(value, compiler._RomString):
            namespace[name] = runtime.Ptr(value.data, 0, 0, len(value.data), value.name, True, value.element)
        else:
            namespace[name] = value
    body: list[ast.stmt] = list(tr.module)
    startup_globals = sorted(tr.globals) or ["__M"]
    main_line = next((fn.lineno for fn in body if isinstance(fn, ast.FunctionDef) and fn.name == "__c_main"), 1)
    first_line = tr.startup[0].lineno if tr.startup else main_line
    startup = ast.FunctionDef("__c_startup", _no_arguments(), [ast.Global(startup_globals), *tr.startup,
                                                                ast.Pass()], [], None)
    _place(startup, first_line)
    main = ast.parse(
        "def main():\n"
        "    global __M\n"
        "    __M = __current_mcu()\n"
        "    while True:\n"
        "        __c_startup()\n"
        "        try:\n"
        "            while True:\n"
        "                __c_main()\n"
        "        except __Restart:\n"
        "            pass\n").body[0]
    _place(main, main_line, force=True)
    run_startup = ast.Expr(ast.Call(ast.Name("__c_startup", ast.Load()), [], []))
    _place(run_startup, first_line)
    return ast.Module([*body, startup, main, run_startup], []), namespace


def _no_arguments() -> ast.arguments:
    return ast.arguments([], [], None, [], [], None, [])


def _place(node: ast.AST, line: int, force: bool = False) -> None:
    for sub in ast.walk(node):
        if isinstance(sub, (ast.expr, ast.stmt, ast.excepthandler, ast.arg)):
            if force or getattr(sub, "lineno", None) is None:
                sub.lineno, sub.col_offset = line, 0
                sub.end_lineno, sub.end_col_offset = line, 1
