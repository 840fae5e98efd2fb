"""What translated C firmware runs on besides the board: pointers into its memory objects, C's division, strings,
and C18's sprintf, each checking what C18 lets through (an index past the end, a char where %X reads an int).

Memory is objects, not bytes: an array is a list (a tuple in program memory), a struct a list of its members, a
variable whose address is taken a list of one. A pointer is one of those objects, an index in it and what it holds;
memcpy and memset see an integer's bytes, lowest first, as C18 lays them out.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from appsim.chip.polling import compared_by_slots
from appsim.errors import CRuntimeError

Element = tuple[int, bool, bool, str]     # what a memory object holds: its size in bytes, signed, an integer, spelled
BYTE: Element = (1, False, True, "unsigned char")


class Ptr:
    """A C pointer to element `i` of memory object `mem` (called `name` in messages), which it may reach from `lo`
    up to `hi` (excluded): a whole array, or the one variable or member it points to. `rom`: in program memory;
    `element`: what the object holds (`Element`), so that what is written there keeps its type (a byte written into
    a char array is a char) and a pointer to another type is refused or reads through a `View`."""

    __slots__ = ("mem", "i", "lo", "hi", "name", "rom", "element")

    def __init__(self, mem: Any, i: int, lo: int, hi: int, name: str, rom: bool = False, element: Element = BYTE):
        self.mem, self.i, self.lo, self.hi, self.name, self.rom, self.element = mem, i, lo, hi, name, rom, element

    @property
    def reads(self) -> Element:
        """The type an element has read through this pointer (a `View`'s own)."""
        return self.element

    def get(self, k: int = 0) -> Any:
        i = self.i + k
        if not self.lo <= i < self.hi:
            raise CRuntimeError(self._outside(i, "read"))
        return self.mem[i]

    def set(self, k: int, value: Any) -> Any:
        """Store `value`, of the type this pointer reads (the translator made it so)."""
        i = self.i + k
        if not self.lo <= i < self.hi:
            raise CRuntimeError(self._outside(i, "write"))
        if self.rom:
            raise CRuntimeError(f"a write through a pointer into program memory ({self.name}): ROM cannot be written "
                                "by a store, so C18 would not change it")
        self.mem[i] = value
        return value

    def set_integer(self, k: int, value: int) -> int:
        """Store any integer as C converts it to the type this pointer reads (a library's byte into a char)."""
        return self.set(k, wrapped(value, self.reads))

    def add(self, k: int) -> Ptr:
        i = self.i + k
        if not self.lo <= i <= self.hi:
            raise CRuntimeError(f"pointer arithmetic left {self.name}: it points {self._where(i)}, and C only "
                                "lets a pointer go as far as one past the end of the object it points into")
        return self._at(i)

    def _at(self, i: int) -> Ptr:
        return Ptr(self.mem, i, self.lo, self.hi, self.name, self.rom, self.element)

    def same(self, other: object) -> bool:
        return isinstance(other, Ptr) and other.mem is self.mem and other.i == self.i

    def minus(self, other: Ptr) -> int:
        if other.mem is not self.mem:
            raise CRuntimeError(f"subtracting pointers into two different objects ({self.name}, {other.name}): "
                                "C defines the difference only within one array")
        return self.i - other.i

    def _where(self, i: int) -> str:
        n = self.hi - self.lo
        if n == 1:
            return f"{i - self.lo:+d} elements away from {self.name}"
        return f"at element {i - self.lo} of {self.name}, which has {n} (0..{n - 1})"

    def _outside(self, i: int, what: str) -> str:
        n = self.hi - self.lo
        past = "reads whatever lies next to it in RAM" if what == "read" else "overwrites whatever lies next to it"
        if n == 1:
            return f"a {what} {i - self.lo:+d} elements away from {self.name}, which is one variable: C18 {past}"
        return f"a {what} of element {i - self.lo} of {self.name}, which has {n} (0..{n - 1}): C18 {past}"

    def __repr__(self) -> str:
        return f"&{self.name}[{self.i - self.lo}]"


class View(Ptr):
    """A pointer to integers of the other signedness than its object holds (`signed char *s = raw;` over unsigned
    chars): what it reads is converted to its own type, what it stores back to the object's, as the same bytes."""

    __slots__ = ("view",)

    def __init__(self, p: Ptr, i: int, view: Element):
        super().__init__(p.mem, i, p.lo, p.hi, p.name, p.rom, p.element)
        self.view = view

    @property
    def reads(self) -> Element:
        return self.view

    def get(self, k: int = 0) -> Any:
        return wrapped(super().get(k), self.view)

    def set(self, k: int, value: Any) -> Any:
        super().set(k, wrapped(value, self.element))
        return value

    def _at(self, i: int) -> Ptr:
        return View(self, i, self.view)


def wrapped(value: int, element: Element) -> int:
    """`value` as C converts it to the integer type `element` (two's complement, its size's bits)."""
    return as_integer(value, element[0], element[1])


def as_integer(value: int, size: int, signed: bool) -> int:
    """`value` as C converts it to an integer of `size` bytes, `signed` or not."""
    bits = 8 * size
    value &= (1 << bits) - 1
    return value - (1 << bits) if signed and value >= 1 << (bits - 1) else value


def viewed(p: Ptr | None, element: Element) -> Ptr | None:
    """`p` converted to a pointer to `element` (through void *, or to the other signedness): the same object, read as
    that type where the bytes mean the same (a `View`), refused where they would not (an int seen as chars)."""
    if p is None or p.reads == element:
        return p
    held = p.element
    if held == element:
        return Ptr(p.mem, p.i, p.lo, p.hi, p.name, p.rom, held)
    if held[0] == element[0] and held[2] and element[2]:
        return View(p, p.i, element)
    raise CRuntimeError(f"a pointer to {element[3]} ({_bytes(element[0])}) is made to point into {p.name}, which "
                        f"holds {held[3]} ({_bytes(held[0])}), through a void pointer: the kit's C keeps memory as "
                        f"objects, not bytes, and does not read one type as another. Point at it with a "
                        f"{held[3]} *")


def _bytes(n: int) -> str:
    return "1 byte" if n == 1 else f"{n} bytes"


compared_by_slots(Ptr)          # a loop that counts through a pointer (`*p++ = ADRESH`) counts
compared_by_slots(View)


class NoValue:
    """What a function that ended without `return` gives (C18 leaves whatever the W register held): using it in any
    way, arithmetic, a comparison, a store into a register, is a run-time error that says so."""

    __slots__ = ("function", "line")

    def __init__(self, function: str, line: int):
        self.function, self.line = function, line

    def _used(self, *args: object) -> Any:
        raise CRuntimeError(f"the value of {self.function}() is used, but {self.function}() (line {self.line}) ended "
                            "without return: C18 gives whatever the W register held, garbage. End it with return and "
                            "its value")

    __add__ = __radd__ = __sub__ = __rsub__ = __mul__ = __rmul__ = __floordiv__ = __rfloordiv__ = _used
    __truediv__ = __rtruediv__ = __mod__ = __rmod__ = __lshift__ = __rlshift__ = __rshift__ = __rrshift__ = _used
    __and__ = __rand__ = __or__ = __ror__ = __xor__ = __rxor__ = __neg__ = __pos__ = __invert__ = __abs__ = _used
    __lt__ = __le__ = __gt__ = __ge__ = __eq__ = __ne__ = __bool__ = __int__ = __index__ = _used
    __hash__ = None                     # type: ignore[assignment]


def outside(name: str, index: int, length: int, write: bool = False) -> int:
    """An index past an array's end: the C runtime error for it (C18 would read or overwrite its neighbour)."""
    past = "overwrites whatever lies after it in RAM" if write else "reads whatever lies after it in RAM"
    raise CRuntimeError(f"{name}[{index}] is outside {name}, which has {length} elements (0..{length - 1}): "
                        f"C18 does not check, and {past}")


def null(what: str) -> Any:
    raise CRuntimeError(f"{what} through a NULL pointer: nothing is there (on the board it reads or writes the "
                        "register file at address 0)")


def deref(p: Ptr | None, k: int = 0) -> Any:
    return null("a read") if p is None else p.get(k)


def store(p: Ptr | None, k: int, value: Any) -> Any:
    return null("a write") if p is None else p.set(k, value)


def put(value: Any, p: Ptr | None, k: int) -> Any:
    """`store`, for a value computed first (`*q++ += 1`: the element loaded, then the pointer it came from)."""
    return null("a write") if p is None else p.set(k, value)


def advance(p: Ptr | None, k: int) -> Ptr | None:
    if p is None:
        return null("arithmetic") if k else None
    return p.add(k)


def order(p: Ptr | None, q: Ptr | None, op: str) -> int:
    """Where `p` is against `q` (negative: before), for `p < q` and the like: C defines it within one object only."""
    if p is None or q is None:
        raise CRuntimeError(f"a pointer is compared by order ({op}) with a NULL pointer: C defines <, <=, >, >= only "
                            "between pointers into one array; test a pointer with == NULL or != NULL")
    if p.mem is not q.mem:
        raise CRuntimeError(f"pointers into two different objects ({p.name}, {q.name}) are compared by order ({op}): "
                            "C defines it only within one array")
    return p.i - q.i


def difference(p: Ptr | None, q: Ptr | None) -> int:
    """`p - q`: how many elements apart, within one object."""
    if p is None or q is None:
        raise CRuntimeError("a pointer difference with a NULL pointer: C defines p - q only between pointers into "
                            "one array")
    return p.minus(q)


def same(p: Ptr | None, q: Ptr | None) -> bool:
    return p is q if p is None or q is None else p.same(q)


def divide(a: int, b: int) -> int:
    """C's division: truncated toward zero."""
    if b == 0:
        raise CRuntimeError("a division by zero: C leaves the result undefined (C18's routine returns garbage)")
    q = abs(a) // abs(b)
    return q if (a < 0) == (b < 0) else -q


def remainder(a: int, b: int) -> int:
    """C's %: the sign of the dividend."""
    if b == 0:
        raise CRuntimeError("a remainder of a division by zero: C leaves the result undefined")
    r = abs(a) % abs(b)
    return r if a >= 0 else -r


MAX_SHIFT = 64              # a shift count past every C18 type's width: beyond it the result is the same


def shift_count(n: int) -> int:
    """A shift's count, at most MAX_SHIFT (1UL << 4000000000 would build a 500 MB number); a negative one is an
    error."""
    if n < 0:
        raise CRuntimeError(f"a shift by {n}: C leaves a negative shift count undefined")
    return min(n, MAX_SHIFT)


def copy(value: Any) -> Any:
    """A struct or array value, copied (C assigns structs by value)."""
    return [copy(item) for item in value] if isinstance(value, list) else value


# ------------------------------------------------------------------ strings
def string_at(p: Ptr | None, function: str) -> list[int]:
    """The characters of the C string `p` points to, up to its NUL (not included)."""
    if p is None:
        raise CRuntimeError(f"{function} was given a NULL pointer where it reads a string")
    mem, i, hi = p.mem, p.i, p.hi
    codes: list[int] = []
    while i < hi:
        code = mem[i]
        if code == 0:
            return codes
        codes.append(code & 0xFF)
        i += 1
    raise CRuntimeError(f"{function} reads a string from {p.name}, and there is no NUL ('\\0') in it: C18 would "
                        f"read on past its end. Leave room for the NUL that ends a C string")


def put_string(p: Ptr | None, codes: Sequence[int], function: str) -> None:
    """Write `codes` and a NUL at `p`."""
    if p is None:
        raise CRuntimeError(f"{function} was given a NULL pointer where it writes a string")
    if p.rom:
        raise CRuntimeError(f"{function} writes into {p.name}, which is in program memory (rom)")
    if len(codes) + 1 > p.hi - p.i:
        raise _no_room(function, len(codes) + 1, p)
    for k, code in enumerate(codes):
        p.set_integer(k, code)
    p.set(len(codes), 0)


def _no_room(function: str, needed: int, p: Ptr, at_least: bool = False) -> CRuntimeError:
    return CRuntimeError(f"{function} writes {'at least ' if at_least else ''}{needed} bytes (the NUL included) into "
                         f"{p.name}, which has room for {p.hi - p.i} there: C18 would overwrite whatever lies after it")


def bytes_at(p: Ptr | None, n: int, function: str) -> bytes:
    """`n` bytes from `p` (an array of BYTE, say)."""
    if n == 0:
        return b""
    if p is None:
        raise CRuntimeError(f"{function} reads {n} bytes through a NULL pointer")
    if p.i + n > p.hi:
        raise CRuntimeError(f"{function} reads {n} bytes from {p.name}, which has {p.hi - p.i} from there: C18 would "
                            "read whatever lies after it")
    return bytes(v & 0xFF for v in p.mem[p.i:p.i + n])


# ------------------------------------------------------------------ sprintf
class Arg:
    """An argument after sprintf's format as C18 pushes it: its value, its size in bytes, its C type as written and
    what it is (`int`, `ram` or `rom` for strings, `ptr`); `promoted`: by -Oi's default argument promotions, as ISO
    C pushes it (a char as an int, which %c and %hhd read and convert)."""

    __slots__ = ("value", "size", "spelled", "kind", "constant", "promoted")

    def __init__(self, value: Any, size: int, spelled: str, kind: str, constant: bool, promoted: bool = False):
        self.value, self.size, self.spelled, self.kind, self.constant = value, size, spelled, kind, constant
        self.promoted = promoted


_LENGTHS = {"hh": (1, "a char"), "h": (2, "an int"), "": (2, "an int"), "H": (3, "a short long"),
            "l": (4, "a long")}


def sprintf(buf: Ptr | None, fmt: Ptr | None, *args: Arg) -> int:
    """C18's sprintf: the format from program memory, the arguments as pushed (not promoted)."""
    text = string_at(fmt, "sprintf's format")
    out: list[int] = []
    pending = list(args)
    i, n = 0, len(text)

    def next_arg(spec: str) -> Arg:
        if not pending:
            raise CRuntimeError(f"sprintf: {spec} has no argument left to read: C18 would read whatever lies on "
                                "the stack")
        return pending.pop(0)

    while i < n:
        c = text[i]
        if c != 0x25:           # '%'
            out.append(c)
            i += 1
            continue
        start = i
        i += 1
        flags = ""
        while i < n and chr(text[i]) in "-+ #0":
            flags += chr(text[i])
            i += 1
        width: int | None = None
        if i < n and text[i] == 0x2A:       # '*'
            width = _int_of(next_arg("*"), 2, True, "*")
            if width < 0:                   # a negative width is the - flag and the width
                flags, width = flags + "-", -width
            i += 1
        else:
            digits = ""
            while i < n and 0x30 <= text[i] <= 0x39:
                digits += chr(text[i])
                i += 1
            width = int(digits) if digits else None
        if width is not None and buf is not None and width + 1 > buf.hi - buf.i:   # no room whatever comes after
            raise _no_room("sprintf", len(out) + width + 1, buf, at_least=True)     # before it pads (%999999999d)
        precision: int | None = None
        if i < n and text[i] == 0x2E:       # '.'
            i += 1
            digits = ""
            while i < n and 0x30 <= text[i] <= 0x39:
                digits += chr(text[i])
                i += 1
            precision = int(digits or "0")
        length = ""
        while i < n and chr(text[i]) in "hlHjzt":
            length += chr(text[i])
            i += 1
        if i >= n:
            raise CRuntimeError(f"sprintf's format ends in the middle of a conversion ({bytes(text[start:]).decode()})")
        conversion = chr(text[i])
        i += 1
        spec = bytes(text[start:i]).decode("latin-1")
        if conversion == "%":
            out.append(0x25)
            continue
        if conversion in "diouxXbB":
            if length not in _LENGTHS:
                raise CRuntimeError(f"sprintf: {spec}: C18 knows no length {length!r} (hh, h, H, l)")
            size, what = _LENGTHS[length]
            arg = next_arg(spec)
            value = _int_of(arg, _pushed(arg, size), conversion in "di", spec, what)
            if size < _pushed(arg, size):   # %hhd of a promoted char: read as an int, converted to a char
                value = as_integer(value, size, conversion in "di")
            if precision is not None and buf is not None and precision + 1 > buf.hi - buf.i:
                raise _no_room("sprintf", len(out) + precision + 1, buf, at_least=True)   # %.999999999d
            digits = _digits(value, conversion, precision)
            sign = "-" if value < 0 else "" if conversion not in "di" else \
                "+" if "+" in flags else " " if " " in flags else ""        # + and space: signed conversions only
            prefix = ""
            if "#" in flags and value:
                prefix = {"x": "0x", "X": "0X", "o": "0", "b": "0b", "B": "0B"}.get(conversion, "")
                if conversion == "o" and digits.startswith("0"):           # # makes the first digit a 0, if not
                    prefix = ""
            body = sign + prefix + digits
            if width is not None and len(body) < width:
                if "-" in flags:
                    body = body + " " * (width - len(body))
                elif "0" in flags and precision is None:
                    body = sign + prefix + "0" * (width - len(body)) + digits
                else:
                    body = " " * (width - len(body)) + body
            out.extend(body.encode("latin-1"))
        elif conversion == "c":
            arg = next_arg(spec)
            code = _int_of(arg, _pushed(arg, 1), False, spec, "a char") & 0xFF
            field_ = [code]
            out.extend(_pad(field_, width, flags))
        elif conversion in "sS":
            arg = next_arg(spec)
            want = "ram" if conversion == "s" else "rom"
            if arg.kind not in ("ram", "rom"):
                raise CRuntimeError(f"sprintf: {spec} reads a string (a char pointer), but its argument is "
                                    f"{arg.spelled}")
            if arg.kind != want:
                raise CRuntimeError(
                    f"sprintf: {spec} reads a string in {'RAM' if want == 'ram' else 'program memory'}, but its "
                    f"argument ({arg.spelled}) is in {'program memory' if arg.kind == 'rom' else 'RAM'}: use "
                    f"{'%S' if arg.kind == 'rom' else '%s'} for it, as C18 tells the two memories apart")
            codes = string_at(arg.value, f"sprintf's {spec}")
            if precision is not None:
                codes = codes[:precision]
            out.extend(_pad(codes, width, flags))
        elif conversion in "pP":
            arg = next_arg(spec)
            if arg.kind not in ("ram", "rom", "ptr"):
                raise CRuntimeError(f"sprintf: {spec} reads a pointer, but its argument is {arg.spelled}")
            out.extend(_pad(list(repr(arg.value).encode("latin-1")), width, flags))
        else:
            raise CRuntimeError(f"sprintf: {spec}: C18's sprintf has no conversion %{conversion} (it has no floating "
                                "point: %d %i %u %o %x %X %b %B %c %s %S %p %%)")
    if pending:
        raise CRuntimeError(f"sprintf was given {len(pending)} argument{'s' if len(pending) > 1 else ''} more than "
                            "its format reads: a conversion is missing from the format")
    put_string(buf, out, "sprintf")
    return len(out)


def _int_of(arg: Arg, size: int, signed: bool, spec: str, what: str = "an int") -> int:
    if arg.kind != "int":
        raise CRuntimeError(f"sprintf: {spec} reads {what}, but its argument is {arg.spelled}")
    if arg.size != size:
        shown = f"{arg.value:#x}" if arg.constant and arg.value >= 0 else str(arg.value)
        why = ("a constant takes the smallest type that holds its value" if arg.constant
               else "the arguments after the format are not promoted")
        lengths = {1: "hh", 2: "", 3: "H", 4: "l"}
        bare = spec[:-1].rstrip("hlHjzt")
        fix = f"{bare}{lengths[arg.size]}{spec[-1]}" if arg.size in lengths else ""
        raise CRuntimeError(
            f"sprintf: {spec} reads {what} ({size} byte{'s' if size > 1 else ''}), but its argument {shown} is "
            f"{arg.spelled} ({arg.size} byte{'s' if arg.size > 1 else ''}): C18 pushes it as it is ({why}), so "
            f"{spec} reads {'bytes past it' if size > arg.size else 'part of it and leaves the rest'}, and what it "
            f"shows is not {shown}. Cast the argument to the size {spec} reads"
            + (f", or write {fix}" if fix and fix != spec else "")
            + ("" if arg.constant or size < arg.size else
               f". If it is computed from chars (RxData[3] << 8), C18 computed it in {arg.size} "
               f"byte{'s' if arg.size > 1 else ''} and its high part is lost already: cast the chars before the "
               "arithmetic, ((int)RxData[3] << 8) | RxData[4]"))
    return as_integer(arg.value, size, signed)


def _pushed(arg: Arg, size: int) -> int:
    """The bytes a conversion reading `size` takes from the stack: an int at least, after -Oi's promotions."""
    return max(size, 2) if arg.promoted else size


def _digits(value: int, conversion: str, precision: int | None) -> str:
    magnitude = abs(value)
    base = {"o": 8, "x": 16, "X": 16, "b": 2, "B": 2}.get(conversion, 10)
    digits = ""
    while magnitude:
        digits = "0123456789abcdef"[magnitude % base] + digits
        magnitude //= base
    if conversion == "X":
        digits = digits.upper()
    if precision is None:
        return digits or "0"
    return digits.rjust(precision, "0")


def _pad(codes: list[int], width: int | None, flags: str) -> list[int]:
    if width is None or len(codes) >= width:
        return codes
    space = [0x20] * (width - len(codes))
    return codes + space if "-" in flags else space + codes
