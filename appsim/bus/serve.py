"""The simulated bus served to python-can programs on this machine (`appsim.can.pythoncan`, interface "appsim"): each
program is one more node, a CAN controller of its own with its error counters, on a local socket on 127.0.0.1.

Every byte a program sends is hostile until shown otherwise: hellos are bounded and timed, records are checked, each
program's queues are bounded both ways, and what cannot be kept is counted, told to the program and in `report()`.
"""
from __future__ import annotations

import contextlib
import hmac
import json
import logging
import re
import secrets
import select
import selectors
import socket
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from appsim.bus.bitlevel import Assembled
from appsim.bus.controller import ErrorCounters, Mode, Wire
from appsim.bus.wire import Bus, BusEvent
from appsim.can import pythoncan as P
from appsim.can.bittiming import BitTiming
from appsim.can.frame import CanFrame
from appsim.sim import PS_PER_SECOND

log = logging.getLogger(__name__)

MAX_CLIENTS = 256               # programs on one classroom at once; the next is told the classroom is full
TX_QUEUE = 64                   # a program's frames waiting for the bus, as the link's queue (70 ms of the bus)
RX_QUEUE = 1024                 # frames and error frames waiting for a program to read them: then they are dropped
ACCEPT_PER_POLL = 32            # connections taken per poll, so a storm of them cannot stall the simulation
SEND_BUFFER = 16 * 1024         # the kernel's buffer towards a program (700 frames): what it holds stays small too
READ_BYTES = 64 * 1024          # read from one program per poll at most
_REPLIES = frozenset((P.SENT, P.REFUSED, P.ABORTED))     # records that answer what a program sent
HELD_LOOK_S = 0.1               # how often a program not read now is looked at (has it closed its end?)
WRITE_AGAIN_S = 0.005           # a program whose socket is full is not written to again before then
CLOSE_S = 1.0                   # what a classroom that ends still sends its programs, to all of them at most
HELLO_TIMEOUT_S = 5.0           # a program that connects and does not say who it is is shown the door
GREETING = 64                   # connections at once that have not said hello yet; the next is told to come again
TOLD_PER_CLIENT = 20            # programs listed by name in the report; the rest are added up
# A node of this kind: 16 TQ a bit, sampled at 75 %, as the classroom's ECANs (brp 1, so Fosc is 32 x the bit rate).
TIMING = BitTiming(brp=1, prseg=5, seg1ph=6, seg2ph=4, sjw=4)
NODE_NAME = re.compile(r"[^A-Za-z0-9_-]")
ERROR_WORDS = (("ACK error", 0), ("bit error", P.CAN_ERR_PROT_BIT), ("stuff error", P.CAN_ERR_PROT_STUFF),
               ("form error", P.CAN_ERR_PROT_FORM), ("CRC error", 0))


