"""Interrupts as the PIC18F8680 takes them (its data sheet's Interrupts chapter): INTCON's global enables, RCON.IPEN's
two priorities, PIR1/PIE1/IPR1 and the ECAN's PIR3/PIE3/IPR3, the latency, GIE cleared on entry and set by RETFIE, a
low-priority routine pre-empted by a high one; C18's `#pragma interrupt`/`interruptlow` as @interrupt/@interruptlow."""
from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from appsim.board.app023 import APP023
from appsim.chip.sfr import HIGH_VECTOR, LOW_VECTOR
from appsim.errors import FirmwareError, FirmwareHung, NoInterruptRoutine
from appsim.firmware import *
from appsim.firmware.loader import load_firmware
from appsim.sim import PS_PER_SECOND

TCY_PS = 100_000                    # 40 MHz: one instruction cycle is 100 ns
ACCESS_PS = 2 * TCY_PS              # a register access
MS = PS_PER_SECOND // 1000
TIMER1_PERIOD_PS = 65536 * 8 * TCY_PS
TIMER1_ON = TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF
CLASSROOM_CAN = (4, 10, 8, 4, 3)


@pytest.fixture
def board(world) -> APP023:
    return APP023(world.bus, "station1")


def firmware(tmp_path: Path, source: str, name: str = "isr.py"):
    """A firmware file written from `source` (dedented), loaded as a board loads it."""
    path = tmp_path / name
    path.write_text("from appsim.firmware import *\n\n" + textwrap.dedent(source))
    return load_firmware(path)


def stopped(board: APP023) -> str:
    process = board.mcu.process
    assert process is not None and isinstance(process.failure, FirmwareHung), process and process.failure_text
    return str(process.failure)


# ====================================================================== priorities and enables

def test_with_ipen_0_every_enabled_source_vectors_to_0x08_once_gie_and_peie_are_set(world, board):
    """Compatibility mode: a peripheral's interrupt needs INTCON.GIE and INTCON.PEIE; nothing vectors to 0x18."""
    taken: list[tuple[str, int]] = []

    def high() -> None:
        taken.append(("high", world.sim.time()))
        PIR1bits.TMR1IF = 0

    def main() -> None:
        OpenTimer1(TIMER1_ON)                   # PIE1.TMR1IE = 1
        IPR1bits.TMR1IP = 0                     # low priority: ignored while RCON.IPEN = 0
        INTCONbits.GIE = 1
        Delay10KTCYx(100)                       # 100 ms: an overflow at 52.4 ms, but PEIE is 0
        taken.append(("PEIE on", world.sim.time()))
        INTCONbits.PEIE = 1
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high, LOW_VECTOR: lambda: taken.append(("low", 0))})
    world.run(0.12)
    kinds = [kind for kind, _ in taken]
    assert kinds == ["PEIE on", "high", "high"], taken
    assert taken[1][1] - taken[0][1] < 10 * TCY_PS, "the pending TMR1IF interrupts as soon as PEIE is set"
    assert taken[2][1] == board.timer1._since + 3 * TCY_PS, "the next overflow interrupts when it happens"


def test_gie_is_cleared_on_entry_and_set_again_by_retfie(world, board):
    seen: dict[str, int] = {}

    def high() -> None:
        seen["in the routine"] = SFR.INTCON
        PIR1bits.TMR1IF = 0

    def main() -> None:
        OpenTimer1(TIMER1_ON)
        SFR.INTCON = 0xC0                       # GIE | PEIE
        Delay10KTCYx(60)
        seen["after RETFIE"] = SFR.INTCON
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high})
    world.run(0.1)
    assert seen == {"in the routine": 0x40, "after RETFIE": 0xC0}


def test_with_ipen_1_a_high_priority_source_vectors_to_0x08_and_a_low_priority_one_to_0x18(world, board):
    """IPR1.TMR1IP = 0 sends Timer1 to 0x18 (with GIEH and GIEL set); IPR3.RXB0IP = 1 sends RXB0 to 0x08."""
    taken: list[str] = []

    def high() -> None:
        taken.append("RXB0 at 0x08" if PIR3bits.RXB0IF else "? at 0x08")
        CANReceiveMessage()                     # clears RXB0IF

    def low() -> None:
        taken.append("TMR1 at 0x18" if PIR1bits.TMR1IF else "? at 0x18")
        PIR1bits.TMR1IF = 0
        CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)

    def main() -> None:
        CANInitialize(*CLASSROOM_CAN, CAN_CONFIG_ALL_MSG)
        CANSetOperationMode(CAN_OP_MODE_LOOP)   # it receives its own frame
        OpenTimer1(TIMER1_ON)
        IPR1bits.TMR1IP = 0
        PIE3bits.RXB0IE = 1                     # IPR3 resets to 0xFF: high priority
        RCONbits.IPEN = 1
        INTCONbits.GIEL = 1
        INTCONbits.GIEH = 1
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high, LOW_VECTOR: low})
    world.run(0.12)
    assert taken == ["TMR1 at 0x18", "RXB0 at 0x08", "TMR1 at 0x18", "RXB0 at 0x08"], taken


