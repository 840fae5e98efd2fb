"""Firmware that stops the clock (a loop touching no register, a sleep, a recursion) is stopped by the watchdog, with
what it saw and where; whatever a firmware raises or catches, it stops that board only; Ctrl-C stops the run."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from appsim.firmware import *
from appsim.sim import FROZEN
from appsim.watchdog import FirmwareHung


@pytest.fixture(autouse=True)
def quick_watchdog(monkeypatch):
    """The watchdog barks every 0.5 s here instead of every 2 s: the same behaviour, sooner."""
    monkeypatch.setattr("appsim.watchdog.WATCHDOG_SECONDS", 0.5)


def sender():
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
    Delay1KTCYx(10)                             # 1 ms
    CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)
    while True:
        CANIsRxReady()


def run_beside_a_sender(world, main, seconds: float = 0.01):
    """`main` on a board named "stuck" beside one that sends a frame at 1 ms; the sender's frame must go through."""
    stuck = world.node("stuck", main)
    world.node("sender", sender)
    world.sim.run(until=world.sim.now + round(seconds * 1e12))
    assert {str(e.frame) for e in world.bus.trace} == {"100 [1] 01"}, "the other board went on sending"
    return stuck.process


def test_an_endless_loop_without_register_access_is_stopped_and_the_others_go_on(world):
    def stuck():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        while True:
            pass

    process = run_beside_a_sender(world, stuck)
    assert isinstance(process.failure, FirmwareHung)
    message = str(process.failure)
    assert "an endless loop such as `while True: pass`" in message
    loop = stuck.__code__.co_firstlineno + 2
    assert (f"at line {loop} of test_watchdog.py (`while True:`)" in message
            or f"at line {loop + 1} of test_watchdog.py (`pass`)" in message), message


def test_except_exception_around_the_loop_does_not_catch_the_watchdog(world):
    def swallower():
        while True:
            try:
                while True:
                    pass
            except Exception:
                pass

    assert not issubclass(FirmwareHung, Exception)
    assert isinstance(run_beside_a_sender(world, swallower).failure, FirmwareHung)


def test_a_firmware_that_catches_everything_is_frozen_where_it_is(world):
    def catches_all():
        while True:
            try:
                while True:
                    pass
            except BaseException:
                pass

    process = run_beside_a_sender(world, catches_all)
    assert isinstance(process.failure, FirmwareHung) and process.finished and process in FROZEN


def test_a_firmware_that_catches_the_watchdog_and_goes_on_with_the_board_never_runs_again(world):
    def goes_on():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        try:
            while True:
                pass
        except BaseException:
            pass
        while True:
            CANSendMessage(0x200, [2], 1, CAN_TX_STD_FRAME)

    process = run_beside_a_sender(world, goes_on)
    assert isinstance(process.failure, FirmwareHung) and process in FROZEN


def test_a_sleep_is_reported_as_a_sleep(world):
    def sleeper():
        while True:
            time.sleep(60)

    message = str(run_beside_a_sender(world, sleeper).failure)
    assert "waiting: a sleep (time.sleep)" in message and "(`time.sleep(60)`)" in message
    assert "PIR1bits.TMR1IF" in message


def test_a_runaway_recursion_is_reported_as_one_and_its_report_stays_short(world):
    def dive(depth):
        sum(range(10_000))          # about 0.1 ms a call: 2 s of it is a few thousand calls deep
        return dive(depth + 1)

    def recursing():
        dive(0)

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(10**6)
    try:
        process = run_beside_a_sender(world, recursing)
    finally:
        sys.setrecursionlimit(limit)
    message = str(process.failure)
    assert "calls deep in dive(): a recursion that does not end" in message
    assert process.failure_text.count("\n  File ") <= 50


def test_a_recursion_error_a_hundred_thousand_calls_deep_stops_that_board_only(world):
    """With the limit raised, formatting the whole traceback took longer than the watchdog: it fired there."""
    def dive(depth):
        return dive(depth + 1)

    def recursing():
        sys.setrecursionlimit(100_000)
        dive(0)

    limit = sys.getrecursionlimit()
    try:
        process = run_beside_a_sender(world, recursing)
    finally:
        sys.setrecursionlimit(limit)
    assert isinstance(process.failure, RecursionError)


@pytest.mark.parametrize("stray", [KeyboardInterrupt, SystemExit, GeneratorExit])
def test_whatever_a_firmware_raises_stops_that_board_only(world, stray):
    def raiser():
        raise stray

    assert isinstance(run_beside_a_sender(world, raiser).failure, stray)


def test_sys_exit_in_firmware_stops_that_board_only(world):
    def quitter():
        sys.exit(0)

    assert isinstance(run_beside_a_sender(world, quitter).failure, SystemExit)


def test_ctrl_c_stops_the_run_wherever_it_lands_and_firmware_cannot_catch_it(world):
    def presses_ctrl_c():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        try:
            os.kill(os.getpid(), signal.SIGINT)
            while True:
                CANIsRxReady()
        except BaseException:
            while True:
                CANIsRxReady()

    board = world.node("stuck", presses_ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        world.sim.run(until=10**10)
    assert world.sim.now < 10**10 and isinstance(board.process.failure, KeyboardInterrupt)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_lone_firmware_writing_registers_forever_stops_where_the_run_ends():
    """It touches registers, so the watchdog does not bark; with no event on the bus it ran past the end for ever."""
    program = ("from appsim.bus.wire import Bus\nfrom appsim.chip.mcu import PIC18F8680\n"
               "from appsim.firmware import *\nfrom appsim.sim import Simulator\n"
               "def writer():\n    while True:\n        SFR.TXB0D0 = 1\n"
               "sim = Simulator()\nmcu = Bus(sim).attach(PIC18F8680(sim, 'alone'))\nmcu.run(writer)\n"
               "sim.run(until=10**9)\nprint(sim.now, mcu.process.local_time - sim.now < 10**6)\n")
    result = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=60)
    assert result.stdout.split() == ["1000000000", "True"], result.stderr
