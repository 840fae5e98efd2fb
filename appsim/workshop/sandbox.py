"""One submission's firmware in its own OS process: each register access crosses a socket to the simulated board.

The simulation and the checks stay in the grader; the child holds only the student's module and the firmware
library it calls (AN738, C18 helpers), as a C build links them in. What the child does to itself only changes
what its firmware does on the board, which is what is graded. What the child may do: see `_child`, docs/grading.md.
"""
from __future__ import annotations

import json
import math
import os
import select
import shutil
import signal
import socket
import struct
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar

from appsim.chip.mcu import PIC18F8680, SFRNames, _firmware_location, current_mcu

NOBODY = 65534
# Wire format (little-endian; a message is a u32 length, then its bytes). Child to grader: a batch of `W`
# address:u16 value:u8 (write) and `S` cycles:u64 (spend), ended by at most one access that waits for its
# answer, `R` address:u16 site:i64 (read) or `G` JSON [function, args] (a GLCD call); or, alone, `L` (loaded),
# `E` (main returned), `X` text (exception), `M` (out of memory), `P` text (refused by the sandbox).
# Grader to child: `V` value:u8, `K` (GLCD call done), `F` JSON [exception type, message].
_LENGTH = struct.Struct("<I")
_WRITE = struct.Struct("<cHB")
_SPEND = struct.Struct("<cQ")
_READ = struct.Struct("<cHq")
_MAX_MESSAGE = 1 << 20
_BATCH_BYTES = 4096             # writes and spends wait at most this long for the next read
_MAX_TEXT = 4000                # characters of a traceback kept in a grade
_GLCD_FUNCTIONS = ("GLCD_Initial", "setcurGLCD", "putsGLCD", "putrsGLCD", "putcGLCD")


@dataclass(frozen=True)
class Limits:
    """What one exercise's firmware may use: wall time in all, wall time without a register access, memory."""

    time_s: float = 60.0
    stall_s: float = 10.0
    memory_mb: int = 256

    def __post_init__(self) -> None:
        if not (self.time_s > 0 and self.stall_s > 0 and self.memory_mb > 0):
            raise ValueError(f"sandbox limits are positive numbers; got {self}")


DEFAULT_LIMITS = Limits()


@dataclass(frozen=True)
class Fault:
    """Why a firmware run earns nothing: `kind` is one word (exception, exited, stalled, ...), `message` explains."""

    kind: str
    message: str


class FirmwareFault(RuntimeError):
    """The sandboxed firmware stopped for a reason that earns no marks (the board's process ends with it)."""


# ====================================================================== the grader's side

