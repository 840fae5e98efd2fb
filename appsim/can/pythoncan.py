"""appsim as a python-can interface: `can.Bus(interface="appsim", channel="classroom")` is one more node on a running
simulated classroom (`appsim classroom --serve`), over a local socket on 127.0.0.1, found through a private registry.

Both ends of that socket are here: where a served classroom is announced (a file per classroom, readable by its user
only, with the port and a secret token), the messages, and `AppsimBus`, the python-can side. It imports only the
standard library and python-can, so `import can` with this plugin stays light (docs/pythoncan.md).
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import socket
import struct
import sys
import tempfile
import threading
import time
import weakref
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import can

log = logging.getLogger("can.appsim")

PROTOCOL = 1
HOST = "127.0.0.1"                  # a served classroom listens here only: nothing leaves the machine
DEFAULT_CHANNEL = "classroom"
CHANNEL_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
HELLO_LIMIT = 4096                  # bytes of the JSON line that opens a connection, each way
CONNECT_TIMEOUT_S = 5.0
LOCAL_QUEUE = 4096                  # messages a client holds for its program before it drops (and counts) the newest

# Messages after the hello: fixed-size records, little-endian. To the classroom: kind, flags, identifier, DLC, data.
TO_CLASSROOM = struct.Struct("<BBIB8s")
SEND, FLUSH = 1, 2
# From the classroom: the same, and the simulated time (seconds since the boards' reset) it happened.
FROM_CLASSROOM = struct.Struct("<BBIB8sd")
FRAME, SENT, ERROR, STATE, LOST, REFUSED, ABORTED = range(1, 8)
EXTENDED, REMOTE = 0x01, 0x02       # flags
ACTIVE, PASSIVE, BUS_OFF = 0, 1, 2  # STATE: data[0]; identifier = TEC | REC << 16

# Error frames as Linux SocketCAN reports them (linux/can/error.h), as python-can's socketcan interface passes them on:
# the error class in the identifier, the details in the 8 data bytes (controller status, protocol error, TEC, REC).
CAN_ERR_LOSTARB, CAN_ERR_CRTL, CAN_ERR_PROT, CAN_ERR_ACK = 0x002, 0x004, 0x008, 0x020
CAN_ERR_BUSOFF, CAN_ERR_BUSERROR, CAN_ERR_RESTARTED, CAN_ERR_CNT = 0x040, 0x080, 0x100, 0x200
CAN_ERR_CRTL_RX_WARNING, CAN_ERR_CRTL_TX_WARNING = 0x04, 0x08
CAN_ERR_CRTL_RX_PASSIVE, CAN_ERR_CRTL_TX_PASSIVE, CAN_ERR_CRTL_ACTIVE = 0x10, 0x20, 0x40
CAN_ERR_PROT_BIT, CAN_ERR_PROT_FORM, CAN_ERR_PROT_STUFF, CAN_ERR_PROT_TX = 0x01, 0x02, 0x04, 0x80
CAN_ERR_PROT_LOC_CRC_SEQ, CAN_ERR_PROT_LOC_ACK = 0x08, 0x19

REFUSALS = (
    "a flag byte with bits other than extended (0x01) and remote (0x02)",
    "an identifier too wide for its frame (11 bits standard, 29 bits extended)",
    "a DLC above 15 (it is a 4-bit field)",
    "a remote frame (RTR) with data",
    "data bytes after its DLC",
    "a record of an unknown kind",
    "a frame from a node in Listen-only mode (it never sends)",
)


class ChannelError(can.CanInitializationError, ValueError):
    """A channel that cannot name a served classroom."""


def check_channel(channel: object) -> str:
    """`channel` as a classroom's name: letters, digits, '.', '_', '-', at most 64, starting with a letter or digit."""
    if not isinstance(channel, str) or not CHANNEL_NAME.fullmatch(channel):
        raise ChannelError(f"appsim: the channel names a served classroom: letters, digits, '.', '_' or '-' (at most "
                           f"64, e.g. {DEFAULT_CHANNEL!r}, as in appsim classroom --serve {DEFAULT_CHANNEL}); "
                           f"got {channel!r}")
    return channel


