"""What the grader tells a sandboxed firmware ahead (PIC18F8680.read_ahead) is what the board then does: a write it
foretells leaves every register as foretold, and a foretelling that were wrong is the grader's fault, never the
student's."""
from __future__ import annotations

import pytest

from appsim.chip.mcu import PIC18F8680
from appsim.chip.usart import USART
from appsim.workshop.checks import check
from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS
from appsim.workshop.grading.worker import grade_exercise
from appsim.workshop.sandbox.children import Limits, Sandbox
from appsim.workshop.sandbox.isolation import isolation

SEED = 2024

# A firmware that writes TXREG in every state the USART can be in, each time after a read (so the sandbox may go on
# from a foretold write) and followed by one: transmitter off, shift register idle, busy with TXREG empty, busy with
# TXREG full (a byte overwritten), and switched off and on while a byte waits.
EVERY_STATE = """from appsim.firmware import *

MESSAGE_ID1 = 0x100


def main():
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)
    PIR1bits.TXIF
    WriteUSART(0x55)
    OpenUSART(USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT & USART_CONT_RX
              & USART_BRGH_HIGH, 129)
    while True:
        for byte in b"ab!":
            PIR1bits.TXIF
            WriteUSART(byte)
        while BusyUSART():
            pass
        TXSTAbits.TXEN = 0
        PIR1bits.TXIF
        WriteUSART(0x22)
        PIR1bits.TXIF
        TXSTAbits.TXEN = 1
        while not PIR1bits.TXIF:
            pass
"""


def foretold_writes(monkeypatch) -> dict[str, int]:
    """Make every write that a peripheral foretells (PIC18F8680.quiet_writes) check, on the board itself, that the
    read-ahead's values after it are what every register then reads, and that nothing else moved; how many did."""
    seen = {"foretold": 0, "not foretold": 0}
    real_write = PIC18F8680.write

    def write(mcu: PIC18F8680, address: int, value: int) -> None:
        if address not in mcu.quiet_writes or mcu.process is None:
            return real_write(mcu, address, value)
        process = mcu.process
        offer = tuple(sorted(set(mcu.sfr_addresses.values())))
        before = mcu.read_ahead(offer, [address])
        horizon, started = process.horizon, process.local_time
        real_write(mcu, address, value)
        if not before.after_writes:
            seen["not foretold"] += 1
            return None
        seen["foretold"] += 1
        [(written, values)] = before.after_writes
        after = mcu.read_ahead(offer)
        told = {a: v for a, v in zip(before.addresses, values, strict=True) if a != written}
        now = {a: v for a, v in zip(after.addresses, after.values, strict=True) if a != written}
        assert now == told, {hex(a): (told[a], now[a]) for a in told if told[a] != now[a]}
        assert (process.horizon, process.local_time) == (horizon, started + mcu.access_ps), "time moved otherwise"
        assert not any(after.seen), "after a write, no register reads as seen since the change"
        return None

    monkeypatch.setattr(PIC18F8680, "write", write)
    return seen


@pytest.mark.parametrize("exercise, source", [("demo1", None), ("ex1", EVERY_STATE)],
                         ids=["the monitor", "every state of the USART"])
def test_a_write_the_read_ahead_foretells_leaves_every_register_as_foretold(monkeypatch, tmp_path, exercise, source):
    seen = foretold_writes(monkeypatch)
    path = SOLUTIONS / EXERCISE_FILES[exercise]
    if source is not None:
        path = tmp_path / "every_state.py"
        path.write_text(source)
    check(exercise, path, seed=SEED)
    assert seen["foretold"] > 20 and seen["not foretold"] > 0, seen     # both kinds happened


def test_a_wrong_foretelling_is_the_graders_fault_never_the_students(monkeypatch):
    """Were the simulator to foretell a write wrongly, the firmware would go on with values the board never had: its
    exercise is not graded (a `grader` fault that says so), rather than blamed on a tampered library."""
    monkeypatch.setattr(USART, "_fills_txreg", lambda self: {0xF9E: 0xFF})      # PIR1: every flag set, TXIF too
    source = (SOLUTIONS / EXERCISE_FILES["demo1"]).read_bytes()
    with Sandbox(isolation(), Limits()) as sandbox:
        record = grade_exercise(sandbox, "demo1", "demo1_monitor.py", source, SEED, None, owner="quinn")
    assert record["fault"] == "grader", record
    assert "a mistake of the simulator's, not the firmware's" in record["checks"][0]["message"]


def test_a_sandboxed_firmware_gets_the_verdict_it_gets_in_process_with_foretold_writes(tmp_path, monkeypatch):
    """The same firmware and seed, judged in process and in the sandbox (where writes are foretold): one verdict."""
    path = tmp_path / "every_state.py"
    path.write_text(EVERY_STATE)
    with Sandbox(isolation(), Limits()) as sandbox:
        record = grade_exercise(sandbox, "ex1", path.name, path.read_bytes(), SEED, None, owner="rosa")
    monkeypatch.chdir(tmp_path)                     # `appsim check every_state.py`, as a student runs it
    verdict = check("ex1", path.name, seed=SEED).to_dict()
    assert (record["score"], record["fault"], record["checks"]) == (verdict["score"], verdict["fault"],
                                                                   verdict["checks"])
