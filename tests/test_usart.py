"""The USART at 19200 N 8 1 to the USB-CDC monitor or CON9 through DSW2, C18's usart.h, and DSW2 1 2 on PORTJ."""
from __future__ import annotations

import itertools
from collections.abc import Callable

import pytest

from appsim.board.app023 import APP023
from appsim.firmware import (
    SFR,
    USART_ASYNCH_MODE,
    USART_BRGH_HIGH,
    USART_BRGH_LOW,
    USART_CONT_RX,
    USART_EIGHT_BIT,
    USART_RX_INT_OFF,
    USART_SINGLE_RX,
    USART_SYNCH_MODE,
    USART_TX_INT_OFF,
    BusyUSART,
    DataRdyUSART,
    OpenUSART,
    PIR1bits,
    PORTJbits,
    RCSTAbits,
    ReadUSART,
    WriteUSART,
    putrsUSART,
    putsUSART,
)
from appsim.sim import PS_PER_SECOND

LINK = USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT & USART_CONT_RX & USART_BRGH_HIGH
SPBRG_19200 = 129                                           # 40 MHz / (16 x 130) = 19230.8 baud
FRAME_PS = 10 * 16 * (SPBRG_19200 + 1) * PS_PER_SECOND // 40_000_000     # 10 bits: 520 µs
MS = PS_PER_SECOND // 1000


def board_running(
    world, main: Callable[[], None] | None = None,
) -> tuple[APP023, list[tuple[int, int]], list[tuple[int, int]]]:
    """A board with listeners on both ends; `main` started on it."""
    board = APP023(world.bus, "station0")
    usb: list[tuple[int, int]] = []
    con9: list[tuple[int, int]] = []
    board.usb.listeners.append(lambda byte, time: usb.append((byte, time)))
    board.con9.listeners.append(lambda byte, time: con9.append((byte, time)))
    if main is not None:
        board.run(main)
    return board, usb, con9


def echo() -> None:
    OpenUSART(LINK, SPBRG_19200)
    while True:
        if DataRdyUSART():
            byte = ReadUSART()
            while BusyUSART():
                pass
            WriteUSART(byte)


def receive_only(config: int = LINK, spbrg: int = SPBRG_19200) -> Callable[[], None]:
    def main() -> None:
        OpenUSART(config, spbrg)
    return main


# ------------------------------------------------------------------ registers
def test_registers_at_their_addresses_with_reset_values(world):
    board, _, _ = board_running(world)
    names = ("TXSTA", "RCSTA", "SPBRG", "TXREG", "RCREG", "BAUDCON", "SPBRGH")
    assert [board.mcu.address_of(n) for n in names] == [0xFAC, 0xFAB, 0xFAF, 0xFAD, 0xFAE, 0xF7E, 0xF7F]
    assert board.mcu.read_name("TXSTA") == 0x02, "TRMT = 1: the shift register is empty"
    assert board.mcu.read_name("RCSTA") == 0 and board.mcu.read_name("PIR1") == 0
    assert board.mcu.read_name("BAUDCON") == 0x40, "RCIDL = 1"


@pytest.mark.parametrize(("txsta", "baudcon", "spbrgh", "spbrg", "baud"), [
    (0x04, 0x00, 0, 129, 40e6 / (16 * 130)),      # BRGH = 1: the classroom's 19200
    (0x00, 0x00, 0, 32, 40e6 / (64 * 33)),        # BRGH = 0
    (0x00, 0x08, 0, 129, 40e6 / (16 * 130)),      # BRG16 = 1, BRGH = 0
    (0x04, 0x08, 2, 0x08, 40e6 / (4 * 521)),      # BRG16 = 1, BRGH = 1: SPBRGH:SPBRG = 520
])
def test_baud_rate_follows_the_data_sheet_formulas(world, txsta, baudcon, spbrgh, spbrg, baud):
    board, _, _ = board_running(world)
    for name, value in (("TXSTA", txsta), ("BAUDCON", baudcon), ("SPBRGH", spbrgh), ("SPBRG", spbrg)):
        board.mcu.write_name(name, value)
    assert board.usart.baud == pytest.approx(baud)


