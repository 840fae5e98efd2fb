"""Timer1 and PIR1: the overflow flag the workshop polls, 16-bit read/write buffering, and C18's timers.h."""
from __future__ import annotations

import itertools

import pytest

from appsim.board.app023 import APP023
from appsim.firmware import (
    T1_8BIT_RW,
    T1_16BIT_RW,
    T1_OSC1EN_OFF,
    T1_PS_1_1,
    T1_PS_1_2,
    T1_PS_1_4,
    T1_PS_1_8,
    T1_SOURCE_EXT,
    T1_SOURCE_INT,
    T1_SYNC_EXT_OFF,
    TIMER_INT_OFF,
    TIMER_INT_ON,
    CloseTimer1,
    OpenTimer1,
    PIE1bits,
    PIR1bits,
    ReadTimer1,
    T1CONbits,
    WriteTimer1,
)
from appsim.sim import PS_PER_SECOND

CLASSROOM = TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF
TCY_PS = 100_000                            # Fosc 40 MHz: one instruction cycle is 100 ns
T1CON, TMR1H, TMR1L = 0xFCD, 0xFCF, 0xFCE
RD16, TMR1ON, TMR1CS = 0x80, 0x01, 0x02


@pytest.fixture
def board(world) -> APP023:
    return APP023(world.bus, "station0")


def overflow_times(world, board: APP023, config: int, seconds: float) -> list[int]:
    """Run the workshop's polling loop (TMR1_OVERFLOW) and note when the firmware sees each overflow."""
    seen: list[int] = []

    def main() -> None:
        OpenTimer1(config)
        while True:
            if PIR1bits.TMR1IF:             # TMR1_OVERFLOW in EX*.C
                PIR1bits.TMR1IF = 0
                seen.append(world.sim.time())

    board.run(main)
    world.run(seconds)
    return seen


def test_registers_are_at_their_addresses_with_their_reset_values(board):
    mcu = board.mcu
    assert {name: mcu.address_of(name) for name in ("T1CON", "TMR1H", "TMR1L", "PIR1", "PIE1", "IPR1")} == {
        "T1CON": 0xFCD, "TMR1H": 0xFCF, "TMR1L": 0xFCE, "PIR1": 0xF9E, "PIE1": 0xF9D, "IPR1": 0xF9F}
    assert [mcu.read_name(n) for n in ("T1CON", "TMR1H", "TMR1L", "PIR1", "PIE1", "IPR1")] == [0, 0, 0, 0, 0, 0xFF]
    mcu.write_name("T1CON", 0xFF)
    assert mcu.read_name("T1CON") == 0xBF, "bit 6 of T1CON is unimplemented on the PIC18F8680"


def test_classroom_setting_overflows_every_52_4288_ms(world, board):
    seen = overflow_times(world, board, CLASSROOM, 1.0)
    period = 65536 * 8 * PS_PER_SECOND // 10_000_000       # 65536 x 8 / 10 MHz
    assert period == 52_428_800_000
    assert len(seen) == 19                                   # 1 s / 52.4288 ms
    assert {b - a for a, b in itertools.pairwise(seen)} == {period}
    assert board.timer1.overflow_period_ps() == period


@pytest.mark.parametrize(("prescale", "mask"), [(1, T1_PS_1_1), (2, T1_PS_1_2), (4, T1_PS_1_4), (8, T1_PS_1_8)])
def test_prescaler_sets_the_overflow_period(world, board, prescale, mask):
    seen = overflow_times(world, board, TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & mask, 0.2)
    assert {b - a for a, b in itertools.pairwise(seen)} == {65536 * prescale * TCY_PS}