class Sandbox:
    """The fork server of one grader process: `RemoteFirmware(sandbox, path)` runs a file's main() in a child."""

    def __init__(self) -> None:
        import subprocess  # here, not at the top: the fork server must not have it (see _AuditPolicy)

        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        command = [sys.executable, "-c", "from appsim.workshop.sandbox import fork_server; fork_server()", str(theirs.fileno())]
        self.network_namespace = os.geteuid() == 0 and _can_unshare_network()
        if self.network_namespace:
            command = ["unshare", "--net", *command]
        self._process = subprocess.Popen(command, pass_fds=[theirs.fileno()], stdin=subprocess.DEVNULL)
        theirs.close()
        self._control = ours
        ready = ours.recv(4096)
        if ready != b"ready":
            self.close()
            raise RuntimeError("the grader's sandbox did not start (see the error above)")

    def _request(self, request: dict[str, Any], fds: list[int] | None = None) -> dict[str, Any]:
        socket.send_fds(self._control, [json.dumps(request).encode()], fds or [])
        return json.loads(self._control.recv(4096))

    def start(self, firmware: Path, directory: Path, limits: Limits) -> tuple[int, socket.socket]:
        """Fork a child running `firmware` (a copy in `directory`); returns its pid and the grader's end."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            reply = self._request({"op": "run", "firmware": str(firmware), "directory": str(directory),
                                   "time_s": limits.time_s, "memory_mb": limits.memory_mb}, [theirs.fileno()])
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
        return reply["pid"], ours

    def wait(self, pid: int) -> int:
        """Reap a child (after its end of the socket closed, or after it was killed); its wait status."""
        return self._request({"op": "wait", "pid": pid})["status"]

    def close(self) -> None:
        self._control.close()       # the fork server's end closes: it exits
        self._process.wait()

    def __enter__(self) -> Sandbox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _can_unshare_network() -> bool:
    import subprocess

    if shutil.which("unshare") is None:
        return False
    return subprocess.run(["unshare", "--net", "true"], capture_output=True, check=False).returncode == 0


class RemoteFirmware:
    """A firmware file's `main` for a board: each call runs the file in a fresh sandboxed child and serves it.

    Give it to `board.run()` (or the checks) like any `main`. The first fault (see `Fault`) is kept in
    `fault`; the run then ends as a crash would. The wall-time limit counts from construction, over all runs.
    """

    def __init__(self, sandbox: Sandbox, firmware: str | Path, limits: Limits = DEFAULT_LIMITS):
        self.sandbox = sandbox
        self.firmware = Path(firmware)
        self.limits = limits
        self.deadline = time.monotonic() + limits.time_s
        self.fault: Fault | None = None
        self.round_trips = 0
        self._live: set[int] = set()
        self._error: Exception | None = None

    def __call__(self) -> None:
        mcu = current_mcu()
        mcu.process.watched = False      # the child's own limits (stall_s, time_s) govern it, not the watchdog
        directory = Path(tempfile.mkdtemp(prefix="appsim-firmware-"))
        pid = None
        try:
            copy = directory / self.firmware.name
            shutil.copyfile(self.firmware, copy)
            pid, channel = self.sandbox.start(copy, directory, self.limits)
            self._live.add(pid)
            with channel:
                fault = self._serve(mcu, _Channel(channel))
            status = self._end(pid)
        finally:
            if pid is not None:
                self._end(pid)
            shutil.rmtree(directory, ignore_errors=True)
        if fault is None:
            fault = _exit_fault(status, self.limits)
        if self.fault is None:
            self.fault = fault
        raise FirmwareFault(fault.message)

    def close(self) -> None:
        """End the children still running (a simulation that stopped while its firmware waited for an answer)."""
        for pid in list(self._live):
            self._end(pid)

    def _end(self, pid: int) -> int:
        if pid not in self._live:
            return 0
        self._live.discard(pid)
        _kill(pid)
        return self.sandbox.wait(pid)

    def _serve(self, mcu: PIC18F8680, channel: _Channel) -> Fault | None:
        """Perform the child's accesses on `mcu` until it ends; the fault that ended it (None: its end closed)."""
        loaded = False
        while True:
            now = time.monotonic()
            if now >= self.deadline:
                return Fault("time", f"time limit: the exercise ran for more than {self.limits.time_s:g} s of "
                                     "wall time; firmware this slow would not keep up with the bus")
            try:
                message = channel.receive(min(self.limits.stall_s, self.deadline - now))
            except TimeoutError:
                if time.monotonic() >= self.deadline:
                    continue
                return Fault("stalled", "the firmware stopped answering: seconds of wall time went by without "
                                        "it touching a register (an endless loop that reads nothing, such as "
                                        "`while True: pass`?)")
            if message is None:
                return None
            op = message[:1]
            if op == b"X" and not loaded:
                return Fault("load", _text(message[1:]))
            if op in (b"E", b"X", b"M", b"P"):
                return _reported_fault(op, message[1:], self.limits)
            if op == b"L" and not loaded:
                loaded = True
                continue
            try:
                reply = self._perform(mcu, message)
            except (struct.error, ValueError, TypeError, IndexError):
                return Fault("protocol", "the firmware's process broke the sandbox's protocol (it tampered with "
                                         "the kit in its own process); its run ends here")
            if reply is None:
                continue
            if self._error is not None:
                reply = b"F" + json.dumps([type(self._error).__name__, str(self._error)]).encode()
                self._error = None
            self.round_trips += 1
            if not channel.send(reply):
                return None

    def _perform(self, mcu: PIC18F8680, message: bytes) -> bytes | None:
        """Do a batch of accesses on `mcu`; the reply when it ends with one that waits for an answer.

        Malformed data raises struct.error, ValueError or TypeError. An access the board refuses (an
        exception from a peripheral) skips the rest of the batch and is raised in the child at its reply.
        """
        position, end = 0, len(message)
        while position < end:
            op = message[position:position + 1]
            if op == b"W":
                _, address, value = _WRITE.unpack_from(message, position)
                position += _WRITE.size
                self._guarded(mcu.write, address, value)
            elif op == b"S":
                _, cycles = _SPEND.unpack_from(message, position)
                position += _SPEND.size
                self._guarded(mcu.spend_cycles, cycles)
            elif op == b"R" and position + _READ.size == end:
                _, address, site = _READ.unpack_from(message, position)
                value = self._guarded(mcu.read, address, site)
                return b"V" + bytes([(value or 0) & 0xFF])
            elif op == b"G":
                function, args = json.loads(message[position + 1:])
                if function not in _GLCD_FUNCTIONS or not isinstance(args, list):
                    raise ValueError(f"no GLCD function {function!r}")
                from appsim.board import glcd
                self._guarded(getattr(glcd, function), *args)
                return b"K"
            else:
                raise ValueError(f"no operation {op!r}")
        return None

    def _guarded(self, access: Any, *args: Any) -> Any:
        if self._error is None:
            try:
                return access(*args)
            except Exception as error:      # the firmware sees it raised, as it would on a local board
                self._error = error
        return None


