"""MPLAB C18's types: char 8-bit (signed unless -k), int 16, short long 24, long 32; pointers, arrays, structs, and
where an object lives (`rom`: program memory, else RAM). Sizes and ranges as C18 has them; no floating point.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace


@dataclass(frozen=True)
class CType:
    """A C type with its qualifiers: `rom` says the object is in program memory (C18's `rom`), `const` and
    `volatile` as in C."""

    const: bool = field(default=False, kw_only=True)
    volatile: bool = field(default=False, kw_only=True)
    rom: bool = field(default=False, kw_only=True)

    def qualified(self, *, const: bool = False, volatile: bool = False, rom: bool = False) -> CType:
        if (const <= self.const) and (volatile <= self.volatile) and (rom <= self.rom):
            return self                 # nothing added (frozen: the same type; `replace` is slow, and this is hot)
        return replace(self, const=self.const or const, volatile=self.volatile or volatile, rom=self.rom or rom)

    def unqualified(self) -> CType:
        if not (self.const or self.volatile or self.rom):
            return self
        return replace(self, const=False, volatile=False, rom=False)

    @property
    def size(self) -> int:
        raise NotImplementedError

    def spelled(self) -> str:
        """The type as C writes it: `const rom char *`."""
        quals = " ".join(q for q, on in (("const", self.const), ("volatile", self.volatile), ("rom", self.rom)) if on)
        return f"{quals} {self._base()}".strip()

    def _base(self) -> str:
        raise NotImplementedError


@dataclass(frozen=True)
class Void(CType):
    @property
    def size(self) -> int:
        return 1

    def _base(self) -> str:
        return "void"


@dataclass(frozen=True)
class Int(CType):
    """An integer type; `width` is set for a bit-field (its values 0 .. 2**width - 1, or signed)."""

    bytes_: int = 2
    signed: bool = True
    name: str = "int"
    width: int | None = None

    @property
    def size(self) -> int:
        return self.bytes_

    @property
    def bits(self) -> int:
        return self.width if self.width is not None else 8 * self.bytes_

    @property
    def low(self) -> int:
        return -(1 << (self.bits - 1)) if self.signed else 0

    @property
    def high(self) -> int:
        return (1 << (self.bits - 1)) - 1 if self.signed else (1 << self.bits) - 1

    def _base(self) -> str:
        return self.name

    def holds(self, low: int, high: int) -> bool:
        return self.low <= low and high <= self.high


@dataclass(frozen=True)
class Pointer(CType):
    target: CType = field(default_factory=Void)

    @property
    def size(self) -> int:
        return 2            # a near data pointer, or a near rom pointer (the small memory model)

    def spelled(self) -> str:
        inner = self.target.spelled()
        quals = " ".join(q for q, on in (("const", self.const), ("volatile", self.volatile)) if on)
        return f"{inner} *{(' ' + quals) if quals else ''}"

    def _base(self) -> str:
        return self.spelled()


@dataclass(frozen=True)
class Array(CType):
    element: CType = field(default_factory=Void)
    length: int | None = None

    @property
    def size(self) -> int:
        if self.length is None:
            raise ValueError("an array of unknown size has no size")
        return self.length * self.element.size

    def spelled(self) -> str:
        return f"{self.element.spelled()}[{'' if self.length is None else self.length}]"

    def _base(self) -> str:
        return self.spelled()


@dataclass(frozen=True)
class Member:
    name: str
    ctype: CType
    width: int | None = None


@dataclass(frozen=True)
class Struct(CType):
    """A struct type; its members are known once it is complete (`members` is None before)."""

    tag: str = ""
    members: tuple[Member, ...] | None = None
    key: int = 0                # tells apart two structs of one tag in different scopes

    @property
    def size(self) -> int:
        if self.members is None:
            raise ValueError(f"struct {self.tag} is incomplete")
        total, bits = 0, 0
        for member in self.members:
            if member.width is not None:
                bits += member.width
                continue
            total += (bits + 7) // 8 + member.ctype.size
            bits = 0
        return max(1, total + (bits + 7) // 8)

    def index(self, name: str) -> int | None:
        for number, member in enumerate(self.members or ()):
            if member.name == name:
                return number
        return None

    def _base(self) -> str:
        return f"struct {self.tag or '(unnamed)'}"


@dataclass(frozen=True)
class Function(CType):
    result: CType = field(default_factory=Void)
    params: tuple[CType, ...] = ()
    names: tuple[str, ...] = ()
    variadic: bool = False

    @property
    def size(self) -> int:
        return 2

    def _base(self) -> str:
        params = ", ".join(p.spelled() for p in self.params) or "void"
        return f"{self.result.spelled()} (*)({params}{', ...' if self.variadic else ''})"


CHAR = Int(bytes_=1, signed=True, name="char")
SCHAR = Int(bytes_=1, signed=True, name="signed char")
UCHAR = Int(bytes_=1, signed=False, name="unsigned char")
INT = Int(bytes_=2, signed=True, name="int")
UINT = Int(bytes_=2, signed=False, name="unsigned int")
SHORT = Int(bytes_=2, signed=True, name="short")
USHORT = Int(bytes_=2, signed=False, name="unsigned short")
SLONG = Int(bytes_=3, signed=True, name="short long")
USLONG = Int(bytes_=3, signed=False, name="unsigned short long")
LONG = Int(bytes_=4, signed=True, name="long")
ULONG = Int(bytes_=4, signed=False, name="unsigned long")
VOID = Void()

# Type specifiers as written (sorted) -> the type.
_SPECIFIERS: dict[tuple[str, ...], Int] = {}
for _words, _type in (
        (("char",), CHAR), (("signed", "char"), SCHAR), (("unsigned", "char"), UCHAR),
        (("int",), INT), (("signed",), INT), (("signed", "int"), INT), (("unsigned",), UINT),
        (("unsigned", "int"), UINT),
        (("short",), SHORT), (("short", "int"), SHORT), (("signed", "short"), SHORT),
        (("signed", "short", "int"), SHORT), (("unsigned", "short"), USHORT), (("unsigned", "short", "int"), USHORT),
        (("short", "long"), SLONG), (("signed", "short", "long"), SLONG), (("unsigned", "short", "long"), USLONG),
        (("long",), LONG), (("long", "int"), LONG), (("signed", "long"), LONG), (("signed", "long", "int"), LONG),
        (("unsigned", "long"), ULONG), (("unsigned", "long", "int"), ULONG)):
    _SPECIFIERS[tuple(sorted(_words))] = _type


def integer_type(words: list[str], unsigned_char: bool = False) -> Int | None:
    """The integer type some type specifiers name (`['unsigned', 'char']`), None if they name none.
    `unsigned_char`: plain char is unsigned (C18's -k)."""
    found = _SPECIFIERS.get(tuple(sorted(words)))
    if found is CHAR and unsigned_char:
        return replace(UCHAR, name="char")
    return found


def is_char_string(ctype: CType) -> bool:
    """A pointer to (or an array of) 1-byte integers: what string functions take."""
    target = ctype.target if isinstance(ctype, Pointer) else ctype.element if isinstance(ctype, Array) else None
    return isinstance(target, Int) and target.size == 1


def common(a: Int, b: Int, promote: bool) -> Int:
    """The type two integer operands are brought to (C's usual arithmetic conversions); without `promote` (C18's
    default) an 8-bit pair stays 8-bit."""
    if promote:
        a, b = promoted(a), promoted(b)
    if a.size != b.size:
        return plain(a if a.size > b.size else b)
    return plain(a if not a.signed else b)


def promoted(a: Int) -> Int:
    """The integer promotion: a type (or bit-field) smaller than int becomes int, which holds all its values."""
    if a.size < 2 or a.width is not None and a.width < 16:
        return INT
    return plain(a)


def plain(a: Int) -> Int:
    """The integer type itself: no qualifier, no bit-field width."""
    return Int(bytes_=a.bytes_, signed=a.signed, name=a.name)


def constant_type(value: int, *, decimal: bool, unsigned: bool, long: bool, promote: bool) -> Int | None:
    """The type of an integer constant: C18 takes the smallest type of the list that holds its value (char first);
    with -Oi, ISO's list (int first). None: no type holds it."""
    if unsigned:
        candidates = [UCHAR, UINT, USLONG, ULONG]
    elif decimal:
        candidates = [CHAR, INT, SLONG, LONG, ULONG]
    else:
        candidates = [CHAR, UCHAR, INT, UINT, SLONG, USLONG, LONG, ULONG]
    if long:
        candidates = [t for t in candidates if t.size == 4]
    if promote:
        candidates = [t for t in candidates if t.size >= 2]
    for candidate in candidates:
        if candidate.low <= value <= candidate.high:
            return candidate
    return None
