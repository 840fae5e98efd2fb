"""Loading a student's firmware file: plain Python with `from appsim.firmware import *` and a `main()`, or C18's C
(a `.c` file, translated by appsim.firmware.c18) with its `void main(void)`.

Each load is a fresh module, so two boards running the same file never share their globals. An empty loop that only an
interrupt routine can end (`while not flag: pass`) becomes a wait for the next interrupt (see `waits_for_interrupts`).
"""
from __future__ import annotations

import ast
import contextlib
import difflib
import io
import itertools
import linecache
import re
import sys
import traceback
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from types import ModuleType

from appsim.chip.sfr import VECTOR_NAMES
from appsim.errors import FirmwareError
from appsim.firmware.interrupts import MARK, idle, in_c18_words, routines
from appsim.sim import TRACEBACK_FRAMES

_loads = itertools.count()
IDLE = "__appsim_idle__"            # the name an empty waiting loop calls (appsim.firmware.interrupts.idle)
LOOP_TEXT = 80                      # characters of a waiting loop's line (and of its file's name) its messages quote


def load_firmware(path: str | Path, defines: Mapping[str, int] | None = None,
                  c_options: Sequence[str] = ()) -> ModuleType:
    """Load a firmware file as a new module; it must define `main()` (a .c file: `void main(void)`).

    `defines` works like `-D MESSAGE_ID1=0x110` on the C18 command line: each name's top-level
    assignment (`MESSAGE_ID1 = 0x100`; in C, its `#define MESSAGE_ID1 0x100`) gets the given value
    instead, and constants computed from it follow. Six stations run one solution file with six
    identifiers this way. `c_options` are C18's command-line options for a .c file (`-Oi`).
    """
    path = Path(path)
    return load_source(path, read_firmware(path), defines, c_options=c_options)


def is_c(path: str | Path, language: str | None = None) -> bool:
    """Whether a firmware is C: `language` ("c" or "python") if given, else its file's suffix (.c)."""
    if language is not None:
        if language not in ("c", "python"):
            raise ValueError(f"a firmware's language is 'c' or 'python'; got {language!r}")
        return language == "c"
    return Path(path).suffix.lower() == ".c"


def load_source(path: str | Path, source: bytes, defines: Mapping[str, int] | None = None, *,
                language: str | None = None, c_options: Sequence[str] = ()) -> ModuleType:
    """Load firmware from its bytes, as if from the file `path` (its name in messages and tracebacks), with
    `defines` as `load_firmware` takes them. Its lines are what tracebacks show, whatever the file holds later.
    C or Python: `language`, else the suffix of `path`."""
    path = Path(path)
    if is_c(path, language):
        from appsim.firmware import c18
        return c18.load(path, source, defines, c_options)
    tree = _parse(path, source)
    text = source.decode("utf-8-sig")                       # _parse has read it so: it decodes
    linecache.cache[str(path)] = (len(source), None, text.splitlines(True), str(path))
    if defines:
        _apply_defines(tree, defines, path)
    waits_for_interrupts(tree, path, text.splitlines())
    try:
        code = compile(tree, str(path), "exec")
    except SyntaxError as error:
        raise _syntax_error(path, error) from None
    module = ModuleType(f"firmware_{path.stem}_{next(_loads)}")
    module.__file__ = str(path)
    vars(module)[IDLE] = idle
    sys.modules[module.__name__] = module   # while its top runs: @dataclass, enum and typing look their module up
    try:
        exec(code, vars(module))
    except Exception as error:
        report = traceback.TracebackException.from_exception(error)
        mine = [frame for frame in report.stack if frame.filename == str(path)]
        where = f"\n(line {mine[-1].lineno}: {mine[-1].line})" if mine else ""
        what = _as_python_words_it(error, report)
        end = "" if what.endswith((".", "?")) else "."          # "Did you mean: 'CANSetFilter'?" ends itself
        raise FirmwareError(f"{path.name} failed while loading, before main() ran: {what}{end} Only constants and "
                            f"functions belong at the top of the file; CAN and LCD calls go inside main().{where}"
                            ) from error
    finally:
        if sys.modules.get(module.__name__) is module:
            del sys.modules[module.__name__]
    if not callable(getattr(module, "main", None)):
        raise FirmwareError(f"{path.name} has no main(): a firmware file defines `def main():` that loops "
                            "forever, as main() does in EX1.C")
    try:
        routines(module)
    except FirmwareError as error:
        raise FirmwareError(f"{path.name}: {error}") from None
    return module


