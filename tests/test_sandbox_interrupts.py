"""Interrupts in the grader's sandbox: a firmware whose routines run in its own process, across the pipes, does on the
bus exactly what it does in process (the same trace, LCD and verdict, faults included), polling firmware talks as it
always did, and every new message is decoded strictly (a forged one is the student's doing, a wrong foretelling the
grader's)."""
from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from appsim.chip.mcu import PIC18F8680, ReadAhead
from appsim.workshop.checks import check, prepare
from appsim.workshop.checks import ex2 as ex2_check
from appsim.workshop.checks.trial import Fatal, Trial
from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS
from appsim.workshop.grading.worker import grade_exercise
from appsim.workshop.sandbox import host
from appsim.workshop.sandbox import protocol as wire
from appsim.workshop.sandbox.children import Limits, Sandbox
from appsim.workshop.sandbox.host import SandboxedFirmware
from appsim.workshop.sandbox.isolation import isolation

SEED = 202
INTERRUPT_SOLUTIONS = SOLUTIONS / "interrupts"
TIMER1_ON = "TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF"
HEAD = "from appsim.firmware import *\n\nMESSAGE_ID1 = 0x100\nTxData = [1, 2, 3, 0, 0]\n"


def ex2_firmware(source: str) -> str:
    """An Ex2-like firmware: the classroom's CAN setup in Normal mode, then `source`'s main() and routines."""
    return HEAD + textwrap.dedent(source).replace("@TIMER1_ON@", TIMER1_ON).replace(
        "@CAN@", "CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)")


# Firmware that takes every path of the interrupt model: each must do on the bus what it does in process.
TRICKY = {
    # Timer1 at low priority sends (and waits 2 ms in its routine); RXB0 at high priority pre-empts it
    "nested priorities": ex2_firmware("""
        seen = []

        @interrupt
        def high_isr():
            window = CANCONbits.WIN
            while CANIsRxReady():
                seen.append(CANReceiveMessage().id)
            CANCONbits.WIN = window

        @interruptlow
        def low_isr():
            PIR1bits.TMR1IF = 0
            TxData[3] = len(seen) & 0xFF
            CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_STD_FRAME)
            Delay1KTCYx(20)

        def main():
            @CAN@
            RCONbits.IPEN = 1
            PIE3bits.RXB0IE = 1
            PIE3bits.RXB1IE = 1
            IPR1bits.TMR1IP = 0
            OpenTimer1(@TIMER1_ON@)
            SFR.INTCON = 0xC0
            GLCD_Initial()
            while True:
                setcurGLCD(1, 1)
                putsGLCD("FRAMES %d" % len(seen))
                Delay10KTCYx(5)
        """),
    # main polls a register in a loop that only a routine's flag ends; the routine sends from inside a delay
    "poll woken and delay interrupted": ex2_firmware("""
        ticks = 0

        @interrupt
        def high_isr():
            global ticks
            PIR1bits.TMR1IF = 0
            ticks += 1
            TxData[4] = ticks
            CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_STD_FRAME)

        def main():
            @CAN@
            OpenTimer1(@TIMER1_ON@)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            seen = 0
            while True:
                while ticks == seen and not CANIsRxReady():
                    pass
                if CANIsRxReady():
                    CANReceiveMessage()
                seen = ticks
                Delay10KTCYx(30)
        """),
    # USART: TXIF is a level, the routine feeds bytes and turns TXIE off when it is done; main waits for a flag
    "level-triggered TXIF": ex2_firmware("""
        text = list(b"EX2 INT")
        done = False

        @interrupt
        def high_isr():
            global done
            if PIR1bits.TMR1IF:
                PIR1bits.TMR1IF = 0
                CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_STD_FRAME)
            if PIE1bits.TXIE and PIR1bits.TXIF:
                if text:
                    SFR.TXREG = text.pop(0)
                else:
                    PIE1bits.TXIE = 0
                    done = True

        def main():
            @CAN@
            OpenUSART(USART_TX_INT_ON & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT & USART_CONT_RX
                      & USART_BRGH_HIGH, 129)
            OpenTimer1(@TIMER1_ON@)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while not done:
                pass
            GLCD_Initial()
            putrsGLCD("SENT")
            while True:
                pass
        """),
    "a routine that leaves its flag set": ex2_firmware("""
        @interrupt
        def high_isr():
            CANIsRxReady()

        def main():
            @CAN@
            OpenTimer1(@TIMER1_ON@)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while True:
                pass
        """),
    "an empty loop no interrupt can end": ex2_firmware("""
        def main():
            @CAN@
            PIE1bits.TMR1IE = 1
            INTCONbits.GIE = 1
            while True:
                pass
        """),
    "an empty loop quoted with its tab and its comment": ex2_firmware("""
        def main():
            @CAN@
            while True:	# 等待中断 ... wait for an interrupt that never comes, quoted in the watchdog's words, cut short
                pass
        """),
    "no routine at the vector": ex2_firmware("""
        def main():
            @CAN@
            OpenTimer1(@TIMER1_ON@)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while True:
                Delay10KTCYx(10)
        """),
    "a routine that crashes": ex2_firmware("""
        @interrupt
        def high_isr():
            PIR1bits.TMR1IF = 0
            CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_STD_FRAME)
            TxData[7] = 1

        def main():
            @CAN@
            OpenTimer1(@TIMER1_ON@)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while True:
                Delay10KTCYx(10)
        """),
}


