"""The sandboxed processes of one grading worker: each starts booting at once, is ended by a watchdog when its time is
up, and the next one is always booting. Light on imports, so a worker's first child boots while the worker loads.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, ClassVar

from appsim.errors import SandboxUnavailable
from appsim.workshop.sandbox import protocol as wire
from appsim.workshop.sandbox.isolation import ENVIRONMENT, Isolation, import_path, seccomp_program
from appsim.workshop.sandbox.protocol import Channel, ProtocolError
from appsim.workshop.sandbox.usage import read_schedstat, schedstat

BOOT = ("import json, sys; settings = json.loads(sys.argv[1]); sys.path[:0] = settings['path']; "
        "from appsim.workshop.sandbox.child import main; main(settings)")
BOOT_S = 30.0                       # a child that has not said hello by then is broken, not slow
BOOT_ATTEMPTS = 3


@dataclass(frozen=True)
class Limits:
    """What one exercise's firmware may use: CPU time (its own process's, and the grader's in simulating for it), time
    asleep (`stall_s`: at once, without a word to the board, and in all), memory, and the size of a file it writes.
    Waiting for a CPU is not counted, so a busy machine does not cut a run short; as a last resort, the wall time in
    all (loading and running) is limited too, by default to `WALL_PER_CPU` times the CPU time."""

    time_s: float = 60.0
    stall_s: float = 10.0
    memory_mb: int = 256
    file_mb: int = 16
    wall_time_s: float | None = None

    WALL_PER_CPU: ClassVar[int] = 10

    @property
    def wall_s(self) -> float:
        return self.wall_time_s if self.wall_time_s is not None else self.WALL_PER_CPU * self.time_s

    def __post_init__(self) -> None:
        if not (self.time_s > 0 and self.stall_s > 0 and self.memory_mb > 0 and self.file_mb > 0 and self.wall_s > 0):
            raise ValueError(f"sandbox limits are positive numbers; got {self}")


DEFAULT_LIMITS = Limits()


# ====================================================================== one sandboxed process

class Child:
    """One sandboxed Python process, booting or ready for its firmware, and the grader's ends of its two pipes.

    `expires_at` (time.monotonic()) is when the watchdog ends it, put off by the time its firmware waits for a CPU (on
    a busy machine), never past `deadline`; `expired` says it did.
    """

    def __init__(self, isolation: Isolation | None, limits: Limits, watchdog: Watchdog):
        from_grader, to_child = os.pipe()
        from_child, to_grader = os.pipe()
        self.channel = Channel(from_child, to_child, wire.MAX_FROM_CHILD)
        self.cpu_limit_s = int(limits.time_s) + 2   # RLIMIT_CPU's soft limit (SIGXCPU); SIGKILL a second later
        settings: dict[str, Any] = {"read_fd": from_grader, "write_fd": to_grader, "path": import_path(),
                                    "memory_mb": limits.memory_mb, "file_mb": limits.file_mb,
                                    "cpu_s": self.cpu_limit_s}
        argv = [sys.executable, "-I", "-S", "-B", "-c", BOOT, json.dumps(settings)]
        theirs = [from_grader, to_grader]
        if isolation is not None:
            read, write = os.pipe()
            os.write(write, seccomp_program())
            os.close(write)
            theirs.append(read)
            argv = isolation.command(argv, read)
        self.expires_at = time.monotonic() + BOOT_S
        self.deadline = math.inf
        self.expired = False
        self.isolated = isolation is not None
        self._schedstat: int | None = None          # the firmware process's /proc schedstat, once it said hello
        self._waited_s = 0.0
        try:
            self.process = subprocess.Popen(argv, pass_fds=theirs, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.PIPE, start_new_session=True, cwd="/",
                                            env=ENVIRONMENT)
        except BaseException:
            self.channel.close()
            raise
        finally:
            for fd in theirs:
                os.close(fd)
        self._watchdog = watchdog
        watchdog.watch(self)

    def ready(self, deadline: float) -> bool:
        """Whether it booted and said hello by `deadline` (which stays its last resort)."""
        self.deadline = deadline
        self.expires_at = min(deadline, self.expires_at)
        try:
            hello = self.channel.receive() == wire.HELLO
        except ProtocolError:
            return False
        if hello and (pid := self.firmware_pid()) is not None:
            self._schedstat = schedstat(f"/proc/{pid}/schedstat")
            self._waited_s = self.waited_for_cpu()
        return hello

    def waited_for_cpu(self) -> float:
        """Seconds its firmware's process has spent ready to run but waiting for a CPU (0 where that is not known)."""
        counts = None if self._schedstat is None else read_schedstat(self._schedstat)
        return 0.0 if counts is None else counts[1]

    def put_off(self) -> None:
        """Put `expires_at` off by the time the firmware waited for a CPU since the last look (a busy machine)."""
        waited = self.waited_for_cpu()
        if waited > self._waited_s:
            self.expires_at = min(self.deadline, self.expires_at + waited - self._waited_s)
            self._waited_s = waited

    def firmware_pid(self) -> int | None:
        """The firmware's own process as this system numbers it (inside the sandbox, bubblewrap's one child), None if
        it cannot be told."""
        pid = self.process.pid
        if not self.isolated:
            return pid
        try:
            with open(f"/proc/{pid}/task/{pid}/children") as children:
                inner = children.read().split()
        except OSError:
            return None
        return int(inner[0]) if len(inner) == 1 else None

    def why_not(self) -> str:
        """What a child that never said hello printed (bubblewrap's or Python's own error), for the grader's log."""
        self.kill()
        assert self.process.stderr is not None
        text = self.process.stderr.read(4000).decode("utf-8", "replace").strip()
        return text or f"it ended with status {self.process.returncode}"

    def ended(self, timeout: float) -> tuple[int, float] | None:
        """How it ended, if it does within `timeout`: its status (a signal as a negative number) and the CPU seconds
        it used (bubblewrap reports a signal as 128 + signal, and counts its child's time as its own)."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                pid, status, usage = os.wait4(self.process.pid, os.WNOHANG)
            except ChildProcessError:       # reaped already
                return (self.process.returncode or 0), 0.0
            if pid:
                code = os.waitstatus_to_exitcode(status)
                self.process.returncode = code
                return (-(code - 128) if code > 128 else code), usage.ru_utime + usage.ru_stime
            if time.monotonic() >= deadline:
                return None
            time.sleep(0.01)

    def expire(self) -> None:
        """The watchdog's doing: its time is up."""
        self.expired = True
        self.process.kill()

    def kill(self) -> None:
        """End it (and, through its namespace, anything it left), and free what the grader holds of it."""
        self._watchdog.forget(self)
        if self._schedstat is not None:
            os.close(self._schedstat)
            self._schedstat = None
        if self.process.poll() is None:
            self.process.kill()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            pass
        self.channel.close()