# ---------------------------------------------------------------------------------------------------- the registry
def runtime_folder() -> Path:
    """Where this user's served classrooms are announced: $XDG_RUNTIME_DIR/appsim (Linux's private runtime folder),
    else appsim-UID in the temporary folder (macOS), else %LOCALAPPDATA%\\appsim\\run (Windows). It is made readable
    by its owner only; one that someone else owns, or that others can read, is refused."""
    if sys.platform == "win32":
        return Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local") / "appsim" / "run"
    xdg = os.environ.get("XDG_RUNTIME_DIR")
    if xdg and Path(xdg).is_dir() and os.stat(xdg).st_uid == os.getuid():
        return Path(xdg) / "appsim"
    return Path(tempfile.gettempdir()) / f"appsim-{os.getuid()}"


def _private_folder(make: bool) -> Path:
    folder = runtime_folder()
    if make:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    if sys.platform != "win32" and folder.exists():
        info = os.lstat(folder)
        if not os.path.isdir(folder) or os.path.islink(folder) or info.st_uid != os.getuid() or info.st_mode & 0o077:
            raise can.CanInitializationError(
                f"appsim: {folder} is where your served classrooms are announced, but it is not a folder of yours "
                "that only you can read (another user made it, or its permissions let others in): remove it, or set "
                "XDG_RUNTIME_DIR to a private folder of yours")
    return folder


def announcement(channel: str) -> Path:
    """The file that announces the classroom served as `channel`."""
    return _private_folder(make=False) / f"{check_channel(channel)}.json"


def announce(channel: str, port: int, token: str, what: str) -> Path:
    """Write the file that tells this user's python-can programs where the classroom `channel` listens (readable by the
    user only, written whole). A classroom still served under that name is an error that says so."""
    path = _private_folder(make=True) / f"{check_channel(channel)}.json"
    current = read_announcement(path)
    if current is not None and _alive(current):
        raise can.CanInitializationError(
            f"appsim: a classroom is already served as {channel!r} (process {current.get('pid')}): stop it, or give "
            f"this one another name (--serve NAME)")
    text = json.dumps({"appsim": PROTOCOL, "host": HOST, "port": port, "token": token, "pid": os.getpid(),
                       "what": what, "started": time.time()})
    temporary = path.with_name(f".{path.name}.{os.getpid()}")
    descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "w", encoding="utf-8") as file:
        file.write(text)
    os.replace(temporary, path)
    return path


def withdraw(path: Path, token: str) -> None:
    """Remove the announcement at `path` if it is still this classroom's (same token)."""
    current = read_announcement(path)
    if current is not None and current.get("token") == token:
        with contextlib.suppress(OSError):
            path.unlink()


def read_announcement(path: Path) -> dict[str, Any] | None:
    """What an announcement says, if it is one (None for a missing, unreadable or foreign file)."""
    try:
        if path.stat().st_size > HELLO_LIMIT:
            return None
        found = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(found, dict) or found.get("appsim") != PROTOCOL or found.get("host") != HOST \
            or not isinstance(found.get("port"), int) or not isinstance(found.get("token"), str):
        return None
    return found


def _alive(found: dict[str, Any]) -> bool:
    """Whether the classroom an announcement names still listens."""
    try:
        with socket.create_connection((HOST, found["port"]), timeout=1.0):
            return True
    except OSError:
        return False


def served() -> list[str]:
    """The channels of this user's classrooms announced now (some may have ended without withdrawing)."""
    try:
        folder = _private_folder(make=False)
        return sorted(path.stem for path in folder.glob("*.json") if CHANNEL_NAME.fullmatch(path.stem))
    except (OSError, can.CanInitializationError):
        return []


# ---------------------------------------------------------------------------------------------------- the records
def refusal(flags: int, can_id: int, dlc: int, data: bytes, kind: int = SEND, *,
            listen_only: bool = False) -> str | None:
    """Why the classroom refuses a frame record (one of `REFUSALS`), or None if it carries a frame CAN can send."""
    if kind != SEND:
        return REFUSALS[5]
    if listen_only:
        return REFUSALS[6]
    if flags & ~(EXTENDED | REMOTE):
        return REFUSALS[0]
    if can_id > (0x1FFF_FFFF if flags & EXTENDED else 0x7FF):
        return REFUSALS[1]
    if dlc > 15:
        return REFUSALS[2]
    if flags & REMOTE and any(data):
        return REFUSALS[3]
    if any(data[min(dlc, 8):]):
        return REFUSALS[4]
    return None


