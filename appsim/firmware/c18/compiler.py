"""C18's C (pycparser's tree of one file) translated into a Python module (an `ast.Module`), every node at the line
and column of the .c file: the same board, checks and grader run it as they run Python firmware.

Cycles are spent where the Python firmware spends them, and nowhere else: at a register access (SFR, NAMEbits) and
at a call of the board's libraries. Computation is free, as in the Python firmware. What the kit cannot run as C18
would (inline assembly, goto, function pointers, floating point, unions) is refused with its line, never guessed at.
"""
from __future__ import annotations

import ast
import copy
import itertools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from pycparser import c_ast

from appsim.chip.sfr import ADDRESSES, BITFIELDS, HIGH_VECTOR, LOW_VECTOR
from appsim.errors import CCompileError
from appsim.firmware.c18 import ctypes18 as T
from appsim.firmware.c18.ctypes18 import Array, CType, Function, Int, Member, Pointer, Struct, Void
from appsim.firmware.c18.library import BINDINGS, RESULTS
from appsim.firmware.c18.runtime import MAX_SHIFT

RT, MCU, LIB = "__rt", "__M", "__lib_"      # the runtime module, the board's MCU, the library functions
# The library functions the translation calls by their own name: the loader knows the kit's Nop by its name (an empty
# waiting loop's body, appsim.firmware.loader.waits_for_interrupts), so `while (!flag) Nop();` is `Nop()` there too.
OWN_NAMES = frozenset({"Nop"})
GOTO = "__c18_goto"                 # `_asm GOTO high_isr _endasm`, the one inline assembly the kit takes, as parsed
# The decorators `#pragma interrupt NAME` and `#pragma interruptlow NAME` put on NAME (appsim.firmware.interrupts)
ROUTINE_MARKS = {HIGH_VECTOR: "__c18_interrupt", LOW_VECTOR: "__c18_interruptlow"}
PRAGMAS = {HIGH_VECTOR: "interrupt", LOW_VECTOR: "interruptlow"}
VECTOR_SECTIONS = {HIGH_VECTOR: "high_vector", LOW_VECTOR: "low_vector"}
MAX_STATEMENTS = 20_000             # statements in one file
MAX_LOOP_NESTING = 18               # Python allows 20 nested blocks; the translation adds one for a switch


_PLACED = (ast.expr, ast.stmt, ast.excepthandler, ast.arg, ast.keyword)
_LEAVES = (ast.expr_context, ast.operator, ast.unaryop, ast.boolop, ast.cmpop)   # nodes with no children, no place


class _Refused(Exception):
    """Raised inside the translator; turned into a CCompileError at the C node."""

    def __init__(self, node: Any, message: str):
        super().__init__(message)
        self.node = node


@dataclass
class Sym:
    """A name in scope: what it is (`var`, `func`, `lib`, `sfr`, `bits`, `enum`, `typedef`), its C type and how the
    Python code reaches it."""

    name: str
    kind: str
    ctype: CType
    py: str = ""
    boxed: bool = False         # a variable whose address is taken: a list of one
    value: int = 0              # an enumerator's value; an SFR's address
    defined: bool = False       # a function with a body
    is_global: bool = False


@dataclass
class E:
    """A C expression translated: its Python expression, its C type, the interval its value lies in (integers), its
    value if it is an integer constant, and whether it denotes an array object to be indexed in place."""

    py: ast.expr
    t: CType
    lo: int | None = None
    hi: int | None = None
    const: int | None = None
    literal: str | None = None      # a string literal's text
    name: str = ""                  # what to call it in messages


@dataclass
class _Loop:
    kind: str                       # "loop" or "switch"
    step: list[ast.stmt] = field(default_factory=list)
    flag: str = ""                  # switch: set when a continue leaves it; do-while: first pass
    used: bool = False


