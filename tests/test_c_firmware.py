"""C firmware (MPLAB C18's C, translated by appsim.firmware.c18) where Python firmware goes: the C solutions earn full
marks, the C starters fail where their Python twins fail with the same messages, six C stations give the Python
stations' bus trace, C18's semantics and traps hold (no integer promotion, constants of the smallest type, variadic
arguments not promoted, rom and RAM apart), and every error names the .c file's line, in C's words."""
from __future__ import annotations

import re
import time

import pytest
from workshop import KIT, classroom

from appsim.chip.mcu import PIC18F8680
from appsim.chip.sfr import ADDRESSES, BITFIELDS
from appsim.errors import CCompileError
from appsim.firmware import adc, an738, timers, usart
from appsim.firmware import c18 as c18_package
from appsim.firmware.c18 import headers
from appsim.firmware.loader import constants, load_firmware, load_source
from appsim.sim import Simulator
from appsim.workshop.checks import check, check_names
from appsim.workshop.course import C_FILES, EXERCISE_FILES
from appsim.workshop.faults import board_fault

SOLUTIONS, STARTERS = KIT / "solutions", KIT / "exercises"
CLASSROOM_EXERCISES = [f"ex{n}" for n in range(1, 7)]


def run_c(source: str, *, options: tuple[str, ...] = (), seconds: float = 0.001, name: str = "t.c"):
    """A C file's main() on a bare PIC18F8680 for `seconds`: its module, and its process."""
    module = load_source(name, source.encode(), c_options=options)
    sim = Simulator()
    mcu = PIC18F8680(sim)
    process = mcu.run(module.main)
    sim.run_for(seconds)
    return module, process


def c_error(source: str, *, name: str = "t.c") -> CCompileError:
    with pytest.raises(CCompileError) as caught:
        load_source(name, source.encode())
    return caught.value


def bytes_of(array: list[int]) -> bytes:
    return bytes(v & 0xFF for v in array).split(b"\0")[0]


MAIN_LOOP = "\nvoid main(void) { work(); while (1) { ClrWdt(); } }\n"  # not an empty loop: one the kit waits in


# ====================================================================== the workshop in C

@pytest.mark.parametrize("seed", [202, 7, 31337])
@pytest.mark.parametrize("exercise", [*CLASSROOM_EXERCISES, "demo1"])
def test_every_c_solution_gets_full_marks(exercise, seed):
    verdict = check(exercise, SOLUTIONS / C_FILES[exercise], seed=seed)
    assert verdict.score == verdict.max_score, str(verdict)


def _without_names(text: str) -> str:
    return re.sub(r"\S*ex\d\.(py|c)", "FILE", text)


@pytest.mark.parametrize("exercise", CLASSROOM_EXERCISES)
def test_every_c_starter_fails_where_its_python_twin_fails_with_the_same_messages(exercise):
    python = check(exercise, STARTERS / EXERCISE_FILES[exercise], seed=202)
    c = check(exercise, STARTERS / C_FILES[exercise], seed=202)
    assert python.score < python.max_score
    assert [(r.name, r.passed) for r in c.checks] == [(r.name, r.passed) for r in python.checks]
    for ours, theirs in zip(c.checks, python.checks, strict=True):
        in_python = _without_names(ours.message).replace("NULL", "None").replace(" && ", " and ")
        assert in_python == _without_names(theirs.message)


def test_the_demo1_c_starter_fails_where_the_python_starter_fails():
    python = check("demo1", STARTERS / "demo1_monitor.py", seed=202)
    c = check("demo1", STARTERS / "demo1_monitor.c", seed=202)
    assert [(r.name, r.passed) for r in c.checks] == [(r.name, r.passed) for r in python.checks]
    assert c.score == python.score == 1


def test_the_demo1_c_solution_prints_what_the_python_solution_prints():
    verdicts = [str(check("demo1", SOLUTIONS / name, seed=9)) for name in ("demo1_monitor.py", "demo1_monitor.c")]
    assert _without_names(verdicts[0].replace("demo1_monitor", "ex1")) == \
        _without_names(verdicts[1].replace("demo1_monitor", "ex1"))


def test_a_check_message_quotes_code_in_the_firmwares_own_language():
    c = check("ex5", STARTERS / "ex5.c", seed=202)
    python = check("ex5", STARTERS / "ex5.py", seed=202)
    assert "CANSendMessage(RTR_ID, NULL, 0" in str(c) and "None" not in str(c)
    assert "CANSendMessage(RTR_ID, None, 0" in str(python)


def _trace(exercise: int, language: str) -> tuple[list[str], list[str]]:
    room = classroom(exercise, seed=exercise, language=language)
    room.run(1.0)
    bus = room.bus
    return [repr(event) for event in (*bus.trace, *bus.loopback_trace)], [b.glcd.text() for b in room.boards]


