"""The simulated clock: busy-waiting is cheap, and a run gives the same trace however loaded the machine is."""
from __future__ import annotations

import hashlib
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import World

from appsim.board.app023 import APP023
from appsim.chip.mcu import PIC18F8680
from appsim.chip.polling import COUNTED_TURNS
from appsim.chip.sfr import current_mcu
from appsim.firmware import *
from appsim.sim import PS_PER_SECOND

SEVEN_NODES = """
import hashlib, sys
sys.path.insert(0, {tests!r})
from conftest import World
from test_bus_gotchas import normal_node
from appsim.firmware import CAN_TX_PRIORITY_0, CAN_TX_PRIORITY_1
w = World()
for k in range(7):
    w.node(f"n{{k}}", normal_node([(0x100 + 0x10 * k, CAN_TX_PRIORITY_0), (0x081 + k, CAN_TX_PRIORITY_1)],
                                  delay_ms=k * 0.37))
w.run(0.2)
print(len(w.bus.trace), hashlib.sha256(repr(w.bus.trace).encode()).hexdigest())
"""


def _counting_reads(mcu: PIC18F8680, register: str) -> list[int]:
    """A list whose one item counts the firmware's reads of `register` on `mcu` from now on."""
    count = [0]
    address = mcu.sfr_addresses[register]
    read = mcu._readers[address]

    def counted(at: int) -> int:
        count[0] += 1
        return read(at)

    mcu._readers[address] = counted
    return count


LOOKS_A_SECOND = 2 * 11     # a polling loop parked 1 s is looked at after 1, 2, 4 ... 512 ms (at most at each of its
                            # two reads), each look a turn or two, to see whether it counts after all


def test_a_firmware_busy_waiting_one_second_for_a_frame_runs_its_loop_a_handful_of_times(world):
    """The frame comes 1 s (simulated) later; the polling loop sees nothing new until then, so it parks."""
    received = []

    def waiter():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        while not CANIsRxReady():
            pass
        received.append(CANReceiveMessage())

    def late_sender():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        Delay10KTCYx(250)
        Delay10KTCYx(250)
        Delay10KTCYx(250)
        Delay10KTCYx(250)                           # 4 x 250 ms
        CANSendMessage(0x100, [1, 2, 3], 3, CAN_TX_STD_FRAME)

    reads = _counting_reads(world.node("waiter", waiter), "RXB0CON")
    world.node("sender", late_sender)
    started = time.perf_counter()
    world.run(1.1)
    wall = time.perf_counter() - started
    received_at = world.bus.frames()[0].end_ps / PS_PER_SECOND
    assert 1.0 < received_at < 1.001
    (message,) = received
    assert (message.id, bytes(message.data[:message.length])) == (0x100, b"\x01\x02\x03")
    assert reads[0] < 10 + 2 * LOOKS_A_SECOND, f"the polling loop ran {reads[0]} times: it should park until the frame"
    print(f"1.1 s simulated with a 1 s busy-wait: {wall * 1e3:.1f} ms wall, {reads[0]} loop turns")


def test_a_parked_loop_sleeps_through_changes_it_does_not_read(world):
    """Timer1 overflows 150 times a second and sets TMR1IF in PIR1; a loop polling only CANIsRxReady()
    reads RXB0CON and RXB1CON, which stay as they were, so it stays parked until the frame comes."""
    overflows = []

    def waiter():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_1 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
        while not CANIsRxReady():
            pass
        overflows.append(PIR1bits.TMR1IF)

    board = APP023(world.bus, "waiter")
    reads = _counting_reads(board.mcu, "RXB0CON")
    board.run(waiter)

    def sender():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        Delay10KTCYx(250)                           # 250 ms: about 38 Timer1 overflows at 1:1
        CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)

    APP023(world.bus, "sender").run(sender)
    world.run(0.3)
    assert overflows == [1], "Timer1 did overflow while the loop waited"
    assert reads[0] < 10 + 2 * LOOKS_A_SECOND, f"the loop turned {reads[0]} times: overflows it never reads woke it"


