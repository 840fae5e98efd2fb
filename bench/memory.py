"""What a grading worker holds while it grades one exercise (its peak resident set, VmHWM): for the solutions, and for
firmware written to make the board and the trace keep as much as they can. `python -m bench.memory` prints it as JSON.

Each firmware is graded in a run of its own, so that nothing a previous exercise left in the worker counts for it.
"""
from __future__ import annotations

import io
import json
import shutil
import sys
import tempfile
from pathlib import Path

from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS

LIMITS = {"time_s": 12.0, "stall_s": 5.0}


def _firmware(body: str, *, top: str = "") -> str:
    return ("from appsim.firmware import *\n" + top + "\nMESSAGE_ID1 = 0x100\n\n\ndef main():\n"
            "    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)\n"
            + "".join(f"    {line}\n" for line in body.strip("\n").splitlines()))


_ECAN = ("ECAN = range(0xF00, 0xF78)\n"
         "MODES = (0x80, 0x00, 0x40, 0x60, 0x20)    # Configuration, Normal, Loopback, Listen-only, Disable")
_FAST_LOOPBACK = "CANSetOperationMode(CAN_OP_MODE_CONFIG)\nSFR.BRGCON1 = 0\nSFR.BRGCON2 = 0x80\nSFR.BRGCON3 = 0\n"
# Firmware that makes the grader keep as much as it can, each graded as one exercise (the longest, Demo1: 1 s).
HOGS: dict[str, tuple[str, str]] = {
    # a filter written in Normal mode: the silicon ignores it, and the ECAN used to keep every one (+346 MB)
    "ignored writes": ("demo1", _firmware("while True:\n    SFR.RXF0SIDH = 0x55")),
    # every ECAN register, in every mode, with ever other values
    "every register, every mode": ("demo1", _firmware(
        "from appsim.chip.sfr import current_mcu\nmcu = current_mcu()\nn = 0\nwhile True:\n"
        "    for mode in MODES:\n        mcu.write(0xF6F, mode)\n        for address in ECAN:\n"
        "            n += 1\n            mcu.write(address, n & 0xFF)", top=_ECAN)),
    # Loopback at the fastest bit rate, a frame on every turn: more than the trace keeps (a memory fault)
    "loopback flood": ("demo1", _firmware(_FAST_LOOPBACK + "CANSetOperationMode(CAN_OP_MODE_LOOP)\nwhile True:\n"
                                          "    CANSendMessage(0x123, [1, 2, 3, 4, 5, 6, 7, 8], 8, "
                                          "CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME)")),
    # Normal mode at the wrong bit rate: every frame runs bit by bit, in error frames, each with its waveform
    "error frames": ("demo1", _firmware("CANSetOperationMode(CAN_OP_MODE_CONFIG)\nSFR.BRGCON1 = 0x03\n"
                                        "SFR.BRGCON2 = 0x9A\nSFR.BRGCON3 = 0x03\n"
                                        "CANSetOperationMode(CAN_OP_MODE_NORMAL)\nwhile True:\n"
                                        "    CANSendMessage(0x000, [0x55] * 8, 8, CAN_TX_PRIORITY_0 & "
                                        "CAN_TX_STD_FRAME)")),
    # Timer1 restarted forever: each write cancels its overflow (cancelled events used to pile up: +11.5 MB)
    "Timer1 restarted": ("demo1", _firmware("OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & "
                                            "T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)\nwhile True:\n    WriteTimer1(0)")),
    # the USART at its fastest, a byte on every turn
    "USART flood": ("demo1", _firmware("SFR.BAUDCON = 0x08\nSFR.SPBRGH = 0\nSFR.SPBRG = 0\nSFR.TXSTA = 0x24\n"
                                       "SFR.RCSTA = 0x90\nwhile True:\n    SFR.TXREG = 0x41")),
    # 100,000 characters for the LCD, over and over
    "LCD text": ("demo1", _firmware("GLCD_Initial()\nwhile True:\n    setcurGLCD(1, 1)\n    putsGLCD('x' * 100000)")),
    # reads from ever new call sites (a deep recursion), and from endless ones (its library patched)
    "call sites": ("demo1", _firmware("def deep(n):\n    SFR.RXB0CON\n    if n:\n        deep(n - 1)\n"
                                      "while True:\n    deep(900)")),
    "endless call sites": ("demo1", _firmware(
        "import itertools\nfrom appsim.workshop.sandbox import child\ncounter = itertools.count()\n"
        "child.firmware_site = lambda: next(counter)\nwhile True:\n    SFR.RXB0CON")),
}


def measure(firmwares: dict[str, tuple[str, str]]) -> dict[str, dict[str, object]]:
    """Each firmware (name -> (exercise, source)) graded in a run of its own: its worker's memory in kB when it took
    the exercise and at its peak, and the exercise's fault."""
    from appsim.workshop.grading.grade import run
    from appsim.workshop.sandbox.children import Limits

    found: dict[str, dict[str, object]] = {}
    with tempfile.TemporaryDirectory(prefix="appsim-bench-memory-") as scratch:
        for name, (exercise, source) in firmwares.items():
            room = Path(scratch) / "class"
            shutil.rmtree(room, ignore_errors=True)
            (room / "student").mkdir(parents=True)
            (room / "student" / EXERCISE_FILES[exercise]).write_text(source)
            memory: dict = {}
            [record] = run([room], results=Path(scratch) / f"{len(found)}.jsonl", jobs=1, seed=1,
                           limits=Limits(**LIMITS), out=io.StringIO(), memory=memory)
            held = memory["student", exercise]
            found[name] = {"exercise": exercise, "start_kb": held.start_kb, "peak_kb": held.peak_kb,
                           "fault": record["exercises"][exercise]["fault"]}
    return found


def solutions() -> dict[str, tuple[str, str]]:
    return {f"solution {exercise}": (exercise, (SOLUTIONS / file).read_text()) for exercise, file in
            EXERCISE_FILES.items()}


if __name__ == "__main__":
    chosen = sys.argv[1:]
    every = {**solutions(), **HOGS}
    print(json.dumps(measure({name: every[name] for name in chosen} if chosen else every)))
