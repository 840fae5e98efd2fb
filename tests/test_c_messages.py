"""What a C file the kit cannot take is told, in C's words at its line, never as an exception of Python's; and what it
takes means what C18 makes of it (found by fuzzing the translator and by trying the CLI as students would)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from appsim.errors import CCompileError
from appsim.firmware import c18
from appsim.workshop.checks import check
from appsim.workshop.course import SOLUTIONS

EX1 = (SOLUTIONS / "ex1.c").read_text()
MAIN = "void main(void) { while (1); }\n"


def _refusal(source: str | bytes, options: tuple[str, ...] = ()) -> CCompileError:
    data = source.encode() if isinstance(source, str) else source
    with pytest.raises(CCompileError) as refused:
        c18.translate("ex1.c", data, {}, options)
    return refused.value


@pytest.mark.parametrize("directive", ["#ifdef", "#ifndef", "#define", "#undef", "#pragma", "#if !"])
def test_a_directive_without_what_it_needs_is_refused_at_its_line(directive):
    """pcpp raised IndexError on each of these: a traceback for the student, a grader fault in a class."""
    refused = _refusal(f"int a;\n{directive}\n" + ("#endif\n" if directive.startswith("#if") else "") + MAIN)
    assert refused.line == 2 and (f"cannot read `{directive}`" in str(refused)
                                  or f"cannot evaluate {directive}" in str(refused)), refused


@pytest.mark.parametrize("source, line", [("void main(void) { int x #line 500\n }\n", 1),
                                          ("void main(void) {\n int x;\n x = 1 # 3\n;}\n", 3)])
def test_a_stray_hash_in_the_code_is_refused_and_never_moves_the_line_count(source, line):
    """`#line 500` in mid-line made the error reporter index past the file (IndexError); `x = 1 # 3` moved every later
    line number silently."""
    refused = _refusal(source)
    assert refused.line == line and "a stray '#'" in str(refused)


@pytest.mark.parametrize("source, words, line", [
    ("#if 1\nint a;\n#else\nint a;\n#elif 1\nint b;\n#endif\n", "#elif after the #else of line 3", 5),
    ("#ifdef X\nint a;\n#else\n#else\n#endif\n", "#else after the #else of line 3", 4),
    ("#if 1\n#ifdef X\n#else\n#endif\n#else\n#else\n#endif\n", "#else after the #else of line 5", 6),
    ("int a;\n#endif\n", "#endif with no #if before it", 2),
    ("int a;\n#else\n", "#else with no #if before it", 2),
    ("#ifndef X\nint a;\n", "this #ifndef has no #endif", 1),
    ("#if 1\n#ifdef X\n#endif\n#ifdef Y\nint a;\n", "its group (2 groups are open at the end)", 4),
], ids=["elif after else", "else after else", "nested", "endif alone", "else alone", "no endif", "two open"])
def test_if_groups_that_do_not_pair_up_are_refused_at_their_line(source, words, line):
    """C18's preprocessor refuses each of these; pcpp took an #elif or an #else after the #else (the file compiled
    in the kit and not in MPLAB) and told the rest as 'Misplaced #endif (the preprocessor)'."""
    refused = _refusal(source + MAIN)
    assert words in str(refused) and refused.line == line, refused


@pytest.mark.parametrize("newline", ["\n", "\r\n"], ids=["LF", "CRLF"])
def test_directives_in_comments_strings_and_continued_lines_are_no_directives(newline):
    source = ('#if 1\n/*\n#else\n#endif\n*/\nrom char s[] = "\\n#endif";\n// #else\nint a;\n#else\nint a;\n#endif\n'
              "#define JOINED 1 \\\n#endif\n" + MAIN)
    c18.translate("ex1.c", source.replace("\n", newline).encode(), {}, ())


def test_a_hash_in_a_string_and_a_pragma_are_no_stray_hash():
    c18.translate("ex1.c", b'#pragma config WDT = OFF\nrom char s[] = "a#b";\nchar c = \'#\';\n' + MAIN.encode(),
                  {}, ())


@pytest.mark.parametrize("source, words, line", [
    (EX1 + "\n/* never closed\n", "a comment that is never closed", 93),
    (EX1.replace('putrsGLCD("EX1 LOOPBACK");', 'putrsGLCD("EX1 LOOPBACK);'), "a string with no closing quote", 71),
    (EX1.replace("void main(void)\n{", "void main(void)\n{\n{", 1), "the file ends inside a function", 66),
    (EX1.replace("    CANSetOperationMode(CAN_OP_MODE_LOOP);\n}", "    CANSetOperationMode(CAN_OP_MODE_LOOP);\n"),
     "is the '}' that ends the function above missing?", 58),
    ('#if "x"\n#endif\n' + EX1, "#if and #elif take an integer expression", 1),
    ("#if 1/0\n#endif\n" + EX1, "#if 1/0: it divides by zero", 1),
], ids=["comment", "string", "extra {", "missing }", "#if string", "#if 1/0"])
def test_a_syntax_error_is_told_in_cs_words_at_its_line(source, words, line):
    refused = _refusal(source)
    assert words in str(refused) and refused.line == line, refused
    for python_words in ("pycparser", "AttributeError", "ZeroDivisionError", "Illegal character", "At end of input"):
        assert python_words not in str(refused)


def test_a_file_saved_with_notepads_bom_loads_in_c_and_in_python(tmp_path):
    for name in ("ex1.c", "ex1.py"):
        path = tmp_path / name
        path.write_bytes(b"\xef\xbb\xbf" + (SOLUTIONS / name).read_bytes())
        verdict = check("ex1", path, seed=3).to_dict()
        assert verdict["score"] == verdict["max_score"], (name, verdict)


def test_a_file_saved_as_utf16_is_told_so():
    assert "saved as UTF-16" in str(_refusal(EX1.encode("utf-16")))


def test_a_character_constant_is_a_plain_char_so_unsigned_with_k():
    source = ("#include \"CAN18XX8.h\"\nunsigned int u; int i; char c;\n"
              "void main(void) { u = '\\xff'; i = '\\xff'; c = '\\xff'; while (1) CANIsRxReady(); }\n")
    module = c18.load(Path("k.c"), source.encode(), None, ("-k",))
    assert "u = 255" in _startup_and_main(module, ["u", "i", "c"]), "'\\xff' is 255 when plain char is unsigned"
    module = c18.load(Path("k.c"), source.encode(), None, ("-k", "-Oi"))
    assert "i = 255" in _startup_and_main(module, ["u", "i", "c"])
    module = c18.load(Path("k.c"), source.encode(), None, ())
    assert "u = 65535" in _startup_and_main(module, ["u", "i", "c"]), "C18's default: '\\xff' is the char -1"


def _startup_and_main(module, names: list[str]) -> str:
    """Run the translated main() until its endless loop, on a board, and show the globals `names`."""
    from conftest import World
    world = World()
    world.node("n", module.main)
    world.run(0.001)
    return ", ".join(f"{name} = {vars(module)[name]}" for name in names)


SHADOWING = {
    "a function's local": ("int x = 5;\nvoid f(void) { int x = 7; x++; }\n", "f();", "x = 5"),
    "a block's local in main": ("int x = 5;\n", "{ int x = 7; x++; }", "x = 5"),
    "a loop counter": ("unsigned char i = 100;\nvoid f(void) { unsigned char i; for (i = 0; i < 3; i++) ; }\n",
                       "f();", "i = 100"),
    "a local array": ("unsigned char buf[2] = {1, 2};\nvoid f(void) { unsigned char buf[2]; buf[0] = 9; }\n",
                      "f();", "buf = [1, 2]"),
    "a parameter": ("int x = 5, r;\nint twice(int x) { x = x * 2; return x; }\n", "r = twice(21);",
                    "x = 5, r = 42"),
    "a local, then the global": ("int x = 5, r;\nvoid f(void) { { int x = 7; } x = x + 1; }\n", "f(); r = x;",
                                 "x = 6, r = 6"),
}


@pytest.mark.parametrize("options, expected", [((), "r = 1, s = -92"), (("-Oi",), "r = 0, s = 65444")])
def test_signedness_and_constants_are_as_the_dialect_table_says(options, expected):
    """docs/c-firmware.md: a signed and an unsigned char make an unsigned operation (C18's default), ISO's promotions
    make both int (-Oi); `8u` is an unsigned char (C18's smallest type: 8u - c is done in c's int), with -Oi an
    unsigned int (8u - c is unsigned)."""
    source = ("signed char b = -1; int c = 100; unsigned char r; long s;\n"
              "void main(void) { r = (b == 0xFF); s = 8u - c; while (1) CANIsRxReady(); }\n")
    module = c18.load(Path("sign.c"), ('#include "CAN18XX8.h"\n' + source).encode(), None, options)
    assert _startup_and_main(module, ["r", "s"]) == expected


@pytest.mark.parametrize("name", sorted(SHADOWING))
def test_a_local_with_a_globals_name_is_a_variable_of_its_own(name):
    """In C the inner declaration hides the global; the translation made them one Python name, declared global in
    the function (the global became 7, 8, 3, [9, 0]), and refused a parameter as 'parameter and global'."""
    declarations, calls, expected = SHADOWING[name]
    source = declarations + f"void main(void) {{ {calls} while (1) CANIsRxReady(); }}\n"
    module = c18.load(Path("shadow.c"), ('#include "CAN18XX8.h"\n' + source).encode(), None, ())
    names = re.findall(r"(\w+) = ", expected)
    assert _startup_and_main(module, names) == expected


@pytest.mark.parametrize("literal", ["'\\x41BC'", '"\\777"', "'\\x'"])
def test_an_escape_out_of_range_is_refused(literal):
    assert "\\x" in str(_refusal(f"int r;\nvoid main(void) {{ r = {literal}[0]; while (1); }}\n"
                                    if literal.startswith('"') else
                                    f"int r;\nvoid main(void) {{ r = {literal}; while (1); }}\n"))


def test_adjacent_string_literals_keep_their_escapes_apart():
    """pycparser keeps "\\x41" "BC" as two literals in one constant; their quotes were read as characters."""
    module = c18.load(Path("s.c"), b'char s[4] = "\\x41" "BC";\nchar t[3] = "\\1" "23";\n' + MAIN.encode(), None, ())
    assert (vars(module)["s"], vars(module)["t"]) == ([0x41, 0x42, 0x43, 0], [1, 0x32, 0x33])


def test_the_no_cast_mistake_is_told_how_to_fix_it(tmp_path):
    """`(RxData[3] << 8) | RxData[4]` passed to %4d: casting the whole expression would not help, C18 computed it in
    one byte already; the message says to cast the chars."""
    path = tmp_path / "ex1.c"
    path.write_text(EX1.replace("((int)RxData[3] << 8) | RxData[4]", "(RxData[3] << 8) | RxData[4]"))
    verdict = check("ex1", path, seed=1).to_dict()
    message = verdict["checks"][0]["message"]
    assert "cast the chars before the arithmetic, ((int)RxData[3] << 8) | RxData[4]" in message, message


def test_the_value_of_a_function_that_ends_without_return_is_an_error_where_it_is_used(tmp_path):
    """It was Python's "unsupported operand type(s) for &: 'NoneType' and 'int'"; a call whose value is not used, or
    one that returns on the way taken, runs on as in C."""
    from appsim.firmware.loader import crash_message
    source = ('#include "CAN18XX8.h"\nunsigned char TxData[8];\nint f(void) { }\nint g(int x) { if (x) return 1; }\n'
              "void main(void)\n{\n    g(1);\n    f();\n    TxData[0] = g(1);\n    TxData[1] = f();\n"
              "    while (1) CANIsRxReady();\n}\n")
    module = c18.load(Path("nov.c"), source.encode(), None, ())
    from conftest import World
    world = World()
    process = world.node("n", module.main).process
    world.sim.run_for(0.001)
    assert process.failure is not None
    message = crash_message(process.failure, "nov.c")
    assert "line 10" in message and "f() (line 3) ended without return" in message, message
    assert "NoneType" not in message and vars(module)["TxData"][0] == 1


def test_a_line_directive_is_refused_so_that_every_line_number_stays_the_files():
    refused = _refusal("#line 40\n" + MAIN)
    assert refused.line == 1 and "#line is not supported" in str(refused)


@pytest.mark.parametrize("spec", ["%999999999d", "%.999999999d", "%12d"])
def test_a_sprintf_width_past_its_buffer_is_the_buffers_error_at_once(spec):
    """A huge width used to pad for seconds until the watchdog called it an endless loop."""
    from appsim.errors import CRuntimeError
    module = c18.load(Path("w.c"), ('#include <stdio.h>\nchar b[8];\nvoid main(void) { sprintf(b, "' + spec
                                    + '", (int)1); while (1); }\n').encode(), None, ())
    with pytest.raises(CRuntimeError, match="writes at least .* bytes .* into b, which has room for 8"):
        module.__c_main()


def test_a_shift_past_every_width_gives_what_c18_gives_without_building_a_huge_number():
    """`1UL << 4000000000` built a 500 MB Python integer, as a constant and at run time."""
    from conftest import World
    source = ('#include "CAN18XX8.h"\nunsigned long a, b, c;\nunsigned long n = 4000000000UL;\nunsigned char k = 31;\n'
              "void main(void) { a = 1UL << 4000000000; b = 1UL << n; c = (1UL << k) | (3 << 1); "
              "while (1) CANIsRxReady(); }\n")
    module = c18.load(Path("s.c"), source.encode(), None, ())
    world = World()
    world.node("n", module.main)
    world.run(0.001)
    assert (module.a, module.b, module.c) == (0, 0, 0x80000006)


def test_a_struct_that_points_to_its_own_kind_is_valid_c():
    """`struct node { struct node *next; int v; }` (a linked list) was refused: "v: struct node is not a struct"."""
    from conftest import World
    source = ('#include "CAN18XX8.h"\nstruct node { struct node *next; int v; } a, b;\nint r;\n'
              "void main(void) { a.next = &b; a.next->v = 4; r = b.v; while (1) CANIsRxReady(); }\n")
    module = c18.load(Path("list.c"), source.encode(), None, ())
    world = World()
    world.node("n", module.main)
    world.run(0.001)
    assert module.r == 4


@pytest.mark.parametrize("source, words", [
    ("int r;\nvoid w(void) { r = sizeof(void); }\n", "void has no size"),
    ("struct s { } x;\n", "has no members"),
    ("void f(void x) { }\n", "a parameter cannot be void"),
    ("#define 1 2\n", "a macro's name is an identifier"),
    ("#define F(x, x) x\n", "names a parameter twice"),
])
def test_what_c18_would_not_compile_is_not_run_either(source, words):
    """Each was accepted and ran; C18 stops at it, so a student would meet it only on the real board."""
    assert words in str(_refusal('#include "CAN18XX8.h"\n' + source + MAIN))