class Translator:
    """One translation: a file's tree into a module's statements, with the kit headers' declarations in scope."""

    def __init__(self, filename: str, lines: Sequence[str], options: Sequence[str], deadline: float):
        self.filename = filename
        self.lines = lines
        self.promote = "-Oi" in options
        self.unsigned_char = "-k" in options
        self.deadline = deadline
        self.scopes: list[dict[str, Sym]] = [{}]
        self.tags: list[dict[str, Struct]] = [{}]
        self.module: list[ast.stmt] = []
        self.startup: list[ast.stmt] = []
        self.globals: set[str] = set()
        self.constants: dict[str, Any] = {}     # module constants: strings, switch tables
        self.loops: list[_Loop] = []
        self.temps = 0
        self.statements = 0
        self.function: Sym | None = None
        self.locals_used: set[str] = set()
        self.addressed: set[str] = set()
        self.struct_keys = 0
        self.main_seen = False
        self.called: set[str] = set()
        self.struct_nodes: dict[int, Struct] = {}
        self.line_ends: dict[int, int] = {}                 # line -> its length in UTF-8 bytes (a node's end)
        self.section: int | None = None                     # the interrupt vector `#pragma code NAME=0x08` places at
        self.marked: dict[str, tuple[int, Any]] = {}        # `#pragma interrupt[low] NAME`: NAME -> (vector, pragma)
        self.vectors: dict[int, tuple[str, Any]] = {}       # vector -> the routine there (a GOTO to it, or itself)
        self.functions: dict[str, ast.FunctionDef] = {}     # the file's functions, by C name

    # ================================================================== errors and locations
    def refuse(self, node: Any, message: str) -> _Refused:
        return _Refused(node, message)

    def error_at(self, node: Any, message: str) -> CCompileError:
        coord = getattr(node, "coord", None)
        line = getattr(coord, "line", 0) or 0
        column = getattr(coord, "column", 0) or 0
        if coord is not None and coord.file and coord.file != self.filename:
            return CCompileError(f"{message} (in the kit's header {coord.file}, line {line})", self.filename, 0, 0)
        return CCompileError(message, self.filename, line, column)

    def at(self, node: Any, py: Any) -> Any:
        """`py` (a Python node or a list of them) placed at the C node's line and column."""
        coord = getattr(node, "coord", None)
        line = getattr(coord, "line", None) or 1
        column = max((getattr(coord, "column", None) or 1) - 1, 0)
        if coord is not None and coord.file and coord.file != self.filename:
            line, column = 1, 0
        end = self.line_ends.get(line)
        if end is None:
            text = self.lines[line - 1] if 0 < line <= len(self.lines) else ""
            end = self.line_ends[line] = len(text.encode("utf-8"))
        end = max(end, column + 1)
        stack = list(py) if isinstance(py, list) else [py]
        while stack:                    # a node placed before was placed with everything below it: not again
            sub = stack.pop()
            if isinstance(sub, _PLACED):
                if getattr(sub, "lineno", None) is not None:
                    continue
                sub.lineno, sub.col_offset = line, column
                sub.end_lineno, sub.end_col_offset = line, end
            _push_children(sub, stack)
        return py

    def tick(self, node: Any) -> None:
        self.statements += 1
        if self.statements > MAX_STATEMENTS:
            raise self.refuse(node, f"the file has more than {MAX_STATEMENTS:,} statements: a firmware is a few "
                                    "hundred")
        if self.statements % 256 == 0 and time.process_time() > self.deadline:
            raise self.refuse(node, "the translation ran out of its time")

    def temp(self, stem: str = "t") -> str:
        self.temps += 1
        return f"__{stem}{self.temps}"

    # ================================================================== scopes
    def lookup(self, name: str) -> Sym | None:
        for scope in reversed(self.scopes):
            if name in scope:
                return scope[name]
        return None

    def declare(self, sym: Sym, node: Any) -> Sym:
        scope = self.scopes[-1]
        old = scope.get(sym.name)
        if old is not None:
            same_kind = old.kind == sym.kind and old.ctype.unqualified() == sym.ctype.unqualified()
            if old.kind in ("func", "lib") and sym.kind in ("func", "lib") and same_kind:
                if sym.defined:
                    if old.defined:
                        raise self.refuse(node, f"{sym.name}() is defined twice")
                    old.defined, old.kind, old.py = True, "func", sym.py
                return old
            if old.kind == "var" and sym.kind == "var" and len(self.scopes) == 1 and same_kind:
                return old          # a global declared again (extern, then defined)
            raise self.refuse(node, f"{sym.name} is declared twice in one scope (first as {self.what(old)})")
        scope[sym.name] = sym
        return sym

    def what(self, sym: Sym) -> str:
        return {"func": "a function", "lib": "a library function", "sfr": "a register", "bits": "a register's bits",
                "enum": "an enumeration constant", "typedef": "a type name",
                "vector": "C18's interrupt vector (a GOTO the core jumps to; nothing calls it)"}.get(
                    sym.kind, sym.ctype.spelled())

    def py_name(self, name: str) -> str:
        """The Python name of a C identifier: itself, unless Python or the translation uses it (a C name with two
        leading underscores is the implementation's, in C as here). A function's parameter or local gets a name of its
        own, apart from the function's other locals and from the globals: in C it hides a global of its name, where
        one Python name would be the global (the function declares every global it assigns `global`)."""
        base = name if name not in _PY_RESERVED and not name.startswith("__") else f"{name}_"
        if self.function is None:
            return base
        candidate, n = base, 1
        while candidate in self.locals_used or candidate in self.globals:
            n += 1
            candidate = f"{base}__{n}"
        self.locals_used.add(candidate)
        return candidate

    # ================================================================== types
    def type_of(self, node: Any, quals: Sequence[str] = ()) -> CType:
        """The C type a declarator tree names."""
        if isinstance(node, c_ast.TypeDecl):
            return self.qualify(self.base_type(node.type, node), list(node.quals) + list(quals), node)
        if isinstance(node, c_ast.PtrDecl):
            target = self.type_of(node.type)
            if isinstance(target, Function):
                raise self.refuse(node, "function pointers are not supported by the kit's C: call the function by "
                                        "name (a switch on a number chooses between functions)")
            return self.qualify(Pointer(target=target), list(node.quals), node)
        if isinstance(node, c_ast.ArrayDecl):
            element = self.type_of(node.type)
            length = None
            if node.dim is not None:
                dim = self.constant(node.dim, "an array's size")
                if dim <= 0:
                    raise self.refuse(node.dim, f"an array's size must be at least 1 (here {dim})")
                if dim * max(self._size(element, node), 1) > 4096:
                    raise self.refuse(node.dim, f"an array of {dim} elements does not fit the PIC18F8680's 3,328 "
                                                "bytes of RAM")
                length = dim
            if isinstance(element, Array) and element.length is None:
                raise self.refuse(node, "an array of arrays needs the size of the inner one")
            return Array(element=element, length=length, rom=element.rom, const=element.const)
        if isinstance(node, c_ast.FuncDecl):
            result = self.type_of(node.type)
            params, names, variadic = [], [], False
            for param in (node.args.params if node.args else []):
                if isinstance(param, c_ast.EllipsisParam):
                    variadic = True
                    continue
                if isinstance(param, c_ast.ID):
                    raise self.refuse(param, "old-style (K&R) parameters: give each parameter its type")
                ptype = self.type_of(param.type)
                if isinstance(ptype, Void) and not isinstance(param.type, c_ast.PtrDecl):
                    if getattr(param, "name", None) or len(node.args.params) > 1:
                        raise self.refuse(param, "a parameter cannot be void: (void) alone says a function takes "
                                                 "no arguments")
                    continue
                if isinstance(ptype, Array):
                    ptype = Pointer(target=ptype.element)
                params.append(ptype)
                names.append(getattr(param, "name", None) or "")
            if isinstance(result, Array):
                raise self.refuse(node, "a function cannot return an array")
            return Function(result=result, params=tuple(params), names=tuple(names), variadic=variadic)
        if isinstance(node, c_ast.Typename):
            return self.type_of(node.type, node.quals)
        raise self.refuse(node, f"this declaration ({type(node).__name__}) is not supported by the kit's C")

    def _size(self, t: CType, node: Any) -> int:
        try:
            return t.size
        except ValueError as error:
            raise self.refuse(node, str(error)) from None

    def qualify(self, t: CType, quals: Sequence[str], node: Any) -> CType:
        if "restrict" in quals or "_Atomic" in quals:
            raise self.refuse(node, f"'{'restrict' if 'restrict' in quals else '_Atomic'}' is not C18's")
        return t.qualified(const="const" in quals, volatile="volatile" in quals, rom="rom" in quals)

    def base_type(self, node: Any, decl: Any) -> CType:
        if isinstance(node, c_ast.IdentifierType):
            words = list(node.names)
            if words == ["void"]:
                return T.VOID
            if any(word in ("float", "double") for word in words):
                raise self.refuse(node, "floating point (float, double) is not supported by the kit's C yet: "
                                        "C18's sprintf has no %f either; compute in integers (millivolts, tenths)")
            if len(words) == 1 and words[0] not in ("char", "int", "short", "long", "signed", "unsigned"):
                sym = self.lookup(words[0])
                if sym is None or sym.kind != "typedef":
                    raise self.refuse(node, f"{words[0]} is not a type")
                return sym.ctype
            found = T.integer_type(words, self.unsigned_char)
            if found is None:
                raise self.refuse(node, f"'{' '.join(words)}' is not a C18 type (char, int, short long, long, each "
                                        "signed or unsigned)")
            return found
        if isinstance(node, c_ast.Struct):
            return self.struct_type(node)
        if isinstance(node, c_ast.Union):
            raise self.refuse(node, "unions are not supported by the kit's C (except the registers' NAMEbits of "
                                    "p18f8680.h): use a struct, or shifts and masks")
        if isinstance(node, c_ast.Enum):
            return self.enum_type(node)
        raise self.refuse(node, f"this type ({type(node).__name__}) is not supported by the kit's C")

    def struct_type(self, node: c_ast.Struct) -> Struct:
        tag = node.name or ""
        known = self.struct_nodes.get(id(node))
        if known is not None:
            return known                # one definition declaring several names: pycparser shares its node
        if node.decls is None:
            for scope in reversed(self.tags):
                if tag in scope:
                    return scope[tag]
            self.struct_keys += 1
            incomplete = Struct(tag=tag, key=self.struct_keys)
            self.tags[-1][tag] = incomplete
            return incomplete
        if not node.decls:
            raise self.refuse(node, f"struct {tag or '{ }'} has no members: C requires at least one")
        members: list[Member] = []
        for decl in node.decls:
            mtype = self.type_of(decl.type)
            width = None
            if decl.bitsize is not None:
                width = self.constant(decl.bitsize, "a bit-field's width")
                if not isinstance(mtype, Int) or not 0 <= width <= 8 * mtype.size:
                    raise self.refuse(decl, "a bit-field is an integer of at most its type's bits")
                mtype = replace(mtype, width=width) if width else mtype
            if decl.name is None:
                if width is None:
                    raise self.refuse(decl, "anonymous struct members are not supported by the kit's C")
                members.append(Member("", mtype, width))
                continue
            if width == 0:
                raise self.refuse(decl, f"{decl.name} is a bit-field of width 0: C lets only an unnamed one be 0 "
                                        "bits wide (`unsigned : 0;`, which starts the next byte)")
            if isinstance(mtype, Struct) and mtype.members is None:
                raise self.refuse(decl, f"struct {mtype.tag} is used before it is complete")
            if any(m.name == decl.name for m in members):
                raise self.refuse(decl, f"struct {tag} has two members named {decl.name}")
            members.append(Member(decl.name, mtype, width))
        existing = self.tags[-1].get(tag) if tag else None
        if existing is not None and existing.members is not None:
            raise self.refuse(node, f"struct {tag} is defined twice")
        key = existing.key if existing is not None else self._new_key()
        struct = Struct(tag=tag, members=tuple(members), key=key)
        if tag:
            self.tags[-1][tag] = struct
        self.struct_nodes[id(node)] = struct
        return struct

    def completed(self, ctype: CType) -> CType:
        """A struct as it is now: one a pointer inside its own definition named while it was incomplete
        (`struct node { struct node *next; }`) has its members once that definition ends."""
        if isinstance(ctype, Struct) and ctype.members is None and ctype.tag:
            for scope in reversed(self.tags):
                found = scope.get(ctype.tag)
                if found is not None and found.key == ctype.key and found.members is not None:
                    return found
        return ctype

    def _new_key(self) -> int:
        self.struct_keys += 1
        return self.struct_keys

    def enum_type(self, node: c_ast.Enum) -> Int:
        """An enumeration's type: the smallest of char, unsigned char, int, unsigned int that holds every value of
        it (an `enum CAN_RX_MSG_FLAGS` is one byte, as a BYTE is); its enumerators are int constants."""
        key = f"enum {node.name}" if node.name else ""
        if node.values is None:
            known = self.lookup(key) if key else None
            if known is None:
                raise self.refuse(node, f"enum {node.name} is not declared (its values come first)")
            assert isinstance(known.ctype, Int)
            return known.ctype
        value, values = 0, []
        for item in node.values.enumerators:
            if item.value is not None:
                value = self.constant(item.value, "an enumeration value")
            if not T.INT.low <= value <= T.UINT.high:
                raise self.refuse(item, f"{item.name} = {value} does not fit an int (C18's enumerations)")
            self.declare(Sym(item.name, "enum", T.INT, value=value), item)
            values.append(value)
            value += 1
        low, high = min(values, default=0), max(values, default=0)
        ctype = next(t for t in (T.CHAR, T.UCHAR, T.INT, T.UINT) if t.low <= low and high <= t.high)
        ctype = replace(ctype, name=f"enum {node.name}" if node.name else "enum")
        if key:
            self.declare(Sym(key, "enumtag", ctype), node)
        return ctype

    # ================================================================== constants
    def constant(self, node: Any, what: str) -> int:
        e = self.rvalue(node)
        if e.const is None:
            raise self.refuse(node, f"{what} must be an integer constant (a number, a #define, an enumerator)")
        return e.const

    # ================================================================== the file
    def translation_unit(self, tree: c_ast.FileAST) -> None:
        self.addressed = _addressed(tree)
        for ext in tree.ext:
            try:
                if isinstance(ext, c_ast.FuncDef):
                    self.function_definition(ext)
                elif isinstance(ext, c_ast.Decl):
                    self.global_declaration(ext)
                elif isinstance(ext, c_ast.Typedef):
                    self.typedef(ext)
                elif isinstance(ext, c_ast.Pragma):
                    self.pragma(ext)
                elif isinstance(ext, c_ast.StaticAssert):
                    raise self.refuse(ext, "_Static_assert is not C18's")
                else:
                    raise self.refuse(ext, f"{type(ext).__name__} at file level is not supported by the kit's C")
            except _Refused as refused:
                raise self.error_at(refused.node, str(refused)) from None
            except RecursionError:
                raise self.error_at(ext, "this is nested too deep for the kit's C: simplify the expression or "
                                         "split the function") from None
        try:
            self.interrupt_routines()
        except _Refused as refused:
            raise self.error_at(refused.node, str(refused)) from None
        for scope in self.scopes[:1]:
            for sym in scope.values():
                if sym.kind == "func" and not sym.defined and sym.name in self.called:
                    raise CCompileError(f"{sym.name}() is declared but never defined: the linker would stop "
                                        "here (write its body, or call a library function)", self.filename)

    def pragma(self, node: c_ast.Pragma, in_function: bool = False) -> None:
        text = (node.string or "").strip()
        words = text.replace("=", " = ").split()
        head = words[0] if words else ""
        if head in PRAGMAS.values() or (head == "code" and "=" in words):
            if in_function:
                raise self.refuse(node, f"#pragma {head} belongs at the top level of the file, outside any function")
            if head == "code":
                self.code_section(node, words)
            else:
                self.interrupt_pragma(node, head, words[1:])
            return
        if head == "code":
            self.section = None         # `#pragma code` alone: back to the default section
            return
        if head in ("config", "udata", "idata", "romdata", "varlocate", "tmpdata", "once"):
            return                      # configuration bits and sections: no effect on the simulated board
        raise self.refuse(node, f"#pragma {head} is not one C18 knows (config, code, romdata, udata, idata, interrupt, "
                                "interruptlow)")

    def code_section(self, node: c_ast.Pragma, words: list[str]) -> None:
        """`#pragma code NAME=ADDRESS`: the code after it goes at ADDRESS. At 0x08 or 0x18, an interrupt vector."""
        at = words.index("=")
        try:
            address = int(" ".join(words[at + 1:at + 2]).rstrip("hH"), 0)
        except ValueError:
            raise self.refuse(node, f"#pragma {node.string.strip()}: the address after = is a number, such as "
                                    "high_vector=0x08") from None
        self.section = address if address in PRAGMAS else None     # elsewhere: placing code changes nothing here

    def interrupt_pragma(self, node: c_ast.Pragma, head: str, words: list[str]) -> None:
        """`#pragma interrupt NAME [section] [save=...] [nosave=...]` (or interruptlow): NAME is a routine. What C18
        saves beyond its own context does not matter to the kit: the routine runs in the firmware's own Python."""
        vector = HIGH_VECTOR if head == "interrupt" else LOW_VECTOR
        if not words or not words[0].isidentifier():
            raise self.refuse(node, f"#pragma {head} names the routine: #pragma {head} "
                                    f"{'high_isr' if vector == HIGH_VECTOR else 'low_isr'}")
        name = words[0]
        before = self.marked.get(name)
        if before is not None and before[0] != vector:
            raise self.refuse(node, f"{name} is named by both #pragma interrupt and #pragma interruptlow: a routine "
                                    "has one priority (one vector, 0x08 or 0x18)")
        if name in self.functions and before is None:
            raise self.refuse(node, f"#pragma {head} {name} comes after {name}'s definition: C18 reads the pragma "
                                    f"first, so write it above void {name}(void)")
        self.marked[name] = (vector, node)

    def typedef(self, node: c_ast.Typedef) -> None:
        ctype = self.type_of(node.type)
        self.declare(Sym(node.name, "typedef", ctype), node)

    def global_declaration(self, decl: c_ast.Decl) -> None:
        self.tick(decl)
        if decl.name is None:           # struct or enum declared alone
            self.type_of(decl.type) if not isinstance(decl.type, (c_ast.Struct, c_ast.Enum)) else \
                self.base_type(decl.type, decl)
            return
        if "register" in decl.storage or "auto" in decl.storage:
            raise self.refuse(decl, f"'{decl.storage[0]}' is for variables inside a function")
        ctype = self.type_of(decl.type, decl.quals)
        if isinstance(ctype, Function):
            self.declare(Sym(decl.name, "func", ctype, py=self.py_name(decl.name)), decl)
            return
        if isinstance(ctype, Void):
            raise self.refuse(decl, f"{decl.name} cannot be void")
        if "extern" in decl.storage and decl.init is None:
            raise self.refuse(decl, f"extern {decl.name}: a firmware is one .c file, and the kit's headers declare "
                                    "no such variable")
        if isinstance(ctype, Array) and ctype.length is None:
            ctype = self.sized_by_initialiser(ctype, decl)
        self._size(ctype, decl)
        sym = self.declare(Sym(decl.name, "var", ctype, py=self.py_name(decl.name),
                               boxed=decl.name in self.addressed and not isinstance(ctype, Array), is_global=True),
                           decl)
        self.globals.add(sym.py)
        value = self.initialiser(ctype, decl.init, decl) if decl.init is not None else self.zero(ctype)
        if decl.init is not None and self._non_constant(decl.init):
            raise self.refuse(decl.init, f"{decl.name} is a global: its initial value must be a constant (C "
                                         "initialises globals before main() runs)")
        self.startup.append(self.at(decl, ast.Assign([_name(sym.py, True)], self.boxed(sym, value))))

    def _non_constant(self, init: Any) -> bool:
        """Whether an initial value needs the program running: a call, a variable's or a register's value (an
        array's or a variable's address is a constant, as in C)."""
        stack = [init]
        while stack:
            node = stack.pop()
            if isinstance(node, c_ast.UnaryOp) and node.op == "&":
                continue
            if isinstance(node, c_ast.FuncCall):
                return True
            if isinstance(node, c_ast.ID):
                sym = self.lookup(node.name)
                if sym is not None and (sym.kind in ("sfr", "bits") or sym.kind == "var"
                                        and not isinstance(sym.ctype, Array)):
                    return True
            stack.extend(child for _, child in node.children())
        return False

    def boxed(self, sym: Sym, value: ast.expr) -> ast.expr:
        return ast.List([value], ast.Load()) if sym.boxed else value

    def sized_by_initialiser(self, ctype: Array, decl: Any) -> Array:
        init = decl.init
        if isinstance(init, c_ast.InitList):
            if isinstance(ctype.element, (Array, Struct)):      # its values may leave the inner braces out
                counted, _ = self.braced(ctype, init.exprs, 0, decl)
                assert isinstance(counted, (ast.List, ast.Tuple))
                return replace(ctype, length=max(1, len(counted.elts)))
            return replace(ctype, length=max(1, len(init.exprs)))
        if isinstance(init, c_ast.Constant) and init.type == "string":
            return replace(ctype, length=len(_string_codes(init.value, self, init)) + 1)
        raise self.refuse(decl, f"{decl.name}[] needs a size or an initialiser that gives one")

    # ================================================================== values of types
    def zero(self, t: CType) -> ast.expr:
        if isinstance(t, Int):
            return ast.Constant(0)
        if isinstance(t, Pointer):
            return ast.Constant(None)
        if isinstance(t, Array):
            assert t.length is not None
            if isinstance(t.element, (Int, Pointer)):
                return ast.BinOp(ast.List([self.zero(t.element)], ast.Load()), ast.Mult(), ast.Constant(t.length))
            return ast.ListComp(self.zero(t.element), [ast.comprehension(
                _name("__", True), _call(_name("range"), [ast.Constant(t.length)]), [], 0)])
        if isinstance(t, Struct):
            if t.members is None:
                raise _Refused(None, f"struct {t.tag} is incomplete")
            return ast.List([self.zero(m.ctype) for m in t.members], ast.Load())
        raise _Refused(None, f"no value of type {t.spelled()}")

    def initialiser(self, t: CType, init: Any, decl: Any) -> ast.expr:
        if isinstance(t, Array):
            assert t.length is not None
            if isinstance(init, c_ast.Constant) and init.type == "string" and isinstance(t.element, Int) \
                    and t.element.size == 1:
                codes = _string_codes(init.value, self, init)
                if len(codes) > t.length:
                    raise self.refuse(init, f"the string has {len(codes)} characters; the array holds {t.length}")
                codes += [0] * (t.length - len(codes))
                values = [c - 0x100 if t.element.signed and c >= 0x80 else c for c in codes]
                return ast.Tuple([ast.Constant(v) for v in values], ast.Load()) if t.rom else \
                    ast.List([ast.Constant(v) for v in values], ast.Load())
            if not isinstance(init, c_ast.InitList):
                raise self.refuse(init, "an array is initialised with { ... }")
            py, used = self.braced(t, init.exprs, 0, decl)
            if used < len(init.exprs):
                raise self.refuse(init, f"{len(init.exprs)} initial values for an array of {t.length}" if
                                  used == t.length else f"{len(init.exprs)} initial values for {t.spelled()}, "
                                                        f"which holds {used} (its inner braces left out)")
            return py
        if isinstance(t, Struct):
            assert t.members is not None
            if not isinstance(init, c_ast.InitList):      # a copy of the struct, as `=` makes
                return _rt("copy", [self.convert(self.rvalue(init), t, init, "the initial value")])
            py, used = self.braced(t, init.exprs, 0, decl)
            if used < len(init.exprs):
                raise self.refuse(init, f"{len(init.exprs)} initial values for struct {t.tag}'s "
                                        f"{len(t.members)} members" + ("" if used == len(t.members) else
                                                                       f", which hold {used} (inner braces left out)"))
            return py
        if isinstance(init, c_ast.InitList):
            if len(init.exprs) != 1:
                raise self.refuse(init, "a single value is initialised with one value")
            init = init.exprs[0]
        return self.convert(self.rvalue(init), t, init, "the initial value")

    def braced(self, t: Array | Struct, exprs: list[Any], at: int, decl: Any) -> tuple[ast.expr, int]:
        """The array or struct `t` from the values `exprs[at:]` of one pair of braces, and where they stop: an
        element or member that is an array or struct itself takes a { ... } of its own, or, with the braces left out
        (`int m[2][2] = {1, 2, 3, 4};`), as many of these values as it has scalars (C99 6.7.8)."""
        if isinstance(t, Array):          # (of no length yet: as many elements as the values make)
            parts = [t.element] * t.length if t.length is not None else [t.element] * len(exprs)
        else:
            assert t.members is not None
            parts = [m.ctype for m in t.members]
        items: list[ast.expr] = []
        for part in parts:
            if at == len(exprs):
                if isinstance(t, Array) and t.length is None:
                    break
                items.append(self.zero(part))
                continue
            value = exprs[at]
            if isinstance(part, (Array, Struct)) and not isinstance(value, c_ast.InitList) \
                    and self._scalar_value(value, part):
                item, at = self.braced(part, exprs, at, decl)
            else:
                item, at = self.initialiser(part, value, decl), at + 1
            items.append(item)
        rom = isinstance(t, Array) and t.rom
        return (ast.Tuple(items, ast.Load()) if rom else ast.List(items, ast.Load())), at

    def _scalar_value(self, node: Any, aggregate: CType) -> bool:
        """Whether `node` cannot initialise `aggregate` whole, as a scalar's value cannot (a string can a char array,
        a struct-valued expression a struct: any expression the kit cannot tell without translating it can)."""
        if isinstance(node, c_ast.Constant):        # a string initialises a char array whole, or its first one's
            return node.type != "string" or not (isinstance(aggregate, Array) and isinstance(aggregate.element, Int)
                                                 and aggregate.element.size == 1)
        if isinstance(node, c_ast.UnaryOp):
            return node.op in ("-", "+", "~", "!", "sizeof")
        if isinstance(node, (c_ast.BinaryOp, c_ast.Cast, c_ast.TernaryOp)):
            return True
        if isinstance(node, c_ast.ID):
            sym = self.lookup(node.name)
            return sym is not None and not isinstance(sym.ctype, (Array, Struct))
        return False

    # ================================================================== functions
    def function_definition(self, node: c_ast.FuncDef) -> None:
        decl = node.decl
        ftype = self.type_of(decl.type, decl.quals)
        assert isinstance(ftype, Function)
        name = decl.name
        if node.param_decls:
            raise self.refuse(node, "old-style (K&R) parameter declarations: give each parameter its type")
        if self.section is not None and self.vector_stub(node, ftype):
            return
        if name == "main":
            self.main_seen = True
            if ftype.params:
                raise self.refuse(decl, "main takes no arguments on the PIC18: void main(void)")
        py = "__c_main" if name == "main" else self.py_name(name)
        sym = self.declare(Sym(name, "func", ftype, py=py, defined=True), decl)
        if sym.py != py:
            sym.py = py
        self.function = sym
        self.locals_used = set()
        self.scopes.append({})
        self.tags.append({})
        args: list[ast.arg] = []
        prologue: list[ast.stmt] = []
        params = node.decl.type.args.params if node.decl.type.args else []
        named = [p for p in params if not isinstance(p, c_ast.EllipsisParam) and getattr(p, "name", None)]
        for param, ptype in zip(named, ftype.params, strict=False):
            psym = self.declare(Sym(param.name, "var", ptype, py=self.py_name(param.name),
                                    boxed=param.name in self.addressed), param)
            if psym.boxed:
                raw = self.temp("arg")
                args.append(ast.arg(raw))
                prologue.append(self.at(param, ast.Assign([_name(psym.py, True)],
                                                          ast.List([_name(raw)], ast.Load()))))
            else:
                args.append(ast.arg(psym.py))
            if isinstance(ptype, Struct):
                prologue.append(self.at(param, ast.Assign([_name(psym.py, True)], _rt("copy", [_name(psym.py)]))))
        body = prologue + self.block(node.body.block_items or [], new_scope=False)
        if not isinstance(ftype.result, Void) and name != "main" and not (body and isinstance(body[-1], ast.Return)):
            line = getattr(node.decl.coord, "line", 0) or 0     # its end may be reached: the value it then gives
            body.append(self.at(node, ast.Return(_rt("NoValue", [ast.Constant(name), ast.Constant(line)]))))
        self.scopes.pop()
        self.tags.pop()
        self.function = None
        assigned = sorted(_stored_names(body) & self.globals)
        if assigned:
            body.insert(0, self.at(node, ast.Global(assigned)))
        if not body:
            body = [ast.Pass()]
        fn = ast.FunctionDef(py, ast.arguments([], args, None, [], [], None, []), body, [], None)
        self.functions[name] = fn
        self.module.append(self.at(decl, fn))

    # ================================================================== interrupts
    def vector_stub(self, node: c_ast.FuncDef, ftype: Function) -> bool:
        """A function in a vector's section (`#pragma code high_vector=0x08`): C18's stub `_asm GOTO high_isr _endasm`
        (True: nothing to translate), or the routine itself (False: translated as any function)."""
        vector, name = self.section, node.decl.name
        assert vector is not None
        if vector in self.vectors:
            raise self.refuse(node, f"a second function at the interrupt vector 0x{vector:02X} (after "
                                    f"{self.vectors[vector][0]}): the vector has room for one GOTO. A #pragma code "
                                    "alone ends the vector's section")
        items = node.body.block_items or []
        call = items[0] if len(items) == 1 else None
        if isinstance(call, c_ast.FuncCall) and isinstance(call.name, c_ast.ID) and call.name.name == GOTO:
            target = call.args.exprs[0] if call.args is not None and len(call.args.exprs) == 1 else None
            assert isinstance(target, c_ast.ID)
            self.vectors[vector] = (target.name, call)
            self.declare(Sym(name, "vector", ftype, defined=True), node.decl)
            return True
        if name in self.marked:
            self.vectors[vector] = (name, node)
            return False
        raise self.refuse(node, f"{name}() is at the interrupt vector 0x{vector:02X} (#pragma code "
                                f"{VECTOR_SECTIONS[vector]}=0x{vector:02X}): what lies there is C18's GOTO to the "
                                f"routine, `void {name}(void) {{ _asm GOTO {self.vector_example(vector)} _endasm }}`, "
                                f"or the routine itself, named by #pragma {PRAGMAS[vector]}")

    def vector_example(self, vector: int) -> str:
        return next((n for n, (v, _) in self.marked.items() if v == vector),
                    "high_isr" if vector == HIGH_VECTOR else "low_isr")

    def interrupt_routines(self) -> None:
        """Each vector's routine checked (named by its pragma, `void NAME(void)`, of the vector's priority), and marked
        with the decorator the Python firmware would give it; a pragma's routine that no vector reaches is refused,
        since on the chip it would never run."""
        for vector, (name, node) in sorted(self.vectors.items()):
            marked = self.marked.get(name)
            if marked is None:
                raise self.refuse(node, f"the interrupt vector 0x{vector:02X} goes to {name}, which no "
                                        f"#pragma {PRAGMAS[vector]} names: C18 would build it as an ordinary function, "
                                        "which saves nothing of what it interrupts and returns without RETFIE (GIE "
                                        f"stays cleared). Write #pragma {PRAGMAS[vector]} {name} above its definition")
            if marked[0] != vector:
                priority = "high" if vector == HIGH_VECTOR else "low"
                raise self.refuse(node, f"the interrupt vector 0x{vector:02X} goes to {name}, named by "
                                        f"#pragma {PRAGMAS[marked[0]]}: the {priority}-priority vector's routine is "
                                        f"named by #pragma {PRAGMAS[vector]}")
        for name, (vector, node) in self.marked.items():
            sym = self.scopes[0].get(name)
            function = self.functions.get(name)
            if sym is None or function is None:
                raise self.refuse(node, f"#pragma {PRAGMAS[vector]} {name}: this file defines no function {name}")
            assert isinstance(sym.ctype, Function)
            if sym.ctype.params or not isinstance(sym.ctype.result, Void):
                raise self.refuse(node, f"{name} is an interrupt routine, which the core calls with nothing and which "
                                        f"returns nothing: void {name}(void)")
            if self.vectors.get(vector, ("",))[0] != name:
                stub = f"interrupt_at_{'high' if vector == HIGH_VECTOR else 'low'}_vector"
                raise self.refuse(node, f"#pragma {PRAGMAS[vector]} {name}: nothing at the vector 0x{vector:02X} "
                                        f"jumps to {name} (C18 places the routine wherever the linker likes, and the "
                                        f"core jumps to 0x{vector:02X}), so it would never run. Put C18's vector "
                                        f"there: #pragma code {VECTOR_SECTIONS[vector]}=0x{vector:02X}, then "
                                        f"void {stub}(void) {{ _asm GOTO {name} _endasm }}, then #pragma code")
            function.decorator_list = [ast.Name(ROUTINE_MARKS[vector], ast.Load())]

    # ================================================================== statements
    def block(self, items: Sequence[Any], new_scope: bool = True) -> list[ast.stmt]:
        if new_scope:
            self.scopes.append({})
            self.tags.append({})
        out: list[ast.stmt] = []
        for item in items:
            out.extend(self.statement(item))
        if new_scope:
            self.scopes.pop()
            self.tags.pop()
        return out

    def body(self, node: Any) -> list[ast.stmt]:
        if isinstance(node, c_ast.Compound):
            stmts = self.block(node.block_items or [])
        else:
            self.scopes.append({})
            stmts = self.statement(node)
            self.scopes.pop()
        return stmts or [self.at(node, ast.Pass())]

    def statement(self, node: Any) -> list[ast.stmt]:
        self.tick(node)
        try:
            return self._statement(node)
        except _Refused:
            raise
        except RecursionError:
            raise self.refuse(node, "this statement is nested too deep for the kit's C") from None

    def _statement(self, node: Any) -> list[ast.stmt]:
        if isinstance(node, c_ast.Decl):
            return self.local_declaration(node)
        if isinstance(node, c_ast.Typedef):
            self.typedef(node)
            return []
        if isinstance(node, c_ast.Compound):
            return self.block(node.block_items or [])
        if isinstance(node, c_ast.EmptyStatement):
            return []
        if isinstance(node, c_ast.If):
            test = self.condition(node.cond)
            orelse = self.body(node.iffalse) if node.iffalse is not None else []
            return [self.at(node, ast.If(test, self.body(node.iftrue), orelse))]
        if isinstance(node, c_ast.While):
            test = self.condition(node.cond)
            with self.loop(_Loop("loop")):
                body = self.body(node.stmt)
            return [self.at(node, ast.While(test, body, []))]
        if isinstance(node, c_ast.DoWhile):
            loop = _Loop("loop", flag=self.temp("first"))
            with self.loop(loop):
                body = self.body(node.stmt)
            test = self.condition(node.cond)
            if not loop.used:
                exit_ = self.at(node.cond, ast.If(ast.UnaryOp(ast.Not(), test), [ast.Break()], []))
                return [self.at(node, ast.While(ast.Constant(True), body + [exit_], []))]
            first = loop.flag
            return self.at(node, [ast.Assign([_name(first, True)], ast.Constant(True)),
                                  ast.While(ast.BoolOp(ast.Or(), [_name(first), test]),
                                            [ast.Assign([_name(first, True)], ast.Constant(False)), *body], [])])
        if isinstance(node, c_ast.For):
            self.scopes.append({})
            init: list[ast.stmt] = []
            if isinstance(node.init, c_ast.DeclList):
                for decl in node.init.decls:
                    init.extend(self.local_declaration(decl))
            elif node.init is not None:
                init = self.expression_statement(node.init)
            test = self.condition(node.cond) if node.cond is not None else ast.Constant(True)
            step = self.expression_statement(node.next) if node.next is not None else []
            with self.loop(_Loop("loop", step=step)):
                body = self.body(node.stmt)
            self.scopes.pop()
            return init + [self.at(node, ast.While(test, body + step, []))]
        if isinstance(node, c_ast.Break):
            if not self.loops:
                raise self.refuse(node, "break outside a loop or a switch")
            return [self.at(node, ast.Break())]
        if isinstance(node, c_ast.Continue):
            return self.continue_(node, len(self.loops) - 1)
        if isinstance(node, c_ast.Return):
            return self.return_(node)
        if isinstance(node, c_ast.Switch):
            return self.switch(node)
        if isinstance(node, (c_ast.Case, c_ast.Default)):
            raise self.refuse(node, "a case label outside its switch's own block (or inside a nested statement): "
                                    "the kit's C takes case labels directly in the switch's { }")
        if isinstance(node, (c_ast.Goto, c_ast.Label)):
            raise self.refuse(node, "goto and labels are not supported by the kit's C: use a loop with break or "
                                    "continue, or a flag")
        if isinstance(node, c_ast.Pragma):
            self.pragma(node, in_function=True)
            return []
        if isinstance(node, c_ast.FuncDef):
            raise self.refuse(node, "a function defined inside a function: C has none")
        return self.expression_statement(node)

    class _LoopContext:
        def __init__(self, translator: Translator, loop: _Loop):
            self.translator, self.loop = translator, loop

        def __enter__(self) -> None:
            loops = self.translator.loops
            if sum(1 for entry in loops if entry.kind == "loop") + len(loops) >= 2 * MAX_LOOP_NESTING:
                raise _Refused(None, f"loops and switches nest more than {MAX_LOOP_NESTING} deep")
            loops.append(self.loop)

        def __exit__(self, *exc: object) -> None:
            self.translator.loops.pop()

    def loop(self, loop: _Loop) -> Translator._LoopContext:
        return Translator._LoopContext(self, loop)

    def continue_(self, node: Any, depth: int) -> list[ast.stmt]:
        while depth >= 0 and self.loops[depth].kind == "switch":
            entry = self.loops[depth]
            entry.used = True
            return [self.at(node, ast.Assign([_name(entry.flag, True)], ast.Constant(True))),
                    self.at(node, ast.Break())]
        if depth < 0:
            raise self.refuse(node, "continue outside a loop")
        entry = self.loops[depth]
        entry.used = True
        return [*self.at(node, [_copy(s) for s in entry.step]), self.at(node, ast.Continue())]

    def return_(self, node: c_ast.Return) -> list[ast.stmt]:
        assert self.function is not None
        ftype = self.function.ctype
        assert isinstance(ftype, Function)
        if node.expr is None:
            if not isinstance(ftype.result, Void) and self.function.name != "main":
                raise self.refuse(node, f"{self.function.name}() returns {ftype.result.spelled()}: return a value")
            return [self.at(node, ast.Return(None))]
        if isinstance(ftype.result, Void):
            raise self.refuse(node, f"{self.function.name}() is void: it returns no value")
        value = self.convert(self.rvalue(node.expr), ftype.result, node.expr, "the value returned")
        if isinstance(ftype.result, Struct):
            value = _rt("copy", [value])
        return [self.at(node, ast.Return(value))]

    def switch(self, node: c_ast.Switch) -> list[ast.stmt]:
        subject = self.rvalue(node.cond)
        if not isinstance(subject.t, Int):
            raise self.refuse(node.cond, "a switch takes an integer")
        subject_t = T.promoted(subject.t) if self.promote else subject.t
        if not isinstance(node.stmt, c_ast.Compound):
            raise self.refuse(node, "the kit's C takes a switch's cases in { }")
        blocks: list[tuple[list[int | None], list[Any]]] = []
        for item in node.stmt.block_items or []:
            if isinstance(item, c_ast.Case):
                value = self.constant(item.expr, "a case label")
                blocks.append(([self._wrap_value(value, subject_t)], list(item.stmts or [])))
            elif isinstance(item, c_ast.Default):
                blocks.append(([None], list(item.stmts or [])))
            elif not blocks:
                raise self.refuse(item, "a statement before the switch's first case label is never reached")
            else:
                blocks[-1][1].append(item)
        table: dict[int, int] = {}
        default = len(blocks)
        for index, (labels, _) in enumerate(blocks):
            for label in labels:
                if label is None:
                    default = index
                elif label in table:
                    raise self.refuse(node, f"case {label} appears twice in one switch")
                else:
                    table[label] = index
        key, flag = self.temp("case"), self.temp("cont")
        entry = _Loop("switch", flag=flag)
        body: list[ast.stmt] = []
        self.scopes.append({})
        with self.loop(entry):
            for index, (_, stmts) in enumerate(blocks):
                inner: list[ast.stmt] = []
                for stmt in stmts:
                    inner.extend(self.statement(stmt))
                body.append(self.at(node, ast.If(ast.Compare(_name(key), [ast.LtE()], [ast.Constant(index)]),
                                                 inner or [ast.Pass()], [])))
        self.scopes.pop()
        table_name = self.temp("cases")
        self.constants[table_name] = table
        subject_py = self.convert(subject, subject_t, node.cond, "the switch's value")
        out = [self.at(node, ast.Assign([_name(key, True)], _call(ast.Attribute(_name(table_name), "get", ast.Load()),
                                                                    [subject_py, ast.Constant(default)])))]
        if entry.used:
            out.append(self.at(node, ast.Assign([_name(flag, True)], ast.Constant(False))))
        out.append(self.at(node, ast.While(ast.Constant(True), body + [ast.Break()], [])))
        if entry.used:
            out.append(self.at(node, ast.If(_name(flag), self.continue_(node, len(self.loops) - 1), [])))
        return out

    def _wrap_value(self, value: int, t: Int) -> int:
        bits = t.bits
        value &= (1 << bits) - 1
        return value - (1 << bits) if t.signed and value >= 1 << (bits - 1) else value

    def local_declaration(self, decl: c_ast.Decl) -> list[ast.stmt]:
        if decl.name is None:
            if isinstance(decl.type, (c_ast.Struct, c_ast.Enum)):
                self.base_type(decl.type, decl)
            return []
        ctype = self.type_of(decl.type, decl.quals)
        if isinstance(ctype, Function):
            self.declare(Sym(decl.name, "func", ctype, py=self.py_name(decl.name)), decl)
            return []
        if "extern" in decl.storage:
            raise self.refuse(decl, f"extern {decl.name} inside a function: declare globals at file level")
        if isinstance(ctype, Array) and ctype.length is None:
            ctype = self.sized_by_initialiser(ctype, decl)
        self._size(ctype, decl)
        if ctype.rom and "static" not in decl.storage:
            raise self.refuse(decl, f"{decl.name} is a rom variable inside a function: program memory holds "
                                    "globals and statics only (C18 says so too); make it static, or global")
        assert self.function is not None
        if "static" in decl.storage:
            py = base = f"__static_{self.function.py}_{decl.name}"
            copies = itertools.count(2)         # another block's static of that name (f's n, f_n's ...): its own
            while py in self.globals:
                py = f"{base}_{next(copies)}"
            sym = self.declare(Sym(decl.name, "var", ctype, py=py, is_global=True,
                                   boxed=decl.name in self.addressed and not isinstance(ctype, Array)), decl)
            self.globals.add(py)
            if decl.init is not None and self._non_constant(decl.init):
                raise self.refuse(decl.init, f"{decl.name} is static: its initial value must be a constant")
            initial = self.initialiser(ctype, decl.init, decl) if decl.init is not None else self.zero(ctype)
            self.startup.append(self.at(decl, ast.Assign([_name(py, True)], self.boxed(sym, initial))))
            return []
        value: ast.expr | None = self.initialiser(ctype, decl.init, decl) if decl.init is not None else (
            self.zero(ctype) if isinstance(ctype, (Array, Struct)) else None)
        sym = self.declare(Sym(decl.name, "var", ctype, py=self.py_name(decl.name),
                               boxed=decl.name in self.addressed and not isinstance(ctype, Array)), decl)
        if value is None:
            if sym.boxed:
                return [self.at(decl, ast.Assign([_name(sym.py, True)], ast.List([ast.Constant(0)], ast.Load())))]
            return []           # C18 leaves it undefined: a read before a write is reported (see loader)
        return [self.at(decl, ast.Assign([_name(sym.py, True)], self.boxed(sym, value)))]

    def expression_statement(self, node: Any) -> list[ast.stmt]:
        if isinstance(node, c_ast.ExprList):
            out: list[ast.stmt] = []
            for item in node.exprs:
                out.extend(self.expression_statement(item))
            return out
        if isinstance(node, c_ast.Assignment):
            return self.assignment(node)
        if isinstance(node, c_ast.UnaryOp) and node.op in ("++", "--", "p++", "p--"):
            target = self.lvalue(node.expr)
            return self.at(node, self.increment(target, node, 1 if "+" in node.op else -1))
        if isinstance(node, c_ast.Cast) and isinstance(self.type_of(node.to_type), Void):
            return self.expression_statement(node.expr)
        e = self.x_FuncCall(node, discard=True) if isinstance(node, c_ast.FuncCall) else self.expr(node)
        return [self.at(node, ast.Expr(e.py))]

    # ================================================================== conditions
    def condition(self, node: Any) -> ast.expr:
        """A C condition as a Python test (its truth is C's: nonzero)."""
        if isinstance(node, c_ast.UnaryOp) and node.op == "!":
            return self.at(node, ast.UnaryOp(ast.Not(), self.condition(node.expr)))
        if isinstance(node, c_ast.BinaryOp) and node.op in ("&&", "||"):
            op = ast.And() if node.op == "&&" else ast.Or()
            return self.at(node, ast.BoolOp(op, [self.condition(node.left), self.condition(node.right)]))
        if isinstance(node, c_ast.BinaryOp) and node.op in _COMPARE:
            return self.comparison(node)
        e = self.rvalue(node)
        if isinstance(e.t, Struct):
            raise self.refuse(node, "a struct is not a condition")
        if e.const is not None:
            return self.at(node, ast.Constant(bool(e.const)))
        return e.py

    def comparison(self, node: c_ast.BinaryOp) -> ast.expr:
        a, b = self.rvalue(node.left), self.rvalue(node.right)
        if isinstance(a.t, Int) and isinstance(b.t, Int):
            t = T.common(a.t, b.t, self.promote)
            left, right = self.as_int(a, t), self.as_int(b, t)
            return self.at(node, ast.Compare(left.py, [_COMPARE[node.op]()], [right.py]))
        a, b = self.pointer_pair(a, b, node)
        if node.op in ("==", "!="):
            test = _rt("same", [a.py, b.py])
            return self.at(node, test if node.op == "==" else ast.UnaryOp(ast.Not(), test))
        return self.at(node, ast.Compare(_rt("order", [a.py, b.py, ast.Constant(node.op)]), [_COMPARE[node.op]()],
                                         [ast.Constant(0)]))

    def pointer_pair(self, a: E, b: E, node: Any) -> tuple[E, E]:
        if isinstance(a.t, Int) and a.const == 0:
            a = E(ast.Constant(None), b.t)
        if isinstance(b.t, Int) and b.const == 0:
            b = E(ast.Constant(None), a.t)
        if not (isinstance(a.t, Pointer) and isinstance(b.t, Pointer)):
            raise self.refuse(node, f"comparing {a.t.spelled()} with {b.t.spelled()}: a pointer compares with a "
                                    "pointer (or NULL)")
        return a, b

    # ================================================================== expressions
    def rvalue(self, node: Any) -> E:
        """The expression's value: an array decays to a pointer to its first element."""
        e = self.expr(node)
        if isinstance(e.t, Array):
            return self.decay(e, node)
        if isinstance(e.t, Function):
            raise self.refuse(node, "function pointers are not supported by the kit's C: call the function")
        return e

    def decay(self, e: E, node: Any) -> E:
        assert isinstance(e.t, Array) and e.t.length is not None
        element = e.t.element
        if e.literal is not None:
            return E(e.py, Pointer(target=element), literal=e.literal, name=e.name)
        py = _rt("Ptr", [e.py, ast.Constant(0), ast.Constant(0), ast.Constant(e.t.length), ast.Constant(e.name),
                         ast.Constant(e.t.rom), _element(element)])
        return E(py, Pointer(target=element.qualified(rom=e.t.rom)), name=e.name)

    def expr(self, node: Any) -> E:
        method = getattr(self, f"x_{type(node).__name__}", None)
        if method is None:
            raise self.refuse(node, f"this expression ({type(node).__name__}) is not supported by the kit's C")
        e = method(node)
        self.at(node, e.py)
        return e

    # -------------------------------------------------------------- leaves
    def x_Constant(self, node: c_ast.Constant) -> E:
        kind = node.type
        if kind == "string":
            codes = _string_codes(node.value, self, node) + [0]
            name = self.temp("str")
            shown = node.value if len(node.value) <= 24 else node.value[:21] + '..."'
            plain = T.integer_type(["char"], self.unsigned_char)       # signed, unsigned with -k
            assert plain is not None
            self.constants[name] = _RomString(tuple(c - 0x100 if plain.signed and c >= 0x80 else c for c in codes),
                                              _element_value(plain), f"the string {shown}")
            return E(_name(name), Array(element=plain.qualified(const=True, rom=True), length=len(codes),
                                        rom=True, const=True), literal=node.value, name=f"the string {shown}")
        if kind == "char":
            codes = _string_codes(node.value[1:-1], self, node, quoted=False)
            if len(codes) != 1:
                raise self.refuse(node, f"{node.value} is not one character")
            plain_char = T.integer_type(["char"], self.unsigned_char)     # signed, unsigned with -k
            assert plain_char is not None
            value = codes[0] & 0xFF
            if plain_char.signed and value >= 0x80:
                value -= 0x100
            t = plain_char if not self.promote else T.INT      # -Oi: an int, with the plain char's value
            return E(ast.Constant(value), t, value, value, value)
        if kind in ("float", "double"):
            raise self.refuse(node, "floating point is not supported by the kit's C yet: compute in integers")
        text = node.value.lower()
        digits = text.rstrip("ul")
        suffix = text[len(digits):]
        try:
            if digits.startswith(("0x", "0b")):
                value = int(digits, 0)
            elif len(digits) > 1 and digits.startswith("0"):
                value = int(digits, 8)
            else:
                value = int(digits)
        except ValueError:
            raise self.refuse(node, f"{node.value} is not a number C18 reads") from None
        typed = T.constant_type(value, decimal=not digits.startswith(("0x", "0b")) and not (
            len(digits) > 1 and digits.startswith("0")), unsigned="u" in suffix, long="l" in suffix,
            promote=self.promote)
        if typed is None:
            raise self.refuse(node, f"{node.value} is too big for any C18 type (32 bits at most)")
        return E(ast.Constant(value), typed, value, value, value)

    def x_ID(self, node: c_ast.ID) -> E:
        sym = self.lookup(node.name)
        if sym is None:
            hint = _HINTS.get(node.name, "")
            raise self.refuse(node, f"{node.name} is not declared{hint}")
        if sym.kind == "enum":
            return E(ast.Constant(sym.value), T.INT, sym.value, sym.value, sym.value)
        if sym.kind == "var":
            py: ast.expr = _name(sym.py)
            if sym.boxed:
                py = ast.Subscript(py, ast.Constant(0), ast.Load())
            t = sym.ctype
            lo, hi = (t.low, t.high) if isinstance(t, Int) else (None, None)
            return E(py, t, lo, hi, name=node.name)
        if sym.kind == "sfr":
            return E(_call(ast.Attribute(_name(MCU), "read", ast.Load()), [ast.Constant(sym.value)]), T.UCHAR,
                     0, 255, name=node.name)
        if sym.kind in ("func", "lib"):
            return E(_name(sym.py), sym.ctype, name=node.name)
        if sym.kind == "bits":
            raise self.refuse(node, f"{node.name} is a register's bits: name one, {node.name}.{_first_bit(sym)}")
        if sym.kind == "typedef":
            raise self.refuse(node, f"{node.name} is a type, not a value")
        raise self.refuse(node, f"{node.name} cannot be used here")

    # -------------------------------------------------------------- operators
    def x_UnaryOp(self, node: c_ast.UnaryOp) -> E:
        op = node.op
        if op == "sizeof":
            measured = self.type_of(node.expr) if isinstance(node.expr, c_ast.Typename) else self.expr(node.expr).t
            if isinstance(measured, Void):
                raise self.refuse(node, "sizeof of void: void has no size")
            if isinstance(measured, Int) and measured.width is not None:
                raise self.refuse(node, "sizeof of a bit-field: C forbids it (a bit-field is part of a byte); take "
                                        "the size of the struct, or of the field's type")
            size = self._size(measured, node)
            t = T.constant_type(size, decimal=True, unsigned=True, long=False, promote=True) or T.UINT
            return E(ast.Constant(size), T.UINT if t.size <= 2 else t, size, size, size)
        if op in ("++", "--", "p++", "p--"):
            return self.increment_value(node)
        if op == "&":
            return self.address_of(node)
        if op == "*":
            p = self.rvalue(node.expr)
            if not isinstance(p.t, Pointer):
                raise self.refuse(node, f"* takes a pointer; this is {p.t.spelled()}")
            if isinstance(p.t.target, Void):
                raise self.refuse(node, "* of a void pointer: cast it to the type it points to first")
            return self.loaded(_rt("deref", [p.py]), p.t.target)
        if op == "!":
            e = self.rvalue(node.expr)
            if e.const is not None:
                v = int(not e.const)
                return E(ast.Constant(v), T.INT, v, v, v)
            return E(ast.IfExp(self.condition(node.expr), ast.Constant(0), ast.Constant(1)), T.INT, 0, 1)
        e = self.rvalue(node.expr)
        if not isinstance(e.t, Int):
            raise self.refuse(node, f"{op} takes an integer; this is {e.t.spelled()}")
        t = T.promoted(e.t) if self.promote else T.plain(e.t)
        assert isinstance(t, Int)
        a = self.as_int(e, t)
        if op == "+":
            return a
        if op == "-":
            if a.const is not None:
                return self.const_int(-a.const, t)
            assert a.lo is not None and a.hi is not None
            return self.fit(E(ast.UnaryOp(ast.USub(), a.py), t, -a.hi, -a.lo), t)
        if op == "~":
            if a.const is not None:
                return self.const_int(~a.const, t)
            assert a.lo is not None and a.hi is not None
            return self.fit(E(ast.UnaryOp(ast.Invert(), a.py), t, ~a.hi, ~a.lo), t)
        raise self.refuse(node, f"the operator {op} is not supported by the kit's C")

    def x_BinaryOp(self, node: c_ast.BinaryOp) -> E:
        op = node.op
        if op in ("&&", "||"):
            return E(ast.IfExp(self.condition(node), ast.Constant(1), ast.Constant(0)), T.INT, 0, 1)
        if op in _COMPARE:
            a, b = self.rvalue(node.left), self.rvalue(node.right)
            if a.const is not None and b.const is not None and isinstance(a.t, Int) and isinstance(b.t, Int):
                t = T.common(a.t, b.t, self.promote)
                x, y = self.as_int(a, t).const, self.as_int(b, t).const
                v = int(_FOLD_COMPARE[op](x, y))
                return E(ast.Constant(v), T.INT, v, v, v)
            return E(ast.IfExp(self.comparison(node), ast.Constant(1), ast.Constant(0)), T.INT, 0, 1)
        a, b = self.rvalue(node.left), self.rvalue(node.right)
        return self.arithmetic(op, a, b, node)

    def arithmetic(self, op: str, a: E, b: E, node: Any) -> E:
        if isinstance(a.t, Pointer) or isinstance(b.t, Pointer):
            return self.pointer_arithmetic(op, a, b, node)
        if not isinstance(a.t, Int) or not isinstance(b.t, Int):
            raise self.refuse(node, f"{op} takes integers; here {a.t.spelled()} and {b.t.spelled()}")
        if op in ("<<", ">>"):
            t = T.promoted(a.t) if self.promote else T.plain(a.t)
            assert isinstance(t, Int)
            x = self.as_int(a, t)
            n = b
            if n.const is not None and x.const is not None:
                if n.const < 0:
                    raise self.refuse(node, f"a shift by {n.const}: C leaves a negative shift undefined")
                shifted = x.const << min(n.const, MAX_SHIFT) if op == "<<" else x.const >> n.const
                return self.const_int(shifted, t)           # past the width: all bits gone, as C18 computes it
            plain = n.lo is not None and n.lo >= 0 and n.hi is not None and n.hi <= MAX_SHIFT
            count = n.py if plain else _rt("shift_count", [n.py])
            assert x.lo is not None and x.hi is not None and n.hi is not None and n.lo is not None
            smax = min(max(n.hi, 0), MAX_SHIFT)
            smin = max(n.lo, 0)
            if op == "<<":
                corners = [x.lo << smin, x.lo << smax, x.hi << smin, x.hi << smax]
                return self.fit(E(ast.BinOp(x.py, ast.LShift(), count), t, min(corners), max(corners)), t)
            corners = [x.lo >> smin, x.lo >> smax, x.hi >> smin, x.hi >> smax]
            return self.fit(E(ast.BinOp(x.py, ast.RShift(), count), t, min(corners), max(corners)), t)
        t = T.common(a.t, b.t, self.promote)
        x, y = self.as_int(a, t), self.as_int(b, t)
        if x.const is not None and y.const is not None:
            if op in ("/", "%") and y.const == 0:
                raise self.refuse(node, f"a division by zero ({x.const} {op} 0)")
            return self.const_int(_FOLD[op](x.const, y.const), t)
        assert x.lo is not None and x.hi is not None and y.lo is not None and y.hi is not None
        if op in ("+", "-", "*"):
            if op == "+":
                lo, hi = x.lo + y.lo, x.hi + y.hi
            elif op == "-":
                lo, hi = x.lo - y.hi, x.hi - y.lo
            else:
                corners = [x.lo * y.lo, x.lo * y.hi, x.hi * y.lo, x.hi * y.hi]
                lo, hi = min(corners), max(corners)
            return self.fit(E(ast.BinOp(x.py, _ARITH[op](), y.py), t, lo, hi), t)
        if op in ("&", "|", "^"):
            if x.lo >= 0 and y.lo >= 0:
                if op == "&":
                    lo, hi = 0, min(x.hi, y.hi)
                else:
                    lo, hi = 0, (1 << max(x.hi, y.hi).bit_length()) - 1
            elif op == "&" and (x.lo >= 0 or y.lo >= 0):
                lo, hi = 0, x.hi if x.lo >= 0 else y.hi
            else:
                lo, hi = t.low, t.high
            return self.fit(E(ast.BinOp(x.py, _ARITH[op](), y.py), t, lo, hi), t)
        if op in ("/", "%"):
            if x.lo >= 0 and y.lo > 0:
                if op == "/":
                    return E(ast.BinOp(x.py, ast.FloorDiv(), y.py), t, x.lo // y.hi, x.hi // y.lo)
                return E(ast.BinOp(x.py, ast.Mod(), y.py), t, 0, min(x.hi, y.hi - 1))
            helper = "divide" if op == "/" else "remainder"
            bound = max(abs(x.lo), abs(x.hi))
            return self.fit(E(_rt(helper, [x.py, y.py]), t, -bound, bound), t)
        raise self.refuse(node, f"the operator {op} is not supported by the kit's C")

    def pointer_arithmetic(self, op: str, a: E, b: E, node: Any) -> E:
        for side in (a, b):
            if isinstance(side.t, Pointer) and isinstance(side.t.target, Void):
                raise _void_arithmetic(self, node)
        if op in ("+", "-") and isinstance(a.t, Pointer) and isinstance(b.t, Int):
            offset = b.py if op == "+" else ast.UnaryOp(ast.USub(), b.py)
            return E(_rt("advance", [a.py, offset]), a.t, name=a.name)
        if op == "+" and isinstance(b.t, Pointer) and isinstance(a.t, Int):
            return E(_rt("advance", [b.py, a.py]), b.t, name=b.name)
        if op == "-" and isinstance(a.t, Pointer) and isinstance(b.t, Pointer):
            return E(_rt("difference", [a.py, b.py]), T.INT, T.INT.low, T.INT.high)
        raise self.refuse(node, f"{op} of {a.t.spelled()} and {b.t.spelled()} is not C")

    def x_TernaryOp(self, node: c_ast.TernaryOp) -> E:
        a, b = self.rvalue(node.iftrue), self.rvalue(node.iffalse)
        test = self.condition(node.cond)
        if isinstance(a.t, Int) and isinstance(b.t, Int):
            t = T.common(a.t, b.t, self.promote)
            x, y = self.as_int(a, t), self.as_int(b, t)
            assert x.lo is not None and y.lo is not None and x.hi is not None and y.hi is not None
            return E(ast.IfExp(test, x.py, y.py), t, min(x.lo, y.lo), max(x.hi, y.hi))
        if isinstance(a.t, Pointer) or isinstance(b.t, Pointer):
            a, b = self.pointer_pair(a, b, node)
            assert isinstance(a.t, Pointer) and isinstance(b.t, Pointer)
            if a.t.target.rom != b.t.target.rom:         # (NULL has the other side's type)
                rom, ram = (a, b) if a.t.target.rom else (b, a)
                raise self.refuse(node, f"one side of ?: points into program memory ({rom.name or rom.t.spelled()}), "
                                        f"the other into RAM ({ram.name or ram.t.spelled()}): C18 reads both as one "
                                        "pointer type, so one of them reads garbage. Make both RAM strings (copy the "
                                        "literal with strcpypgm2ram) or both ROM")
            return E(ast.IfExp(test, a.py, b.py), a.t)
        if a.t.unqualified() == b.t.unqualified():
            return E(ast.IfExp(test, a.py, b.py), a.t)
        raise self.refuse(node, f"the two sides of ?: are {a.t.spelled()} and {b.t.spelled()}")

    def x_ExprList(self, node: c_ast.ExprList) -> E:
        """The comma operator: each in turn, the value of the last."""
        if not node.exprs:
            raise self.refuse(node, "an empty expression")
        first = [self.expr(item).py for item in node.exprs[:-1]]
        last = self.rvalue(node.exprs[-1])
        return E(ast.Subscript(ast.Tuple([*first, last.py], ast.Load()), ast.Constant(-1), ast.Load()), last.t,
                 last.lo, last.hi)

    def x_Cast(self, node: c_ast.Cast) -> E:
        t = self.type_of(node.to_type)
        e = self.rvalue(node.expr)
        if isinstance(t, Void):
            return E(ast.Subscript(ast.Tuple([e.py, ast.Constant(None)], ast.Load()), ast.Constant(1), ast.Load()),
                     T.VOID)
        if isinstance(t, Int):
            if not isinstance(e.t, Int):
                raise self.refuse(node, f"a cast of {e.t.spelled()} to {t.spelled()}: the kit's C keeps pointers "
                                        "and numbers apart (addresses are not numbers here)")
            return self.as_int(e, T.plain(t))
        if isinstance(t, Pointer):
            if isinstance(e.t, Int):
                if e.const == 0:
                    return E(ast.Constant(None), t)
                raise self.refuse(node, f"a cast of a number to {t.spelled()}: the kit's C has no addresses as "
                                        "numbers; point at a variable with &")
            if isinstance(e.t, Pointer):
                return E(self.pointer_converted(e, t, node, "the cast", cast=True), t, name=e.name, literal=e.literal)
        raise self.refuse(node, f"a cast to {t.spelled()} is not supported by the kit's C")

    # -------------------------------------------------------------- calls
    def x_FuncCall(self, node: c_ast.FuncCall, discard: bool = False) -> E:
        if not isinstance(node.name, c_ast.ID):
            raise self.refuse(node, "function pointers are not supported by the kit's C: call a function by name")
        name = node.name.name
        if name == GOTO:
            raise self.refuse(node, "inline assembly (_asm GOTO ... _endasm) is C18's interrupt vector, and belongs "
                                    "alone in a function at the vector: #pragma code high_vector=0x08 (or "
                                    "low_vector=0x18), the function, then #pragma code. Elsewhere, call the function")
        sym = self.lookup(name)
        if sym is None:
            hint = _HINTS.get(name, ": declare it (a prototype) above its first call, or include its header")
            raise self.refuse(node, f"{name}() is not declared{hint}")
        if sym.kind not in ("func", "lib"):
            raise self.refuse(node, f"{name} is {self.what(sym)}, not a function")
        ftype = sym.ctype
        assert isinstance(ftype, Function)
        given = list(node.args.exprs) if node.args is not None else []
        if len(given) < len(ftype.params) or (len(given) > len(ftype.params) and not ftype.variadic):
            plural = "s" if len(ftype.params) != 1 else ""
            raise self.refuse(node, f"{name}() takes {len(ftype.params)} argument{plural}"
                                    f"{' or more' if ftype.variadic else ''}; here it has {len(given)}"
                                    + _ARITY_HINTS.get((name, len(given)), ""))
        args: list[ast.expr] = []
        for k, (arg, ptype) in enumerate(zip(given, ftype.params, strict=False)):
            e = self.rvalue(arg)
            what = f"argument {k + 1} of {name}()" + (f" ({ftype.names[k]})" if k < len(ftype.names)
                                                        and ftype.names[k] else "")
            value = self.convert(e, ptype, arg, what)
            if isinstance(ptype, Struct):
                value = _rt("copy", [value])
            args.append(value)
        for arg in given[len(ftype.params):]:
            args.append(self.variadic(self.rvalue(arg), arg))
        self.called.add(name)
        result = ftype.result
        call = _call(_name(sym.py), args)
        if isinstance(result, Int) and not discard:
            if sym.kind == "lib":
                lo, hi = RESULTS.get(name, (-(1 << 40), 1 << 40))
                return self.fit(E(call, result, lo, hi), result)
            return E(call, result, result.low, result.high)
        return E(call, result)

    def variadic(self, e: E, node: Any) -> ast.expr:
        """An argument after `...`: C18 pushes it as it is (an 8-bit value is one byte), unless -Oi promotes it."""
        if isinstance(e.t, Int):
            t = T.promoted(e.t) if self.promote else e.t
            kind, size = "int", t.size
            spelled = ("a constant of type " if e.const is not None else "") + t.spelled()
            value = self.as_int(e, t).py if t is not e.t else e.py
        elif isinstance(e.t, Pointer):
            value, size, spelled = e.py, 2, e.t.spelled() if e.literal is None else f"the literal {e.literal}"
            kind = "rom" if e.t.target.rom and T.is_char_string(e.t) else "ram" if T.is_char_string(e.t) else "ptr"
        else:
            raise self.refuse(node, f"a {e.t.spelled()} cannot be passed to a function's ... arguments")
        return _rt("Arg", [value, ast.Constant(size), ast.Constant(spelled), ast.Constant(kind),
                           ast.Constant(e.const is not None), ast.Constant(self.promote)])

    # -------------------------------------------------------------- conversions
    def as_int(self, e: E, t: Int) -> E:
        """`e` (an integer) converted to `t`: wrapped into its range where its interval does not fit."""
        if e.const is not None:
            return self.const_int(e.const, t)
        return self.fit(E(e.py, t, e.lo, e.hi, name=e.name), t)

    def const_int(self, value: int, t: Int) -> E:
        v = self._wrap_value(value, t)
        return E(ast.Constant(v), t, v, v, v)

    def fit(self, e: E, t: Int) -> E:
        """Wrap `e`'s value into `t` (two's complement) unless its interval shows it fits."""
        if e.lo is not None and e.hi is not None and t.low <= e.lo and e.hi <= t.high:
            return E(e.py, t, e.lo, e.hi, e.const, e.literal, e.name)    # replace(e, t=t), without its cost
        mask = (1 << t.bits) - 1
        if t.signed:
            half = 1 << (t.bits - 1)
            py: ast.expr = ast.BinOp(ast.BinOp(ast.BinOp(e.py, ast.Add(), ast.Constant(half)), ast.BitAnd(),
                                               ast.Constant(mask)), ast.Sub(), ast.Constant(half))
        else:
            py = ast.BinOp(e.py, ast.BitAnd(), ast.Constant(mask))
        return E(py, t, t.low, t.high, name=e.name)

    def convert(self, e: E, t: CType, node: Any, what: str) -> ast.expr:
        """`e` converted as an assignment converts it to `t` (an argument, an initial value, a returned value),
        refusing what C18 would compile into a wrong program."""
        if isinstance(t, Int):
            if isinstance(e.t, Pointer):
                raise self.refuse(node, f"{what} is {t.spelled()}, and this is a pointer ({e.t.spelled()}): did "
                                        "you mean the value it points to, *p or p[0]?")
            if not isinstance(e.t, Int):
                raise self.refuse(node, f"{what} is {t.spelled()}; this is {e.t.spelled()}")
            return self.as_int(e, replace(T.plain(t), width=t.width)).py
        if isinstance(t, Pointer):
            if isinstance(e.t, Int):
                if e.const == 0:
                    return ast.Constant(None)
                target = t.target.spelled()
                raise self.refuse(node, f"{what} is {t.spelled()}: the address of a {target} where the function "
                                        f"writes or reads it; {e.name} is a {e.t.spelled()}, not an address: pass "
                                        f"its address, &{e.name}" if e.name else
                                        f"{what} is {t.spelled()}: an address; a number is not one here")
            if not isinstance(e.t, Pointer):
                raise self.refuse(node, f"{what} is {t.spelled()}; this is {e.t.spelled()}")
            return self.pointer_converted(e, t, node, what)
        if isinstance(t, Struct):
            if not isinstance(e.t, Struct) or e.t.key != t.key:
                raise self.refuse(node, f"{what} is {t.spelled()}; this is {e.t.spelled()}")
            return e.py
        raise self.refuse(node, f"{what} of type {t.spelled()} is not supported by the kit's C")

    def pointer_converted(self, e: E, t: Pointer, node: Any, what: str, cast: bool = False) -> ast.expr:
        """`e` as a pointer of type `t`; refused where it would point to a type of another size. To the other
        signedness, or from a void pointer, it reads through `runtime.viewed` (which checks what the object holds)."""
        assert isinstance(e.t, Pointer)
        source, target = e.t.target, t.target
        if source.rom and not target.rom:
            thing = f"the string literal {e.literal}" if e.literal is not None else f"{e.name or 'this'} " \
                                                                                     f"({e.t.spelled()})"
            fix = {"putsGLCD": "putrsGLCD", "putsUSART": "putrsUSART", "strcpy": "strcpypgm2ram",
                   "strcmp": "strcmppgm2ram", "strlen": "strlenpgm"}
            function = what.split(" of ")[-1].split("(")[0] if " of " in what else ""
            hint = (f": use {fix[function]}() for a string in program memory" if function in fix else
                    ": copy it into a char array in RAM first (strcpypgm2ram), or make the pointer const rom char *")
            raise self.refuse(node, f"{what} points into RAM ({t.spelled()}), but {thing} is in program memory: C18 "
                                    "puts string literals in ROM, and reading ROM addresses from RAM gives "
                                    f"garbage (C18 warns: type qualifier mismatch){hint}")
        if target.rom and not source.rom and not cast:
            function = what.split(" of ")[-1].split("(")[0] if " of " in what else ""
            fix = {"putrsGLCD": "putsGLCD", "putrsUSART": "putsUSART", "strcpypgm2ram": "strcpy"}
            hint = f": use {fix[function]}() for a string in RAM" if function in fix else ""
            raise self.refuse(node, f"{what} points into program memory ({t.spelled()}), but {e.name or 'this'} is "
                                    f"in RAM ({e.t.spelled()}){hint}")
        if isinstance(target, Void):
            return e.py
        if isinstance(source, Void):
            return _rt("viewed", [e.py, _element(target)])
        s, d = source.unqualified(), target.unqualified()
        if isinstance(s, Int) and isinstance(d, Int) and s.size == d.size:
            return e.py if s.signed == d.signed else _rt("viewed", [e.py, _element(d)])
        if s == d or (isinstance(s, Struct) and isinstance(d, Struct) and s.key == d.key):
            return e.py
        if isinstance(s, Pointer) and isinstance(d, Pointer):
            return e.py
        size_s = self._size(s, node) if not isinstance(s, Function) else 0
        size_d = self._size(d, node) if not isinstance(d, Function) else 0
        raise self.refuse(node, f"{what} points to {d.spelled()} ({_bytes(size_d)}), but "
                                f"{e.name or 'this'} points to {s.spelled()} ({_bytes(size_s)})"
                                f": {'the function would write past it' if size_d > size_s else 'the sizes differ'} "
                                f"(C18 warns: suspicious pointer conversion). The kit's C does not reinterpret "
                                "memory: give it a variable of the type it points to")

    # -------------------------------------------------------------- lvalues
    def lvalue(self, node: Any) -> _LValue:
        if isinstance(node, c_ast.ID):
            sym = self.lookup(node.name)
            if sym is None:
                raise self.refuse(node, f"{node.name} is not declared{_HINTS.get(node.name, '')}")
            if sym.kind == "var":
                if isinstance(sym.ctype, Array):
                    raise self.refuse(node, f"{node.name} is an array: assign its elements, {node.name}[i] = ...")
                if sym.ctype.const:
                    raise self.refuse(node, f"{node.name} is const: it cannot be assigned")
                return _VarLV(self, sym, node)
            if sym.kind == "sfr":
                return _SfrLV(self, sym.value, None, node)
            raise self.refuse(node, f"{node.name} is {self.what(sym)}: it cannot be assigned")
        if isinstance(node, c_ast.StructRef):
            base = node.name
            if isinstance(base, c_ast.ID) and node.type == ".":
                sym = self.lookup(base.name)
                if sym is not None and sym.kind == "bits":
                    fields = BITFIELDS[sym.name[:-4]]
                    bit = node.field.name
                    if bit not in fields:
                        raise self.refuse(node.field, _no_bit(sym.name, bit, fields))
                    return _SfrLV(self, sym.value, fields[bit], node)
            container, index, mtype = self.member(node)
            if mtype.const:
                raise self.refuse(node, f"{node.field.name} is const")
            return _ItemLV(self, container, ast.Constant(index), mtype, node)
        if isinstance(node, c_ast.ArrayRef):
            base = self.expr(node.name)
            if isinstance(base.t, Array):
                if base.t.rom or base.t.const:
                    where = "in program memory" if base.t.rom else "const"
                    raise self.refuse(node, f"{base.name or 'this array'} is {where}: it cannot be written")
                position = self.checked_index(base, node.subscript, node, write=True)
                return _ItemLV(self, base.py, position, base.t.element, node)
            p = self.rvalue(node.name)
            if not isinstance(p.t, Pointer):
                raise self.refuse(node, f"{p.t.spelled()} cannot be indexed")
            k = self.rvalue(node.subscript)
            if not isinstance(k.t, Int):
                raise self.refuse(node.subscript, "an index is an integer")
            return _PtrLV(self, p.py, k.py, p.t.target, node)
        if isinstance(node, c_ast.UnaryOp) and node.op == "*":
            p = self.rvalue(node.expr)
            if not isinstance(p.t, Pointer):
                raise self.refuse(node, f"* takes a pointer; this is {p.t.spelled()}")
            return _PtrLV(self, p.py, ast.Constant(0), p.t.target, node)
        raise self.refuse(node, "this cannot be assigned (it is not a variable, an element or a member)")

    def checked_index(self, base: E, subscript: Any, node: Any, write: bool = False) -> ast.expr:
        assert isinstance(base.t, Array) and base.t.length is not None
        k = self.rvalue(subscript)
        if not isinstance(k.t, Int):
            raise self.refuse(subscript, "an index is an integer")
        n = base.t.length
        if k.const is not None:
            if not 0 <= k.const < n:
                raise self.refuse(node, f"{base.name or 'the array'}[{k.const}] is outside {base.name or 'it'}, "
                                        f"which has {n} elements (0..{n - 1})")
            return ast.Constant(k.const)
        assert k.lo is not None and k.hi is not None
        if 0 <= k.lo and k.hi < n:
            return k.py
        test_value: ast.expr
        if isinstance(k.py, ast.Name):
            value: ast.expr = k.py
            test_value = k.py
        else:
            temp = self.temp("i")
            value, test_value = _name(temp), ast.NamedExpr(_name(temp, True), k.py)
        if k.lo < 0:                    # an index that can be negative: 0 <= i < n
            test: ast.expr = ast.Compare(ast.Constant(0), [ast.LtE(), ast.Lt()], [test_value, ast.Constant(n)])
        else:
            test = ast.Compare(test_value, [ast.Lt()], [ast.Constant(n)])
        fail = _rt("outside", [ast.Constant(base.name or "the array"), _copy(value), ast.Constant(n),
                               ast.Constant(write)])
        return ast.IfExp(test, _copy(value), fail)

    def member(self, node: c_ast.StructRef) -> tuple[ast.expr, int, CType]:
        if node.type == ".":
            base = self.expr(node.name)
            stype = base.t
            container = base.py
        else:
            p = self.rvalue(node.name)
            if not isinstance(p.t, Pointer):
                raise self.refuse(node, f"-> takes a pointer to a struct; this is {p.t.spelled()}")
            stype = p.t.target
            container = _rt("deref", [p.py])
        stype = self.completed(stype)
        if not isinstance(stype, Struct) or stype.members is None:
            raise self.refuse(node, f"{node.field.name}: {stype.spelled()} is not a struct"
                                    + (" (use -> for a pointer)" if isinstance(stype, Pointer) else ""))
        index = stype.index(node.field.name)
        if index is None:
            raise self.refuse(node.field, f"struct {stype.tag} has no member {node.field.name}")
        mtype = stype.members[index].ctype
        if stype.const or stype.rom:
            mtype = mtype.qualified(const=stype.const, rom=stype.rom)
        return container, index, mtype

    def x_StructRef(self, node: c_ast.StructRef) -> E:
        base = node.name
        if isinstance(base, c_ast.ID) and node.type == ".":
            sym = self.lookup(base.name)
            if sym is not None and sym.kind == "bits":
                fields = BITFIELDS[sym.name[:-4]]
                bit = node.field.name
                if bit not in fields:
                    raise self.refuse(node.field, _no_bit(sym.name, bit, fields))
                shift, width = fields[bit]
                py: ast.expr = _call(ast.Attribute(_name(MCU), "read", ast.Load()), [ast.Constant(sym.value)])
                if shift:
                    py = ast.BinOp(py, ast.RShift(), ast.Constant(shift))
                if shift + width < 8:
                    py = ast.BinOp(py, ast.BitAnd(), ast.Constant((1 << width) - 1))
                return E(py, T.UCHAR, 0, (1 << width) - 1, name=f"{base.name}.{bit}")
        container, index, mtype = self.member(node)
        return self.loaded(ast.Subscript(container, ast.Constant(index), ast.Load()), mtype, node.field.name)

    def x_ArrayRef(self, node: c_ast.ArrayRef) -> E:
        base = self.expr(node.name)
        if isinstance(base.t, Array) and base.literal is None:     # ("AB"[1] is a pointer's: a literal is one)
            index = self.checked_index(base, node.subscript, node)
            name = f"{base.name}[]" if base.name else ""
            return self.loaded(ast.Subscript(base.py, index, ast.Load()), base.t.element, name,
                               rom=base.t.rom)
        p = self.rvalue(node.name)
        if not isinstance(p.t, Pointer):
            raise self.refuse(node, f"{p.t.spelled()} cannot be indexed")
        k = self.rvalue(node.subscript)
        if not isinstance(k.t, Int):
            raise self.refuse(node.subscript, "an index is an integer")
        return self.loaded(_rt("deref", [p.py, k.py]), p.t.target)

    def loaded(self, py: ast.expr, t: CType, name: str = "", rom: bool = False) -> E:
        if isinstance(t, Int):
            return E(py, t, t.low, t.high, name=name)
        if isinstance(t, Array) and rom:
            t = replace(t, rom=True)
        return E(py, t, name=name)

    def address_of(self, node: c_ast.UnaryOp) -> E:
        target = node.expr
        if isinstance(target, c_ast.ID):
            sym = self.lookup(target.name)
            if sym is None:
                raise self.refuse(target, f"{target.name} is not declared")
            if sym.kind in ("sfr", "bits"):
                raise self.refuse(node, f"&{target.name}: the kit's C does not take a register's address; read "
                                        "it or write it by name")
            if sym.kind in ("func", "lib"):
                raise self.refuse(node, "function pointers are not supported by the kit's C")
            if sym.kind != "var":
                raise self.refuse(node, f"{target.name} has no address")
            if isinstance(sym.ctype, Array):
                return self.decay(self.expr(target), node)
            assert sym.boxed, "addressed variables are boxed"
            t = Pointer(target=sym.ctype)
            return E(_rt("Ptr", [_name(sym.py), ast.Constant(0), ast.Constant(0), ast.Constant(1),
                                 ast.Constant(target.name), ast.Constant(sym.ctype.rom),
                                 _element(sym.ctype)]), t, name=f"&{target.name}")
        if isinstance(target, c_ast.ArrayRef):
            base = self.expr(target.name)
            if isinstance(base.t, Array):
                assert base.t.length is not None
                k = self.rvalue(target.subscript)
                index = k.py
                return E(_rt("Ptr", [base.py, index, ast.Constant(0), ast.Constant(base.t.length),
                                     ast.Constant(base.name), ast.Constant(base.t.rom),
                                     _element(base.t.element)]),
                         Pointer(target=base.t.element.qualified(rom=base.t.rom)), name=base.name)
            p = self.rvalue(target.name)
            k = self.rvalue(target.subscript)
            if not isinstance(p.t, Pointer):
                raise self.refuse(node, "& of an element of something that is not an array")
            return E(_rt("advance", [p.py, k.py]), p.t, name=p.name)
        if isinstance(target, c_ast.StructRef):
            container, member, mtype = self.member(target)
            if isinstance(mtype, Int) and mtype.width is not None:
                raise self.refuse(node, f"&{target.field.name}: {target.field.name} is a bit-field, which has no "
                                        "address (C forbids it: it is part of a byte); copy it into a variable and "
                                        "pass that variable's address")
            return E(_rt("Ptr", [container, ast.Constant(member), ast.Constant(member), ast.Constant(member + 1),
                                 ast.Constant(target.field.name), ast.Constant(mtype.rom),
                                 _element(mtype)]), Pointer(target=mtype),
                     name=target.field.name)
        if isinstance(target, c_ast.UnaryOp) and target.op == "*":
            return self.rvalue(target.expr)
        raise self.refuse(node, "& takes a variable, an element or a member")

    # -------------------------------------------------------------- assignment
    def assignment(self, node: c_ast.Assignment) -> list[ast.stmt]:
        target = self.lvalue(node.lvalue)
        value = self.assigned_value(node, target)
        return self.at(node, target.store(value))

    def assigned_value(self, node: c_ast.Assignment, target: _LValue) -> ast.expr:
        if node.op == "=":
            e = self.rvalue(node.rvalue)
            if isinstance(target.t, Struct):
                return _rt("copy", [self.convert(e, target.t, node.rvalue, "the value assigned")])
            return self.convert(e, target.t, node.rvalue, f"{target.name or 'the variable'}")
        op = node.op[:-1]
        current = target.load_once()
        result = self.arithmetic(op, current, self.rvalue(node.rvalue), node)
        return self.convert(result, target.t, node, "the result")

    def x_Assignment(self, node: c_ast.Assignment) -> E:
        target = self.lvalue(node.lvalue)
        value = self.assigned_value(node, target)
        return target.store_value(value)

    def increment(self, target: _LValue, node: Any, step: int) -> list[ast.stmt]:
        return target.store(self._stepped(target, node, step))

    def _stepped(self, target: _LValue, node: Any, step: int) -> ast.expr:
        current = target.load_once()
        if isinstance(target.t, Pointer):
            if isinstance(target.t.target, Void):
                raise _void_arithmetic(self, node)
            return _rt("advance", [current.py, ast.Constant(step)])
        if not isinstance(target.t, Int):
            raise self.refuse(node, f"++ and -- take a number or a pointer; this is {target.t.spelled()}")
        one = E(ast.Constant(step), target.t, step, step, step)
        return self.convert(self.arithmetic("+", current, one, node), target.t, node, "the result")

    def increment_value(self, node: c_ast.UnaryOp) -> E:
        target = self.lvalue(node.expr)
        step = 1 if "+" in node.op else -1
        if node.op in ("++", "--"):
            return target.store_value(self._stepped(target, node, step))
        old = self.temp("old")
        current = target.load_once()
        saved = E(ast.NamedExpr(_name(old, True), current.py), current.t, current.lo, current.hi)
        target.cached = saved
        new = self._stepped(target, node, step)
        stored = target.store_value(new)
        return E(ast.Subscript(ast.Tuple([stored.py, _name(old)], ast.Load()), ast.Constant(1), ast.Load()),
                 current.t, current.lo, current.hi)


class _RomString:
    """A string literal: its characters in program memory (NUL included), plain chars (`element`)."""

    def __init__(self, data: tuple[int, ...], element: tuple[int, bool, bool, str], name: str):
        self.data, self.element, self.name = data, element, name


class _LValue:
    """Where a value is stored: loaded, stored (as statements, or as an expression giving the value stored)."""

    t: CType
    name: str = ""
    cached: E | None = None

    def __init__(self, translator: Translator, node: Any):
        self.tr, self.node = translator, node

    def load(self) -> ast.expr:
        raise NotImplementedError

    def load_once(self) -> E:
        if self.cached is not None:
            return self.cached
        py = self.load()
        t = self.t
        lo, hi = (t.low, t.high) if isinstance(t, Int) else (None, None)
        return E(py, t, lo, hi, name=self.name)

    def store(self, value: ast.expr) -> list[ast.stmt]:
        raise NotImplementedError

    def store_value(self, value: ast.expr) -> E:
        temp = self.tr.temp("v")
        held = ast.NamedExpr(_name(temp, True), value)
        stmts = self.store(_name(temp))
        assert len(stmts) == 1
        stmt = stmts[0]
        effect = stmt.value if isinstance(stmt, ast.Expr) else _assign_as_call(stmt)
        t = self.t
        lo, hi = (t.low, t.high) if isinstance(t, Int) else (None, None)
        return E(ast.Subscript(ast.Tuple([held, effect, _name(temp)], ast.Load()), ast.Constant(2), ast.Load()),
                 t, lo, hi)


class _VarLV(_LValue):
    def __init__(self, translator: Translator, sym: Sym, node: Any):
        super().__init__(translator, node)
        self.sym, self.t, self.name = sym, sym.ctype, sym.name

    def target(self) -> ast.expr:
        if self.sym.boxed:
            return ast.Subscript(_name(self.sym.py), ast.Constant(0), ast.Store())
        return _name(self.sym.py, True)

    def load(self) -> ast.expr:
        if self.sym.boxed:
            return ast.Subscript(_name(self.sym.py), ast.Constant(0), ast.Load())
        return _name(self.sym.py)

    def store(self, value: ast.expr) -> list[ast.stmt]:
        return [ast.Assign([self.target()], value)]

    def store_value(self, value: ast.expr) -> E:
        t = self.t
        lo, hi = (t.low, t.high) if isinstance(t, Int) else (None, None)
        if not self.sym.boxed:
            return E(ast.NamedExpr(_name(self.sym.py, True), value), t, lo, hi)
        return super().store_value(value)


class _ItemLV(_LValue):
    """An element of a list: an array's, or a struct's member."""

    def __init__(self, translator: Translator, container: ast.expr, index: ast.expr, t: CType, node: Any):
        super().__init__(translator, node)
        self.t = t
        self.width = t.width if isinstance(t, Int) else None
        self.first_container, self.container = _held(translator, "c", container)
        self.first_index, self.index = _held(translator, "k", index)
        self.used = False

    def _parts(self) -> tuple[ast.expr, ast.expr]:
        if not self.used:
            self.used = True
            return self.first_container, self.first_index
        return _copy(self.container), _copy(self.index)

    def load(self) -> ast.expr:
        container, index = self._parts()
        return ast.Subscript(container, index, ast.Load())

    def store(self, value: ast.expr) -> list[ast.stmt]:
        container, index = self._parts()
        return [ast.Assign([ast.Subscript(container, index, ast.Store())], value)]


class _PtrLV(_LValue):
    """An element through a pointer: the pointer and the offset each evaluated once, also where the element is both
    loaded and stored (`p[g()] += 5`, `*q++ += 1`)."""

    def __init__(self, translator: Translator, pointer: ast.expr, offset: ast.expr, t: CType, node: Any):
        super().__init__(translator, node)
        self.t = t
        if isinstance(t, Void):
            raise translator.refuse(node, "a void pointer points to nothing to store: cast it first")
        if t.rom or t.const:
            raise translator.refuse(node, f"this points to {'program memory' if t.rom else 'a const'}: it "
                                          "cannot be written")
        self.first_pointer, self.pointer = _held(translator, "p", pointer)
        self.first_offset, self.offset = _held(translator, "k", offset)
        self.used = False

    def _parts(self) -> list[ast.expr]:
        if not self.used:
            self.used = True
            return [self.first_pointer, self.first_offset]
        return [_copy(self.pointer), _copy(self.offset)]

    def load(self) -> ast.expr:
        return _rt("deref", self._parts())

    def _stored(self, value: ast.expr) -> ast.expr:
        if self.used:       # `value` holds the load, which evaluates the pointer and the offset: it comes first
            return _rt("put", [value, *self._parts()])
        return _rt("store", [*self._parts(), value])

    def store(self, value: ast.expr) -> list[ast.stmt]:
        return [ast.Expr(self._stored(value))]

    def store_value(self, value: ast.expr) -> E:
        t = self.t
        lo, hi = (t.low, t.high) if isinstance(t, Int) else (None, None)
        return E(self._stored(value), t, lo, hi)


def _void_arithmetic(translator: Translator, node: Any) -> _Refused:
    return translator.refuse(node, "arithmetic on a void pointer: void has no size, so C does not say how far it "
                                   "moves; cast it to a pointer to what it points at first")


def _held(translator: Translator, kind: str, py: ast.expr) -> tuple[ast.expr, ast.expr]:
    """`py` as first used (kept in a temporary, unless it is a name or a constant) and as used again."""
    if _simple(py):
        return py, py
    temp = translator.temp(kind)
    return ast.NamedExpr(_name(temp, True), py), _name(temp)


class _SfrLV(_LValue):
    """A register, or one of its bit fields: a write is a register write; a bit field's is read-modify-write (the
    value first, then the register read, then the write: as the Python firmware's `RXB0CONbits.RXFUL = 0`)."""

    def __init__(self, translator: Translator, address: int, bits: tuple[int, int] | None, node: Any):
        super().__init__(translator, node)
        self.address, self.bits = address, bits
        self.t = T.UCHAR if bits is None else replace(T.UCHAR, width=bits[1])

    def _read(self) -> ast.expr:
        return _call(ast.Attribute(_name(MCU), "read", ast.Load()), [ast.Constant(self.address)])

    def load(self) -> ast.expr:
        if self.bits is None:
            return self._read()
        shift, width = self.bits
        py: ast.expr = self._read()
        if shift:
            py = ast.BinOp(py, ast.RShift(), ast.Constant(shift))
        if shift + width < 8:
            py = ast.BinOp(py, ast.BitAnd(), ast.Constant((1 << width) - 1))
        return py

    def store(self, value: ast.expr) -> list[ast.stmt]:
        write = ast.Attribute(_name(MCU), "write", ast.Load())
        if self.bits is None:
            return [ast.Expr(_call(write, [ast.Constant(self.address), value]))]
        shift, width = self.bits
        mask = ((1 << width) - 1) << shift
        if isinstance(value, ast.Constant) and isinstance(value.value, int):
            bits = (value.value << shift) & mask
            kept = ast.BinOp(self._read(), ast.BitAnd(), ast.Constant(~mask & 0xFF))
            new: ast.expr = kept if bits == 0 else ast.BinOp(kept, ast.BitOr(), ast.Constant(bits))
        else:
            shifted = ast.BinOp(ast.BinOp(value, ast.LShift(), ast.Constant(shift)), ast.BitAnd(), ast.Constant(mask))
            new = ast.BinOp(shifted, ast.BitOr(), ast.BinOp(self._read(), ast.BitAnd(), ast.Constant(~mask & 0xFF)))
        return [ast.Expr(_call(write, [ast.Constant(self.address), new]))]


# ====================================================================== helpers
def _assign_as_call(stmt: ast.stmt) -> ast.expr:
    """An `x[k] = v` statement as an expression (for an assignment used as a value)."""
    assert isinstance(stmt, ast.Assign) and isinstance(stmt.targets[0], ast.Subscript)
    target = stmt.targets[0]
    return _call(ast.Attribute(target.value, "__setitem__", ast.Load()), [target.slice, stmt.value])


def _simple(py: ast.expr) -> bool:
    return isinstance(py, (ast.Name, ast.Constant))


def _copy(node: Any) -> Any:
    """A fresh copy of an expression tree (a node may appear once in a tree)."""
    return _strip_walrus(copy.deepcopy(node))


class _StripWalrus(ast.NodeTransformer):
    """In a copy, `(t := e)` has done its work already: it becomes `t`."""

    def visit_NamedExpr(self, node: ast.NamedExpr) -> ast.expr:
        return ast.copy_location(ast.Name(node.target.id, ast.Load()), node)


def _strip_walrus(node: Any) -> Any:
    return _StripWalrus().visit(node)


def _name(identifier: str, store: bool = False) -> ast.Name:
    return ast.Name(identifier, ast.Store() if store else ast.Load())


def _call(func: ast.expr, args: list[ast.expr]) -> ast.Call:
    return ast.Call(func, args, [])


def _rt(helper: str, args: list[ast.expr]) -> ast.Call:
    return _call(ast.Attribute(_name(RT), helper, ast.Load()), args)


def _bytes(n: int) -> str:
    return f"{n} byte{'s' if n != 1 else ''}"


def _element(t: CType) -> ast.Constant:
    """What a memory object of elements `t` holds, for its pointers (`runtime.Element`): size, signed, an integer,
    spelled."""
    return ast.Constant(_element_value(t))      # type: ignore[arg-type]  # a tuple of constants is one


def _element_value(t: CType) -> tuple[int, bool, bool, str]:
    t = t.unqualified()
    if isinstance(t, Int):
        return t.size, t.signed, True, t.spelled()
    try:
        size = t.size
    except (ValueError, NotImplementedError):    # an incomplete struct, a function: nothing a pointer reads
        size = 0
    return size, False, False, t.spelled()


def _first_bit(sym: Sym) -> str:
    return next(iter(BITFIELDS[sym.name[:-4]]))


def _no_bit(bits: str, bit: str, fields: dict[str, tuple[int, int]]) -> str:
    return f"{bits} has no bit or field named {bit}; it has {', '.join(fields)}"


def _stored_names(nodes: list[ast.stmt]) -> set[str]:
    """The names the statements assign (ast.walk's Name nodes in a Store context, walked without its cost)."""
    found = set()
    stack: list[Any] = list(nodes)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Name):
            if isinstance(node.ctx, ast.Store):
                found.add(node.id)
        else:
            _push_children(node, stack)
    return found