def test_a_high_priority_interrupt_pre_empts_a_low_priority_routine_which_then_goes_on(world, board):
    order: list[str] = []

    def high() -> None:
        order.append("high")
        CANReceiveMessage()

    def low() -> None:
        order.append("low starts")
        PIR1bits.TMR1IF = 0
        CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)
        Delay1KTCYx(20)                         # 2 ms: the frame comes back in loopback meanwhile
        order.append("low ends")

    def main() -> None:
        CANInitialize(*CLASSROOM_CAN, CAN_CONFIG_ALL_MSG)
        CANSetOperationMode(CAN_OP_MODE_LOOP)
        OpenTimer1(TIMER1_ON)
        IPR1bits.TMR1IP = 0
        PIE3bits.RXB0IE = 1
        RCONbits.IPEN = 1
        SFR.INTCON = 0xC0                       # GIEH | GIEL
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high, LOW_VECTOR: low})
    world.run(0.06)
    assert order == ["low starts", "high", "low ends"]


def test_a_low_priority_interrupt_waits_until_the_high_priority_routine_returns(world, board):
    """GIEH is cleared while the high-priority routine runs, and that disables every interrupt."""
    order: list[str] = []

    def high() -> None:
        order.append("high starts")
        CANReceiveMessage()
        OpenTimer1(TIMER1_ON)                   # clears TMR1IF ...
        PIR1bits.TMR1IF = 1                     # ... and a low-priority flag is set by hand
        Delay1KTCYx(10)
        order.append("high ends")

    def low() -> None:
        order.append("low")
        PIR1bits.TMR1IF = 0
        PIE1bits.TMR1IE = 0

    def main() -> None:
        CANInitialize(*CLASSROOM_CAN, CAN_CONFIG_ALL_MSG)
        CANSetOperationMode(CAN_OP_MODE_LOOP)
        PIE3bits.RXB0IE = 1
        PIE1bits.TMR1IE = 1
        IPR1bits.TMR1IP = 0
        RCONbits.IPEN = 1
        SFR.INTCON = 0xC0
        CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high, LOW_VECTOR: low})
    world.run(0.02)
    assert order == ["high starts", "high ends", "low"]


def test_a_routine_is_not_entered_again_while_it_runs_but_at_once_after_its_retfie(world, board):
    """Its own flag set again while it runs waits for RETFIE; the next entry follows it at once."""
    entries: list[int] = []

    def high() -> None:
        entries.append(world.sim.time())
        PIR1bits.TMR1IF = 0
        if len(entries) == 1:
            PIR1bits.TMR1IF = 1                 # set again, while GIE is 0
            Delay1KTCYx(1)

    def main() -> None:
        OpenTimer1(TIMER1_ON)
        SFR.INTCON = 0xC0
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high})
    world.run(0.06)
    assert len(entries) == 2
    assert 1_000 * TCY_PS < entries[1] - entries[0] < 1_030 * TCY_PS, "after the first returned, not inside it"


def test_interrupt_latency_is_three_instruction_cycles_from_the_flag_to_the_vector(world, board):
    """The core takes the interrupt 3 Tcy after the event that set the flag (an internal source) while main waits:
    the routine starts 3 cycles after Timer1 rolls over (C18's own entry code comes on top of that for a routine
    marked @interrupt: see the next test)."""
    seen: list[int] = []

    def high() -> None:
        seen.append(world.sim.time())
        PIR1bits.TMR1IF = 0
        seen.append(world.sim.time())

    def main() -> None:
        OpenTimer1(TIMER1_ON)
        SFR.INTCON = 0xC0
        while True:
            board.mcu.wait_for_interrupt("the test's loop")

    board.run(main, {HIGH_VECTOR: high})
    world.run(0.06)
    overflow = board.timer1._since            # when it last rolled over
    assert seen == [overflow + 3 * TCY_PS, overflow + 3 * TCY_PS + 2 * ACCESS_PS], "then a read and a write of PIR1"