def _reader(ref: weakref.ref[AppsimBus], sock: socket.socket) -> None:
    """The bus's reader thread: what the classroom sends, taken into the bus while there is one. Between reads it holds
    only a weak reference, so a bus dropped without `shutdown()` (a notebook cell run again) is collected, and shut
    down, as python-can's own buses are."""
    pending = b""
    why = "the classroom ended (appsim stopped serving it)"
    try:
        while chunk := sock.recv(65536):
            pending += chunk
            whole = len(pending) - len(pending) % FROM_CLASSROOM.size
            bus = ref()
            if bus is None:
                return
            bus._took(pending[:whole])
            del bus
            pending = pending[whole:]
    except OSError as error:
        why = f"the connection to the classroom broke ({error})"
    bus = ref()
    if bus is not None:
        bus._end(why)


def _deadline(timeout: float | None, what: str) -> float | None:
    """When a wait of `timeout` seconds (None: for ever) ends, on time.monotonic()'s clock."""
    if timeout is None or timeout >= threading.TIMEOUT_MAX:          # math.inf: for ever, as asked
        return None
    if timeout != timeout:
        raise ValueError(f"appsim: {what}'s timeout is a number of seconds (or None: wait for ever), not NaN")
    return time.monotonic() + timeout


def _record(message: can.Message) -> bytes:
    """The record that sends `message`; a ValueError that says what CAN cannot carry."""
    if not isinstance(message, can.Message):
        raise TypeError(f"appsim: send takes a can.Message, not {type(message).__name__}: "
                        "bus.send(can.Message(arbitration_id=0x123, data=[1, 2]))")
    if message.is_error_frame:
        raise ValueError("appsim: a program cannot send an error frame; CAN controllers send them when they see errors")
    if message.is_fd:
        raise ValueError("appsim: the classroom's bus is classic CAN 2.0B (the PIC18F8680's ECAN): no CAN FD frames")
    can_id, dlc = int(message.arbitration_id), int(message.dlc)
    extended, remote = bool(message.is_extended_id), bool(message.is_remote_frame)
    if not 0 <= can_id <= (0x1FFF_FFFF if extended else 0x7FF):
        raise ValueError(f"appsim: identifier 0x{can_id:X} does not fit a {'29' if extended else '11'}-bit "
                         f"{'extended' if extended else 'standard'} frame"
                         + ("" if extended else " (is_extended_id=True for 29 bits)"))
    if not 0 <= dlc <= 8:
        raise ValueError(f"appsim: a classic CAN frame carries 0..8 data bytes; this one's DLC is {dlc}")
    data = b"" if remote else bytes(message.data)
    if not remote and len(data) != dlc:
        raise ValueError(f"appsim: the message has {len(data)} data bytes but DLC {dlc}")
    return TO_CLASSROOM.pack(SEND, (EXTENDED if extended else 0) | (REMOTE if remote else 0), can_id, dlc,
                             data.ljust(8, b"\0"))