@pytest.mark.parametrize("exercise", range(1, 7))
def test_six_c_stations_give_the_bus_trace_of_six_python_stations(exercise):
    python, c = _trace(exercise, "python"), _trace(exercise, "c")
    assert len(python[0]) > 10
    assert c[0] == python[0]
    assert c[1] == python[1]


def test_a_c_station_joins_a_python_classroom_by_its_defined_id(tmp_path):
    room = classroom(2)
    firmware = tmp_path / "ex2.c"
    text = (SOLUTIONS / "ex2.c").read_text()
    firmware.write_text(text.replace("#define MESSAGE_ID1 0x100", "#define MESSAGE_ID1 0x130"))
    room.join(firmware, 4)
    room.run(0.3)
    assert {e.frame.can_id for e in room.bus.frames() if e.sender == "station4"} == {0x130}


# ====================================================================== defines, constants, identity

def test_a_define_replaces_the_files_define_and_constants_lists_them():
    path = SOLUTIONS / "ex6.c"
    assert constants(path) == ["MESSAGE_ID1", "RX_Filter0", "RX_Mask0", "RX_Filter2", "RX_Mask1"]
    module = load_firmware(path, {"MESSAGE_ID1": 0x140})
    assert (module.MESSAGE_ID1, module.RX_Filter2, module.RX_Filter0) == (0x140, 0x140, 0x088)
    with pytest.raises(CCompileError, match="has no #define RTR_ID to replace"):
        load_firmware(path, {"RTR_ID": 0x82})


def test_the_station_is_read_from_the_c_files_defines(tmp_path):
    firmware = tmp_path / "ex5.c"
    text = (SOLUTIONS / "ex5.c").read_text()
    firmware.write_text(text.replace("#define RTR_ID      0x81", "#define RTR_ID      0x83"))
    verdict = check("ex5", firmware, seed=3)
    assert verdict.score == verdict.max_score and "RTR_ID = 0x083" in str(verdict)


def test_the_kits_headers_say_what_the_python_library_says():
    """The headers are the kit's own text: their constants must be the Python library's, value for value, and
    p18f8680.h must declare every register and bit the kit models, at its address."""
    for header, module in (("adc.h", adc), ("timers.h", timers), ("usart.h", usart)):
        text = headers.header_text(header)
        defined = dict(re.findall(r"#define (\w+)\s+(0b[01]+)", text))
        names = [n for n in module.__all__ if isinstance(getattr(module, n), int) and n.isupper()]
        assert {n: int(v, 0) for n, v in defined.items()} == {n: getattr(module, n) for n in names}
    can = headers.header_text("CAN18XX8.h")
    enumerators = dict(re.findall(r"\b(CAN_\w+)\s*=\s*(0b[01]+)", can))
    assert enumerators and all(getattr(an738, name) == int(value, 0) for name, value in enumerators.items())
    assert (KIT / "appsim/firmware/c18/include/p18f8680.h").read_text() == headers.device_header()
    fast = c18_package.header_symbols("p18f8680.h", ())
    parsed = c18_package.header_symbols("p18f8680.h", (), parsed=True)
    assert fast == parsed
    assert {n for n, s in parsed.items() if s.kind == "sfr"} == set(ADDRESSES)
    assert {n[:-4] for n, s in parsed.items() if s.kind == "bits"} == set(BITFIELDS)


def test_can_is_rx_ready_is_the_macro_over_the_registers():
    text = headers.header_text("CAN18XX8.h")
    assert "#define CANIsRxReady()          (RXB0CONbits.RXFUL || RXB1CONbits.RXFUL)" in text
    signature = "BOOL CANReceiveMessage(unsigned long *id, BYTE *Data, BYTE *DataLen, enum CAN_RX_MSG_FLAGS *MsgFlags);"
    assert signature in text


# ====================================================================== C18's semantics

SEMANTICS = r"""
#include <p18f8680.h>
#include <stdio.h>
unsigned char a = 0x80, b = 0x80;
unsigned int sum8, sum16;
char c = -1; unsigned char u = 255;
int equal, quotient = -7 / 2, rest = -7 % 2, product;
unsigned long big = 0xFFFFFFFF;
short long medium = 0x7FFFFF;
char buf[40];
struct frame { unsigned long id; unsigned char data[8]; unsigned char len; } queue[4], copy;
int cases[4], loop, calls;
static int counted(void) { static int n = 0; return ++n; }
void fill(struct frame *f, unsigned long id) { f->id = id; f->len = 3; f->data[2] = 0x55; }
int pick(int v) {
    int r = 0;
    switch (v) { case 1: r = 10; case 2: r += 20; break; case 3: r = 30; break; default: r = -1; }
    return r;
}
void work(void) {
    int k;
    sum8 = a + b;
    sum16 = (unsigned int)a + b;
    equal = c == u;
    product = 200 * 2;
    big++;
    medium++;
    sprintf(buf, "%5d|%-4hhX|%03u|%c|%S|%lu", (int)-42, 0xABu, (unsigned int)7, (char)'Z', "rom", 123456UL);
    fill(&queue[1], 0x123);
    copy = queue[1];
    copy.data[0] = 9;
    for (k = 0; k < 4; k++) cases[k] = pick(k);
    k = 0;
    do { loop += k; k++; if (k == 2) continue; } while (k < 5);
    calls = counted() + counted();
}
"""