def test_a_routine_marked_interrupt_costs_c18s_entry_and_exit_code_on_top(world, board, tmp_path):
    module = firmware(tmp_path, """
        seen = []

        @interrupt
        def high_isr():
            PIR1bits.TMR1IF = 0
            seen.append(1)

        def main():
            OpenTimer1(TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while True:
                pass
        """)
    times: list[int] = []
    real_write = board.mcu.write

    def write(address: int, value: int) -> None:
        real_write(address, value)
        if address == 0xF9E:                    # PIR1: the routine's clear of TMR1IF
            times.append(world.sim.time())

    board.mcu.write = write                     # type: ignore[method-assign]
    board.run(module)
    world.run(0.06)
    overflow = board.timer1._since
    # latency 3, C18's GOTO and context save 10, then PIR1bits.TMR1IF = 0: a read and a write (2 + 2)
    assert times[-1] == overflow + (3 + 10 + 2 + 2) * TCY_PS
    assert module.seen == [1]


# ====================================================================== the ECAN's sources: ICODE and WIN

def test_icode_shows_the_highest_priority_pending_source_and_win_maps_its_buffer_into_the_rxb0_window(world, board):
    """The ISR of DS39500's recipe: copy CANSTAT.ICODE into CANCON.WIN, read the buffer at RXB0's addresses, clear the
    flag, until ICODE = 000. RXB1's frame (ICODE 101) and TXB0's end of transmission (ICODE 100, above RXB1)."""
    served: list[tuple[int, int]] = []

    def high() -> None:
        while CANSTATbits.ICODE:
            code = CANSTATbits.ICODE
            CANCONbits.WIN = code
            served.append((code, SFR.RXB0SIDH))         # the windowed buffer's SIDH
            if code == 0b101:                           # RXB1
                SFR.RXB0CON = SFR.RXB0CON & 0x7F        # RXFUL of the buffer in the window: RXB1's
                PIR3bits.RXB1IF = 0
            elif code == 0b100:                         # TXB0
                PIR3bits.TXB0IF = 0
            CANCONbits.WIN = 0

    def main() -> None:
        CANInitialize(*CLASSROOM_CAN, CAN_CONFIG_VALID_STD_MSG)       # masks 0: RXB1 takes every standard frame
        CANSetOperationMode(CAN_OP_MODE_CONFIG)
        CANSetFilter(CAN_FILTER_B1_F1, 0x7FF, CAN_CONFIG_STD_MSG)   # RXB0 takes only 0x7FF
        CANSetFilter(CAN_FILTER_B1_F2, 0x7FF, CAN_CONFIG_STD_MSG)
        CANSetMask(CAN_MASK_B1, 0x7FF, CAN_CONFIG_STD_MSG)
        CANSetOperationMode(CAN_OP_MODE_LOOP)
        SFR.PIE3 = 0x06                                 # TXB0IE | RXB1IE
        SFR.INTCON = 0xC0
        SFR.TXB0SIDH, SFR.TXB0SIDL, SFR.TXB0DLC = 0x20, 0x00, 0     # ID 0x100, sent from TXB0
        TXB0CONbits.TXREQ = 1
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high})
    world.run(0.01)
    assert served == [(0b100, 0x20), (0b101, 0x20)], "TXB0 (100) first, then RXB1 (101) through the window"
    assert not board.ecan.get("RXB1CON") & 0x80, "RXB1's RXFUL cleared through the window"


# ====================================================================== waiting: polls and empty loops

def test_a_polling_loop_parked_on_its_registers_wakes_to_take_an_interrupt(world, board):
    times: dict[str, int] = {}
    flag = []

    def high() -> None:
        PIR1bits.TMR1IF = 0
        flag.append(1)

    def main() -> None:
        CANInitialize(*CLASSROOM_CAN, CAN_CONFIG_ALL_MSG)
        OpenTimer1(TIMER1_ON)
        SFR.INTCON = 0xC0
        while not flag and not CANIsRxReady():      # parked on RXB0CON, which nothing changes
            pass
        times["left the loop"] = world.sim.time()
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high})
    world.run(0.06)
    assert 0 < times["left the loop"] - board.timer1._since < 100 * TCY_PS, "at Timer1's roll-over"


