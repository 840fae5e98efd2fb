"""Helpers for the python-can interface's tests: a simulated bus served in this process (in a thread of its own, on the
wall clock), python-can programs run in other processes, and a registry folder private to each test."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import threading
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
    """A simulated bus (and what `build(bus)` puts on it) served as `channel` in a thread of this process, in real
    time, until the `with` block ends; `server` is the ClassroomServer, `report` what it said at the end."""

    def __init__(self, env: dict[str, str], channel: str = "test", *, build: Any = None, **server: Any):
        self.env, self.channel, self.build, self.options = env, channel, build, server
        self.server: Any = None
        self.bus: Any = None
        self.report = ""
        self.failure: BaseException | None = None
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        from appsim.bus.realtime import WallClock
        from appsim.bus.serve import ClassroomServer
        from appsim.bus.wire import Bus
        from appsim.sim import Simulator

        saved = os.environ.get("XDG_RUNTIME_DIR")
        os.environ["XDG_RUNTIME_DIR"] = self.env["XDG_RUNTIME_DIR"]
        try:
            self.bus = Bus(Simulator(), 125_000)
            if self.build is not None:
                self.build(self.bus)
            self.server = ClassroomServer(self.bus, self.channel, **self.options)
            clock = WallClock(self.bus.sim)
            clock.add_poller(self.server.poll)
            self._ready.set()
            clock.run(None, stop=self._stop.is_set)
        except BaseException as error:      # the test says what went wrong
            self.failure = error
        finally:
            if saved is None:
                os.environ.pop("XDG_RUNTIME_DIR", None)
            else:
                os.environ["XDG_RUNTIME_DIR"] = saved
            if self.server is not None:
                self.server.close()
                self.report = self.server.report()
            self._ready.set()

    def __enter__(self) -> Served:
        self._thread.start()
        assert self._ready.wait(30), "the served bus did not start"
        if self.failure is not None:
            raise self.failure
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(30)

    def wait_for(self, condition: Any, timeout: float = 20) -> None:
        """Until `condition(server)` holds (the server is read between its polls; close enough for counts)."""
        deadline = time.monotonic() + timeout
        while not condition(self.server):
            assert time.monotonic() < deadline, "timed out waiting on the served bus"
            time.sleep(0.05)