def _push_children(node: ast.AST, stack: list[Any]) -> None:
    """Put the node's children on `stack` (ast.iter_child_nodes's, without the leaves: Load, Add ...), looking only
    in the fields that may hold nodes."""
    fields = _NODE_FIELDS.get(type(node))
    if fields is None:
        fields = _NODE_FIELDS[type(node)] = (() if isinstance(node, ast.Constant) else
                                             tuple(f for f in node._fields if f not in _NEVER_NODES))
    for name in fields:
        value = getattr(node, name, None)
        if isinstance(value, list):
            stack += [item for item in value if isinstance(item, ast.AST) and not isinstance(item, _LEAVES)]
        elif isinstance(value, ast.AST) and not isinstance(value, _LEAVES):
            stack.append(value)


# The fields of Python's AST (its ASDL) that hold an identifier, a number or a flag, never a node to walk into; and
# the rest of each node type's fields, as they are met.
_NEVER_NODES = frozenset({"id", "ctx", "op", "attr", "arg", "kind", "type_comment", "name", "module", "level",
                          "is_async", "conversion", "simple"})
_NODE_FIELDS: dict[type, tuple[str, ...]] = {}


def _addressed(tree: Any) -> set[str]:
    """The names whose address the file takes (&name): those variables live in a list of one."""
    found = set()
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, c_ast.UnaryOp) and node.op == "&" and isinstance(node.expr, c_ast.ID):
            found.add(node.expr.name)
        stack.extend(child for _, child in node.children())
    return found