def timeout_loop(tries: int, seen: list[tuple[int, int]]):
    """Firmware: waits for a frame with a timeout, 1 ms (Delay10KTCYx(1)) between two looks, then says which came
    first: (tries waited, the identifier received or -1), and a frame 0x1F0 whose data is the tries waited."""
    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        count = 0
        while not CANIsRxReady() and count < tries:
            Delay10KTCYx(1)
            count += 1
        seen.append((count, CANReceiveMessage().id if CANIsRxReady() else -1))
        CANSendMessage(0x1F0, [count], 1, CAN_TX_STD_FRAME)
    return main


def test_a_loop_that_waits_between_its_reads_is_not_parked_its_timeout_comes(world):
    """Nothing comes: the loop looks 50 times, 1 ms apart, and gives up 50 ms later, as on the chip (a delay is time
    the loop sees pass, so it is no polling loop to park)."""
    seen: list[tuple[int, int]] = []
    world.node("waiter", timeout_loop(50, seen))
    world.node("listener", lambda: CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG))    # ACKs, sends nothing
    world.run(0.2)
    assert seen == [(50, -1)], "the timeout loop never timed out: it was parked as a polling loop"
    (sent,) = world.bus.frames()
    assert sent.frame.can_id == 0x1F0 and sent.frame.data == bytes([50])
    assert 0.050 < sent.start_ps / PS_PER_SECOND < 0.0505, "50 waits of 1 ms, then the frame"


def test_a_loop_that_waits_between_its_reads_sees_a_frame_at_its_next_look_not_sooner(world):
    """The frame ends at about 25 ms: the loop sees it at its next look, after the 1 ms wait it is in, and counts the
    waits it made; the frame it sends comes up to 1 ms after the one it waited for, not at once."""
    seen: list[tuple[int, int]] = []

    def sender():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        Delay10KTCYx(25)
        CANSendMessage(0x100, [1, 2, 3], 3, CAN_TX_STD_FRAME)

    world.node("waiter", timeout_loop(200, seen))
    world.node("sender", sender)
    world.run(0.2)
    first, answer = world.bus.frames()
    assert first.frame.can_id == 0x100 and answer.frame.can_id == 0x1F0
    (count, received), = seen
    assert received == 0x100 and answer.frame.data == bytes([count])
    waited_ms = first.end_ps * 1000 / PS_PER_SECOND
    assert count == math.ceil(waited_ms - 0.01), (count, waited_ms)      # the waits before it, each 1 ms (and a CALL)
    assert 0 < answer.start_ps - first.end_ps <= PS_PER_SECOND // 1000 + PS_PER_SECOND // 10_000


def test_a_loop_that_reads_timer1_for_its_timeout_is_not_parked_its_timeout_comes(world):
    """No delay, but Timer1 (1:8, 1,250 counts a millisecond) tells the loop when 40 ms are up: a register that time
    changes is time the loop sees pass, so it never parks, and it gives up 40 ms later."""
    seen = []

    def waiter():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
        WriteTimer1(0)
        while not CANIsRxReady() and ReadTimer1() < 40 * 1250:
            pass
        seen.append(ReadTimer1() // 1250)
        CANSendMessage(0x1F0, [1], 1, CAN_TX_STD_FRAME)

    world.node("waiter", waiter)
    world.node("listener", lambda: CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG))
    world.run(0.1)
    assert seen == [40], "the loop reading Timer1 never timed out: it was parked as a polling loop"
    (sent,) = world.bus.frames()
    assert 0.040 < sent.start_ps / PS_PER_SECOND < 0.0405


def test_a_spin_with_a_count_turns_as_a_counting_loop_then_parks_until_the_next_look(world):
    """No delay in the loop: it reads, counts and reads again. Nothing changed on the board, but its count did: it may
    be a timeout, so it is no polling loop to park for good. Found counting at the first look (after 1 ms), it turns
    COUNTED_TURNS reads at each look, the looks backing off (1, 2, 4 ... ms), and the frame at 25 ms ends it: a few
    thousand turns, not the 100,000 the chip would make."""
    turns = []

    def spinner():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        count = 0
        while not CANIsRxReady() and count < 10**9:
            count += 1
        turns.append(count)

    def sender():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        Delay10KTCYx(25)
        CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)

    board = world.node("spinner", spinner)
    world.node("sender", sender)
    world.run(0.1)
    (frame,) = world.bus.frames()
    (count,) = turns
    on_the_chip = frame.end_ps // (2 * board.access_ps)
    assert COUNTED_TURNS // 2 <= count <= LOOKS_A_SECOND * COUNTED_TURNS // 2 < on_the_chip, (count, on_the_chip)


