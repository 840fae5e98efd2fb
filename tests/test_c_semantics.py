"""What translated C computes is what C18 computes: struct copies, block statics, lvalues through pointers evaluated
once, a value read through a pointer of the other signedness, the string and memory functions, and what C refuses
(found by a differential sweep of the translator against the dialect of docs/c-firmware.md)."""
from __future__ import annotations

from pathlib import Path

import pytest

from appsim.errors import CCompileError, CRuntimeError
from appsim.firmware import c18
from appsim.firmware.loader import crash_message


def _run(source: str, options: tuple[str, ...] = ()) -> dict[str, object]:
    """The C file's globals after its main() ran once (pure computation: no board needed)."""
    module = c18.load(Path("sem.c"), source.encode(), None, options)
    module.__c_main()
    return vars(module)


VALUES = {
    "a struct initialised from a struct is a copy": (
        "struct S { int x; unsigned char c; };\nint r1, r2;\n"
        "void main(void) { struct S a = {1, 2}; struct S b = a; b.x = 5; r1 = a.x; r2 = b.x; }\n",
        {"r1": 1, "r2": 5}),
    "an array of structs initialised from structs, and a struct from *p": (
        "struct S { int x; };\nint r1, r2, r3;\n"
        "void main(void) { struct S a = {1}, b = {2}; struct S arr[2] = {a, b}; struct S *p = &a;\n"
        "    struct S c = *p; arr[0].x = 10; c.x = 30; r1 = a.x; r2 = b.x; r3 = arr[0].x; }\n",
        {"r1": 1, "r2": 2, "r3": 10}),
    "a local struct initialised from a global one is a copy": (
        "struct S { int x; };\nstruct S a = {1};\nint r1;\n"
        "void main(void) { struct S b = a; b.x = 9; r1 = a.x; }\n",
        {"r1": 1}),
    "two block statics of one name in one function are two variables": (
        "int r1, r2;\nvoid f(void) {\n    { static int n = 0; n++; r1 = n; }\n"
        "    { static int n = 100; n++; r2 = n; }\n}\nvoid main(void) { f(); f(); }\n",
        {"r1": 2, "r2": 102}),
    "p[g()] += 5 calls g() once": (
        "unsigned char buf[4] = {10, 20, 30, 40};\nunsigned char calls;\n"
        "unsigned char g(void) { calls++; return calls; }\n"
        "void main(void) { unsigned char *p = buf; p[g()] += 5; }\n",
        {"buf": [10, 25, 30, 40], "calls": 1}),
    "p[i++] += 5 and p[i++]++": (
        "unsigned char buf[4] = {10, 20, 30, 40};\nunsigned char i, r1, r2, r3;\n"
        "void main(void) { unsigned char *p = buf; i = 0; p[i++] += 5; r1 = i; p[i++]++; r2 = i; r3 = p[i++]++; }\n",
        {"buf": [15, 21, 31, 40], "r1": 1, "r2": 2, "r3": 30, "i": 3}),
    "*q++ += 1": (
        "unsigned char a1[3] = {1, 2, 3};\nunsigned char n;\n"
        "void main(void) { unsigned char *q = a1; *q++ += 1; n = q - a1; }\n",
        {"a1": [2, 2, 3], "n": 1}),
    "*(q + 1) |= 0x10 and ++*(q + 2)": (
        "unsigned char a1[3] = {1, 2, 3};\nunsigned char r;\n"
        "void main(void) { unsigned char *q = a1; *(q + 1) |= 0x10; ++*(q + 2); r = (*(q + 2))--; }\n",
        {"a1": [1, 18, 3], "r": 4}),
    "(*s.count)++ and *s.count += 10": (
        "struct C { int *count; } s;\nint hits;\n"
        "void main(void) { s.count = &hits; (*s.count)++; *s.count += 10; }\n",
        {"hits": [11]}),
    "a signed char pointer over unsigned chars reads signed chars": (
        "unsigned char raw[2] = {0xFF, 0x80};\nint r1, r2, r3;\n"
        "void main(void) { signed char *s = raw; r1 = s[0]; r2 = s[1] / 2; s[1] = -2; r3 = raw[1]; }\n",
        {"r1": -1, "r2": -64, "r3": 254}),
    "an unsigned char pointer over chars reads unsigned chars": (
        "char text[3] = {-1, 65, 0};\nunsigned char r1, r2; int r3;\n"
        "void main(void) { unsigned char *u = text; r1 = (u[0] == 255); r2 = (u[0] > 127); r3 = u[0] + 1;\n"
        "    *u = 200; r3 = r3 + (text[0] == -56); }\n",
        {"r1": 1, "r2": 1, "r3": 1}),
    "a parameter of the other signedness, and the pointer converted back": (
        "char text[2] = {-3, 0};\nint r1, r2;\n"
        "unsigned char first(unsigned char *p) { return p[0]; }\n"
        "void main(void) { unsigned char *u = text; char *c = (char *)u; r1 = first(text); r2 = c[0]; }\n",
        {"r1": 253, "r2": -3}),
    "an int pointer over unsigned ints": (
        "unsigned int w[1] = {0xFFFF};\nlong r1;\n"
        "void main(void) { int *p = (int *)w; r1 = *p; }\n",
        {"r1": -1}),
    "memset fills chars with what the byte is in a char": (
        "#include <string.h>\nchar cbuf[2]; unsigned char ubuf[2];\nunsigned char r1, r2; int r3;\n"
        "void main(void) { memset(cbuf, 0xFF, 2); memset(ubuf, -1, 2); r1 = (cbuf[0] == -1); r2 = (ubuf[0] == 255);"
        " r3 = ubuf[1]; }\n",
        {"r1": 1, "r2": 1, "r3": 255, "cbuf": [-1, -1]}),
    "memcpy of bytes into chars": (
        "#include <string.h>\nunsigned char src[2] = {0xE9, 0x80};\nchar dst[2];\nint r1;\n"
        "void main(void) { memcpy(dst, src, 2); r1 = dst[0]; }\n",
        {"r1": -23, "dst": [-23, -128]}),
    "strncpy keeps a char a char": (
        "#include <string.h>\nchar src[3] = {-23, 65, 0};\nchar dst[4];\nint r1, r2;\n"
        "void main(void) { strncpy(dst, src, 4); r1 = dst[0]; r2 = (dst[0] == src[0]); }\n",
        {"r1": -23, "r2": 1, "dst": [-23, 65, 0, 0]}),
    "memcpy and memset count bytes": (
        "#include <string.h>\nint src[4] = {1, -2, 3, 4}; int dst[4]; int ibuf[4] = {1, 2, 3, 4};\nint r1;\n"
        "void main(void) { memcpy(dst, src, sizeof(src)); memset(ibuf, 0, sizeof(ibuf)); r1 = dst[3]; }\n",
        {"r1": 4, "dst": [1, -2, 3, 4], "ibuf": [0, 0, 0, 0]}),
    "memset of an int array sets each of its bytes": (
        "#include <string.h>\nint ibuf[2]; unsigned int ubuf[2];\n"
        "void main(void) { memset(ibuf, 0xFF, sizeof ibuf); memset(ubuf, 1, 3); }\n",
        {"ibuf": [-1, -1], "ubuf": [0x0101, 0x0001]}),
    "memcpy packs a long into bytes, little-endian, and back": (
        "#include <string.h>\nunsigned long v = 0x11223344UL, w;\nunsigned char TxData[8];\n"
        "void main(void) { memcpy(TxData, &v, 4); memcpy(&w, TxData + 1, 2); }\n",
        {"TxData": [0x44, 0x33, 0x22, 0x11, 0, 0, 0, 0], "w": [0x2233]}),
    "memcpy copies a struct": (
        "#include <string.h>\nstruct S { int x; unsigned char c; } a = {7, 8}, b;\nint r1;\n"
        "void main(void) { memcpy(&b, &a, sizeof a); a.x = 1; r1 = b.x; }\n",
        {"r1": 7}),
    "initialisers with their inner braces left out": (
        "struct N { int a[2]; int b; } x = {1, 2, 3};\nint m[2][2] = {1, 2, 3, 4};\n"
        "struct P { int x, y; } ps[2] = {1, 2, 3, 4}, qs[2] = {{5, 6}, 7};\nint z[2][2] = {{1}, 2, 3};\n"
        'struct S { char name[3]; int v; } s[2] = {"ab", 1, "c", 2};\nstruct P us[] = {1, 2, 3};\n'
        "int n = sizeof us / sizeof us[0];\nvoid main(void) { }\n",
        {"x": [[1, 2], 3], "m": [[1, 2], [3, 4]], "ps": [[1, 2], [3, 4]], "qs": [[5, 6], [7, 0]], "z": [[1, 0], [2, 3]],
         "s": [[[97, 98, 0], 1], [[99, 0, 0], 2]], "us": [[1, 2], [3, 0]], "n": 2}),
}