_ESCAPES = {"n": 10, "t": 9, "r": 13, "0": 0, "a": 7, "b": 8, "f": 12, "v": 11, "\\": 92, "'": 39, '"': 34, "?": 63}


def _string_codes(text: str, tr: Translator, node: Any, quoted: bool = True) -> list[int]:
    """The character codes of a C string literal (its quotes included, unless not `quoted`)."""
    if quoted:
        if not (text.startswith('"') and text.endswith('"')):
            raise tr.refuse(node, f"{text} is not a string C18 reads")
        text = text[1:-1]
    codes: list[int] = []
    i = 0
    while i < len(text):
        c = text[i]
        if c == '"' and quoted and text.startswith('" "', i):
            i += 3                      # where pycparser kept two adjacent literals apart: "\x41" "BC" is A, B, C
            continue
        if c != "\\":
            code = ord(c)
            if code > 0xFF:
                raise tr.refuse(node, f"the character {c!r} is not one byte: the GLCD and the USART take codes 0..255")
            codes.append(code)
            i += 1
            continue
        i += 1
        c = text[i] if i < len(text) else ""
        if c == "x":
            j = i + 1
            while j < len(text) and text[j] in "0123456789abcdefABCDEF":
                j += 1
            if j == i + 1:
                raise tr.refuse(node, "\\x without hexadecimal digits after it: write \\x41 for 'A'")
            codes.append(_escape_code(f"\\{text[i:j]}", int(text[i + 1:j], 16), tr, node))
            i = j
        elif c in "01234567":
            j = i
            while j < len(text) and j < i + 3 and text[j] in "01234567":
                j += 1
            codes.append(_escape_code(f"\\{text[i:j]}", int(text[i:j], 8), tr, node))
            i = j
        elif c in _ESCAPES:
            codes.append(_ESCAPES[c])
            i += 1
        else:
            raise tr.refuse(node, f"\\{c} is not an escape C knows")
    return codes