@pytest.fixture(scope="module")
def sandbox():
    with Sandbox(isolation(), Limits(time_s=30, stall_s=5)) as sandbox:
        yield sandbox


def outcome(trial_of, run) -> tuple[object, list[str], str]:
    """What a trial shows: its verdict's checks or the fault that stopped it, the bus trace, the LCD."""
    trial: Trial = trial_of()
    try:
        judged: object = [(c.name, c.passed, c.message) for c in run(trial)]
    except Fatal as fatal:
        judged = (fatal.fault.kind, fatal.fault.message)
    return judged, [repr(e) for e in (*trial.bus.trace, *trial.bus.loopback_trace)], trial.board.glcd.text()


def both_ways(sandbox: Sandbox, tmp_path: Path, monkeypatch, exercise: str, source: str, run):
    path = tmp_path / EXERCISE_FILES[exercise]
    path.write_text(source)
    monkeypatch.chdir(tmp_path)                     # the file by its own name, as the grader's child names it
    local = outcome(lambda: prepare(exercise, path.name, SEED), run)
    firmware = SandboxedFirmware(sandbox, path.name, source.encode(), sandbox.limits)
    try:
        remote = outcome(lambda: prepare(exercise, firmware, SEED), run)
    finally:
        firmware.close()
    return local, remote


@pytest.mark.parametrize("name", sorted(TRICKY))
def test_a_firmware_with_interrupts_does_the_same_on_the_bus_sandboxed_as_in_process(sandbox, tmp_path, monkeypatch,
                                                                                     name):
    local, remote = both_ways(sandbox, tmp_path, monkeypatch, "ex2", TRICKY[name], ex2_check.run)
    assert remote == local
    assert local[1], "it did something on the bus"


@pytest.mark.parametrize("name, words", [
    ("a routine that leaves its flag set", "was entered 10,000 times in a row"),
    ("an empty loop no interrupt can end", "but INTCONbits.PEIE is 0"),
    ("an empty loop quoted with its tab and its comment",
     "waits in an empty loop at line 8 of ex2.py (`while True: # 等待中断 ... wait for an interrupt that never comes, "
     "quoted in the ...`), which only"),
    ("no routine at the vector", "the firmware has no @interrupt routine"),
    ("a routine that crashes", "high_isr(), the high-priority interrupt routine (@interrupt, vector 0x08), crashed "
                               "at line 10 of ex2.py (`TxData[7] = 1`): IndexError"),
])
def test_the_tricky_firmwares_end_as_they_should(sandbox, tmp_path, monkeypatch, name, words):
    local, _ = both_ways(sandbox, tmp_path, monkeypatch, "ex2", TRICKY[name], ex2_check.run)
    kind, message = local[0]
    assert kind in ("stalled", "exception") and words in message, local[0]


@pytest.mark.parametrize("exercise", ["ex1", "ex3", "ex6"])
def test_the_interrupt_driven_solutions_get_full_marks_and_the_same_trace_sandboxed(sandbox, tmp_path, monkeypatch,
                                                                                    exercise):
    from appsim.workshop.checks import _MODULES

    source = (INTERRUPT_SOLUTIONS / EXERCISE_FILES[exercise]).read_text()
    local, remote = both_ways(sandbox, tmp_path, monkeypatch, exercise, source, _MODULES[exercise].run)
    assert remote == local
    assert all(passed for _, passed, _ in local[0]), local[0]
    record = grade_exercise(sandbox, exercise, EXERCISE_FILES[exercise], source.encode(), SEED, None)
    assert record["score"] == record["max_score"] and record["fault"] is None, record