@pytest.mark.parametrize("name", sorted(VALUES))
def test_what_c18_computes(name):
    source, expected = VALUES[name]
    globals_ = _run(source)
    assert {key: globals_[key] for key in expected} == expected


def test_a_frame_received_into_a_char_array_holds_chars():
    """A plain `char RxData[8]` (signed) filled by CANReceiveMessage held 255 and 128, outside a char."""
    from conftest import World
    source = ('#include <p18f8680.h>\n#include "CAN18XX8.h"\nBYTE TxData[2] = {0xFF, 0x80};\nchar RxData[8];\n'
              "unsigned long RX_ID1; BYTE DataLen; char Flags;\nint r1 = 99, r2 = 99;\n"
              "void main(void) {\n    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG);\n"
              "    CANSetOperationMode(CAN_OP_MODE_LOOP);\n"
              "    CANSendMessage(0x100, TxData, 2, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME);\n"
              "    while (!CANIsRxReady());\n    CANReceiveMessage(&RX_ID1, RxData, &DataLen, &Flags);\n"
              "    r1 = RxData[0]; r2 = RxData[1] < 0;\n    while (1) CANIsRxReady();\n}\n")
    module = c18.load(Path("canrx.c"), source.encode(), None, ())
    world = World()
    world.node("n", module.main)
    world.run(0.05)
    assert (module.r1, module.r2, module.RxData[:2], module.RX_ID1) == (-1, 1, [-1, -128], [0x100])