def test_a_delay_is_interrupted_where_the_interrupt_comes_and_lasts_its_own_time_besides(world, board):
    times: dict[str, int] = {}

    def high() -> None:
        times.setdefault("routine", world.sim.time())
        PIR1bits.TMR1IF = 0
        Delay1KTCYx(10)                             # 1 ms in the routine

    def main() -> None:
        OpenTimer1(TIMER1_ON)
        SFR.INTCON = 0xC0
        start = world.sim.time()
        Delay10KTCYx(100)                           # 100 ms, Timer1 overflows at 52.4 ms
        times["delay"] = world.sim.time() - start
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high})
    world.run(0.11)
    rolled_over = board.timer1._since - TIMER1_PERIOD_PS     # the first of two roll-overs
    assert times["routine"] - rolled_over == 3 * TCY_PS, "taken when Timer1 rolls over, not after the delay"
    routine_ps = (3 + 2 + 2 + 10 + 1_000 * 10 + 2) * TCY_PS     # latency, TMR1IF = 0, Delay1KTCYx(10), RETFIE
    assert abs(times["delay"] - (100 * MS + routine_ps)) < 50 * TCY_PS


def test_while_not_flag_pass_waits_for_the_next_interrupt_and_ends_when_the_routine_sets_the_flag(world, board,
                                                                                                   tmp_path):
    module = firmware(tmp_path, """
        done = False
        ends = []

        @interrupt
        def high_isr():
            global done
            PIR1bits.TMR1IF = 0
            done = True

        def main():
            OpenTimer1(TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while not done:
                pass
            ends.append(ReadTimer1())
            while True:
                Nop()
        """)
    board.run(module)
    world.run(0.2)
    assert board.mcu.process.failure is None
    assert len(module.ends) == 1 and module.ends[0] < 100, "right after the first overflow"


def test_an_empty_loop_that_only_an_interrupt_could_end_stops_at_once_saying_which_enables_are_off(board, world,
                                                                                                   tmp_path):
    cases = {
        "INTCONbits.GIE is 0": "",
        "no interrupt source is enabled": "INTCONbits.GIE = 1",
        "PIE1bits.TMR1IE is set, but INTCONbits.PEIE is 0": "PIE1bits.TMR1IE = 1\n    INTCONbits.GIE = 1",
        "only low-priority sources are enabled (PIE1bits.TMR1IE": (
            "PIE1bits.TMR1IE = 1\n    IPR1bits.TMR1IP = 0\n    RCONbits.IPEN = 1\n    INTCONbits.GIEH = 1"),
    }
    for words, setup in cases.items():
        module = firmware(tmp_path, f"def main():\n    {setup or 'pass'}\n    while True:\n        pass\n")
        board.run(module)
        world.sim.run_for(0.01)
        message = stopped(board)
        line = (tmp_path / "isr.py").read_text().splitlines().index("    while True:") + 1
        assert message.startswith(f"main() waits in an empty loop at line {line} of isr.py (`while True:`), which "
                                  "only an interrupt routine can end, and no interrupt can come: "), message
        assert words in message


def test_an_empty_loop_inside_a_routine_stops_saying_that_gie_is_cleared_while_it_runs(board, world, tmp_path):
    module = firmware(tmp_path, """
        @interrupt
        def high_isr():
            while True:
                pass

        def main():
            PIE1bits.TMR1IE = 1
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            PIR1bits.TMR1IF = 1
            while True:
                Delay10KTCYx(10)
        """)
    board.run(module)
    world.sim.run_for(0.01)
    message = stopped(board)
    assert message.startswith("the high-priority interrupt routine (@interrupt, vector 0x08) waits in an empty loop "
                              "at line 6 of isr.py"), message
    assert "INTCONbits.GIE is cleared while an interrupt routine runs" in message


def test_only_provably_empty_loops_wait_a_loop_that_reads_a_register_still_polls(board, world, tmp_path):
    module = firmware(tmp_path, """
        seen = []

        class Ready:
            def __bool__(self):
                return bool(PIR1bits.TMR1IF)       # a register read hidden in a value: spins as written

        ready = Ready()

        def main():
            OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
            while not PIR1bits.TMR1IF:
                pass
            seen.append(ReadTimer1())
            PIR1bits.TMR1IF = 0
            while not ready:
                pass
            seen.append(ReadTimer1())
            while True:
                Delay10KTCYx(10)
        """)
    board.run(module)
    world.run(0.12)
    assert board.mcu.process.failure is None, board.mcu.process.failure_text
    assert len(module.seen) == 2 and all(count < 100 for count in module.seen), "each left its loop at an overflow"


def test_a_routine_that_leaves_its_flag_set_is_entered_again_at_once_until_the_watchdog_says_why(board, world,
                                                                                              tmp_path):
    module = firmware(tmp_path, """
        entries = 0

        @interrupt
        def high_isr():
            global entries
            entries += 1

        def main():
            OpenTimer1(TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while True:
                pass
        """)
    board.run(module)
    world.sim.run_for(1.0)
    message = stopped(board)
    assert module.entries == 10_000
    assert message == ("the high-priority interrupt routine (@interrupt, vector 0x08) was entered 10,000 times in a "
                       "row: each time it returned (RETFIE), PIR1bits.TMR1IF was still pending, and the core takes a "
                       "pending interrupt again right after RETFIE, so main() has not run one instruction since the "
                       "first. Clear the source's flag in the routine (`PIR1bits.TMR1IF = 0` for Timer1's), or "
                       "disable the source (its enable bit: PIE1bits.TXIE for a transmit routine with nothing left "
                       "to send)")


