"""Helpers for the python-can interface's tests: a simulated bus served in this process (in a thread of its own, on the
wall clock), python-can programs run in other processes, and a registry folder private to each test."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

KIT = Path(__file__).resolve().parent.parent


def private_runtime(tmp_path: Path) -> dict[str, str]:
    """An environment whose served classrooms are announced in a folder of this test's own (XDG_RUNTIME_DIR)."""
    runtime = tmp_path / "run"
    runtime.mkdir(mode=0o700, exist_ok=True)
    return {**os.environ, "XDG_RUNTIME_DIR": str(runtime), "PYTHONPATH": str(KIT)}


def program(source: str, env: dict[str, str], *, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """A python-can program in a process of its own; its exit status and what it printed."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(source)], env=env, capture_output=True, text=True,
                          timeout=timeout)


def start(source: str, env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(source)], env=env, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


class Served:
    """A bare simulated bus (and what `build(bus)` puts on it) served as `channel` in the background of this process
    (`appsim.bus.serve.ServedInBackground`), announced in the test's own runtime folder, until the `with` block ends;
    `server` is the ClassroomServer, `report` what it said at the end."""

    def __init__(self, env: dict[str, str], channel: str = "test", *, build: Any = None, **server: Any):
        self.env, self.channel, self.build, self.options = env, channel, build, server
        self.report = ""

    def _bus(self) -> Any:
        from appsim.bus.wire import Bus
        from appsim.sim import Simulator

        bus = Bus(Simulator(), 125_000)
        if self.build is not None:
            self.build(bus)
        return bus

    def __enter__(self) -> Served:
        from appsim.bus.serve import ServedInBackground

        saved = os.environ.get("XDG_RUNTIME_DIR")
        os.environ["XDG_RUNTIME_DIR"] = self.env["XDG_RUNTIME_DIR"]     # where the thread announces it
        try:
            self.served = ServedInBackground(self._bus, self.channel, **self.options)
        finally:
            if saved is None:
                os.environ.pop("XDG_RUNTIME_DIR", None)
            else:
                os.environ["XDG_RUNTIME_DIR"] = saved
        self.server, self.bus = self.served.server, self.served.bus
        return self

    def __exit__(self, *exc: object) -> None:
        self.report = self.served.stop().report

    def wait_for(self, condition: Any, timeout: float = 20) -> None:
        """Until `condition(server)` holds (the server is read between its polls; close enough for counts)."""
        deadline = time.monotonic() + timeout
        while not condition(self.server):
            assert time.monotonic() < deadline, "timed out waiting on the served bus"
            time.sleep(0.05)