def test_c18s_integer_semantics_hold():
    module, process = run_c(SEMANTICS + MAIN_LOOP)
    assert process.failure is None
    assert module.sum8 == 0, "C18 adds two unsigned chars in 8 bits (no integer promotion)"
    assert module.sum16 == 256
    assert module.equal == 1, "char -1 and unsigned char 255 compare as unsigned chars"
    assert (module.quotient, module.rest) == (-3, -1), "division truncates toward zero"
    assert module.product == 400, "200 is an int (a decimal constant is never an unsigned char)"
    assert (module.big, module.medium) == (0, -0x800000), "32-bit and 24-bit (short long) wrap around"
    assert bytes_of(module.buf) == b"  -42|AB  |007|Z|rom|123456"
    assert module.queue[1] == [0x123, [0, 0, 0x55, 0, 0, 0, 0, 0], 3]
    assert module.copy[1][0] == 9 and module.queue[1][1][0] == 0, "a struct is assigned by value"
    assert module.cases == [-1, 30, 20, 30], "case 1 falls through into case 2"
    assert module.loop == 10 and module.calls == 3


def test_with_minus_oi_integer_promotions_hold():
    module, _ = run_c(SEMANTICS + MAIN_LOOP, options=("-Oi",))
    assert module.sum8 == 256


def test_a_constant_takes_the_smallest_type():
    module, _ = run_c("""
        #include <p18f8680.h>
        int a, b, c;
        void work(void) { a = 0x10 * 0x10; b = 16 * 16; c = 0x100 * 2; }
    """ + MAIN_LOOP)
    assert (module.a, module.b, module.c) == (0, 0, 0x200), "0x10 and 16 are chars: their product is a char"


def test_globals_are_initialised_again_at_every_reset_and_main_is_called_again_when_it_returns():
    source = """
        #include <p18f8680.h>
        int runs = 0;
        unsigned char started;
        void main(void) { runs++; started = 1; Nop(); if (runs == 3) { while (1) Nop(); } }
    """
    module = load_source("reset.c", source.encode())
    sim = Simulator()
    mcu = PIC18F8680(sim)
    mcu.run(module.main)
    sim.run_for(0.001)
    assert module.runs == 3, "C18's startup calls main() again when it returns, without initialising again"
    mcu.run(module.main)            # a reset: C startup runs again
    sim.run_for(0.001)
    assert module.runs == 3


def test_reset_restarts_the_c_program_from_its_startup():
    module, process = run_c("""
        #include <p18f8680.h>
        int boots = 0, total = 0;
        void main(void) { total++; boots++; Nop(); if (total < 3) Reset(); while (1) Nop(); }
    """)
    assert process.failure is None and module.boots == 1


# ====================================================================== C18's traps, each with the verdict it deserves

def _edited(exercise: str, *edits: tuple[str, str]) -> str:
    text = (SOLUTIONS / C_FILES[exercise]).read_text()
    for old, new in edits:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text


SHIFT_NO_CAST = ('sprintf(LCD, "A/D    %4d", ((int)RxData[3] << 8) | RxData[4]);',
                 'adc = (RxData[3] << 8) | RxData[4];\n                    sprintf(LCD, "A/D    %4d", adc);')


@pytest.mark.parametrize("options, passes", [((), False), (("-Oi",), True)])
def test_the_high_byte_lost_without_a_cast_shows_on_lcd_line_3_under_c18s_default(tmp_path, options, passes):
    firmware = tmp_path / "ex3.c"
    firmware.write_text(_edited("ex3", SHIFT_NO_CAST, ("char LCD[22];", "char LCD[22];\nunsigned int adc;")))
    verdict = check("ex3", firmware, seed=202, c_options=options)       # the master's A/D is above 255 there
    lcd = next(r for r in verdict.checks if r.name == check_names("ex3")[2])
    assert lcd.passed == passes, str(verdict)
    if not passes:
        assert "Line 3" in lcd.message or "line 3" in lcd.message