class ClientNode(ErrorCounters):
    """A python-can program's CAN controller on the simulated bus: a transmit queue sent in order (as SocketCAN's), no
    acceptance filter, and fault confinement by ISO 11898-1 (error-active, error-passive, bus-off, and back after 128
    times 11 recessive bits). It is its own `Controller` (`appsim.bus.controller`)."""

    def __init__(self, name: str, bit_rate: int, client: Client):
        self.name = name
        self.fosc = 32 * bit_rate
        self.wire: Wire | None = None
        self.opmode = self.requested = Mode.DISABLE
        self.tec = self.rec = 0
        self.on_wire: str | None = None
        self.queue: deque[CanFrame] = deque()
        self.client = client
        self._recovery = 0

    @property
    def controller(self) -> ClientNode:
        return self

    @property
    def state(self) -> int:
        return P.BUS_OFF if self.bus_off else P.PASSIVE if self.error_passive else P.ACTIVE

    def request(self, mode: Mode) -> None:
        """Join the bus (NORMAL, LISTEN_ONLY) or leave it (DISABLE): it takes effect after 11 recessive bits."""
        self.requested = mode
        if self.wire is not None:
            self.wire.mode_requested(self)

    def transmit(self, frame: CanFrame) -> None:
        self.queue.append(frame)
        if self.wire is not None and self.opmode == Mode.NORMAL:
            self.wire.transmit_requested(self)

    # ------------------------------------------------------------------ what the wire asks and tells
    def bit_timing(self) -> BitTiming:
        return TIMING

    def enter_requested_mode(self) -> None:
        self.opmode = self.requested
        if self.opmode == Mode.LISTEN_ONLY:
            self._counters(0, 0)

    def next_transmission(self) -> str | None:
        return "TX" if self.queue and self.opmode == self.requested == Mode.NORMAL else None

    def frame_in(self, buffer: str) -> CanFrame:
        return self.queue[0]

    def transmission_started(self, buffer: str) -> None:
        self.on_wire = buffer

    def transmission_succeeded(self, buffer: str) -> None:
        self.on_wire = None
        frame = self.queue.popleft()
        self._counters(max(self.tec - 1, 0), self.rec)
        if self.requested != Mode.DISABLE:
            self.client.sent(frame)
        else:                                   # its program left while it was on the wire: told nothing, counted
            self.client.server.totals["went through"] += 1

    def arbitration_lost(self, buffer: str) -> None:
        self.on_wire = None
        if self.requested != Mode.DISABLE:
            self.client.error(P.CAN_ERR_LOSTARB, 0, 0)
        else:
            self._left_unsent()

    def transmission_failed(self, buffer: str, *, tec_increment: int = 8) -> None:
        self.on_wire = None
        self._counters(self.tec + tec_increment, self.rec)
        if self.requested == Mode.DISABLE:
            self._left_unsent()

    def _left_unsent(self) -> None:
        """The frame its program left on the wire did not go through, and never will: it is not sent again."""
        self.client.server.totals["frames it left before they went through"] += 1

    def frame_received(self, frame: CanFrame) -> str:
        if self.rec:
            self._counters(self.tec, self.rec - 1 if self.rec <= 127 else 119)
        return self.client.received(frame)

    def receive_error(self, *, rec_increment: int = 1, assembled: Assembled | None = None,
                      acknowledged: bool = False) -> None:
        rec = self.rec
        if acknowledged and rec:            # rule 8 first, as frame_received counts it
            rec = rec - 1 if rec <= 127 else 119
        self._counters(self.tec, min(rec + rec_increment, 255))

    def bus_activity(self) -> None: ...

    def bus_off_recovery(self, sequences: int) -> None:
        if not self.bus_off:
            return
        self._recovery += sequences
        if self._recovery >= 128:
            self._recovery = 0
            self._counters(0, 0)
            self.client.error(P.CAN_ERR_RESTARTED, 0, 0)
            if self.queue and self.wire is not None:
                self.wire.transmit_requested(self)

    def _counters(self, tec: int, rec: int) -> None:
        self.tec, self.rec = tec, rec
        self.client.state_changed()


def controller_status(node: ClientNode) -> int:
    """SocketCAN's controller-status byte for the node's counters (data[1] of an error frame)."""
    status = 0
    if node.tec > 127:
        status |= P.CAN_ERR_CRTL_TX_PASSIVE
    elif node.tec > 95:
        status |= P.CAN_ERR_CRTL_TX_WARNING
    if node.rec > 127:
        status |= P.CAN_ERR_CRTL_RX_PASSIVE
    elif node.rec > 95:
        status |= P.CAN_ERR_CRTL_RX_WARNING
    return status or P.CAN_ERR_CRTL_ACTIVE


def _refusal(why: str, *, again: bool = False) -> bytes:
    """The line that turns a program away, with why (and, with `again`, that it may come again soon)."""
    answer: dict[str, object] = {"appsim": P.PROTOCOL, "ok": False, "error": why}
    if again:
        answer["again"] = True
    return json.dumps(answer).encode() + b"\n"


