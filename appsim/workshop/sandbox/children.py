"""The sandboxed processes of one grading worker: a sandbox per submission (a zygote, booted once), a fresh child
forked in it for each exercise, ended by a watchdog when its time is up. Light on imports, so a worker's first
sandbox boots while the worker loads.
"""
from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import ClassVar

from appsim.errors import SandboxUnavailable
from appsim.schedstat import read_schedstat, schedstat
from appsim.workshop.sandbox import protocol as wire
from appsim.workshop.sandbox.isolation import ENVIRONMENT, Isolation, import_path, seccomp_program
from appsim.workshop.sandbox.protocol import Channel, ProtocolError

BOOT = ("import json, sys; settings = json.loads(sys.argv[1]); sys.path[:0] = settings['path']; "
        "from appsim.workshop.sandbox.zygote import main; main(settings)")
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
    c_options: tuple[str, ...] = ()         # not a limit: C18's command-line options (-Oi) a .c firmware is built with

    WALL_PER_CPU: ClassVar[int] = 10

    @property
    def wall_s(self) -> float:
        return self.wall_time_s if self.wall_time_s is not None else self.WALL_PER_CPU * self.time_s

    def __post_init__(self) -> None:
        object.__setattr__(self, "c_options", tuple(self.c_options))     # from JSON, a list
        if not (self.time_s > 0 and self.stall_s > 0 and self.memory_mb > 0 and self.file_mb > 0 and self.wall_s > 0):
            raise ValueError(f"sandbox limits are positive numbers; got {self}")


DEFAULT_LIMITS = Limits()


# ====================================================================== one submission's sandbox

def _memory_file(data: bytes) -> int:
    """A file descriptor from which `data` reads (a memfd where Linux has them, else a pipe small data fits in)."""
    if hasattr(os, "memfd_create"):
        descriptor = os.memfd_create("appsim-kit-headers")
        view = memoryview(data)
        while view:
            view = view[os.write(descriptor, view):]
        os.lseek(descriptor, 0, os.SEEK_SET)
        return descriptor
    read, write = os.pipe()
    os.write(write, data)
    os.close(write)
    return read


