"""C18's delays.h: Delay1KTCYx and Delay10KTCYx take an unsigned char, and a count of 0 means 256 units."""
from __future__ import annotations

import pytest

from appsim.firmware import Delay1KTCYx, Delay10KTCYx
from appsim.firmware.runtime import CALL_CYCLES

TCY_PS = 100_000


def waited(world, delay, unit) -> int:
    """The instruction cycles `delay(unit)` takes on a board."""
    times: list[int] = []

    def main() -> None:
        times.append(world.sim.time())
        delay(unit)
        times.append(world.sim.time())

    world.node("delays", main)
    world.run(1.0)
    return (times[1] - times[0]) // TCY_PS


@pytest.mark.parametrize(("delay", "cycles"), [(Delay1KTCYx, 1_000), (Delay10KTCYx, 10_000)],
                         ids=["Delay1KTCYx", "Delay10KTCYx"])
def test_a_count_of_0_means_256_units_as_c18_counts_it(world, delay, cycles):
    assert waited(world, delay, 0) == CALL_CYCLES + 256 * cycles
    assert waited(world, delay, 255) == CALL_CYCLES + 255 * cycles


@pytest.mark.parametrize("delay", [Delay1KTCYx, Delay10KTCYx], ids=["Delay1KTCYx", "Delay10KTCYx"])
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