def test_polling_firmware_talks_to_the_grader_as_it_did_before_interrupts(sandbox, monkeypatch):
    """With INTCON.GIE = 0 no access waits that did not wait before: no WRITE_WAIT, SPEND_WAIT, IDLE or VECTOR; the
    solutions make no more round trips than the kit did before interrupts (counted then, seed 202: 42, 78, 156, 158,
    191, 119), but for one each time a parked loop is looked at to see whether it counts (appsim.chip.polling: 4 to 16
    of them an exercise)."""
    seen: set[bytes] = set()
    real = wire.decode_batch

    def decode(message: bytes):
        accesses, codes = real(message)
        seen.update(op for op, *_ in accesses)
        return accesses, codes

    monkeypatch.setattr(host.wire, "decode_batch", decode)
    trips = {}
    for exercise in ("ex1", "ex2", "ex3", "ex4", "ex5", "ex6"):
        firmware = SandboxedFirmware(sandbox, EXERCISE_FILES[exercise],
                                     (SOLUTIONS / EXERCISE_FILES[exercise]).read_bytes(), sandbox.limits)
        try:
            assert check(exercise, firmware, seed=SEED).passed
        finally:
            firmware.close()
        trips[exercise] = firmware.round_trips
    assert not seen & {wire.WRITE_WAIT, wire.SPEND_WAIT, wire.IDLE, wire.RETFIE}, seen
    before = {"ex1": 46, "ex2": 88, "ex3": 167, "ex4": 174, "ex5": 203, "ex6": 129}
    assert all(trips[exercise] <= before[exercise] for exercise in before), trips


# ====================================================================== a loop that waits between its reads

WAITS = {
    "delay": """
            count = 0
            while not CANIsRxReady() and count < @TRIES@:
                Delay10KTCYx(1)
                count += 1""",
    "timer1": """
            OpenTimer1(@TIMER1_OFF@)
            WriteTimer1(0)
            while not CANIsRxReady() and ReadTimer1() < @TRIES@ * 1250:
                pass
            count = ReadTimer1() // 1250                # Timer1 at 1:8 counts 1,250 a millisecond""",
}


def timeout_loop(filter_id: int, tries: int, wait: str = "delay") -> str:
    """Ex2-like firmware whose filters take only `filter_id`: it waits for such a frame with a timeout of `tries` ms,
    by `WAITS[wait]` (1 ms, Delay10KTCYx(1), between two looks; or reading Timer1 until it says so), then sends its
    frame with the milliseconds it waited in data byte 3 and says on the LCD which came first."""
    waiting = WAITS[wait].replace("@TRIES@", str(tries)).replace("@TIMER1_OFF@", TIMER1_ON.replace("TIMER_INT_ON",
                                                                                                    "TIMER_INT_OFF"))
    return ex2_firmware(f"""
        def main():
            GLCD_Initial()
            @CAN@
            CANSetOperationMode(CAN_OP_MODE_CONFIG)
            for mask in (CAN_MASK_B1, CAN_MASK_B2):
                CANSetMask(mask, 0x7FF, CAN_CONFIG_STD_MSG)
            for each in (CAN_FILTER_B1_F1, CAN_FILTER_B1_F2, CAN_FILTER_B2_F1, CAN_FILTER_B2_F2, CAN_FILTER_B2_F3,
                         CAN_FILTER_B2_F4):
                CANSetFilter(each, {filter_id:#x}, CAN_CONFIG_STD_MSG)
            CANSetOperationMode(CAN_OP_MODE_NORMAL){waiting}
            TxData[3] = count
            CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_STD_FRAME)
            setcurGLCD(1, 1)
            putrsGLCD("RECEIVED" if CANIsRxReady() else "TIMED OUT")
            while True:
                Delay10KTCYx(100)
        """)


def sent_frames(trial_of) -> tuple[list, str]:
    """The good frames of a trial of Ex2's check, and its LCD."""
    trial: Trial = trial_of()
    try:
        ex2_check.run(trial)
    except Fatal:
        pass
    return [event for event in trial.bus.trace if not event.error], trial.board.glcd.text()