class Zygote:
    """One submission's sandbox: a sandboxed Python process that booted once (see `zygote`) and forks a fresh child for
    each of that submission's exercises. The grader's end of its control socket; `expires_at` ends it if it does not
    boot in time."""

    def __init__(self, isolation: Isolation | None, limits: Limits, watchdog: Watchdog, c_state: bytes | None = None):
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.control = ours
        self.limits = limits
        self.isolated = isolation is not None
        self.cpu_limit_s = int(limits.time_s) + 2   # each child's RLIMIT_CPU (SIGXCPU); SIGKILL a second later
        settings = {"memory_mb": limits.memory_mb, "file_mb": limits.file_mb, "cpu_s": self.cpu_limit_s,
                    "seccomp": seccomp_program().hex() if self.isolated else "", "control_fd": theirs.fileno(),
                    "path": import_path() if isolation is None else list(isolation.path),
                    "c_options": list(limits.c_options)}
        passed = [theirs.fileno()]
        if c_state is not None:         # the kit headers' state (grader-made, trusted): the zygote loads C at boot
            state_fd = settings["c_state_fd"] = _memory_file(c_state)
            passed.append(state_fd)
        python = sys.executable if isolation is None else isolation.executable
        argv = [python, "-I", "-S", "-B", "-c", BOOT, json.dumps(settings)]
        if isolation is not None:
            read, write = os.pipe()
            os.write(write, seccomp_program(may_fork=True))
            os.close(write)
            passed.append(read)
            argv, copies = isolation.command(argv, read)
            passed += copies
        self.expires_at = time.monotonic() + BOOT_S
        self.expired = False
        self._ended: dict[int, tuple[int, float]] = {}     # children it reported ended: pid -> (status, CPU seconds)
        self._pid: int | None = None
        try:
            self.process = subprocess.Popen(argv, pass_fds=passed, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.PIPE, start_new_session=True, cwd="/",
                                            env=ENVIRONMENT)
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
            for fd in passed[1:]:
                os.close(fd)
        self.watchdog = watchdog
        watchdog.watch(self)

    def ready(self, deadline: float) -> bool:
        """Whether it booted and said hello by `deadline` (or its boot time: the watchdog ends it then, which ends
        this wait); from then on it has no time limit of its own: its children have theirs."""
        self.expires_at = min(deadline, self.expires_at)
        hello = self._answer(None) == wire.HELLO
        self.watchdog.forget(self)
        return hello and not self.expired

    def fork(self, deadline: float, c: bool = False) -> Child | None:
        """A fresh child for one exercise (`c`: for a C firmware), None if this sandbox forks no more (it ended, or does
        not answer)."""
        from_grader, to_child = os.pipe()
        from_child, to_grader = os.pipe()
        try:
            socket.send_fds(self.control, [wire.FORK_C if c else wire.FORK], [from_grader, to_grader])
            reply = self._answer(time.monotonic() + FORK_S)
        except OSError:
            reply = None
        finally:
            os.close(from_grader)
            os.close(to_grader)
        pid = 0
        if reply is not None and len(reply) == wire.FORKED_MESSAGE.size and reply[:1] == wire.FORKED:
            _, pid = wire.FORKED_MESSAGE.unpack(reply)
        if pid <= 0:
            os.close(from_child)
            os.close(to_child)
            return None
        return Child(self, pid, Channel(from_child, to_child, wire.MAX_FROM_CHILD), deadline)

    def ended(self, pid: int, timeout: float) -> tuple[int, float] | None:
        """How its child `pid` ended, if it says so within `timeout`: the status (a signal as a negative number) and
        the CPU seconds the child used."""
        until = time.monotonic() + timeout
        while pid not in self._ended:
            if self._next(until) is None:
                return None
        return self._ended.pop(pid)

    def host_pid(self, pid: int) -> int | None:
        """Its child `pid` (as numbered in the sandbox) as this system numbers it; None if it cannot be told."""
        if not self.isolated:
            return pid
        own = self.own_pid()
        try:
            with open(f"/proc/{own}/task/{own}/children") as children:
                candidates = children.read().split()
        except (OSError, TypeError):
            return None
        for candidate in candidates:
            try:
                with open(f"/proc/{candidate}/status") as status:
                    numbers = next(line for line in status if line.startswith("NSpid:")).split()[1:]
            except (OSError, StopIteration):
                continue
            if numbers and numbers[-1] == str(pid):
                return int(candidate)
        return None

    def own_pid(self) -> int | None:
        """The zygote's process as this system numbers it (inside the sandbox, bubblewrap's one child)."""
        if self._pid is None:
            pid = self.process.pid
            if self.isolated:
                try:
                    with open(f"/proc/{pid}/task/{pid}/children") as children:
                        inner = children.read().split()
                except OSError:
                    return None
                if len(inner) != 1:
                    return None
                pid = int(inner[0])
            self._pid = pid
        return self._pid

    def _answer(self, until: float | None) -> bytes | None:
        """Its next message other than ENDED, None once it ended or `until` passed."""
        while (message := self._next(until)) is not None:
            if message[:1] != wire.ENDED:
                return message
        return None

    def _next(self, until: float | None) -> bytes | None:
        """Its next message (an ENDED one noted), None once it ended or `until` (time.monotonic()) passed."""
        if until is not None:
            left = until - time.monotonic()
            if left <= 0 or not select.select([self.control], [], [], left)[0]:
                return None
        try:
            message = self.control.recv(wire.MAX_CONTROL)
        except OSError:
            return None
        if len(message) == wire.ENDED_MESSAGE.size and message[:1] == wire.ENDED:
            _, pid, status, cpu_s = wire.ENDED_MESSAGE.unpack(message)
            self._ended[pid] = (status, cpu_s)
            if len(self._ended) > ENDED_KEPT:
                del self._ended[next(iter(self._ended))]
        return message or None

    def why_not(self) -> str:
        """What a zygote that never said hello printed (bubblewrap's or Python's own error), for the grader's log."""
        self.kill()
        assert self.process.stderr is not None
        text = self.process.stderr.read(4000).decode("utf-8", "replace").strip()
        return text or f"it ended with status {self.process.returncode}"

    def put_off(self) -> None:
        """Booting, it has no firmware that waits for a CPU."""

    def expire(self) -> None:
        """The watchdog's doing: it did not boot in time, or a child it forked that cannot be told apart (its number
        outside unknown) ran out of time."""
        self.expired = True
        self.process.kill()

    def kill(self) -> None:
        """End the sandbox, and everything in it."""
        self.watchdog.forget(self)
        if self.process.poll() is None:
            self.process.kill()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            pass
        self.control.close()