# ------------------------------------------------------------------ transmit
def test_putrsusart_hello_reaches_the_usb_monitor_one_frame_after_another(world):
    def main() -> None:
        OpenUSART(LINK, SPBRG_19200)
        putrsUSART("hello\r\n")

    _, usb, con9 = board_running(world, main)
    world.run(0.01)
    assert bytes(byte for byte, _ in usb) == b"hello\r\n\0", "C18's putrsUSART sends the terminating NUL too"
    assert con9 == []
    gaps = [b - a for (_, a), (_, b) in itertools.pairwise(usb)]
    # C18's BusyUSART waits for TRMT (shift register empty): each frame (520 µs) plus the loop's few cycles.
    assert all(FRAME_PS <= gap < FRAME_PS + 2_000_000 for gap in gaps), gaps
    assert FRAME_PS == 520_000_000


def test_feeding_txreg_on_txif_sends_frames_back_to_back_every_520_us(world):
    def main() -> None:
        OpenUSART(LINK, SPBRG_19200)
        for byte in b"CAN":
            while not PIR1bits.TXIF:            # TXREG empty: the previous byte is in the shift register
                pass
            SFR.TXREG = byte

    _, usb, _ = board_running(world, main)
    world.run(0.01)
    assert bytes(byte for byte, _ in usb) == b"CAN"
    assert [b - a for (_, a), (_, b) in itertools.pairwise(usb)] == [FRAME_PS, FRAME_PS]


def test_txif_and_trmt_follow_txreg_and_the_shift_register(world):
    states = []

    def state() -> tuple[int, int]:
        return PIR1bits.TXIF, SFR.TXSTA & 0x02

    def main() -> None:
        OpenUSART(LINK, SPBRG_19200)
        states.append(state())
        SFR.TXREG = 0x41                        # straight into the shift register
        states.append(state())
        SFR.TXREG = 0x42                        # waits in TXREG
        states.append(state())

    board, usb, _ = board_running(world, main)
    world.run(0.01)
    assert states == [(1, 0x02), (1, 0), (0, 0)]
    assert bytes(byte for byte, _ in usb) == b"AB"
    assert board.mcu.read_name("TXSTA") & 0x02 and board.interrupts.flag(4)


def test_putsusart_stops_at_the_first_nul(world):
    _, usb, _ = board_running(world, lambda: (OpenUSART(LINK, SPBRG_19200), putsUSART(b"ID\0junk")))
    world.run(0.01)
    assert bytes(byte for byte, _ in usb) == b"ID\0"


# ------------------------------------------------------------------ receive
def test_echo_firmware_sends_back_what_the_pc_types(world):
    board, usb, _ = board_running(world, echo)
    world.run(0.001)
    board.usb.write(b"CAN 202")
    world.run(0.02)
    assert bytes(byte for byte, _ in usb) == b"CAN 202"
    assert board.usb.lost == 0


def test_third_byte_into_a_full_fifo_sets_oerr_and_the_receiver_stops_until_cren_is_cleared(world):
    board, _, _ = board_running(world, receive_only())
    world.run(0.001)
    board.usb.write(b"ABCD")                    # nobody reads RCREG
    world.run(0.01)
    mcu = board.mcu
    assert mcu.read_name("RCSTA") & 0x02, "OERR"
    assert board.usb.lost == 2, "C overran the FIFO; D found the receiver blocked by OERR"
    assert [mcu.read_name("RCREG"), mcu.read_name("RCREG")] == [ord("A"), ord("B")]
    assert not board.interrupts.flag(5), "RCIF: the FIFO is empty"
    board.usb.write(b"E")
    world.run(0.01)
    assert not board.interrupts.flag(5) and board.usb.lost == 3, "OERR still blocks reception"
    mcu.write_name("RCSTA", mcu.read_name("RCSTA") & ~0x10)     # CREN = 0 clears OERR
    mcu.write_name("RCSTA", mcu.read_name("RCSTA") | 0x10)
    assert not mcu.read_name("RCSTA") & 0x02
    board.usb.write(b"F")
    world.run(0.01)
    assert mcu.read_name("RCREG") == ord("F")


def test_firmware_sees_oerr_through_rcstabits(world):
    seen = []

    def main() -> None:
        OpenUSART(LINK, SPBRG_19200)
        while not RCSTAbits.OERR:
            pass
        seen.append((ReadUSART(), ReadUSART(), DataRdyUSART()))

    board, _, _ = board_running(world, main)
    world.run(0.001)
    board.usb.write(b"xyz")
    world.run(0.01)
    assert seen == [(ord("x"), ord("y"), False)]