def test_sprintf_x_of_a_one_byte_constant_is_a_run_time_error_naming_the_c_line(tmp_path):
    firmware = tmp_path / "ex5.c"
    firmware.write_text(_edited("ex5", ("(unsigned int)RTR_ID", "RTR_ID")))
    verdict = check("ex5", firmware, seed=202)
    message = verdict.checks[0].message
    line = next(n for n, text in enumerate(firmware.read_text().splitlines(), 1) if '"TX ID  0x%03X RTR"' in text)
    assert verdict.score == 0 and verdict.fault == "exception"
    assert f"line {line} of ex5.c" in message and "%03X reads an int (2 bytes)" in message
    assert "0x81 is a constant of type unsigned char (1 byte)" in message and "%03hhX" in message


def test_putsglcd_with_a_rom_literal_is_refused_at_its_line(tmp_path):
    firmware = tmp_path / "ex1.c"
    firmware.write_text(_edited("ex1", ('putrsGLCD("EX1 LOOPBACK");', 'putsGLCD("EX1 LOOPBACK");')))
    verdict = check("ex1", firmware, seed=202)
    message = verdict.checks[0].message
    line = next(n for n, text in enumerate(firmware.read_text().splitlines(), 1) if 'putsGLCD("EX1' in text)
    assert verdict.fault == "load" and f"ex1.c:{line}:" in message
    assert "in program memory" in message and "use putrsGLCD()" in message


def test_forgetting_rxful_0_after_reading_rxb0_by_its_registers_freezes_what_the_node_sees(tmp_path):
    direct = ("            CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);\n"
              "            setcurGLCD(4, 1);\n"
              "            if (CANMessageFlag & CAN_RX_RTR_FRAME) {",
              "            RX_ID1 = ((unsigned int)RXB0SIDH << 3) | (RXB0SIDL >> 5);\n"
              "            DataLen = RXB0DLC & 0x0F;\n"
              "            RxData[3] = RXB0D3;\n"
              "            RxData[4] = RXB0D4;\n"
              "            CANMessageFlag = RXB0DLCbits.RXRTR ? CAN_RX_RTR_FRAME : 0;\n"
              "            RXB0CONbits.RXFUL = 0;\n"
              "            setcurGLCD(4, 1);\n"
              "            if (CANMessageFlag & CAN_RX_RTR_FRAME) {")
    good, forgot = tmp_path / "good" / "ex3.c", tmp_path / "forgot" / "ex3.c"
    forgetting = (direct[0], direct[1].replace("            RXB0CONbits.RXFUL = 0;\n", ""))
    for path, edit in ((good, direct), (forgot, forgetting)):
        path.parent.mkdir()
        path.write_text(_edited("ex3", edit, ("if (CANIsRxReady()) {", "if (RXB0CONbits.RXFUL) {")))
    assert check("ex3", good, seed=202).score == check("ex3", good, seed=202).max_score
    verdict = check("ex3", forgot, seed=202)
    failed = {r.name for r in verdict.failed()}
    assert check_names("ex3")[2] in failed, str(verdict)       # the LCD never follows the master's A/D


def test_an_out_parameter_without_its_ampersand_is_refused_in_cs_words(tmp_path):
    firmware = tmp_path / "ex2.c"
    firmware.write_text(_edited("ex2", ("CANReceiveMessage(&RX_ID1,", "CANReceiveMessage(RX_ID1,")))
    verdict = check("ex2", firmware, seed=202)
    message = verdict.checks[0].message
    assert verdict.fault == "load"
    assert "argument 1 of CANReceiveMessage() (id) is unsigned long *" in message
    assert "RX_ID1 is a unsigned long, not an address: pass its address, &RX_ID1" in message


def test_an_out_parameter_of_the_wrong_size_is_refused():
    error = c_error("""
        #include "CAN18XX8.h"
        unsigned int id; BYTE data[8], len; enum CAN_RX_MSG_FLAGS flags;
        void main(void) { CANReceiveMessage(&id, data, &len, &flags); }
    """)
    assert error.line == 4
    assert "points to unsigned long (4 bytes), but &id points to unsigned int (2 bytes)" in str(error)


def test_an_index_out_of_range_is_reported_at_its_c_line():
    module, process = run_c("""
        #include <p18f8680.h>
        unsigned char data[8];
        unsigned char i;
        void work(void) {
            for (i = 0; i <= 8; i++)
                data[i] = i;
        }
    """ + MAIN_LOOP, name="oob.c")
    fault = board_fault(process)
    assert fault is not None and fault.kind == "exception"
    assert "at line 7 of oob.c (`data[i] = i;`)" in fault.message
    assert "data[8] is outside data, which has 8 elements (0..7)" in fault.message


def test_a_local_read_before_it_is_set_is_reported():
    _, process = run_c("""
        #include <p18f8680.h>
        int out;
        void work(void) { int x; out = x + 1; }
    """ + MAIN_LOOP, name="unset.c")
    fault = board_fault(process)
    assert fault is not None and "x is read before anything was stored in it" in fault.message