# ====================================================================== empty waiting loops

_CONDITION_NODES = (ast.Name, ast.Constant, ast.UnaryOp, ast.BoolOp, ast.Compare, ast.BinOp, ast.expr_context,
                    ast.unaryop, ast.boolop, ast.cmpop, ast.operator)


def waits_for_interrupts(tree: ast.Module, path: Path, lines: Sequence[str]) -> None:
    """Rewrite (in place) every provably empty waiting loop inside a function: `while COND:` whose body is only `pass`,
    `...` or `Nop()`, and whose condition reads names and constants with no call, attribute or subscript (no register
    read): `while True: pass`, `while not flag: pass`, `while count == seen: Nop()`. Only an interrupt routine can end
    such a loop, so on the chip it spins until one does; here each turn first calls `__appsim_idle__(LOOP, (NAMES),
    (CALLS))`, which waits until the next interrupt is taken (appsim.firmware.interrupts.idle: only when the names
    hold plain values and the calls are the kit's Nop, so that nothing else can change the condition). `lines` are the
    file's, which the loop's message quotes (a C file's: its C18 `while (!flag);` translates to exactly this shape)."""
    for loop in _loops_in_functions(tree.body, False):
        if not _empty(loop) or not all(isinstance(node, _CONDITION_NODES) for node in ast.walk(loop.test)):
            continue
        names = list(dict.fromkeys(node.id for node in ast.walk(loop.test) if isinstance(node, ast.Name)))
        calls = ["Nop"] if any(isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Call)
                               for statement in loop.body) else []
        quoted = lines[loop.lineno - 1] if 0 < loop.lineno <= len(lines) else ""
        wait = ast.Expr(ast.Call(ast.Name(IDLE, ast.Load()), [
            ast.Constant(f"line {loop.lineno} of {_shown(path.name)} (`{_shown(quoted)}`)"),
            ast.Tuple([ast.Name(name, ast.Load()) for name in names], ast.Load()),
            ast.Tuple([ast.Name(name, ast.Load()) for name in calls], ast.Load())], []))
        first = loop.body[0]
        for node in ast.walk(wait):     # the new nodes only, at the place of the loop's first statement
            if isinstance(node, (ast.expr, ast.stmt)):
                ast.copy_location(node, first)
        loop.body.insert(0, wait)


def _loops_in_functions(statements: list[ast.stmt], in_function: bool) -> Iterator[ast.While]:
    """The `while` loops among `statements` and the statements inside them that lie in a function (a loop can only be
    a statement, so expressions are never looked into)."""
    for statement in statements:
        inside = in_function or isinstance(statement, (ast.FunctionDef, ast.AsyncFunctionDef))
        if isinstance(statement, ast.While) and in_function:
            yield statement
        for name in ("body", "orelse", "finalbody"):
            block = getattr(statement, name, None)
            if isinstance(block, list):
                yield from _loops_in_functions(block, inside)
        for part in (*getattr(statement, "handlers", ()), *getattr(statement, "cases", ())):
            yield from _loops_in_functions(part.body, inside)


def _shown(text: str, most: int = LOOP_TEXT) -> str:
    """`text` on one line of printable characters, at most `most` of them, as a message quotes it."""
    text = "".join(c if c.isprintable() else "?" for c in " ".join(text.split()))
    return text if len(text) <= most else text[:most - 3] + "..."


def _empty(loop: ast.While) -> bool:
    """A loop body of `pass`, `...` and `Nop()` only."""
    for statement in loop.body:
        if isinstance(statement, ast.Pass):
            continue
        if not isinstance(statement, ast.Expr):
            return False
        value = statement.value
        if isinstance(value, ast.Constant) and value.value is Ellipsis:
            continue
        if not (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "Nop"
                and not value.args and not value.keywords):
            return False
    return True


def constants(path: str | Path) -> list[str]:
    """The names a firmware file assigns at top level (`NAME = <expr>`; in C, its `#define NAME <constant>`): the
    ones `defines` can replace."""
    path = Path(path)
    if is_c(path):
        from appsim.firmware import c18
        return c18.constants(path, read_firmware(path))
    return list(_assignments(_parse(path, read_firmware(path))))