def _escape_code(escape: str, code: int, tr: Translator, node: Any) -> int:
    """An escape's character code, refused past one byte (C requires a diagnostic there; C18 gives one)."""
    if code > 0xFF:
        raise tr.refuse(node, f"the escape {escape} is out of range: a char holds 0..255 (0xFF, \\377). \\x takes "
                              "every hexadecimal digit after it: end the string there (\"\\x41\" \"BC\") to "
                              "follow it with a letter")
    return code


_COMPARE = {"==": ast.Eq, "!=": ast.NotEq, "<": ast.Lt, "<=": ast.LtE, ">": ast.Gt, ">=": ast.GtE}
_FOLD_COMPARE = {"==": lambda a, b: a == b, "!=": lambda a, b: a != b, "<": lambda a, b: a < b,
                 "<=": lambda a, b: a <= b, ">": lambda a, b: a > b, ">=": lambda a, b: a >= b}
_ARITH = {"+": ast.Add, "-": ast.Sub, "*": ast.Mult, "&": ast.BitAnd, "|": ast.BitOr, "^": ast.BitXor}


def _c_div(a: int, b: int) -> int:
    q = abs(a) // abs(b)
    return q if (a < 0) == (b < 0) else -q


def _c_mod(a: int, b: int) -> int:
    r = abs(a) % abs(b)
    return r if a >= 0 else -r