@pytest.mark.parametrize("setup", ["never opened", "single receive", "cren cleared"])
def test_bytes_arriving_with_the_receiver_off_are_lost(world, setup):
    main = {
        "never opened": lambda: None,
        "single receive": receive_only(LINK & USART_SINGLE_RX),     # SREN does nothing in asynchronous mode
        "cren cleared": lambda: (OpenUSART(LINK, SPBRG_19200), setattr(RCSTAbits, "CREN", 0)),
    }[setup]
    board, _, _ = board_running(world, main)
    world.run(0.001)
    board.usb.write(b"lost")
    world.run(0.01)
    assert board.usb.lost == 4 and not board.interrupts.flag(5)


def test_wrong_baud_rate_receives_garbage(world):
    board, _, _ = board_running(world, receive_only(LINK & USART_BRGH_LOW, 64))   # 9615 baud, PC at 19200
    world.run(0.001)
    board.usb.write(b"\x55")
    world.run(0.01)
    assert board.interrupts.flag(5), "the receiver saw a start bit and took a byte"
    assert board.mcu.read_name("RCREG") != 0x55, "sampled at half the rate, 0x55 is not 0x55"


def test_synchronous_mode_is_refused_with_a_clear_error(world):
    board, _, _ = board_running(world, receive_only(USART_SYNCH_MODE & USART_EIGHT_BIT, 129))
    world.sim.run(until=MS)
    assert "synchronous mode" in str(board.mcu.process.failure)
    assert "USART_ASYNCH_MODE" in str(board.mcu.process.failure)


# ------------------------------------------------------------------ DSW2
def test_dsw2_defaults_to_the_usb_monitor(world):
    board, _, _ = board_running(world)
    assert str(board.dsw2) == "DSW2: 5 6 ON (USART -> PIC18F2550 USB)"
    assert board.usb.connected and not board.con9.connected


def test_dsw2_3_4_routes_the_usart_to_con9(world):
    board, usb, con9 = board_running(world, echo)
    board.dsw2.set([3, 4])
    assert str(board.dsw2) == "DSW2: 3 4 ON (USART -> CON9 RS-232)"
    world.run(0.001)
    board.usb.write(b"u")
    board.con9.write(b"c")
    world.run(0.01)
    assert usb == [] and bytes(byte for byte, _ in con9) == b"c"
    assert board.usb.lost == 1


@pytest.mark.parametrize(("on", "explained"), [
    ([3, 4, 5, 6], "switches of both pairs are ON"),
    ([5], "5 ON alone"),
    ([], "3 4 and 5 6 are all OFF"),
    ([5, 6, 3], "switches of both pairs are ON"),
])
def test_dsw2_routing_to_both_or_neither_sends_bytes_nowhere_and_says_why(world, on, explained):
    board, usb, con9 = board_running(world, lambda: (OpenUSART(LINK, SPBRG_19200), putrsUSART("x")))
    board.dsw2.set(on)
    world.run(0.01)
    assert usb == [] and con9 == []
    assert board.dsw2.route is None
    assert explained in board.dsw2.routing and "nowhere" in str(board.dsw2)


def test_dsw2_1_and_2_read_on_portj_and_a_polling_firmware_sees_the_switch(world):
    seen = []

    def main() -> None:
        seen.append((PORTJbits.RJ0, PORTJbits.RJ1))
        while PORTJbits.RJ0:                    # wait for DSW2 1 to be switched ON
            pass
        seen.append((PORTJbits.RJ0, PORTJbits.RJ1, world.sim.time()))

    board, _, _ = board_running(world, main)
    board.dsw2.on(2)
    world.sim.call_at(5 * MS, lambda: board.dsw2.on(1))
    world.run(0.01)
    assert seen[0] == (1, 0), "OFF reads 1 (pulled up), ON reads 0"
    assert seen[1][:2] == (0, 0) and 5 * MS <= seen[1][2] < 5 * MS + MS // 100


def test_portj_outputs_read_back_the_latch(world):
    board, _, _ = board_running(world)
    mcu = board.mcu
    assert mcu.read_name("TRISJ") == 0xFF
    mcu.write_name("TRISJ", 0xFE)               # RJ0 an output
    mcu.write_name("PORTJ", 0x00)
    assert mcu.read_name("PORTJ") & 0x03 == 0b10, "RJ0 the latch, RJ1 still DSW2 2 (OFF)"
    assert mcu.read_name("LATJ") == 0x00


def test_dsw2_positions_are_1_to_8(world):
    board, _, _ = board_running(world)
    with pytest.raises(ValueError, match="positions 1..8"):
        board.dsw2.on(9)
