"""Test helpers for a real Linux vcan: is there one, run a command inside User-Mode Linux, candump and cansend.

Host tests boot UML with `run_in_uml`; the tests in tests/inside_uml use `Candump` and `cansend` on vcan0.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

KIT = Path(__file__).resolve().parent.parent
VCAN_UML = KIT / "tools" / "vcan-uml"
INSIDE_UML_ENV = "APPSIM_INSIDE_UML"
ARPHRD_CAN = 280


def has_vcan(channel: str = "vcan0") -> bool:
    """True if this kernel has a CAN interface of that name (vcan0 inside UML; none on a machine without CAN)."""
    try:
        return int(Path("/sys/class/net", channel, "type").read_text()) == ARPHRD_CAN
    except (OSError, ValueError):
        return False


def inside_uml() -> bool:
    """True when running under tools/vcan-uml."""
    return os.environ.get(INSIDE_UML_ENV) == "1"


def uml_missing() -> str | None:
    """Why tools/vcan-uml cannot run here, or None if it can."""
    if shutil.which("linux") is None:
        return "User-Mode Linux is not installed (apt-get install user-mode-linux kmod iproute2 can-utils)"
    return None


def run_in_uml(command: Sequence[str], *, timeout: float = 300.0, vcan: int = 1,
               options: Sequence[str] = ()) -> subprocess.CompletedProcess[str]:
    """Run COMMAND inside UML with vcan0..vcan{vcan-1} up, from the kit's directory; its output (stdout and
    stderr together, plus vcan-uml's own errors) and exit status come back in the result."""
    return subprocess.run(
        [sys.executable, str(VCAN_UML), "--timeout", str(timeout), "--vcan", str(vcan), *options, "--", *command],
        cwd=KIT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        timeout=timeout + 60, check=False,
    )


def _receivers(channel: str) -> int:
    """How many sockets receive every frame on that channel (candump or a python-can bus without filters)."""
    lines = Path("/proc/net/can/rcvlist_all").read_text().splitlines()
    return sum(1 for line in lines if line.split()[:1] == [channel])


class Candump:
    """`candump -L CHANNEL` in the background, its lines collected: `with Candump() as dump: ...; dump.wait_for(1)`.

    Starting returns only once candump's socket is bound, so no frame sent afterwards is missed.
    """

    def __init__(self, channel: str = "vcan0") -> None:
        self.channel = channel
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self._process: subprocess.Popen[str] | None = None
        self._reader: threading.Thread | None = None

    def start(self, timeout: float = 5.0) -> Candump:
        before = _receivers(self.channel)
        self._process = subprocess.Popen(
            ["candump", "-L", self.channel],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        deadline = time.monotonic() + timeout
        while _receivers(self.channel) <= before:
            if self._process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise AssertionError(f"candump -L {self.channel} did not start: {self._process.stderr.read()}")
            time.sleep(0.005)
        return self

    def _read(self) -> None:
        assert self._process is not None and self._process.stdout is not None
        for line in self._process.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()

    @property
    def frames(self) -> list[str]:
        """The frames seen, as cansend writes them (`123#DEADBEEF`): each line without timestamp and channel."""
        return [line.split()[-1] for line in self.lines]

    def wait_for(self, count: int, timeout: float = 5.0) -> list[str]:
        """The frames once at least `count` have been seen; fails saying what was seen if they do not come."""
        with self._changed:
            if not self._changed.wait_for(lambda: len(self.lines) >= count, timeout):
                raise AssertionError(f"candump saw {len(self.lines)} of {count} frames on {self.channel}: {self.lines}")
        return self.frames

    def stop(self) -> None:
        if self._process is not None and self._process.poll() is None:
            self._process.terminate()
            self._process.wait(timeout=5)
        if self._reader is not None:
            self._reader.join(timeout=5)

    def __enter__(self) -> Candump:
        return self.start() if self._process is None else self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def cansend(frame: str, channel: str = "vcan0") -> None:
    """`cansend CHANNEL FRAME`, e.g. cansend("123#DEADBEEF"); fails with cansend's own message if it refuses."""
    result = subprocess.run(["cansend", channel, frame], capture_output=True, text=True, timeout=10, check=False)
    if result.returncode != 0:
        raise AssertionError(f"cansend {channel} {frame} failed: {result.stderr.strip() or result.stdout.strip()}")