def test_open_timer1_sets_the_registers_as_c18_does(world, board):
    fields = {}

    def main() -> None:
        OpenTimer1(TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
        fields.update(RD16=T1CONbits.RD16, T1CKPS=T1CONbits.T1CKPS, T1OSCEN=T1CONbits.T1OSCEN,
                      T1SYNC=T1CONbits.T1SYNC, TMR1CS=T1CONbits.TMR1CS, TMR1ON=T1CONbits.TMR1ON,
                      TMR1IE=PIE1bits.TMR1IE, TMR1IF=PIR1bits.TMR1IF)

    board.run(main)
    world.run(0.001)
    # T1_SYNC_EXT_OFF leaves T1SYNC = 1 ("do not synchronise"); it only matters for an external clock.
    assert fields == {"RD16": 1, "T1CKPS": 3, "T1OSCEN": 0, "T1SYNC": 1, "TMR1CS": 0, "TMR1ON": 1,
                      "TMR1IE": 1, "TMR1IF": 0}


def test_read_timer1_counts_instruction_cycles_from_write_timer1(world, board):
    reads = []

    def main() -> None:
        OpenTimer1(CLASSROOM & T1_PS_1_1)
        WriteTimer1(1000)
        written = world.sim.time()
        reads.append((ReadTimer1(), world.sim.time() - written))

    board.run(main)
    world.run(0.001)
    [(value, elapsed)] = reads
    assert 1000 < value <= 1000 + elapsed // TCY_PS


def test_16_bit_mode_reads_tmr1h_as_latched_by_the_tmr1l_read(world, board):
    mcu, sim = board.mcu, world.sim
    mcu.write(T1CON, RD16 | TMR1ON)                          # 1:1, counting from 0 at t = 0
    sim.run(until=0x1FF * TCY_PS)
    assert mcu.read(TMR1L) == 0xFF
    sim.run(until=0x200 * TCY_PS)                             # the count carries into the high byte
    assert mcu.read(TMR1H) == 0x01, "TMR1H reads the buffer latched when TMR1L was read"
    assert mcu.read(TMR1L) == 0x00 and mcu.read(TMR1H) == 0x02


def test_8_bit_mode_reads_the_live_high_byte_and_can_see_the_carry(world, board):
    mcu, sim = board.mcu, world.sim
    mcu.write(T1CON, TMR1ON)                                 # RD16 = 0
    sim.run(until=0x1FF * TCY_PS)
    assert mcu.read(TMR1L) == 0xFF
    sim.run(until=0x200 * TCY_PS)
    assert mcu.read(TMR1H) == 0x02, "low byte 0xFF with high byte 0x02: the 8-bit read tears"


def test_16_bit_mode_writes_tmr1h_only_with_the_next_tmr1l_write(world, board):
    mcu = board.mcu
    mcu.write(T1CON, RD16)                                   # stopped, so the count stays put
    mcu.write(TMR1H, 0x12)
    assert mcu.read(TMR1L) == 0x00 and mcu.read(TMR1H) == 0x00
    mcu.write(TMR1H, 0x12)
    mcu.write(TMR1L, 0x34)
    assert board.timer1.value() == 0x1234
    mcu.write(T1CON, 0)                                      # 8-bit mode: each byte goes straight in
    mcu.write(TMR1H, 0x56)
    assert board.timer1.value() == 0x5634


def test_overflow_sets_tmr1if_exactly_when_the_count_rolls_over(world, board):
    mcu, sim = board.mcu, world.sim
    mcu.write(TMR1H, 0xFF)
    mcu.write(TMR1L, 0xF0)
    mcu.write(T1CON, TMR1ON)
    sim.run(until=16 * TCY_PS - 1)
    assert not board.interrupts.flag(0) and board.timer1.value() == 0xFFFF
    sim.run(until=16 * TCY_PS)
    assert PIR1_TMR1IF(mcu) and board.timer1.value() == 0x0000
    mcu.write_name("PIR1", 0)
    assert not PIR1_TMR1IF(mcu), "firmware clears the latched flag"
    sim.run(until=(16 + 65536) * TCY_PS)
    assert PIR1_TMR1IF(mcu), "the timer keeps counting and overflows again 65536 counts later"


def PIR1_TMR1IF(mcu) -> bool:
    return bool(mcu.read_name("PIR1") & 0x01)


def test_external_clock_does_not_count_on_the_app023(world, board):
    mcu = board.mcu
    mcu.write(T1CON, TMR1ON | TMR1CS)
    world.sim.run(until=PS_PER_SECOND)
    assert board.timer1.value() == 0 and not PIR1_TMR1IF(mcu)


def test_external_clock_via_open_timer1_never_overflows(world, board):
    assert overflow_times(world, board, TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_EXT & T1_PS_1_8, 0.5) == []


def test_close_timer1_stops_the_count(world, board):
    values = []

    def main() -> None:
        OpenTimer1(TIMER_INT_ON & T1_8BIT_RW & T1_SOURCE_INT & T1_PS_1_8)
        CloseTimer1()
        values.append((ReadTimer1(), PIE1bits.TMR1IE))

    board.run(main)
    world.run(0.2)
    assert values == [(board.timer1.value(), 0)]
    assert not PIR1_TMR1IF(board.mcu)


def test_changing_t1con_keeps_the_prescaler_phase(world, board):
    mcu, sim = board.mcu, world.sim
    mcu.write(T1CON, 0x30 | TMR1ON)                          # 1:8: one count per 800 ns
    sim.run(until=8 * TCY_PS * 10 + 4 * TCY_PS)               # 10 counts and half a prescaler period
    mcu.write(T1CON, 0x30 | TMR1ON | RD16)
    sim.run(until=8 * TCY_PS * 11)
    assert board.timer1.value() == 11


@pytest.mark.parametrize(("call", "message"), [
    (lambda: OpenTimer1(0x1FF), "one byte of TIMER_INT_"),
    (lambda: WriteTimer1(70_000), "0..65535"),
])
def test_bad_arguments_say_what_is_wrong(world, board, call, message):
    board.run(call)
    world.sim.run(until=PS_PER_SECOND // 1000)
    assert message in str(board.mcu.process.failure)
