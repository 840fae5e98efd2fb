"""Demo1 with the wrong SPBRG: its USART sends at another baud rate than the PIC18F2550 bridge reads (19200), so a
program on the USB-CDC port reads garbage, as with a real board, and the monitor's summary says why."""
from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

KIT = Path(__file__).resolve().parent.parent
RIGHT = "USART_BRGH_HIGH, 129)"


@pytest.mark.parametrize("spbrg, baud", [(64, "38,462"), (255, "9,766")])
def test_a_demo1_at_another_baud_rate_reaches_the_pc_as_garbage_and_the_summary_says_why(tmp_path, spbrg, baud):
    source = (KIT / "solutions" / "demo1_monitor.py").read_text()
    assert RIGHT in source
    firmware = tmp_path / "demo1_wrong_baud.py"
    firmware.write_text(source.replace(RIGHT, f"USART_BRGH_HIGH, {spbrg})"))
    monitor = subprocess.Popen([sys.executable, "-m", "appsim", "monitor", "--firmware", str(firmware), "--seconds",
                                "3", "--transport", "socket"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, cwd=KIT)
    try:
        assert monitor.stdout is not None
        url = re.search(r"socket://127\.0\.0\.1:\d+", monitor.stdout.readline())[0]
        got = bytearray()
        with serial.serial_for_url(url, timeout=0.1) as port:
            ends = time.monotonic() + 3.5
            while time.monotonic() < ends:
                got += port.read(4096)
        out, err = monitor.communicate(timeout=60)
    finally:
        monitor.kill()
    assert monitor.returncode == 0, err
    assert got and b"APP023 CAN monitor" not in got and b"0x088" not in got, bytes(got[:200])
    assert (f"Demo1's firmware set its USART to {baud} baud, but the port runs at 19,200 baud (the PIC18F2550 "
            "bridge's UART, 19200 8N1): what reached the PC is garbage. With BRGH = 1, baud = Fosc / "
            "(16 x (SPBRG + 1)), so SPBRG = 129 at 40 MHz") in out, out
    assert f"bytes from the board came at {baud} baud: the bridge's UART at 19,200 baud misread them" in out