ENDED_KEPT = 64                     # ends a zygote told that nobody asked about (a bound on what it can make us keep)
FORK_S = 10.0                       # a zygote that does not answer a fork by then is broken


class Child:
    """One exercise's process, forked by its submission's zygote, and the grader's ends of its two pipes.

    `expires_at` (time.monotonic()) is when the watchdog ends it, put off by the time its firmware waits for a CPU (on
    a busy machine), never past `deadline`; `expired` says it did.
    """

    def __init__(self, zygote: Zygote, pid: int, channel: Channel, deadline: float):
        self.zygote = zygote
        self.pid = pid
        self.channel = channel
        self.cpu_limit_s = zygote.cpu_limit_s
        self.expires_at = min(deadline, time.monotonic() + BOOT_S)
        self.deadline = deadline
        self.expired = False
        self._host_pid = zygote.host_pid(pid)
        self._pidfd = _pidfd(self._host_pid)
        self._schedstat: int | None = None          # the firmware process's /proc schedstat, once it said hello
        self._waited_s = 0.0
        self._watchdog = zygote.watchdog
        self._watchdog.watch(self)

    def ready(self, deadline: float) -> bool:
        """Whether it said hello (it is walled in and waits for its firmware) in time."""
        try:
            hello = self.channel.receive() == wire.HELLO
        except ProtocolError:
            return False
        self.expires_at = deadline
        if not hello or self.expired:
            return False
        if self._host_pid is not None:
            self._schedstat = schedstat(f"/proc/{self._host_pid}/schedstat")
            self._waited_s = self.waited_for_cpu()
        return True

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
        """The firmware's own process as this system numbers it, None if it cannot be told."""
        return self._host_pid

    def why_not(self) -> str:
        """Why a child never said hello, for the grader's log."""
        self.kill()
        ended = self.zygote.ended(self.pid, 1.0)
        return f"it ended with status {ended[0]}" if ended else "its sandbox ended"

    def ended(self, timeout: float) -> tuple[int, float] | None:
        """How it ended, if it does within `timeout`: its status (a signal as a negative number) and the CPU seconds
        it used, as its zygote saw it (None if the zygote cannot say)."""
        return self.zygote.ended(self.pid, timeout)

    def expire(self) -> None:
        """The watchdog's doing: its time is up."""
        self.expired = True
        self._signal()

    def kill(self) -> None:
        """End it, and free what the grader holds of it."""
        self._watchdog.forget(self)
        if self._schedstat is not None:
            os.close(self._schedstat)
            self._schedstat = None
        self._signal()
        if self._pidfd is not None:
            os.close(self._pidfd)
            self._pidfd = None
        self.channel.close()

    def _signal(self) -> None:
        if self._pidfd is not None:
            try:
                signal.pidfd_send_signal(self._pidfd, signal.SIGKILL)
            except OSError:
                pass                    # it has ended already
        elif self._host_pid is not None and not self.zygote.isolated:
            try:
                os.kill(self._host_pid, signal.SIGKILL)
            except OSError:
                pass
        else:                           # it cannot be told apart in its sandbox: the sandbox ends with it
            self.zygote.expire()


def _pidfd(pid: int | None) -> int | None:
    """A descriptor that names process `pid` for good (no other process that gets its number later), where there are."""
    if pid is None or not hasattr(os, "pidfd_open"):
        return None
    try:
        return os.pidfd_open(pid)
    except OSError:
        return None