REFUSED = {
    "the address of a bit-field": ("struct T { unsigned b:3; unsigned c:5; } t;\n"
                                   "void main(void) { unsigned int *p = &t.b; *p = 100; }\n", "bit-field"),
    "sizeof a bit-field": ("struct T { unsigned b:3; } t;\nint r;\nvoid main(void) { r = sizeof(t.b); }\n",
                           "bit-field"),
    "a ROM string in a ?: where RAM is meant": (
        '#include <string.h>\nchar buf[8], out[8];\nunsigned char flag;\n'
        'void main(void) { strcpy(out, flag ? buf : "rom"); }\n', "program memory"),
    "a ROM string in the first operand of ?:": (
        '#include <string.h>\nchar buf[8], out[8];\nunsigned char flag;\n'
        'void main(void) { strcpy(out, flag ? "rom" : buf); }\n', "program memory"),
    "more values than the braces-left-out array holds": ("int m[2][2] = {1, 2, 3, 4, 5};\nvoid main(void) { }\n",
                                                         "5 initial values for int.2..2., which holds 4"),
    "++ of a void pointer": ("int y;\nvoid main(void) { void *v = &y; v++; }\n", "void pointer"),
    "a void pointer plus one": ("int y;\nvoid *w;\nvoid main(void) { void *v = &y; w = v + 1; }\n", "void pointer"),
    "a named bit-field of width 0": ("struct T { unsigned b:0; unsigned c:3; } t;\nvoid main(void) { }\n",
                                     "width 0"),
}


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_what_c_refuses_is_refused_at_its_line(name):
    source, words = REFUSED[name]
    with pytest.raises(CCompileError, match=words) as refused:
        c18.translate("sem.c", source.encode(), {}, ())
    assert refused.value.line >= 1


FAULTS = {
    "an ordered comparison with NULL": ("unsigned char buf[3];\nunsigned char *p = buf, *q;\nint r1 = 9;\n"
                                        "void main(void) { r1 = (p > q); }\n", "NULL"),
    "an ordered comparison with 0": ("unsigned char buf[3];\nint r1 = 9;\n"
                                     "void main(void) { unsigned char *p = buf; if (p > 0) r1 = 1; }\n", "NULL"),
    "NULL minus NULL": ("int r1 = 9;\nvoid main(void) { unsigned char *p = 0, *q = 0; r1 = q - p; }\n", "NULL"),
    "a pointer minus NULL": ("unsigned char buf[3];\nint r1 = 9;\n"
                             "void main(void) { unsigned char *p = buf, *q = 0; r1 = p - q; }\n", "NULL"),
    "an int seen as bytes through void *": (
        "unsigned int w = 0x1234;\nunsigned char r1;\n"
        "void main(void) { void *v = &w; unsigned char *c = v; r1 = c[0]; }\n", "unsigned int"),
    "a memcpy of part of an int": ("#include <string.h>\nint a[2] = {1, 2}; struct S { int x; } s, t;\n"
                                   "void main(void) { memcpy(&t, &s, 1); }\n", "part of"),
}