# ---------------------------------------------------------------------------------------------------- the client
class AppsimBus(can.BusABC):
    """A node on a served simulated classroom (`appsim classroom --serve CHANNEL`), found by its `channel`.

    Its frames contend for the simulated bus at its bit rate, are ACKed by the nodes there (or not), can lose
    arbitration and fail with errors; it receives every frame that goes through, and, with `error_frames`, an error
    frame (as SocketCAN reports them) for each error it sees, and its error state is `state` (`tec`, `rec`).
    `receive_own_messages`: its own frames come back once they went through (`is_rx` False). `listen_only`: it never
    ACKs or sends, as a CAN controller in Listen-only mode. `name`: its name in the classroom's trace.
    """

    def __init__(self, channel: str = DEFAULT_CHANNEL, can_filters: can.typechecking.CanFilters | None = None, *,
                 receive_own_messages: bool = False, error_frames: bool = True, listen_only: bool = False,
                 name: str | None = None, bitrate: int | None = None, timeout: float = CONNECT_TIMEOUT_S,
                 **kwargs: object):
        self.channel = check_channel(channel)
        self.channel_info = f"appsim classroom {self.channel!r}"
        self.receive_own_messages = receive_own_messages
        self.error_frames = error_frames
        self.listen_only = bool(listen_only)
        self._sock = self._connect(timeout, name, listen_only)
        welcome = self._hello
        self.node: str = welcome["node"]
        self.bit_rate: int = welcome["bit_rate"]
        self.tx_queue: int = welcome["tx_queue"]
        self.channel_info = f"appsim classroom {self.channel!r} ({welcome.get('what', '')}), node {self.node}"
        if bitrate is not None and bitrate != self.bit_rate:
            self._sock.close()
            raise can.CanInitializationError(
                f"appsim: the classroom {self.channel!r} runs at {self.bit_rate} bit/s; a node at bitrate={bitrate} "
                "would see only errors there: leave bitrate out, or give the classroom's")
        self.tec = self.rec = 0
        self._state = ACTIVE
        self.lost_in_classroom = 0      # frames for this node the classroom dropped: it did not read them in time
        self.lost_here = 0              # ... that arrived here while LOCAL_QUEUE messages waited for the program
        self.refused: list[str] = []
        self._outstanding = 0           # frames sent that the classroom has not finished with (at most tx_queue)
        self._received: deque[can.Message] = deque()
        self._ended: str | None = None
        self._lock = threading.Condition()
        self._send_lock = threading.Lock()
        self._reader = threading.Thread(target=_reader, args=(weakref.ref(self), self._sock),
                                        name=f"appsim-{self.channel}", daemon=True)
        self._reader.start()
        super().__init__(channel, can_filters=can_filters, **kwargs)

    # ------------------------------------------------------------------ connecting
    def _connect(self, timeout: float, name: str | None, listen_only: bool) -> socket.socket:
        """The connection, once the classroom has welcomed this node; a classroom busy with other programs' hellos
        (it says to come again) is asked again until `timeout` has passed."""
        deadline = time.monotonic() + timeout
        while True:
            sock, answer = self._knock(max(deadline - time.monotonic(), 0.1), name, listen_only)
            if answer.get("ok"):
                break
            sock.close()
            if not (answer.get("again") is True and time.monotonic() < deadline):
                raise can.CanInitializationError(
                    f"appsim: the classroom {self.channel!r} refused this node: {answer.get('error')}")
            time.sleep(0.05)
        sock.settimeout(None)
        self._hello: dict[str, Any] = answer
        return sock

    def _knock(self, timeout: float, name: str | None, listen_only: bool) -> tuple[socket.socket, dict[str, Any]]:
        """Connect and say hello: the socket and the classroom's answer (a dict)."""
        path = announcement(self.channel)
        found = read_announcement(path)
        if found is None:
            others = [c for c in served() if c != self.channel]
            hint = f" (served now: {', '.join(others)})" if others else ""
            raise can.CanInitializationError(
                f"appsim: no classroom is served as {self.channel!r} for this user{hint}: start one with "
                f"`appsim classroom --serve {self.channel}` and keep it running, then connect again")
        try:
            sock = socket.create_connection((HOST, found["port"]), timeout=timeout)
        except OSError as error:
            raise can.CanInitializationError(
                f"appsim: the classroom served as {self.channel!r} (process {found.get('pid')}) is not running any "
                f"more ({error.strerror or error}): start it again with `appsim classroom --serve {self.channel}`") \
                from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        hello = {"appsim": PROTOCOL, "token": found["token"], "name": name, "listen_only": bool(listen_only)}
        try:
            sock.sendall(json.dumps(hello).encode() + b"\n")
            answer = json.loads(self._line(sock))
        except (OSError, ValueError) as error:
            sock.close()
            raise can.CanInitializationError(
                f"appsim: the classroom served as {self.channel!r} did not answer as an appsim classroom does "
                f"({error}): is another program using its port? Start it again") from None
        if not isinstance(answer, dict):
            sock.close()
            raise can.CanInitializationError(
                f"appsim: the classroom served as {self.channel!r} did not answer as an appsim classroom does: "
                "is another program using its port? Start it again")
        return sock, answer

    @staticmethod
    def _line(sock: socket.socket) -> bytes:
        """One line of the hello, byte by byte (what follows it belongs to the reader)."""
        line = bytearray()
        while not line.endswith(b"\n"):
            byte = sock.recv(1)
            if not byte:
                raise OSError("it closed the connection")
            line += byte
            if len(line) > HELLO_LIMIT:
                raise ValueError("its answer is too long")
        return bytes(line)

    # ------------------------------------------------------------------ the reader thread (see `_reader`)
    def _took(self, records: bytes) -> None:
        with self._lock:
            for record in FROM_CLASSROOM.iter_unpack(records):
                self._take(*record)
            self._lock.notify_all()

    def _end(self, why: str) -> None:
        with self._lock:
            self._ended = self._ended or why
            self._lock.notify_all()

    def _take(self, kind: int, flags: int, can_id: int, dlc: int, data: bytes, stamp: float) -> None:
        if kind in (FRAME, SENT):
            if kind == SENT:
                self._outstanding = max(0, self._outstanding - 1)
                if not self.receive_own_messages:
                    return
            remote = bool(flags & REMOTE)
            self._keep(can.Message(timestamp=stamp, arbitration_id=can_id, is_extended_id=bool(flags & EXTENDED),
                                   is_remote_frame=remote, dlc=dlc, data=b"" if remote else data[:min(dlc, 8)],
                                   channel=self.channel, is_rx=kind == FRAME))
        elif kind == ERROR:
            if self.error_frames:
                self._keep(can.Message(timestamp=stamp, arbitration_id=can_id, is_error_frame=True, dlc=8, data=data,
                                       channel=self.channel))
        elif kind == STATE:
            self.tec, self.rec, self._state = can_id & 0xFFFF, can_id >> 16, data[0]
        elif kind == LOST:
            self.lost_in_classroom += can_id
            log.warning("%s: the classroom dropped %d frames for this node: the program did not read them in time "
                        "(%d in all)", self.channel_info, can_id, self.lost_in_classroom)
        elif kind in (REFUSED, ABORTED):
            self._outstanding = max(0, self._outstanding - can_id)
            if kind == REFUSED:
                self.refused.append(REFUSALS[min(data[0], len(REFUSALS) - 1)])

    def _keep(self, message: can.Message) -> None:
        if len(self._received) >= LOCAL_QUEUE:
            self.lost_here += 1
            if self.lost_here in (1, 10, 100) or self.lost_here % 1000 == 0:
                log.warning("%s: %d messages waited for the program, which did not read them: %d dropped so far",
                            self.channel_info, LOCAL_QUEUE, self.lost_here)
            return
        self._received.append(message)

    # ------------------------------------------------------------------ python-can's side
    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = _deadline(timeout, "recv")
        with self._lock:
            if self._is_shutdown:
                raise can.CanOperationError(f"appsim: {self.channel_info}: {self._ended}")
            while not self._received:
                if self._ended is not None:
                    raise can.CanOperationError(f"appsim: {self.channel_info}: {self._ended}")
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return None, False
                self._lock.wait(left)
            return self._received.popleft(), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Queue `msg` for the simulated bus; it waits there (`tx_queue` frames at most) until it wins arbitration and
        goes through. With the queue full, wait up to `timeout` seconds (None: as long as it takes), then raise."""
        if self.listen_only:
            raise can.CanOperationError(f"appsim: {self.channel_info} is in Listen-only mode: it never sends (open "
                                        "the bus without listen_only=True to send)")
        record = _record(msg)
        deadline = _deadline(timeout, "send")
        with self._lock:
            while self._outstanding >= self.tx_queue:
                if self._ended is not None:
                    break
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise can.CanOperationError(
                        f"appsim: {self.channel_info}: its transmit queue of {self.tx_queue} frames is full: the "
                        f"frames before it have not gone through (the bus is busy, nobody ACKs, or this node is "
                        f"{self.state_words}); wait, or send with a longer timeout")
                self._lock.wait(left)
            if self._ended is not None:
                raise can.CanOperationError(f"appsim: {self.channel_info}: {self._ended}")
            self._outstanding += 1
        self._send(record)

    def flush_tx_buffer(self) -> None:
        """Take the frames still waiting in this node's transmit queue off it (the one on the wire finishes)."""
        with self._lock:
            if self._ended is not None:
                raise can.CanOperationError(f"appsim: {self.channel_info}: {self._ended}")
        self._send(TO_CLASSROOM.pack(FLUSH, 0, 0, 0, bytes(8)))

    def _send(self, record: bytes) -> None:
        try:
            with self._send_lock:
                self._sock.sendall(record)
        except OSError as error:
            raise can.CanOperationError(f"appsim: {self.channel_info}: {self._ended or f'could not send: {error}'}") \
                from None

    @property
    def state(self) -> can.BusState:
        """ACTIVE (error-active), PASSIVE (error-passive: TEC or REC above 127) or ERROR (bus-off: TEC above 255)."""
        return {ACTIVE: can.BusState.ACTIVE, PASSIVE: can.BusState.PASSIVE}.get(self._state, can.BusState.ERROR)

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        raise NotImplementedError("appsim: a node's error state follows its error counters; for a node that only "
                                  "listens, open the bus with listen_only=True")

    @property
    def state_words(self) -> str:
        return ("error-active", "error-passive", "bus-off")[min(self._state, 2)]

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        self._end("this bus was shut down")
        super().shutdown()
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
        if self._reader is not threading.current_thread():
            self._reader.join(timeout=2.0)

    @staticmethod
    def _detect_available_configs() -> Sequence[can.typechecking.AutoDetectedConfig]:
        return [{"interface": "appsim", "channel": channel} for channel in served()]