class _Channel:
    """The grader's end of one child's socket: whole messages in, replies out, with a timeout."""

    def __init__(self, sock: socket.socket):
        self._fd = sock.fileno()
        self._buffer = bytearray()
        self._poll = select.poll()
        self._poll.register(self._fd, select.POLLIN)

    def receive(self, timeout_s: float) -> bytes | None:
        """The next message; None when the child's end closed; TimeoutError if none came within `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while True:
            buffer = self._buffer
            if len(buffer) >= 4:
                (length,) = _LENGTH.unpack_from(buffer)
                if length == 0 or length > _MAX_MESSAGE:
                    return b"?"         # no message of this protocol: a protocol fault
                if len(buffer) >= 4 + length:
                    message = bytes(buffer[4:4 + length])
                    del buffer[:4 + length]
                    return message
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not self._poll.poll(math.ceil(remaining * 1000)):
                raise TimeoutError
            try:
                chunk = os.read(self._fd, 1 << 16)
            except ConnectionResetError:
                chunk = b""
            if not chunk:
                return None
            buffer += chunk

    def send(self, reply: bytes) -> bool:
        try:
            os.write(self._fd, _LENGTH.pack(len(reply)) + reply)
            return True
        except (BrokenPipeError, ConnectionResetError):
            return False


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _text(data: bytes) -> str:
    text = data.decode("utf-8", "replace")
    return text if len(text) <= _MAX_TEXT else text[:_MAX_TEXT] + "\n..."


def _reported_fault(op: bytes, data: bytes, limits: Limits) -> Fault:
    if op == b"E":
        return Fault("returned", "main() returned: firmware's main() loops forever, as main() does in EX1.C; "
                                 "once it returns the board does nothing more")
    if op == b"M":
        return Fault("memory", f"memory limit: the firmware needed more than {limits.memory_mb} MB")
    if op == b"P":
        return Fault("forbidden", f"the sandbox refused it: {_text(data)}. Firmware acts only through the "
                                  "board (registers, the library); this run earns no marks")
    return Fault("exception", f"the firmware raised an exception:\n{_text(data)}")


def _exit_fault(status: int, limits: Limits) -> Fault:
    """The child's end closed without saying why: it exited, or the CPU limit stopped it."""
    if os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGXCPU:
        return Fault("time", f"CPU time limit: the firmware computed for more than {limits.time_s:g} s")
    return Fault("exited", "the firmware exited (sys.exit, os._exit) while the board was running it: "
                           "firmware never exits; main() loops forever")


# ====================================================================== the child's side

class _Unavailable(ModuleType):
    """A module the sandbox does not give firmware (numpy loads ctypes, which would escape the audit hook)."""

    def __getattr__(self, name: str) -> Any:
        raise ImportError(f"{self.__name__} is not available to firmware in the grader's sandbox")