def test_sprintf_past_the_end_of_its_buffer_is_reported():
    _, process = run_c("""
        #include <p18f8680.h>
        #include <stdio.h>
        char line[8];
        void work(void) { sprintf(line, "A/D    %4d", (int)1023); }
    """ + MAIN_LOOP)
    fault = board_fault(process)
    assert fault is not None and "sprintf writes 12 bytes (the NUL included) into line, which has room for 8" \
        in fault.message


# ====================================================================== errors in C's words; what the kit refuses

@pytest.mark.parametrize("source, line, words", [
    ("#include <p18f8680.h>\nvoid main(void) {\n    int x = 1\n    x = 2;\n}\n", 4, "is a ';' missing"),
    ("void main(void) {\n    undefined_thing = 3;\n}\n", 2, "undefined_thing is not declared"),
    ("void main(void) {\n    RXB0CONbits.RXFUL = 0;\n}\n", 2, "#include <p18f8680.h> declares the registers"),
    ("#include <p18f8680.h>\nvoid main(void) {\n    RXB0CONbits.FULL = 0;\n}\n", 3,
     "RXB0CONbits has no bit or field named FULL"),
    ("void main(void) {\n    _asm nop _endasm\n}\n", 2, "inline assembly"),
    ("void main(void) {\nagain:\n    goto again;\n}\n", 2, "goto and labels are not supported"),
    ("void f(void) {}\nvoid main(void) {\n    void (*p)(void) = f;\n}\n", 3, "function pointers are not supported"),
    ("float volts;\nvoid main(void) {}\n", 1, "floating point"),
    ("union u { char a; int b; } x;\nvoid main(void) {}\n", 1, "unions are not supported"),
    ("#pragma interrupt high_isr\nvoid high_isr(void) {}\nvoid main(void) {}\n", 1,
     "nothing at the vector 0x08 jumps to high_isr"),
    ("#pragma interruptlow low_isr\nvoid low_isr(void) {}\nvoid main(void) {}\n", 1,
     "#pragma code low_vector=0x18, then void interrupt_at_low_vector(void) { _asm GOTO low_isr _endasm }"),
    ("#pragma code high_vector=0x08\nvoid v(void) {}\n#pragma code\nvoid main(void) {}\n", 2,
     "v() is at the interrupt vector 0x08"),
    ("void f(void) {}\n#pragma code high_vector=0x08\nvoid v(void) { _asm GOTO f _endasm }\n#pragma code\n"
     "void main(void) {}\n", 3, "goes to f, which no #pragma interrupt names"),
    ("void low(void);\n#pragma code high_vector=0x08\nvoid v(void) { _asm GOTO low _endasm }\n#pragma code\n"
     "#pragma interruptlow low\nvoid low(void) {}\nvoid main(void) {}\n", 3, "named by #pragma interruptlow"),
    ("void main(void) {\n    _asm GOTO main _endasm\n}\n", 2, "belongs alone in a function at the vector"),
    ("#pragma interrupt isr\nvoid isr(int n) {}\nvoid main(void) {}\n", 1, "void isr(void)"),
    ("void isr(void) {}\n#pragma interrupt isr\nvoid main(void) {}\n", 2, "comes after isr's definition"),
    ("#pragma interrupt nobody\nvoid main(void) {}\n", 1, "defines no function nobody"),
    ("void main(void) {\n#pragma interrupt main\n}\n", 2, "belongs at the top level of the file"),
    ("#pragma code high_vector=0x08\nvoid a(void) { _asm GOTO isr _endasm }\nvoid b(void) {}\n", 3,
     "A #pragma code alone ends the vector's section"),
    ('#include "/etc/hostname"\nvoid main(void) {}\n', 1, "includes only its own headers"),
    ('#include "../secrets.h"\nvoid main(void) {}\n', 1, "includes only its own headers"),
    ("#include __FILE__\nvoid main(void) {}\n", 1, "includes only its own headers"),
    ("#error not finished\nvoid main(void) {}\n", 1, "#error not finished"),
    ("int x;\n", 0, "there is no main()"),
])
def test_an_error_names_the_c_line_and_what_is_wrong(source, line, words):
    error = c_error(source)
    assert error.line == line, str(error)
    assert words in str(error), str(error)
    assert str(error).startswith(f"t.c:{line}:" if line else "t.c: ")


def test_pragmas_of_c18_are_accepted_and_0b_constants_and_nop_clrwdt_work():
    module, process = run_c("""
        #include <p18f8680.h>
        #pragma config OSC = HSPLL, WDT = OFF, LVP = OFF
        #pragma romdata
        rom const char banner[] = "APP023";
        #pragma udata
        unsigned char mask = 0b10100101;
        #pragma code
        void work(void) { Nop(); ClrWdt(); }
    """ + MAIN_LOOP)
    assert process.failure is None and module.mask == 0xA5 and bytes(module.banner[:6]) == b"APP023"