@pytest.mark.parametrize("wait", sorted(WAITS))
@pytest.mark.parametrize("filter_id, tries, lcd", [
    (0x7EF, 40, "TIMED OUT"),           # nobody sends 0x7EF: the timeout comes, 40 ms later
    (0x088, 250, "RECEIVED"),           # the master's broadcast comes first, seen at the loop's next look
])
def test_a_loop_that_waits_between_its_reads_times_out_the_same_sandboxed_as_in_process(sandbox, tmp_path,
                                                                                        monkeypatch, filter_id, tries,
                                                                                        lcd, wait):
    """A delay between two reads, or a read of Timer1, is time the loop sees pass, in the grader's sandbox as on the
    board: the child does not ask for a read that would park, the board does not park it, and the loop ends as on the
    chip, by its timeout or at its first look after the frame came, with the milliseconds it counted."""
    source = timeout_loop(filter_id, tries, wait)
    local, remote = both_ways(sandbox, tmp_path, monkeypatch, "ex2", source, ex2_check.run)
    assert remote == local
    frames, shown = sent_frames(lambda: prepare("ex2", EXERCISE_FILES["ex2"], SEED))
    assert shown.splitlines()[0].strip() == lcd, shown
    (own,) = [event for event in frames if event.frame.can_id == 0x100 and not event.frame.remote]
    count = own.frame.data[3]
    if lcd == "TIMED OUT":
        assert count == tries
        return
    first = next(event for event in frames if event.frame.can_id == 0x088)
    assert 2 < count < tries, f"it waited {count} ms: parked, it would have counted 2 waits"
    assert 0 < own.start_ps - first.end_ps <= 1_100_000_000, "it sends at its first look after the frame, <= 1 ms"


# ====================================================================== strict decoding

def forged(message: str) -> str:
    """Ex2-like firmware that enables Timer1's interrupt honestly, then sends `message` (a Python bytes expression)
    down its own pipe as the kit's library would, and waits to be judged."""
    return ex2_firmware(f"""
        import struct
        from appsim.chip.sfr import current_mcu

        @interrupt
        def high_isr():
            PIR1bits.TMR1IF = 0

        def main():
            @CAN@
            OpenTimer1(@TIMER1_ON@)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            channel = current_mcu()._channel
            channel.send({message})
            channel.receive()
            while True:
                pass
        """)


@pytest.mark.parametrize("message, words", [
    ('b"B" + struct.pack("<cB", b"T", 0x08)', "a RETFIE where no interrupt routine runs"),
    ('b"B" + struct.pack("<cB", b"T", 0x10)', "a RETFIE from vector 0x10, where the PIC18 has no routine"),
    ('b"B" + struct.pack("<cB", b"T", 0x08) + struct.pack("<cHB", b"W", 0xF00, 1)',
     "an access after one that waits for its answer"),
    ('b"B" + struct.pack("<cHB", b"W", 0xFF2, 0)', "a write of INTCON that did not wait for its answer"),
    ('b"B" + struct.pack("<cH", b"I", 2) + b"\\xff\\xfe"', "whose loop is not text"),
    ('b"B" + struct.pack("<cH", b"I", 9) + b"line 1"', "whose loop is not the length it says"),
    ('b"B" + struct.pack("<cH", b"I", 4) + b"a\\x1bb\\x00"', "whose loop is not printable"),
    ('b"B" + struct.pack("<cH", b"I", 0)', "or too long to be one"),
    ('b"B" + struct.pack("<cQ", b"S", 2_000_000)', "an access where the board may take an interrupt did not wait"),
    ('b"B" + struct.pack("<cHB", b"W", 0xF30, 0) + struct.pack("<cQ", b"S", 2_000_000)',
     "an access where the board may take an interrupt did not wait"),
])
def test_a_forged_interrupt_message_is_the_students_doing(sandbox, message, words):
    record = grade_exercise(sandbox, "ex2", "ex2.py", forged(message).encode(), SEED, None)
    assert record["fault"] == "protocol", record
    assert words in record["checks"][0]["message"], record["checks"][0]["message"]


def test_a_budget_the_grader_got_wrong_is_the_graders_fault_never_the_students(sandbox, monkeypatch):
    """Were the board to offer more time than there is to its next event, an honest firmware would spend it without a
    word and the board would take an interrupt inside that spend: the exercise is not judged (`grader`), the student is
    not blamed."""
    real = PIC18F8680.read_ahead

    def generous(mcu: PIC18F8680, addresses, written=()) -> ReadAhead:
        return real(mcu, addresses, written)._replace(budget_ps=10**12)      # a whole second, whatever comes

    monkeypatch.setattr(PIC18F8680, "read_ahead", generous)
    source = ex2_firmware("""
        @interrupt
        def high_isr():
            PIR1bits.TMR1IF = 0

        def main():
            @CAN@
            OpenTimer1(@TIMER1_ON@)
            INTCONbits.PEIE = 1
            INTCONbits.GIE = 1
            while True:
                SFR.TMR1L
                Delay10KTCYx(100)
        """)
    record = grade_exercise(sandbox, "ex2", "ex2.py", source.encode(), SEED, None)
    assert record["fault"] == "grader", record
    assert "a mistake of the simulator's, not the firmware's" in record["checks"][0]["message"]