def test_seven_node_trace_is_identical_in_separate_processes_even_under_load():
    script = SEVEN_NODES.format(tests=str(Path(__file__).parent))
    env = {**os.environ, "PYTHONHASHSEED": "random"}

    def run() -> str:
        return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                              env=env, timeout=120).stdout

    quiet = run()
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 2)]
    try:
        loaded = run()
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    frames, digest = quiet.split()
    assert int(frames) >= 14
    assert loaded == quiet, "the trace changed when the machine was busy: simulated time leaked wall time"
    assert hashlib.sha256(b"").hexdigest() != digest


TIMED_BLOCK = ("TMR1L", "RXB0CON", "COMSTAT", "RXB0CON", "RXB1CON", "PIR3")   # Timer1 first: never a polling loop
POLLED_BLOCK = ("COMSTAT", "RXB0CON", "RXB0CON", "RXB1CON")                   # parks on its second turn
LIT_BLOCK = ("LATJ", "COMSTAT", "PIR3", "RXB0CON", "RXB1CON", "TXB0CON", "RXB0CON", "RXB1CON")  # a LED lit each turn


def _second_rxb0con(names: tuple[str, ...]) -> int:
    return max(k for k, name in enumerate(names) if name == "RXB0CON")


def block_reader(block: bool, names: tuple[str, ...], record: list):
    """Firmware: a frame is coming; it reads a block of registers (RXB0CON twice) again and again, by `read_each` or
    one read at a time, and records what it read and when, until the frame is in."""
    def main():
        mcu = current_mcu()
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_1 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
        block_of = [mcu.address_of(name) for name in names]
        while len(record) < 10_000:
            if names == LIT_BLOCK:
                mcu.write(block_of[0], len(record) & 0xFF)     # a change: no read of the block is a read again
            values = mcu.read_each(block_of) if block else [mcu.read(address) for address in block_of]
            record.append((tuple(values), mcu.process.local_time))
            if values[_second_rxb0con(names)] & 0x80:      # RXFUL
                break
    return main


@pytest.mark.parametrize("names", [TIMED_BLOCK, POLLED_BLOCK, LIT_BLOCK])
def test_a_block_of_reads_reads_what_and_when_the_reads_one_by_one_do(names):
    """`read_each` is the libraries' shortcut for reads in a row: the same values at the same instants (a register read
    twice is a read again, Timer1 ticks between reads, a polling loop parks at the same read, a frame that comes in
    the middle of a block is seen by the reads after it), the same bus trace. The frame comes a cycle later each time,
    so it meets every read of the block."""
    mid_block = 0
    for delay_cycles in range(5_000, 5_000 + (18 if names == LIT_BLOCK else 1)):
        runs = {}
        for block in (False, True):
            record: list = []
            world = World()
            world.node("reader", block_reader(block, names, record))
            world.node("sender", sender_after(delay_cycles))
            world.run(0.01)
            runs[block] = (record, repr(world.bus.trace))
        (one_by_one, trace), (in_a_block, block_trace) = runs[False], runs[True]
        assert in_a_block == one_by_one and block_trace == trace
        assert in_a_block[-1][0][_second_rxb0con(names)] & 0x80, "the frame came in"
        if names == POLLED_BLOCK:
            assert len(in_a_block) == 2, "the loop parked on its second turn until the frame came"
        else:
            assert len(in_a_block) > 100, "the loop turned: Timer1's count or the LED kept it from parking"
        mid_block += not in_a_block[-1][0][names.index("RXB0CON")] & 0x80   # its first RXB0CON had not seen it
    if names == LIT_BLOCK:
        assert mid_block, "the frame came in the middle of a block at least once"


def sender_after(cycles: int):
    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        current_mcu().wait_cycles(cycles)
        CANSendMessage(0x100, [1, 2, 3], 3, CAN_TX_STD_FRAME)
    return main