def test_writing_to_a_rom_array_is_refused():
    error = c_error('rom const char banner[] = "X";\nvoid main(void) {\n    banner[0] = 1;\n}\n')
    assert error.line == 3 and "program memory" in str(error)


def test_no_python_traceback_reaches_a_student_from_a_broken_c_file(tmp_path):
    for text in ("void main(void) { int x = ; }", "}}}", "\x00\x01\x02", "void main(void) { while (1) { int"):
        firmware = tmp_path / "ex1.c"
        firmware.write_bytes(text.encode())
        verdict = check("ex1", firmware, seed=1)
        assert verdict.fault == "load", str(verdict)
        assert "Traceback" not in str(verdict)


# ====================================================================== hostile input, each a named fault in time

@pytest.mark.parametrize("source, words", [
    ("#define A0 x x x x x x x x\n" + "".join(f"#define A{n} A{n - 1} A{n - 1} A{n - 1} A{n - 1}\n"
                                              for n in range(1, 24)) + "int y = A23;\nvoid main(void) {}\n",
     "macro bomb"),
    ("int x = " + "(" * 5000 + "1" + ")" * 5000 + ";\nvoid main(void) {}\n", "nest more than"),
    ("void main(void) {\n" + "if (1) {\n" * 200 + "}\n" * 200 + "}\n", "nest more than"),
    ("".join(f"int v{n} = {n};\n" for n in range(60_000)) + "void main(void) {}\n", "characters"),
    ("".join(f"int v{n} = {n};\n" for n in range(20_000)) + "void main(void) {}\n", "more than 10,000 lines"),
    ('#include "t.c"\nvoid main(void) {}\n', "includes only its own headers"),
    ("#define F(x) x x x x x x x x\n#define G(x) F(F(F(F(x))))\nint y = G(G(G(G(1))));\nvoid main(void) {}\n",
     ":3: the macro F() expands to more than 200,000 tokens"),      # at its line, not when the 5 s run out
])
def test_hostile_c_is_refused_by_a_named_limit_quickly(source, words):
    started = time.process_time()
    error = c_error(source)
    assert words in str(error), str(error)[:500]
    assert time.process_time() - started < 10, "the translation's CPU time is limited to 5 s"


def test_a_translated_file_is_cached_by_its_content_defines_and_options():
    source = (SOLUTIONS / "ex2.c").read_bytes()
    first = c18_package.translate("cache.c", source, {}, ())
    assert c18_package.translate("cache.c", source, {}, ()) is first
    assert c18_package.translate("cache.c", source, {"MESSAGE_ID1": 0x110}, ()) is not first
    assert c18_package.translate("cache.c", source, {}, ("-Oi",)) is not first
    assert c18_package.translate("cache.c", source + b"\n", {}, ()) is not first
    one = load_source("cache.c", source)
    other = load_source("cache.c", source)
    assert one is not other and one.TxData is not other.TxData, "each load is a fresh module with its own globals"


# ====================================================================== graded in the sandbox

def test_a_class_in_c_is_graded_in_the_sandbox_either_language_per_exercise(tmp_path):
    import io
    import json

    import nbformat

    from appsim.workshop.grading.grade import run
    from appsim.workshop.sandbox.children import Limits

    root = tmp_path / "class"
    (root / "alice").mkdir(parents=True)
    for name in C_FILES.values():
        (root / "alice" / name).write_text((SOLUTIONS / name).read_text())
    (root / "bob").mkdir()
    (root / "bob" / "ex1.py").write_text((SOLUTIONS / "ex1.py").read_text())
    (root / "bob" / "ex1.c").write_text((SOLUTIONS / "ex1.c").read_text())
    (root / "bob" / "ex2.c").write_text((SOLUTIONS / "ex2.c").read_text())
    (root / "bob" / "ex3.py").write_text((SOLUTIONS / "ex3.py").read_text())
    (root / "carol").mkdir()
    notebook = nbformat.read(KIT / "notebooks" / "ex1.ipynb", as_version=4)
    for cell in notebook.cells:
        tags = cell.metadata.get("tags", [])
        if "firmware-c" in tags:
            cell.source = "%%writefile ex1.c\n" + (SOLUTIONS / "ex1.c").read_text()
        if "firmware-choice" in tags:
            cell.source = 'FIRMWARE = "ex1.c"'
    nbformat.write(notebook, root / "carol" / "ex1.ipynb")
    records = {r["submission"]: r for r in run([root], results=tmp_path / "grades.jsonl", jobs=2, seed=11,
                                                limits=Limits(time_s=20, stall_s=5), out=io.StringIO())}
    alice = records["alice"]
    assert alice["score"] == alice["max_score"], json.dumps(alice, indent=1)[:3000]
    bob = records["bob"]["exercises"]
    assert bob["ex1"]["fault"] == "ambiguous" and "ex1.c and ex1.py were both handed in" in \
        bob["ex1"]["checks"][0]["message"]
    assert bob["ex2"]["score"] == bob["ex2"]["max_score"] and bob["ex3"]["score"] == bob["ex3"]["max_score"]
    carol = records["carol"]["exercises"]["ex1"]
    assert carol["score"] == carol["max_score"] and "ex1.c ran" in carol["checks"][0]["message"]