_FOLD = {"+": lambda a, b: a + b, "-": lambda a, b: a - b, "*": lambda a, b: a * b, "&": lambda a, b: a & b,
         "|": lambda a, b: a | b, "^": lambda a, b: a ^ b, "/": _c_div, "%": _c_mod}
_PY_RESERVED = {"False", "None", "True", "and", "as", "assert", "async", "await", "class", "def", "del", "elif",
                "except", "finally", "from", "global", "import", "in", "is", "lambda", "nonlocal", "not", "or",
                "pass", "raise", "try", "with", "yield", "main", "print", "len", "range", "__rt", "__M"}
_ARITY_HINTS = {
    ("OpenADC", 2): (": the two-argument OpenADC(config, config2) is C18's for parts without an acquisition time; for "
                     "the PIC18F8680 it is OpenADC(config, config2, portconfig), the ADC_nANA port configuration "
                     "third and an ADC_n_TAD in config: OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD, ADC_CH0 & "
                     "ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS, ADC_1ANA)"),
}
_HINTS = {
    "RXB0CONbits": ": #include <p18f8680.h> declares the registers",
    "CANInitialize": ": #include \"CAN18XX8.h\"", "CANIsRxReady": ": #include \"CAN18XX8.h\"",
    "putsGLCD": ": #include \"APP023_GLCD.h\"", "putrsGLCD": ": #include \"APP023_GLCD.h\"",
    "sprintf": ": #include <stdio.h>", "OpenADC": ": #include <adc.h>", "OpenTimer1": ": #include <timers.h>",
    "OpenUSART": ": #include <usart.h>", "NULL": ": #include <stdio.h> defines it",
    "printf": ": the kit's stdio.h has sprintf (then putsUSART or putsGLCD the text); printf is not provided",
}