@dataclass
class Client:
    """One connected program: its socket, its node once it has said hello, its queues and its account."""

    server: ClassroomServer
    sock: socket.socket
    peer: str
    since: float = field(default_factory=time.monotonic)
    node: ClientNode | None = None
    inbox: bytes = b""                  # bytes read and not yet a whole hello or record
    outbox: bytearray = field(default_factory=bytearray)    # bytes for the program, of whole records
    records: deque[bytes] = field(default_factory=deque)    # what waits for room in outbox, in the bus's order
    frames_waiting: int = 0             # ... of them frames and error frames: past rx_queue the newest are dropped
    replies_waiting: int = 0            # ... of them SENT, REFUSED, ABORTED: never dropped; the program is not read
                                        # while tx_queue of them wait (it does not read its replies)
    frames_in: int = 0                  # frames the program sent
    delivered: int = 0                  # ... that went through on the bus
    refused: Counter[str] = field(default_factory=Counter)
    aborted: int = 0                    # ... taken off its queue by flush_tx_buffer()
    frames_out: int = 0                 # frames and error frames for it
    dropped: int = 0                    # ... dropped: it did not read them in time
    dropped_untold: int = 0
    state_due: bool = False
    closing: str = ""                   # why it is being shown the door, "" while it is welcome
    held: bool = False                  # not read now (no room for what it sends): out of the selector meanwhile
    looked_at: float = 0.0              # when a held program was last seen to be still there
    write_again_at: float = 0.0         # its socket was full: not tried again before then

    @property
    def name(self) -> str:
        return self.node.name if self.node is not None else self.peer

    # ------------------------------------------------------------------ events of its node
    def received(self, frame: CanFrame) -> str:
        return "to the program" if self._queue(self._pack(P.FRAME, frame)) else "dropped: the program did not read"

    def sent(self, frame: CanFrame) -> None:
        self.delivered += 1
        self.reply(self._pack(P.SENT, frame))

    def reply(self, record: bytes) -> None:
        """SENT, REFUSED or ABORTED: kept in order with the frames (its own frame comes back where the bus carried it),
        never dropped."""
        self.replies_waiting += 1
        self.records.append(record)

    def state_changed(self) -> None:
        self.state_due = True

    def error(self, error_class: int, protocol: int, location: int) -> None:
        node = self.node
        assert node is not None
        data = bytes((0, controller_status(node), protocol, location, 0, 0, min(node.tec, 255), node.rec))
        cls = error_class | P.CAN_ERR_CNT | (P.CAN_ERR_BUSOFF if node.bus_off else 0) | \
            (P.CAN_ERR_CRTL if node.error_passive else 0)
        self._queue(P.FROM_CLASSROOM.pack(P.ERROR, 0, cls, 8, data, self._now()))

    def _pack(self, kind: int, frame: CanFrame) -> bytes:
        flags = (P.EXTENDED if frame.extended else 0) | (P.REMOTE if frame.remote else 0)
        return P.FROM_CLASSROOM.pack(kind, flags, frame.can_id, frame.dlc, frame.data.ljust(8, b"\0"), self._now())

    def _now(self) -> float:
        return self.server.bus.sim.now / PS_PER_SECOND

    def _queue(self, record: bytes) -> bool:
        """Keep a frame or error frame for the program, if its queue has room; else count it dropped."""
        self.frames_out += 1
        if self.frames_waiting >= self.server.rx_queue:
            self.dropped += 1
            self.dropped_untold += 1
            return False
        self.frames_waiting += 1
        self.records.append(record)
        return True

    # ------------------------------------------------------------------ the socket
    def fill_outbox(self) -> None:
        """Move what waits into the bytes to send, in order; the state and the drops told when they changed."""
        limit = 64 * P.FROM_CLASSROOM.size
        node = self.node
        if node is not None and self.state_due and len(self.outbox) < limit:     # one, the latest, when room
            self.state_due = False
            self.outbox += P.FROM_CLASSROOM.pack(P.STATE, 0, node.tec | node.rec << 16, 1,
                                                 bytes((node.state,)).ljust(8, b"\0"), self._now())
        if self.dropped_untold and len(self.outbox) < limit:
            self.outbox += P.FROM_CLASSROOM.pack(P.LOST, 0, self.dropped_untold, 0, bytes(8), self._now())
            self.dropped_untold = 0
        while self.records and len(self.outbox) < limit:
            record = self.records.popleft()
            if record[0] in _REPLIES:
                self.replies_waiting -= 1
            else:
                self.frames_waiting -= 1
            self.outbox += record