def test_a_c_firmware_that_loops_without_touching_a_register_is_stopped_at_its_c_line():
    _, process = run_c("#include <p18f8680.h>\nint n;\nvoid main(void) {\n    n = 1;\n    while (1) { n++; }\n}\n",
                       name="stuck.c", seconds=3.0)
    fault = board_fault(process)
    assert fault is not None and fault.kind == "stalled", fault
    assert "at line 5 of stuck.c (`while (1) { n++; }`)" in fault.message and "`while(1);`" in fault.message


def test_a_c_empty_loop_no_interrupt_can_end_stops_at_once_naming_its_c_line():
    _, process = run_c("#include <p18f8680.h>\nint n;\nvoid main(void) {\n    n = 1;\n    while (1);\n}\n",
                       name="stuck.c", seconds=0.001)
    fault = board_fault(process)
    assert fault is not None and fault.kind == "stalled", fault
    assert fault.message.startswith("main() waits in an empty loop at line 5 of stuck.c (`while (1);`), which only an "
                                    "interrupt routine can end, and no interrupt can come: INTCONbits.GIE is 0"), fault


def test_the_command_line_takes_c18s_minus_oi_as_c18s_command_line_does(tmp_path):
    import subprocess
    import sys

    firmware = tmp_path / "ex3.c"
    firmware.write_text(_edited("ex3", SHIFT_NO_CAST, ("char LCD[22];", "char LCD[22];\nunsigned int adc;")))
    runs = {flags: subprocess.run([sys.executable, "-m", "appsim", "check", "ex3", str(firmware), "--seed", "202",
                                   *flags], capture_output=True, text=True, timeout=120, cwd=tmp_path)
            for flags in ((), ("-Oi",), ("--c-option=-Oi",))}
    assert runs[()].returncode == 1 and "FAIL  LCD shows the master's A/D and ID" in runs[()].stdout
    assert runs["-Oi",].returncode == 0 and runs["--c-option=-Oi",].returncode == 0, runs["-Oi",].stdout
    wrong = subprocess.run([sys.executable, "-m", "appsim", "check", "ex3", str(firmware), "--c-option=-O2"],
                           capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert wrong.returncode == 2 and "not a C18 option the kit knows" in wrong.stderr


# ====================================================================== the kit headers' state, handed to a sandbox

_TRANSLATE_ALL = """
import hashlib, marshal, sys
from pathlib import Path
from appsim.firmware import c18
if sys.argv[1] == "adopt":
    c18.adopt(sys.stdin.buffer.read())
for path in sorted(p for folder in sys.argv[2:] for p in Path(folder).rglob("*.c")):
    translated = c18.translate(path.name, path.read_bytes(), {}, ())
    print(path.name, hashlib.sha256(marshal.dumps(translated.code)).hexdigest(), sorted(translated.constants.items()))
"""


def test_the_headers_state_the_grader_hands_over_translates_every_file_as_headers_parsed_here():
    import subprocess
    import sys

    state = c18_package.header_state()
    folders = [str(SOLUTIONS), str(STARTERS)]
    parsed = subprocess.run([sys.executable, "-c", _TRANSLATE_ALL, "parse", *folders], capture_output=True,
                            check=True).stdout
    adopted = subprocess.run([sys.executable, "-c", _TRANSLATE_ALL, "adopt", *folders], input=state,
                             capture_output=True, check=True).stdout
    assert parsed.count(b"\n") == 17 and adopted == parsed, "solutions, interrupts, starters"
    with pytest.raises(ValueError):
        c18_package.adopt(__import__("pickle").dumps(("not", "the", "kit's")))



@pytest.mark.parametrize("isolated", [False, True])
def test_a_sandbox_booted_with_the_headers_state_loads_c_at_boot_and_grades_it(isolated):
    import shutil

    from appsim.workshop.sandbox.children import Limits, Sandbox
    from appsim.workshop.sandbox.host import SandboxedFirmware
    from appsim.workshop.sandbox.isolation import isolation

    if isolated and not shutil.which("bwrap"):
        pytest.skip("needs bubblewrap")
    with Sandbox(isolation() if isolated else None, Limits(time_s=20)) as sandbox:
        sandbox.expect_c(c18_package.header_state())
        for exercise in ("ex1", "ex6"):
            firmware = SandboxedFirmware(sandbox, C_FILES[exercise], (SOLUTIONS / C_FILES[exercise]).read_bytes(),
                                         sandbox.limits, owner="alice")
            try:
                verdict = check(exercise, firmware, seed=5)
            finally:
                firmware.close()
            assert verdict.score == verdict.max_score, str(verdict)


def test_the_grader_gives_a_submissions_exercises_to_one_worker_and_so_one_sandbox():
    import collections
    from types import SimpleNamespace

    from appsim.workshop.grading.grade import ORDER, _next_for, _Task

    alice, bob, carol = (SimpleNamespace(name=n) for n in ("alice", "bob", "carol"))
    waiting = collections.deque(_Task(n, s, e) for n, (s, e) in
                                enumerate((s, e) for s in (alice, bob, carol) for e in ORDER))
    one, two = SimpleNamespace(submission=None), SimpleNamespace(submission=None)
    taken: dict[str, list[str]] = {"one": [], "two": []}
    while waiting:          # the two workers take turns: each keeps to its submission while it has tasks left
        for name, worker, other in (("one", one, two), ("two", two, one)):
            if waiting:
                task = _next_for(worker, waiting, [other.submission])
                worker.submission = task.submission
                taken[name].append(task.submission.name)
    assert taken["one"][:8] == ["alice"] * 7 + ["carol"] and taken["two"][:7] == ["bob"] * 7
    assert taken["two"][7:] == ["carol"] * 3 and taken["one"][8:] == ["carol"] * 3, \
        "the last submission's tasks go to whichever worker is free, so that both end together"


# ====================================================================== issue 22 and 28, in C

def test_a_c_identifier_of_no_station_gets_the_python_twins_partial_credit_in_check_and_in_grade(tmp_path):
    """MESSAGE_ID1 read by appsim.firmware.identity from the C module as from the Python one, in process and in the
    sandbox: the same station (station 1's place), the same partial credit, the same words."""
    import io

    from appsim.workshop.grading.grade import run
    from appsim.workshop.sandbox.children import Limits

    c = (SOLUTIONS / "ex2.c").read_text().replace("#define MESSAGE_ID1 0x100", "#define MESSAGE_ID1 0x160")
    python = (SOLUTIONS / "ex2.py").read_text().replace("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 0x160")
    for name, text in (("c_student", ("ex2.c", c)), ("py_student", ("ex2.py", python))):
        (tmp_path / "class" / name).mkdir(parents=True)
        (tmp_path / "class" / name / text[0]).write_text(text[1])
    records = {r["submission"]: r["exercises"]["ex2"] for r in run(
        [tmp_path / "class"], results=tmp_path / "g.jsonl", jobs=1, seed=9, limits=Limits(time_s=20),
        out=io.StringIO())}
    in_process = check("ex2", tmp_path / "class" / "c_student" / "ex2.c", seed=9)
    assert records["c_student"]["score"] == in_process.score == records["py_student"]["score"] == 4
    assert [r["message"] for r in records["c_student"]["checks"]][1:] == [r.message for r in in_process.checks][1:]
    assert "MESSAGE_ID1 = 0x160 is not a station's identifier" in " ".join(r.message for r in in_process.checks)


def test_appsim_check_takes_a_notebook_whose_firmware_cell_is_c(tmp_path):
    import subprocess
    import sys

    import nbformat

    notebook = nbformat.read(KIT / "notebooks" / "ex1.ipynb", as_version=4)
    for cell in notebook.cells:
        tags = cell.metadata.get("tags", [])
        if "firmware-c" in tags:
            cell.source = "%%writefile ex1.c\n" + (SOLUTIONS / "ex1.c").read_text()
        if "firmware-choice" in tags:
            cell.source = 'FIRMWARE = "ex1.c"'
    nbformat.write(notebook, tmp_path / "mine.ipynb")
    done = subprocess.run([sys.executable, "-m", "appsim", "check", "ex1", str(tmp_path / "mine.ipynb"), "--seed", "3"],
                          capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.startswith("EX1: 5/5"), done.stdout + done.stderr
    notebook.metadata["appsim"] = {"exercise": "ex2"}
    nbformat.write(notebook, tmp_path / "other.ipynb")
    refused = subprocess.run([sys.executable, "-m", "appsim", "check", "ex1", str(tmp_path / "other.ipynb")],
                             capture_output=True, text=True)
    assert refused.returncode == 2 and "EX2's notebook" in refused.stderr, refused.stderr