def header_symbols(tree: c_ast.FileAST, filename: str, options: Sequence[str]) -> dict[str, Sym]:
    """The declarations of a kit header, as symbols: registers (at their addresses), their NAMEbits, library
    functions (each bound to its Python implementation), typedefs and enumerators."""
    tr = Translator(filename, [], options, time.process_time() + 60)
    tr.filename = "\0"          # every node is in a header: errors name the header
    for ext in tree.ext:
        try:
            if isinstance(ext, c_ast.Typedef):
                tr.typedef(ext)
            elif isinstance(ext, c_ast.Decl):
                if ext.name is None:
                    tr.base_type(ext.type, ext)
                    continue
                if ext.name.endswith("bits") and ext.name[:-4] in BITFIELDS and isinstance(ext.type, c_ast.TypeDecl) \
                        and isinstance(ext.type.type, c_ast.Union):
                    tr.declare(Sym(ext.name, "bits", T.UCHAR, value=ADDRESSES[ext.name[:-4]]), ext)
                    continue
                ctype = tr.type_of(ext.type, ext.quals)
                if isinstance(ctype, Function):
                    if ext.name not in BINDINGS:
                        raise RuntimeError(f"{filename} declares {ext.name}, which the kit does not provide")
                    tr.declare(Sym(ext.name, "lib", ctype, py=library_name(ext.name)), ext)
                elif ext.name in ADDRESSES:
                    tr.declare(Sym(ext.name, "sfr", ctype, value=ADDRESSES[ext.name]), ext)
                else:
                    raise RuntimeError(f"{filename} declares {ext.name}, which is no register of the kit")
        except _Refused as refused:
            raise RuntimeError(f"{filename}: {refused}") from None
    return tr.scopes[0]


def library_name(name: str) -> str:
    """The Python name the translation calls library function `name` by."""
    return name if name in OWN_NAMES else LIB + name


def device_symbols() -> dict[str, Sym]:
    """The symbols of p18f8680.h, from the register map it is written from (appsim.firmware.c18.headers)."""
    symbols: dict[str, Sym] = {}
    register = T.UCHAR.qualified(volatile=True)
    for name, address in ADDRESSES.items():
        symbols[name] = Sym(name, "sfr", register, value=address)
        if name in BITFIELDS:
            symbols[f"{name}bits"] = Sym(f"{name}bits", "bits", T.UCHAR, value=address)
    for name in ("Nop", "ClrWdt", "Reset"):
        symbols[name] = Sym(name, "lib", Function(result=T.VOID), py=library_name(name))
    return symbols