class Watchdog:
    """Ends each child whose `expires_at` has passed, which ends the grader's wait on it: one thread per grader. At each
    tick it first puts each child's end off by the time it waited for a CPU, so a busy machine stalls nobody."""

    TICK_S = 0.02

    def __init__(self) -> None:
        self._children: set[Child | Zygote] = set()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    def watch(self, child: Child | Zygote) -> None:
        with self._lock:
            self._children.add(child)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="appsim-sandbox-watchdog", daemon=True)
                self._thread.start()

    def forget(self, child: Child | Zygote) -> None:
        with self._lock:
            self._children.discard(child)

    def _run(self) -> None:
        while True:
            time.sleep(self.TICK_S)
            with self._lock:
                for child in self._children:
                    child.put_off()
                now = time.monotonic()
                expired = [c for c in self._children if c.expires_at <= now]
                self._children.difference_update(expired)
            for child in expired:           # outside the lock: ending one may forget another (its sandbox)
                child.expire()


class Sandbox:
    """One grading worker's sandboxes: one per submission (a zygote), which forks a fresh child for each exercise.
    While a submission is graded, the next one's sandbox may boot (`take(..., spare=True)`).

    `isolation` None runs them as plain processes (only for a class whose code is trusted: `--trusted`).
    """

    def __init__(self, isolation: Isolation | None, limits: Limits = DEFAULT_LIMITS):
        self.isolation = isolation
        self.limits = limits
        self.watchdog = Watchdog()
        self._spare: Zygote | None = None
        self._zygote: Zygote | None = None
        self._owner: object = None
        self.c_state: bytes | None = None   # once a C firmware came: the kit headers' state, for every sandbox after

    def take(self, deadline: float, owner: object = None, *, spare: bool = False, c: bool = False) -> Child:
        """A fresh child for one exercise of submission `owner`, in that submission's sandbox (booted now, or while the
        one before was graded); `spare` starts the next submission's sandbox booting; `c`: for a C firmware.
        SandboxUnavailable if none will boot."""
        problem = ""
        for _ in range(BOOT_ATTEMPTS):
            if self._zygote is None or self._owner != owner or self._zygote.process.poll() is not None:
                problem = self._switch(deadline, owner, spare)
                if self._zygote is None:
                    if time.monotonic() >= deadline:
                        break
                    continue
            child = self._zygote.fork(deadline, c)
            if child is not None and child.ready(deadline):
                return child
            problem = child.why_not() if child is not None else "its sandbox ended"
            self._zygote.kill()
            self._zygote = None
            if time.monotonic() >= deadline:
                break
        raise SandboxUnavailable(f"the grader could not start a sandbox for this firmware: {problem}")

    def _switch(self, deadline: float, owner: object, spare: bool) -> str:
        """Make a booted sandbox submission `owner`'s; what went wrong if none booted."""
        if self._zygote is not None:
            self._zygote.kill()
            self._zygote = None
        zygote = self._spare if self._spare is not None and not self._spare.expired else self._zygote_()
        if zygote is not self._spare and self._spare is not None:
            self._spare.kill()          # it waited for its turn past its boot time, and the watchdog ended it
        self._spare = self._zygote_() if spare else None
        if not zygote.ready(deadline):
            return zygote.why_not()
        self._zygote, self._owner = zygote, owner
        return ""

    def warm(self) -> None:
        """Start the first sandbox booting now (a worker does this before it loads the simulator)."""
        if self._spare is None:
            self._spare = self._zygote_()

    def expect_c(self, c_state: bytes) -> None:
        """C firmware is being graded: sandboxes booted from now on load the C translator and `c_state`, the kit
        headers' state (`appsim.firmware.c18.header_state`), at boot (a spare boots while the submission before it is
        graded), so that none parses the headers itself."""
        self.c_state = c_state

    def _zygote_(self) -> Zygote:
        return Zygote(self.isolation, self.limits, self.watchdog, self.c_state)

    def close(self) -> None:
        for zygote in (self._spare, self._zygote):
            if zygote is not None:
                zygote.kill()
        self._spare = self._zygote = None

    def __enter__(self) -> Sandbox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