def read_firmware(path: Path) -> bytes:
    """The bytes of the firmware file at `path`, or a FirmwareError that says what is there instead."""
    if path.is_dir():
        raise FirmwareError(f"{path} is a folder, not a firmware file: give the path of a .py or .c file, such as "
                            "exercises/ex1.py")
    if not path.is_file():
        what = f"{path} is not a regular file" if path.exists() else f"there is no firmware file at {path}"
        near = _near(path)
        raise FirmwareError(f"{what}: " + (f"did you mean {path.parent / near}?" if near else
                                           "give the path of a .py or .c file such as exercises/ex1.py"))
    try:
        return path.read_bytes()
    except OSError as error:
        raise FirmwareError(f"{path} cannot be read: {error.strerror}") from None


def _near(path: Path) -> str | None:
    """The name of a file beside `path` that is most likely what a typo meant (my_exl.py: my_ex1.py), if any."""
    try:
        names = [entry.name for entry in path.parent.iterdir() if entry.suffix == path.suffix and entry.is_file()]
    except OSError:
        return None
    return next(iter(difflib.get_close_matches(path.name, names, n=1, cutoff=0.8)), None)


def _parse(path: Path, source: bytes) -> ast.Module:
    try:
        return ast.parse(source.decode("utf-8-sig"), filename=str(path))     # Notepad's UTF-8 starts with a BOM
    except UnicodeDecodeError as error:
        if source.startswith((b"\xff\xfe", b"\xfe\xff")):
            raise FirmwareError(f"{path.name} is saved as UTF-16 (Unicode): save it as UTF-8, as every Python editor "
                                "does by default") from None
        raise FirmwareError(f"{path.name} is not UTF-8 text (byte {error.start} is 0x{source[error.start]:02X}): "
                            "save it as UTF-8, as every Python editor does by default") from None
    except SyntaxError as error:
        raise _syntax_error(path, error) from None
    except (ValueError, RecursionError, MemoryError) as error:    # NUL bytes; nesting too deep for the parser
        raise FirmwareError(f"{path.name} cannot be parsed as Python ({type(error).__name__}: {error})") from None


def _syntax_error(path: Path, error: SyntaxError) -> FirmwareError:
    """The error's line quoted as a load error's is, with a caret under where Python stopped reading."""
    line = (error.text or "").splitlines()[0].rstrip() if (error.text or "").strip() else ""
    quoted = ""
    if line:
        indent = len(line) - len(line.lstrip())
        caret = min(max((error.offset or 1) - 1, indent), len(line))
        quoted = f"\n(line {error.lineno}: {line.strip()})\n{' ' * (len(f'(line {error.lineno}: ') + caret - indent)}^"
    return FirmwareError(f"{path.name}, line {error.lineno}: {error.msg}: fix the Python syntax there{quoted}")


def _assignments(tree: ast.Module) -> dict[str, list[ast.Assign | ast.AnnAssign]]:
    assigned: dict[str, list[ast.Assign | ast.AnnAssign]] = {}
    for statement in tree.body:
        if isinstance(statement, ast.Assign) and len(statement.targets) == 1:
            target = statement.targets[0]
        elif isinstance(statement, ast.AnnAssign) and statement.value is not None:
            target = statement.target
        else:
            continue
        if isinstance(target, ast.Name):
            assigned.setdefault(target.id, []).append(statement)
    return assigned


def _apply_defines(tree: ast.Module, defines: Mapping[str, int], path: Path) -> None:
    """Replace the value of each top-level `NAME = <expr>` named in `defines` (in place)."""
    assigned = _assignments(tree)
    for name, value in defines.items():
        if name not in assigned:
            raise FirmwareError(
                f"-D {name}: {path} has no top-level assignment `{name} = ...` to replace. It defines "
                f"{', '.join(assigned) or 'no constants'}; a define replaces one of those, as the C18 "
                "command line's -D replaces a #define.")
        if not isinstance(value, int) or isinstance(value, bool):
            raise FirmwareError(f"-D {name}={value!r}: a define is an integer, such as {name}=0x110")
        for statement in assigned[name]:
            statement.value = ast.copy_location(ast.Constant(value), statement)