def test_a_routine_that_never_returns_keeps_main_from_running_and_the_watchdog_says_so(board, world, tmp_path):
    module = firmware(tmp_path, """
        @interrupt
        def high_isr():
            spins = 0
            while True:
                spins += 1

        def main():
            PIE1bits.TMR1IE = 1
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            PIR1bits.TMR1IF = 1
            while True:
                Delay10KTCYx(10)
        """)
    board.run(module)
    world.sim.run_for(0.01)
    message = stopped(board)
    assert message.startswith("the high-priority interrupt routine (@interrupt, vector 0x08) ran 2 s"), message
    assert ("at line 7 of isr.py (`while True:`)" in message or "at line 8 of isr.py (`spins += 1`)" in message)
    assert "without touching any register: it never returns, so main() never runs again" in message


# ====================================================================== the routines, as a firmware file marks them

def test_an_interrupt_at_a_vector_with_no_routine_crashes_the_firmware_in_the_workshops_words(board, world):
    def main() -> None:
        PIE1bits.TMR1IE = 1
        PIR1bits.TMR1IF = 1
        SFR.INTCON = 0xC0

    board.run(main)
    world.sim.run_for(0.01)
    failure = board.mcu.process.failure
    assert isinstance(failure, NoInterruptRoutine)
    assert str(failure).startswith("an interrupt was taken at vector 0x08, but the firmware has no @interrupt "
                                   "routine: with INTCONbits.GIE set, every enabled source")
    assert "(as `#pragma interrupt NAME` does in C18)" in str(failure)


@pytest.mark.parametrize("source, words", [
    ("@interrupt\ndef a():\n    pass\n\n@interrupt\ndef b():\n    pass\n",
     "a() and b() are both marked @interrupt: the PIC18 has one routine at vector 0x08"),
    ("@interruptlow\ndef a(source):\n    pass\n",
     "a() is an interrupt routine, which the core calls with no arguments"),
    ("@interrupt\n@interruptlow\ndef a():\n    pass\n", "a() is marked both @interrupt and @interruptlow"),
])
def test_routines_that_c18_would_not_link_do_not_load(tmp_path, source, words):
    with pytest.raises(FirmwareError, match="isr.py") as error:
        firmware(tmp_path, source + "\ndef main():\n    pass\n")
    assert words in str(error.value)


def test_interrupt_marks_a_function_only_and_returns_it_unchanged():
    def high_isr() -> None:
        pass

    assert interrupt(high_isr) is high_isr and interruptlow.__name__ == "interruptlow"
    with pytest.raises(TypeError, match="marks a function defined with `def`"):
        interrupt(print)            # type: ignore[arg-type]


# ====================================================================== the USART's level-triggered flags

def test_txif_interrupts_while_txreg_is_empty_so_a_routine_feeds_a_string_byte_by_byte(world, board):
    sent: list[int] = []
    board.usb.listeners.append(lambda byte, time_ps: sent.append(byte))
    text = list(b"CAN 202")

    def high() -> None:
        if text:
            TXREG = text.pop(0)
            SFR.TXREG = TXREG
        else:
            PIE1bits.TXIE = 0                       # nothing more to send: TXIF stays 1, so disable it

    def main() -> None:
        OpenUSART(USART_TX_INT_ON & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT & USART_CONT_RX
                  & USART_BRGH_HIGH, 129)
        SFR.INTCON = 0xC0
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high})
    world.run(0.01)
    assert bytes(sent) == b"CAN 202"


def test_rcif_interrupts_when_a_byte_arrives_and_reading_rcreg_clears_it(world, board):
    received: list[int] = []

    def high() -> None:
        received.append(ReadUSART())

    def main() -> None:
        OpenUSART(USART_TX_INT_OFF & USART_RX_INT_ON & USART_ASYNCH_MODE & USART_EIGHT_BIT & USART_CONT_RX
                  & USART_BRGH_HIGH, 129)
        SFR.INTCON = 0xC0
        while True:
            Delay10KTCYx(10)

    board.run(main, {HIGH_VECTOR: high})
    world.sim.call_at(1 * MS, lambda: board.usb.write(b"hello"))
    world.run(0.01)
    assert bytes(received) == b"hello"