class Watchdog:
    """Ends each child whose `expires_at` has passed, which ends the grader's wait on it: one thread per grader. At each
    tick it first puts each child's end off by the time it waited for a CPU, so a busy machine stalls nobody."""

    TICK_S = 0.02

    def __init__(self) -> None:
        self._children: set[Child] = set()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    def watch(self, child: Child) -> None:
        with self._lock:
            self._children.add(child)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="appsim-sandbox-watchdog", daemon=True)
                self._thread.start()

    def forget(self, child: Child) -> None:
        with self._lock:
            self._children.discard(child)

    def _run(self) -> None:
        while True:
            time.sleep(self.TICK_S)
            with self._lock:
                for child in self._children:
                    child.put_off()
                now = time.monotonic()
                for child in [c for c in self._children if c.expires_at <= now]:
                    self._children.discard(child)
                    child.expire()


class Sandbox:
    """One grading worker's supply of sandboxed children: each exercise gets a fresh one, the next already booting.

    `isolation` None runs children as plain processes (only for a class whose code is trusted: `--trusted`).
    """

    def __init__(self, isolation: Isolation | None, limits: Limits = DEFAULT_LIMITS):
        self.isolation = isolation
        self.limits = limits
        self.watchdog = Watchdog()
        self._spare: Child | None = None

    def take(self, deadline: float) -> Child:
        """A child that has booted; the next one starts booting meanwhile. SandboxUnavailable if none will boot."""
        problem = ""
        for _ in range(BOOT_ATTEMPTS):
            child = self._spare or self._child()
            self._spare = self._child()
            if child.ready(deadline):
                return child
            problem = child.why_not()
            if time.monotonic() >= deadline:
                break
        raise SandboxUnavailable(f"the grader could not start a sandbox for this firmware: {problem}")

    def warm(self) -> None:
        """Start the first child booting now (a worker does this before it loads the simulator)."""
        if self._spare is None:
            self._spare = self._child()

    def _child(self) -> Child:
        return Child(self.isolation, self.limits, self.watchdog)

    def close(self) -> None:
        if self._spare is not None:
            self._spare.kill()
            self._spare = None

    def __enter__(self) -> Sandbox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