@pytest.mark.parametrize("name", sorted(FAULTS))
def test_what_c_leaves_undefined_is_a_run_time_error_in_cs_words(name):
    source, words = FAULTS[name]
    module = c18.load(Path("sem.c"), source.encode(), None, ())
    with pytest.raises(CRuntimeError, match=words) as fault:
        module.__c_main()
    told = crash_message(fault.value, "sem.c")
    assert "Error" not in told and "NoneType" not in told and "attribute" not in told


def test_statics_whose_names_meet_are_still_variables_of_their_own():
    """`f`'s static `x_y` and `f_x`'s static `y` were both __static_f_x_y."""
    source = ("int r1, r2;\nvoid f(void) { static int x_y = 1; x_y++; r1 = x_y; }\n"
              "void f_x(void) { static int y = 10; y++; r2 = y; }\n"
              "void main(void) { f(); f_x(); f(); }\n")
    assert {k: v for k, v in _run(source).items() if k in ("r1", "r2")} == {"r1": 3, "r2": 11}


@pytest.mark.parametrize("options, expected", [((), (-23, -23, 66, -23)), (("-k",), (233, 233, 66, 233))])
def test_a_string_literal_holds_plain_chars_and_can_be_indexed(options, expected):
    """A ROM string read through `const rom char *` gave 233 for '\\xe9' (plain char is signed), and `"AB"[1]` or
    `*"\\xe9"` was Python's TypeError ('Ptr' object is not subscriptable)."""
    source = ('int r1, r2, r3, r4;\nconst rom char tab[2] = {-23, 5};\n'
              'void main(void) { const rom char *s = "\\xe9"; r1 = s[0]; r2 = tab[0]; r3 = "AB"[1]; r4 = *"\\xe9"; }\n')
    globals_ = _run(source, options)
    assert tuple(globals_[name] for name in ("r1", "r2", "r3", "r4")) == expected


SPRINTF = {
    '"%+u|% x|%#.3o|%#o", 65535u, 65535u, (int)8, (int)8': "65535|ffff|010|010",
    '"%+d|% d|%*d|%-*d|", (int)5, (int)5, (int)-4, (int)7, (int)3, (int)1': "+5| 5|7   |1  |",
}


@pytest.mark.parametrize("arguments", sorted(SPRINTF))
def test_sprintf_flags_are_isos(arguments):
    """+ and space sign only %d and %i; # gives %o one leading 0; a negative * width is the - flag (C99 7.19.6.1)."""
    source = f"#include <stdio.h>\nchar b[32];\nvoid main(void) {{ sprintf(b, {arguments}); }}\n"
    text = bytes(code & 0xFF for code in _run(source)["b"]).split(b"\0")[0].decode()
    assert text == SPRINTF[arguments]


def test_with_oi_a_char_goes_to_c_and_hh_as_iso_promotes_it():
    """Under -Oi the char is promoted to an int, as ISO pushes it, so %c and %hhd read an int: the kit refused both,
    telling the student to cast (which cannot help) because "the arguments are not promoted"."""
    source = ("#include <stdio.h>\nchar b[16];\nvoid main(void) { char c = 'A'; signed char d = -3; "
              'sprintf(b, "%c%hhd%hhu", c, d, (unsigned char)200); }\n')
    for options in ((), ("-Oi",)):
        assert bytes(code & 0xFF for code in _run(source, options)["b"]).split(b"\0")[0] == b"A-3200"
    as_int = source.replace("%hhd", "%d")
    assert bytes(code & 0xFF for code in _run(as_int, ("-Oi",))["b"]).split(b"\0")[0] == b"A-3200"
    with pytest.raises(CRuntimeError, match="%d reads an int .2 bytes., but its argument -3 is signed char"):
        _run(as_int)