def fork_server() -> None:
    """The fork server's main loop (run by `Sandbox` as a fresh interpreter; argv[1] is its socket's fd)."""
    control = socket.socket(fileno=int(sys.argv[1]))
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # Ctrl-C is for the grader, which ends everything
    sys.modules.setdefault("numpy", _Unavailable("numpy"))   # the GLCD imports it for pictures only
    import appsim.firmware
    import appsim.can.frame
    import appsim.firmware.loader
    import appsim.can.slcan
    from appsim.board.app023 import APP023
    from appsim.bus.wire import Bus
    from appsim.sim import Simulator

    addresses = dict(APP023(Bus(Simulator(), 125_000)).mcu.sfr_addresses)
    nobody = os.geteuid() == 0 and all(_readable_by_all(Path(p)) for p in (sys.prefix, appsim.firmware.__file__))
    for name in ("ctypes", "_ctypes", "subprocess", "_posixsubprocess"):    # the audit hook refuses them again
        sys.modules.pop(name, None)
    control.send(b"ready")
    while True:
        try:
            message, fds, _, _ = socket.recv_fds(control, 65536, 1)
        except ConnectionResetError:
            message, fds = b"", []
        if not message:
            return
        request = json.loads(message)
        if request["op"] == "run":
            pid = os.fork()
            if pid == 0:
                try:
                    control.close()
                    _child(fds[0], request, addresses, nobody)
                finally:
                    os._exit(0)
            os.close(fds[0])
            control.send(json.dumps({"pid": pid}).encode())
        else:
            try:
                _, status = os.waitpid(request["pid"], 0)
            except ChildProcessError:
                status = 0
            control.send(json.dumps({"status": status}).encode())


class _RemoteMCU(SFRNames):
    """What `current_mcu()` returns in the child: the board's PIC18F8680, across the socket."""

    def __init__(self, fd: int, addresses: dict[str, int]):
        self._fd = fd
        self._pending = bytearray()
        self.sfr_addresses = addresses

    # --------------------------------------------------------------- the MCU's interface to firmware
    def read(self, address: int, site: object = None) -> int:
        self._pending += _READ.pack(b"R", _address(address), _call_site())
        return self._exchange()[1]

    def write(self, address: int, value: int) -> None:
        self._pending += _WRITE.pack(b"W", _address(address), value & 0xFF)
        if len(self._pending) > _BATCH_BYTES:
            self.flush()

    def spend_cycles(self, cycles: int) -> None:
        if not isinstance(cycles, int) or cycles < 0:
            raise ValueError(f"instruction cycles are a whole number >= 0; got {cycles!r}")
        self._pending += _SPEND.pack(b"S", cycles)
        if len(self._pending) > _BATCH_BYTES:
            self.flush()

    def __getattr__(self, name: str) -> Any:
        raise AttributeError(f"in the grader's sandbox the firmware reaches the board only through its registers "
                             f"and the library; the MCU's {name!r} is not there")

    # --------------------------------------------------------------- the socket
    def glcd(self, function: str, args: tuple[Any, ...]) -> None:
        def plain(value: Any) -> Any:
            if isinstance(value, (bytes, bytearray)):
                return list(value)
            raise TypeError(f"{function} takes strings, bytes, character codes and line/column numbers; "
                            f"got {value!r}")
        self._pending += b"G" + json.dumps([function, list(args)], default=plain).encode()
        self._exchange()

    def flush(self) -> None:
        if self._pending:
            _send_all(self._fd, _LENGTH.pack(len(self._pending)) + self._pending)
            self._pending = bytearray()

    def report(self, op: bytes, text: str = "") -> None:
        """Tell the grader how the run ends (after the accesses still waiting in the batch)."""
        self.flush()
        _send_all(self._fd, _LENGTH.pack(1 + len(text.encode())) + op + text.encode())

    def _exchange(self) -> bytes:
        self.flush()
        reply = _receive_all(self._fd)
        if reply[:1] == b"F":
            kind, text = json.loads(reply[1:])
            raise _ERRORS.get(kind, RuntimeError)(text)
        return reply


_ERRORS: dict[str, type[Exception]] = {"ValueError": ValueError, "TypeError": TypeError,
                                       "RuntimeError": RuntimeError, "KeyError": KeyError}


def _address(address: int) -> int:
    if not isinstance(address, int) or not 0 <= address <= 0xFFF:
        raise ValueError(f"the PIC18F8680's data memory has addresses 0x000..0xFFF; got {address!r}")
    return address