class ClassroomServer:
    """Serves `bus` to python-can programs of this user as `channel` (see `appsim.can.pythoncan`): it listens on
    127.0.0.1 at a port the system picks and announces it, with a secret token, in the user's private registry.

    Call `poll()` often (a `WallClock` does, between slices): it takes new programs, reads their frames into their
    nodes' queues and sends them what their nodes received, in the bus's order (its own frames where the bus carried
    them). A program whose transmit queue is full is not read until there is room again (its own `send` waits or says
    the queue is full), nor one that leaves `tx_queue` answers to its frames unread; one that does not read loses the
    newest frames past `rx_queue`, counted and told to it. `report()` accounts for every program and frame."""

    def __init__(self, bus: Bus, channel: str = P.DEFAULT_CHANNEL, *, what: str = "",
                 max_clients: int = MAX_CLIENTS, tx_queue: int = TX_QUEUE, rx_queue: int = RX_QUEUE):
        self.bus = bus
        self.channel = P.check_channel(channel)
        self.what = what or f"a simulated bus at {bus.bit_rate // 1000} kbit/s"
        self.max_clients, self.tx_queue, self.rx_queue = max_clients, tx_queue, rx_queue
        self.token = secrets.token_hex(16)
        self.clients: list[Client] = []
        self.gone: list[Client] = []        # programs that left, for the report (the last TOLD_PER_CLIENT kept whole)
        self.gone_count = 0
        self.totals: Counter[str] = Counter()
        self.turned_away: Counter[str] = Counter()
        self.accept_failures: Counter[str] = Counter()   # why accept() failed -> how many times (not programs)
        self._free: list[ClientNode] = []   # nodes of programs that left, reused by the next (the bus only grows so)
        self._numbers = 0
        self._selector = selectors.DefaultSelector()
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((P.HOST, 0))
        self._listener.listen(max_clients)
        self._listener.setblocking(False)
        self.port: int = self._listener.getsockname()[1]
        try:
            self.announcement = P.announce(self.channel, self.port, self.token, self.what)
        except BaseException:
            self._listener.close()
            raise
        self._selector.register(self._listener, selectors.EVENT_READ, None)
        bus.trace.listeners.append(self._event)

    @property
    def how_to_join(self) -> str:
        return (f"serving it to python-can as channel {self.channel!r} on {P.HOST}:{self.port} (this user only): "
                f"can.Bus(interface='appsim', channel='{self.channel}'), or python -m can.viewer -i appsim "
                f"-c {self.channel}")

    # ------------------------------------------------------------------ between slices
    def poll(self) -> None:
        """Take new programs, read what they sent, send what waits for them. Never raises for a program's doing."""
        for key, _ in self._selector.select(0):
            if key.data is None:
                self._accept()
            else:
                self._guarded(self._read, key.data)
        now = time.monotonic()
        for client in list(self.clients):
            if client.node is None and not client.closing and now - client.since > HELLO_TIMEOUT_S:
                self._refuse(client, f"it did not say who it is within {HELLO_TIMEOUT_S:g} s")
            elif client.held:
                self._guarded(self._room_again, client)
            elif client.node is not None and len(client.inbox) >= P.TO_CLASSROOM.size and not client.closing:
                self._guarded(self._records, client)        # what it sent before there was room for it
            if now >= client.write_again_at:
                self._guarded(self._write, client)

    def _guarded(self, step: Callable[[Client], None], client: Client) -> None:
        """A step of one program's, which must not end the classroom for the others whatever the program sent: should
        the classroom fail on it, that program alone is shown the door, and the failure is logged for appsim's
        authors."""
        try:
            step(client)
        except Exception as error:
            log.exception("the classroom failed on what %s sent", client.name)
            self.totals["failed on a program"] += 1
            self._left(client, f"the classroom failed on what it sent ({type(error).__name__}: {error}): a fault of "
                               "appsim's, please report it")

    def _accept(self) -> None:
        for _ in range(ACCEPT_PER_POLL):
            try:
                sock, peer = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as error:            # out of file descriptors, say: the others go on, it is tried again
                self.accept_failures[error.strerror or str(error)] += 1
                return
            sock.setblocking(False)
            if sum(c.node is None and not c.closing for c in self.clients) >= GREETING:
                self._turn_away_now(sock, f"{GREETING} connections were waiting to say hello already: connect "
                                          "again in a few seconds")     # appsim's python-can interface does
                continue
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER)
            client = Client(self, sock, f"{peer[0]}:{peer[1]}")
            self.clients.append(client)
            self._selector.register(sock, selectors.EVENT_READ, client)

    def _read(self, client: Client) -> None:
        if client.closing:
            self._drain(client)
            return
        room = P.HELLO_LIMIT + 1 - len(client.inbox)        # before its hello: the hello, at most
        if client.node is not None:
            space = self._room(client)
            if space <= 0:      # read again once the bus has taken some, or the program has read its replies
                self._hold(client)
                return
            room = space * P.TO_CLASSROOM.size - len(client.inbox)
            if room <= 0:                       # its inbox holds that many records already
                self._records(client)
                return
        try:
            chunk = client.sock.recv(max(room, 1))
        except (BlockingIOError, InterruptedError):
            return
        except OSError as error:
            self._left(client, f"its connection broke ({error.strerror or error})")
            return
        if not chunk:
            self._left(client, "")
            return
        client.inbox += chunk
        if client.node is None:
            self._hello(client)
        else:
            self._records(client)

    def _room(self, client: Client) -> int:
        """Records the program may still send: its node's queue holds `tx_queue` frames, and `tx_queue` answers at
        most wait for it."""
        assert client.node is not None
        return self.tx_queue - max(len(client.node.queue), client.replies_waiting)

    def _hold(self, client: Client) -> None:
        """A program not read now is out of the selector (so that what waits in its socket costs nothing at each
        poll) until there is room again; meanwhile it is looked at now and then."""
        self._selector.unregister(client.sock)
        client.held, client.looked_at = True, time.monotonic()

    def _room_again(self, client: Client) -> None:
        if self._room(client) > 0:
            self._selector.register(client.sock, selectors.EVENT_READ, client)
            client.held = False
            self._read(client)
        elif time.monotonic() - client.looked_at >= HELD_LOOK_S:
            client.looked_at = time.monotonic()
            self._still_there(client)

    def _still_there(self, client: Client) -> None:
        """A program not read now (its queue is full) that has closed its end leaves all the same."""
        try:
            if not client.sock.recv(1, socket.MSG_PEEK):
                self._left(client, "")
        except (BlockingIOError, InterruptedError):
            pass
        except OSError as error:
            self._left(client, f"its connection broke ({error.strerror or error})")

    def _drain(self, client: Client) -> None:
        """A program being shown the door: what it still sends is read and ignored until it closes."""
        try:
            if not client.sock.recv(READ_BYTES):
                self._left(client, "")
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self._left(client, "")

    def _hello(self, client: Client) -> None:
        line, newline, rest = client.inbox.partition(b"\n")
        if len(line) > P.HELLO_LIMIT:
            self._refuse(client, f"its hello was longer than {P.HELLO_LIMIT} bytes")
            return
        if not newline:
            return
        try:
            hello = json.loads(line)
            token = hello["token"].encode()
            if hello.get("appsim") != P.PROTOCOL:
                raise ValueError
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError):   # UnicodeError is a ValueError
            self._refuse(client, "it did not open as appsim's python-can interface does (a JSON hello with the "
                                 "classroom's token): use can.Bus(interface='appsim', ...)")
            return
        if not hmac.compare_digest(token, self.token.encode()):
            self._refuse(client, "wrong token: a program may join only a classroom its own user serves")
            return
        if sum(c.node is not None for c in self.clients) >= self.max_clients:
            self._refuse(client, f"the classroom is full: {self.max_clients} python-can programs are on it already")
            return
        client.inbox = rest
        listen_only = hello.get("listen_only") is True
        self._join(client, hello.get("name"), listen_only)
        welcome = {"appsim": P.PROTOCOL, "ok": True, "node": client.name, "bit_rate": self.bus.bit_rate,
                   "tx_queue": self.tx_queue, "rx_queue": self.rx_queue, "what": self.what}
        client.outbox += json.dumps(welcome).encode() + b"\n"
        log.info("%s joined the classroom from %s%s", client.name, client.peer, " (listen-only)" if listen_only else "")
        self._records(client)

    def _join(self, client: Client, asked: object, listen_only: bool) -> None:
        name = self._name(asked)
        node = next((n for n in self._free if n.on_wire is None), None)
        if node is None:
            node = self.bus.attach(ClientNode(name, self.bus.bit_rate, client))
        else:
            self._free.remove(node)
            node.queue.clear()
            node.name, node.client, node.tec, node.rec = name, client, 0, 0
        client.node = node
        node.request(Mode.LISTEN_ONLY if listen_only else Mode.NORMAL)
        client.state_due = True

    def _name(self, asked: object) -> str:
        taken = {port.name for port in self.bus.ports}
        base = NODE_NAME.sub("", asked)[:12] if isinstance(asked, str) else ""
        if base and base not in taken:
            return base
        while True:
            self._numbers += 1
            name = f"{base or 'pycan'}{self._numbers}"
            if name not in taken:
                return name

    def _records(self, client: Client) -> None:
        node = client.node
        assert node is not None
        size = P.TO_CLASSROOM.size
        whole = min(len(client.inbox) // size, max(self._room(client), 0)) * size
        for kind, flags, can_id, dlc, data in P.TO_CLASSROOM.iter_unpack(client.inbox[:whole]):
            if kind == P.FLUSH:
                waiting = len(node.queue) - (node.on_wire is not None)
                for _ in range(waiting):
                    node.queue.pop()
                client.aborted += waiting
                client.reply(P.FROM_CLASSROOM.pack(P.ABORTED, 0, waiting, 0, bytes(8), client._now()))
                continue
            client.frames_in += 1
            why = P.refusal(flags, can_id, dlc, data, kind, listen_only=node.requested == Mode.LISTEN_ONLY)
            if why is not None:
                client.refused[why] += 1
                client.reply(P.FROM_CLASSROOM.pack(P.REFUSED, 0, 1, 0,
                                                   bytes((P.REFUSALS.index(why),)).ljust(8, b"\0"), client._now()))
                continue
            remote = bool(flags & P.REMOTE)
            node.transmit(CanFrame(can_id, b"" if remote else data[:min(dlc, 8)], extended=bool(flags & P.EXTENDED),
                                   remote=remote, dlc=dlc))
        client.inbox = client.inbox[whole:]

    def _write(self, client: Client) -> None:
        client.fill_outbox()
        if not client.outbox:
            if client.closing:
                self._left(client, client.closing)
            return
        try:
            sent = client.sock.send(client.outbox)
        except (BlockingIOError, InterruptedError):
            client.write_again_at = time.monotonic() + WRITE_AGAIN_S
            return
        except OSError as error:
            self._left(client, f"its connection broke ({error.strerror or error})")
            return
        del client.outbox[:sent]

    def _turn_away_now(self, sock: socket.socket, why: str) -> None:
        """A connection not taken now: told why (and to come again) if its socket takes the line at once, closed."""
        with contextlib.suppress(OSError):
            sock.send(_refusal(why, again=True))
        sock.close()
        self.turned_away[why] += 1

    def _refuse(self, client: Client, why: str) -> None:
        """Tell the program why it cannot join, then close (once that is sent)."""
        client.outbox = bytearray(_refusal(why))
        client.records.clear()
        client.closing = why
        self.turned_away[why] += 1
        log.warning("a program from %s was turned away: %s", client.peer, why)

    def _left(self, client: Client, why: str) -> None:
        """The program is gone (or shown the door): its node leaves the bus, its account goes to the report."""
        if client not in self.clients:
            return
        self.clients.remove(client)
        if not client.held:
            self._selector.unregister(client.sock)
        client.sock.close()
        node = client.node
        if node is None:
            return
        if client.inbox:
            self.totals["bytes of a record cut off when it left"] += len(client.inbox)
        self.totals["frames it left before they went through"] += len(node.queue) - (node.on_wire is not None)
        node.request(Mode.DISABLE)              # it sends nothing more; the frame on the wire, if any, ends
        self._free.append(node)
        self._account(client)
        log.info("%s left the classroom%s", client.name, f": {why}" if why else "")

    def _account(self, client: Client) -> None:
        self._account_into(self.totals, client)
        self.gone_count += 1
        self.gone.append(client)
        if len(self.gone) > TOLD_PER_CLIENT:
            self.gone.pop(0)

    # ------------------------------------------------------------------ error frames, as each program's node saw them
    def _event(self, event: BusEvent) -> None:
        if not event.error:
            return
        seen = dict(event.received)
        for client in self.clients:
            node = client.node
            if node is None or node.opmode not in (Mode.NORMAL, Mode.LISTEN_ONLY):
                continue
            if event.sender == node.name:       # its own error, or the error flag of another over its frame
                first = event.error.split(";")[0]
                words, transmitting = first if first.endswith(f"({node.name})") else "bit error", True
            elif node.name in seen:
                words, transmitting = seen[node.name], False
            else:
                continue
            error_class, protocol, location = P.CAN_ERR_PROT | P.CAN_ERR_BUSERROR, 0, 0
            label = min(((words.find(w), w, bits) for w, bits in ERROR_WORDS if w in words), default=None)
            if label is not None:
                protocol = label[2]
                if label[1] == "ACK error":
                    error_class |= P.CAN_ERR_ACK
                    location = P.CAN_ERR_PROT_LOC_ACK
                elif label[1] == "CRC error":
                    location = P.CAN_ERR_PROT_LOC_CRC_SEQ
            client.error(error_class, protocol | (P.CAN_ERR_PROT_TX if transmitting else 0), location)

    # ------------------------------------------------------------------ the account
    def report(self) -> str:
        """Every program that joined and what became of its frames, both ways."""
        totals = Counter(self.totals)
        for client in self.clients:
            if client.node is not None:
                self._account_into(totals, client)
        joined = self.gone_count + sum(1 for c in self.clients if c.node is not None)
        lines = [f"served as {self.channel!r} on {P.HOST}:{self.port}: {joined} python-can program(s) joined, "
                 f"{sum(1 for c in self.clients if c.node is not None)} still on; they sent "
                 f"{totals['frames from programs']} frames = {totals['went through']} went through + "
                 f"{totals['refused']} refused + {totals['taken off by flush']} taken off by flush_tx_buffer + "
                 f"{totals['frames it left before they went through']} left unsent when the program left + "
                 f"{self._waiting()} still queued; {totals['frames and error frames for programs']} frames and error "
                 f"frames for them, {totals['dropped: a program did not read them']} dropped (not read in time)"]
        for client in [*self.gone, *(c for c in self.clients if c.node is not None)][-TOLD_PER_CLIENT:]:
            if client.dropped or client.refused:
                lines.append(f"  {client.name}: {client.dropped} frames dropped (it did not read them in time)"
                             + "".join(f"; refused {n} x {why}" for why, n in client.refused.items()))
        if totals["unsent at the end: frames"] or totals["unsent at the end: bytes"]:
            lines.append(f"  when the classroom ended, {totals['unsent at the end: frames']} frames and error frames "
                         f"(and {totals['unsent at the end: bytes']} bytes on their way) had not reached programs "
                         "that were not reading")
        if totals["failed on a program"]:
            lines.append(f"  {totals['failed on a program']} programs were shown the door when the classroom failed on "
                         "what they sent (a fault of appsim's: the log says where)")
        if totals["bytes of a record cut off when it left"]:
            lines.append(f"  {totals['bytes of a record cut off when it left']} bytes of unfinished records were "
                         "dropped when programs left in the middle of one")
        lines += [f"  turned away {count} x {why}" for why, count in self.turned_away.items()]
        lines += [f"  could not take a connection ({why}): {count} tries, each poll while it lasted"
                  for why, count in self.accept_failures.items()]
        return "\n".join(lines)

    @staticmethod
    def _account_into(totals: Counter[str], client: Client) -> None:
        for what, count in (("frames from programs", client.frames_in), ("went through", client.delivered),
                            ("refused", sum(client.refused.values())), ("taken off by flush", client.aborted),
                            ("frames and error frames for programs", client.frames_out),
                            ("dropped: a program did not read them", client.dropped)):
            totals[what] += count

    def _waiting(self) -> int:
        return sum(len(c.node.queue) for c in self.clients if c.node is not None)

    def close(self) -> None:
        """Stop serving: the announcement is withdrawn, every program's connection closed (their recv then says the
        classroom ended)."""
        P.withdraw(self.announcement, self.token)
        deadline = time.monotonic() + CLOSE_S
        for client in list(self.clients):
            self._last_words(client, deadline)
            if client.frames_waiting or client.outbox:
                self.totals["unsent at the end: frames"] += client.frames_waiting
                self.totals["unsent at the end: bytes"] += len(client.outbox)
            self._left(client, "the classroom ended")
        self._selector.close()
        self._listener.close()
        if self._event in self.bus.trace.listeners:
            self.bus.trace.listeners.remove(self._event)

    @staticmethod
    def _last_words(client: Client, deadline: float) -> None:
        """What waits for the program, sent as far as it reads it by `deadline` (one for them all: a program that does
        not read holds nobody up)."""
        client.fill_outbox()
        while client.outbox and time.monotonic() < deadline:
            try:
                sent = client.sock.send(client.outbox)
            except (BlockingIOError, InterruptedError):
                select.select([], [client.sock], [], max(0.0, min(0.05, deadline - time.monotonic())))
                continue
            except OSError:
                return
            del client.outbox[:sent]
            client.fill_outbox()

    def __enter__(self) -> ClassroomServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ServedInBackground:
    """The bus `build()` makes (with what it puts on it), served as `channel` and run in real time in a thread of its
    own for `seconds` (None: until `stop()`), while the caller goes on: a notebook's cells, a test. The bus and its
    nodes are built in that thread, where their firmware runs; `server`, `bus`, and once stopped `report`."""

    def __init__(self, build: Callable[[], Bus], channel: str = P.DEFAULT_CHANNEL, *, seconds: float | None = None,
                 what: str = "", **options: Any):
        self.channel, self.seconds = channel, seconds
        self.bus: Bus | None = None
        self.server: ClassroomServer | None = None
        self.how_to_join = self.report = ""
        self.failure: BaseException | None = None
        self._build, self._what, self._options = build, what, options
        self._stop, self._ready = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"appsim-{channel}", daemon=True)
        self._thread.start()
        self._ready.wait(30)
        if self.failure is not None:
            raise self.failure

    def _run(self) -> None:
        from appsim.bus.realtime import WallClock

        try:
            self.bus = self._build()
            self.server = ClassroomServer(self.bus, self.channel, what=self._what, **self._options)
            self.how_to_join = self.server.how_to_join
            clock = WallClock(self.bus.sim)
            clock.add_poller(self.server.poll)
            self._ready.set()
            clock.run(self.seconds, stop=self._stop.is_set)
        except BaseException as error:          # told by the constructor, or kept in `failure`
            self.failure = error
        finally:
            if self.server is not None:
                self.server.close()
                self.report = self.server.report()
            self._ready.set()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def stop(self) -> ServedInBackground:
        """Stop serving (its programs' next recv says the classroom ended); what they did is then `report`."""
        self._stop.set()
        self._thread.join(30)
        return self
