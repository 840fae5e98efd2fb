"""C18's delays.h, all of it, in Python and in C: Delay1TCY and Delay10TCY, and Delay10TCYx .. Delay10KTCYx, which take
an unsigned char, a count of 0 meaning 256 units."""
from __future__ import annotations

from itertools import pairwise

import pytest

from appsim.errors import CCompileError
from appsim.firmware import DELAYS, Delay1KTCYx, Delay1TCY, Delay10KTCYx, Delay10TCY, Delay10TCYx, Delay100TCYx
from appsim.firmware.loader import load_source
from appsim.firmware.runtime import CALL_CYCLES

TCY_PS = 100_000
COUNTED = [(Delay10TCYx, 10), (Delay100TCYx, 100), (Delay1KTCYx, 1_000), (Delay10KTCYx, 10_000)]


def waited(world, main) -> int:
    """The instruction cycles between the two marks `main(mark)` makes on a board."""
    times: list[int] = []
    world.node("delays", lambda: main(lambda: times.append(world.sim.time())))
    world.run(1.0)
    return (times[1] - times[0]) // TCY_PS


def delayed(world, delay, *unit: int) -> int:
    def main(mark) -> None:
        mark()
        delay(*unit)
        mark()
    return waited(world, main)


@pytest.mark.parametrize(("delay", "cycles"), COUNTED, ids=[delay.__name__ for delay, _ in COUNTED])
def test_a_count_of_0_means_256_units_as_c18_counts_it(world, delay, cycles):
    assert delayed(world, delay, 0) == CALL_CYCLES + 256 * cycles


@pytest.mark.parametrize(("delay", "cycles"), COUNTED, ids=[delay.__name__ for delay, _ in COUNTED])
def test_each_unit_is_its_cycles_after_the_call(world, delay, cycles):
    assert delayed(world, delay, 255) == CALL_CYCLES + 255 * cycles


def test_delay1tcy_is_a_nop_and_delay10tcy_is_delay10tcyx_of_1(world):
    assert delayed(world, Delay1TCY) == 1
    assert delayed(world, Delay10TCY) == CALL_CYCLES + 10


def test_the_kit_has_every_delay_of_c18s_delays_h():
    assert [delay.__name__ for delay in DELAYS] == ["Delay1TCY", "Delay10TCY", "Delay10TCYx", "Delay100TCYx",
                                                   "Delay1KTCYx", "Delay10KTCYx"]


@pytest.mark.parametrize("delay", [delay for delay, _ in COUNTED], ids=[delay.__name__ for delay, _ in COUNTED])
def test_the_unit_is_an_unsigned_char_and_a_larger_count_says_what_c18_would_wait(world, delay):
    raised: list[str] = []

    def main() -> None:
        for unit in (256, 650, -1, 2.5, True):
            with pytest.raises(ValueError) as error:
                delay(unit)
            raised.append(str(error.value))

    world.node("delays", main)
    world.run(0.01)
    assert raised[0].startswith(f"{delay.__name__} takes an unsigned char, 0..255 units (0 means 256); got 256: "
                                "C18 would wait 256 units (it keeps the low byte)")
    assert "got 650: C18 would wait 138 units" in raised[1]
    assert len(raised) == 5


C_DELAYS = """#include <p18f8680.h>
#include <delays.h>
void main(void)
{
    LATJ = 1;
    Delay1TCY();
    LATJ = 2;
    Delay10TCY();
    LATJ = 3;
    Delay10TCYx(0);
    LATJ = 4;
    Delay100TCYx(7);
    LATJ = 5;
    Delay1KTCYx(1);
    LATJ = 6;
    Delay10KTCYx(2);
    LATJ = 7;
    while (1)
        Delay10KTCYx(0);
}
"""


def test_c_firmware_waits_what_the_python_delays_wait(world):
    """The same delays from C (delays.h): the time between the LED writes is each delay and one write."""
    module = load_source("delays.c", C_DELAYS.encode())
    mcu = world.node("c")
    latj = mcu.address_of("LATJ")
    marks: list[tuple[int, int]] = []
    write = mcu.write

    def watched(address: int, value: int) -> None:
        write(address, value)
        if address == latj:
            marks.append((value, world.sim.time()))
    mcu.write = watched                                      # type: ignore[method-assign]
    mcu.run(module.main)
    world.run(0.05)
    gaps = [(later - earlier) // TCY_PS - 2 for (_, earlier), (_, later) in pairwise(marks)]   # and a write's 2
    assert [value for value, _ in marks] == [1, 2, 3, 4, 5, 6, 7]
    assert gaps == [1, CALL_CYCLES + 10, CALL_CYCLES + 2_560, CALL_CYCLES + 700, CALL_CYCLES + 1_000,
                    CALL_CYCLES + 20_000]


def test_a_c_delay_outside_delays_h_is_refused_saying_so():
    with pytest.raises(CCompileError) as error:
        load_source("d.c", C_DELAYS.replace("Delay100TCYx(7)", "Delay100MSx(7)").encode())
    assert "Delay100MSx" in str(error.value)


def test_delays_h_alone_gives_every_delay_in_c():
    module = load_source("only.c", b"#include <delays.h>\nvoid main(void)\n{\n    Delay1TCY();\n    Delay10TCY();\n"
                                   b"    Delay100TCYx(1);\n    while (1)\n        Delay10KTCYx(0);\n}\n")
    assert callable(module.main)