def _call_site() -> int:
    """Where in the firmware (outside the kit) this access comes from, as one number (see PIC18F8680.read)."""
    return hash(_firmware_location())


def _send_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        try:
            view = view[os.write(fd, view):]
        except OSError:
            os._exit(0)             # the grader went away


def _receive_all(fd: int) -> bytes:
    def exactly(count: int) -> bytes:
        data = b""
        while len(data) < count:
            chunk = os.read(fd, count - len(data))
            if not chunk:
                os._exit(0)         # the grader ended this run
            data += chunk
        return data
    (length,) = _LENGTH.unpack(exactly(4))
    return exactly(length)


def _readable_by_all(path: Path) -> bool:
    """Whether user nobody could read `path` (every directory above it searchable by others)."""
    return all(os.stat(directory).st_mode & 0o001 for directory in path.resolve().parents)


def _child(fd: int, request: dict[str, Any], addresses: dict[str, int], nobody: bool) -> None:
    """Set the child up, load the firmware and run its main() (never returns: the caller exits).

    Before any student code runs: stdout and stderr go nowhere; the working directory is a fresh temporary
    directory holding only the firmware file; with `nobody` (as root, when the Python installation and the kit
    are readable by all) it becomes user nobody; limits on address space, CPU time, processes, file size and
    open files; the library reaches the board through `_RemoteMCU`; and `_AuditPolicy` refuses processes,
    signals, sockets, ctypes and files outside that directory. As root, the fork server (and so the child) is
    in a network namespace of its own (`unshare --net`): no network at all.
    """
    import resource

    from appsim.board import glcd
    from appsim.firmware.loader import FirmwareError, load_firmware

    directory = Path(request["directory"]).resolve()
    firmware = Path(request["firmware"])
    null = os.open(os.devnull, os.O_RDWR)
    for standard in (0, 1, 2):          # what the firmware prints is never read
        os.dup2(null, standard)
    os.close(null)
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)       # a file too big fails with an error instead
    os.chdir(directory)
    if nobody:
        os.chown(directory, NOBODY, NOBODY)
        os.setgroups([])
        os.setgid(NOBODY)
        os.setuid(NOBODY)
    with open("/proc/self/statm") as statm:
        size = int(statm.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    cpu = math.ceil(request["time_s"]) + 1
    for limit, value in ((resource.RLIMIT_AS, size + (request["memory_mb"] << 20)),
                         (resource.RLIMIT_CPU, cpu), (resource.RLIMIT_NPROC, 0), (resource.RLIMIT_CORE, 0),
                         (resource.RLIMIT_FSIZE, 16 << 20), (resource.RLIMIT_NOFILE, 32)):
        resource.setrlimit(limit, (value, value + 1 if limit == resource.RLIMIT_CPU else value))

    mcu = _RemoteMCU(fd, addresses)
    for module in list(sys.modules.values()):
        if module is not None and module.__name__.startswith("appsim") and hasattr(module, "current_mcu"):
            module.current_mcu = lambda: mcu    # type: ignore[attr-defined]
    for function in _GLCD_FUNCTIONS:
        forward = _glcd_forward(mcu, function, getattr(glcd, function).__doc__)
        setattr(glcd, function, forward)
        setattr(sys.modules["appsim.firmware"], function, forward)
    sys.addaudithook(_AuditPolicy(mcu, directory))

    try:
        module = load_firmware(firmware)
    except FirmwareError as error:
        mcu.report(b"X", str(error).replace(str(firmware), firmware.name))
        return
    mcu.report(b"L")
    try:
        module.main()
    except MemoryError:
        mcu.report(b"M")
    except SystemExit:
        mcu.flush()                     # the firmware exited: the grader sees its end close
    except BaseException as error:
        mcu.report(b"X", _student_traceback(error, firmware))
    else:
        mcu.report(b"E")


def _glcd_forward(mcu: _RemoteMCU, function: str, doc: str | None) -> Any:
    def forward(*args: Any) -> None:
        mcu.glcd(function, args)
    forward.__name__ = forward.__qualname__ = function
    forward.__doc__ = doc
    return forward


def _student_traceback(error: BaseException, firmware: Path) -> str:
    """The traceback's lines in the student's own file, and the error (the kit's frames left out)."""
    lines = ["Traceback (in your file):"]
    for frame in traceback.extract_tb(error.__traceback__):
        if frame.filename == str(firmware):
            lines.append(f"  {firmware.name}, line {frame.lineno}, in {frame.name}: {frame.line}")
    lines.extend(line.rstrip("\n") for line in traceback.format_exception_only(type(error), error))
    return "\n".join(lines).replace(str(firmware), firmware.name)


class _AuditPolicy:
    """The audit hook of a child: what firmware may not do, refused and reported to the grader."""

    REFUSED: ClassVar[dict[str, str]] = {
        "os.fork": "starting a process (os.fork)", "os.forkpty": "starting a process (os.forkpty)",
        "os.posix_spawn": "starting a process (os.posix_spawn)", "os.spawn": "starting a process (os.spawn*)",
        "os.exec": "running a program (os.exec*)", "os.system": "running a command (os.system)",
        "subprocess.Popen": "starting a process (subprocess)", "os.kill": "sending a signal (os.kill)",
        "os.killpg": "sending a signal (os.killpg)", "signal.pthread_kill": "sending a signal",
        "socket.__new__": "opening a socket (network)", "resource.setrlimit": "changing its limits",
        "resource.prlimit": "changing its limits", "os.chroot": "changing its root directory",
    }
    REFUSED_MODULES: ClassVar[set[str]] = {"ctypes", "_ctypes", "_posixsubprocess", "cffi", "_cffi_backend"}
    # event -> positions of its path arguments, and whether it changes the file system
    PATHS: ClassVar[dict[str, tuple[tuple[int, ...], bool]]] = {"os.listdir": ((0,), False), "os.scandir": ((0,), False), "os.chdir": ((0,), False),
             "os.remove": ((0,), True), "os.rmdir": ((0,), True), "os.mkdir": ((0,), True),
             "os.rename": ((0, 1), True), "os.link": ((0, 1), True), "os.symlink": ((0, 1), True),
             "os.chmod": ((0,), True), "os.chown": ((0,), True), "os.truncate": ((0,), True),
             "os.utime": ((0,), True), "os.mkfifo": ((0,), True), "os.mknod": ((0,), True),
             "os.setxattr": ((0,), True), "os.removexattr": ((0,), True)}
    _WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND

    def __init__(self, mcu: _RemoteMCU, directory: Path):
        import site

        import appsim
        self.mcu = mcu
        self.directory = str(directory)
        roots = {sys.prefix, sys.base_prefix, sys.exec_prefix, *site.getsitepackages(),
                 str(Path(appsim.__file__).parent)}
        self.readable = tuple(os.path.realpath(root) for root in roots) + (self.directory,)

    def __call__(self, event: str, args: tuple[Any, ...]) -> None:
        if event in self.REFUSED:
            self.refuse(self.REFUSED[event])
        elif event.startswith("ctypes."):
            self.refuse("ctypes")
        elif event == "import" and args[0].partition(".")[0] in self.REFUSED_MODULES:
            self.refuse(f"importing {args[0]}")
        elif event == "open":
            path, mode, flags = args
            writes = (any(c in mode for c in "wax+") if isinstance(mode, str)
                      else bool((flags or 0) & self._WRITE_FLAGS))
            self.check(path, writes, "writing" if writes else "reading")
        elif event in self.PATHS:
            positions, writes = self.PATHS[event]
            for position in positions:
                if position < len(args):
                    self.check(args[position], writes, f"{event}() on")

    def check(self, path: Any, writes: bool, what: str) -> None:
        if path is None:
            return
        if isinstance(path, int):
            self.refuse(f"{what} a file by its descriptor ({path})")
        real = os.path.realpath(os.fsdecode(os.fspath(path)))
        allowed = (self.directory,) if writes else self.readable
        if not any(real == root or real.startswith(root + os.sep) for root in allowed) and real != os.devnull:
            self.refuse(f"{what} {real}, outside the firmware's own temporary directory")

    def refuse(self, what: str) -> None:
        self.mcu.report(b"P", what)
        raise PermissionError(f"the grader's sandbox does not allow {what}")