def crash_message(error: BaseException, filename: str | None) -> str:
    """What a student reads when main() raised `error`: the line of their own file it came from, the error as
    Python words it (with its "Did you mean ...?") or, for a frame's data read past its DLC, as the workshop would,
    and what that means for the board."""
    report = traceback.TracebackException.from_exception(error, limit=-TRACEBACK_FRAMES)
    mine = [frame for frame in report.stack if filename is not None and frame.filename == filename]
    place = (f" at line {mine[-1].lineno} of {Path(mine[-1].filename).name} (`{mine[-1].line}`)" if mine else "")
    what = _in_c_words(error, filename) or _past_the_data(error, filename) or _as_python_words_it(error, report)
    who = _crashed_in(error, filename)
    message = f"{who} crashed{place}: {what}\nThe board stopped there: nothing after that line ran."
    return in_c18_words(message) if _is_c_file(filename) else message


def _crashed_in(error: BaseException, filename: str | None) -> str:
    """main(), or the interrupt routine the error came from (innermost: a routine may interrupt main's calls)."""
    frames = []
    tb = error.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    for frame in reversed(frames):
        function = frame.f_globals.get(frame.f_code.co_name) if frame.f_code.co_filename == filename else None
        vector = getattr(function, MARK, None) if getattr(function, "__code__", None) is frame.f_code else None
        if vector in VECTOR_NAMES:
            return f"{frame.f_code.co_name}(), {VECTOR_NAMES[vector]},"
    return "main()"


def _as_python_words_it(error: BaseException, report: traceback.TracebackException) -> str:
    """The error's last line as Python prints it, "Did you mean: 'CANSetFilter'?" included. Before 3.12 only the
    interpreter's own report makes that suggestion (the traceback module does not), so it is taken from there."""
    what = list(report.format_exception_only())[-1].strip()
    if sys.version_info < (3, 12) and isinstance(error, (NameError, AttributeError)):
        printed = io.StringIO()
        with contextlib.redirect_stderr(printed):
            sys.__excepthook__(type(error), error, error.__traceback__)
        _, found, suggestion = printed.getvalue().rstrip().rpartition(". Did you mean: ")
        if found and "\n" not in suggestion:
            what += f". Did you mean: {suggestion}"
    return what


def _in_c_words(error: BaseException, filename: str | None) -> str | None:
    """For firmware translated from C, what went wrong as C would say it."""
    if not _is_c_file(filename):
        return None
    from appsim.firmware import c18
    return c18.describe(error)


def _is_c_file(filename: str | None) -> bool:
    """Whether `filename`'s code was translated from C (only once the translator has been loaded can it be)."""
    if "appsim.firmware.c18" not in sys.modules:
        return False
    from appsim.firmware import c18
    return c18.is_c_file(filename)


_SUBSCRIPT = re.compile(r"\b([A-Za-z_]\w*)\[\s*(-?\w+)\s*\]")      # RxData[3], RxData[i]


def _past_the_data(error: BaseException, filename: str | None) -> str | None:
    """For an IndexError from reading a received frame's data (CANReceiveMessage's bytes, DataLen of them) past its
    end, on a line of the student's file: that, in the workshop's words. Nothing is evaluated: names are looked up."""
    if not isinstance(error, IndexError) or filename is None or error.__traceback__ is None:
        return None
    innermost = error.__traceback__
    while innermost.tb_next is not None:
        innermost = innermost.tb_next
    frame = innermost.tb_frame
    if frame.f_code.co_filename != filename:
        return None
    for match in _SUBSCRIPT.finditer(linecache.getline(filename, innermost.tb_lineno)):
        name, index = match.groups()
        data = frame.f_locals.get(name, frame.f_globals.get(name))
        number = _integer(index, frame.f_locals.get(index, frame.f_globals.get(index)))
        if isinstance(data, bytes) and len(data) <= 8 and number is not None and not -len(data) <= number < len(data):
            return (f"IndexError: the frame had {len(data)} data byte{'' if len(data) == 1 else 's'}; "
                    f"check DataLen before reading {name}[{index}]")
    return None


def _integer(text: str, value: object) -> int | None:
    """The index `text` as a number: a literal (3, 0x03), else the integer the name holds."""
    try:
        return int(text, 0)
    except ValueError:
        return value if isinstance(value, int) and not isinstance(value, bool) else None
