"""A link from the simulated bus to any python-can bus (a Linux vcan, python-can's virtual or udp_multicast bus, a
real adapter): the outside world is one more node on the simulated bus, and every frame it sends is accounted for.

Frames that go through on the simulated bus are sent outside. Frames from outside wait in a bounded queue and
contend for the simulated bus; what the ECAN cannot hold is rejected with the reason, what finds the queue full is
dropped, and errors of the outside bus are counted, never fatal: `BusLink.report()` adds it all up.
"""
from __future__ import annotations

import errno
import logging
import operator
import os
import queue
import socket
import struct
import sys
import time
from collections import Counter, deque
from typing import Any

import can

from appsim.bus.wire import Bus
from appsim.can.frame import EXTENDED_ID_MAX, STANDARD_ID_MAX, CanFrame
from appsim.sim import PS_PER_SECOND

log = logging.getLogger(__name__)

QUEUE_FRAMES = 64           # frames from outside waiting for the simulated bus: 70 ms of 8-byte frames at 125 kbit/s
READ_PER_POLL = 16          # frames read per poll from a bus whose kernel counts what it drops, so a flood cannot stall
                            # the simulation (at 1 ms slices, 16,000 frames/s: twice what a 1 Mbit/s bus carries)
READ_BUDGET_S = 0.0003      # an in-process bus (python-can's virtual) is read further, for this much of each poll
PYTHON_QUEUE_FRAMES = 1024  # frames a python-can queue the link reads may hold; the newest beyond are dropped, counted
WARN_EVERY_PS = PS_PER_SECOND   # drops are reported as they happen, at most once a simulated second
REOPEN_EVERY_S = 1.0        # an interface that is gone is opened again this often (wall seconds) until it is back
ECHOES_AWAITED = 4096       # own frames whose multicast echo is awaited; past that the oldest is given up, counted
KINDS_KEPT = 16             # reasons told apart in one tally; later new ones are counted together
OTHER_KINDS = f"other reasons (beyond the first {KINDS_KEPT} kinds; the log names each the first time)"

SO_MEMINFO = 55             # Linux <asm-generic/socket.h>: a socket's memory counters (Linux 4.6+) ...
SK_MEMINFO = struct.Struct("9I")    # ... SK_MEMINFO_RMEM_ALLOC .. SK_MEMINFO_DROPS: the last counts dropped packets

GONE = (errno.ENODEV, errno.ENXIO)     # what an unplugged adapter or a deleted vcan answers
MEANINGS = {
    errno.ENETDOWN: "the interface is down: frames to and from it are lost until it is up again",
    errno.ENOBUFS: "the interface's transmit queue is full: that bus is saturated, or nobody there ACKs",
    **dict.fromkeys(GONE, "the interface is gone (adapter unplugged, vcan deleted)"),
}

ERROR_FRAME = "error frame reported by the outside bus (the ECAN sees only its own wire's errors)"
FD_FRAME = "CAN FD frame (the ECAN is classic CAN 2.0B: it cannot receive FD frames)"
BAD_FLAG = "a flag (is_extended_id, is_remote_frame, is_error_frame, is_fd) that is neither True nor False"
DLC_ABOVE_8 = "DLC above 8 (RXBnDLC codes 1001..1111 are reserved: at most 8 data bytes)"


def to_message(frame: CanFrame) -> can.Message:
    return can.Message(arbitration_id=frame.can_id, data=frame.data, dlc=frame.dlc,
                       is_extended_id=frame.extended, is_remote_frame=frame.remote)


def _integer(value: Any) -> int | None:
    """`value` as an int if it is an integer (numpy's included), else None."""
    try:
        return operator.index(value)
    except Exception:
        return None


def frame_or_rejection(message: object) -> CanFrame | str:
    """The frame the PIC18F8680's ECAN takes from `message`, or why it cannot take it.

    `message` is whatever an outside bus handed over: every field is checked, none is trusted.
    """
    if not isinstance(message, can.Message):
        return "not a python-can Message"
    flags = [_integer(getattr(message, name))
             for name in ("is_error_frame", "is_fd", "is_extended_id", "is_remote_frame")]
    if any(flag not in (0, 1) for flag in flags):
        return BAD_FLAG
    error, fd, extended, remote = map(bool, flags)
    if error:
        return ERROR_FRAME
    if fd:
        return FD_FRAME
    ident, dlc, data = _integer(message.arbitration_id), _integer(message.dlc), message.data
    if ident is None:
        return "identifier that is not a number"
    if ident < 0:
        return "negative identifier"
    if ident > (EXTENDED_ID_MAX if extended else STANDARD_ID_MAX):
        return f"identifier too wide for a {'29-bit extended' if extended else '11-bit standard'} frame"
    if dlc is None:
        return "DLC that is not a number"
    if not 0 <= dlc <= 15:
        return "DLC outside 0..15 (it is a 4-bit field)"
    if dlc > 8:
        return DLC_ABOVE_8
    if not isinstance(data, (bytes, bytearray)):
        return "data that is not bytes"
    if remote:
        return "remote frame (RTR) with data" if data else CanFrame(ident, extended=extended, remote=True, dlc=dlc)
    if len(data) != dlc:
        return f"{'fewer' if len(data) < dlc else 'more'} data bytes than its DLC says"
    return CanFrame(ident, bytes(data), extended=extended)


def echoes_own_frames(outside: can.BusABC) -> bool:
    """python-can's udp_multicast hands a bus its own frames back (multicast loopback, which other
    programs on the same PC need): those echoes must not re-enter the simulated bus."""
    from can.interfaces.udp_multicast import UdpMulticastBus
    return isinstance(outside, UdpMulticastBus)


def kernel_socket(outside: can.BusABC) -> socket.socket | None:
    """A handle on the outside bus's own socket, where it has one whose drops Linux counts (socketcan, udp_multicast).

    On a CAN socket it also turns on CAN FD frames (python-can's fd=True): the kernel would hide them otherwise.
    """
    if sys.platform != "linux":
        return None
    try:
        sock = socket.socket(fileno=os.dup(outside.fileno()))
    except (NotImplementedError, OSError, ValueError, TypeError):
        return None     # no socket (virtual, most adapters' drivers), or not a socket (a serial port)
    try:
        if sock.family == socket.AF_CAN:
            sock.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FD_FRAMES, 1)
        socket_drops(sock)
    except (OSError, struct.error):     # Linux before 4.6, or not a raw CAN socket
        sock.close()
        return None
    return sock


def python_queue(outside: can.BusABC) -> queue.Queue | None:
    """The queue in which an in-process python-can bus (virtual) keeps what its peers sent until the link reads it."""
    found = getattr(outside, "queue", None)
    return found if isinstance(found, queue.Queue) else None


def socket_drops(sock: socket.socket) -> int:
    """Packets the kernel dropped because the socket's receive buffer was full, since it was opened."""
    return SK_MEMINFO.unpack(sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, SK_MEMINFO.size))[-1]


class BusLink:
    """Joins `bus` to a python-can bus: pass a `can.BusABC`, or python-can's own settings
    (`interface=..., channel=...`, else `~/.canrc` and the CAN_INTERFACE/CAN_CHANNEL environment).

    Call `poll()` often (a `WallClock` does, between slices) to bring in what arrived outside. Nothing
    from outside is lost uncounted: received = delivered + rejected + dropped + queued, and where the
    kernel drops frames before the link reads them (socketcan, udp_multicast) those are counted too.
    Errors of the outside bus are counted and reported once each; an interface that is gone (unplugged,
    vcan deleted) is opened again when it is back, if the link opened it.
    """

    def __init__(self, bus: Bus, outside: can.BusABC | None = None, *, name: str = "outside",
                 queue_frames: int = QUEUE_FRAMES, **config: Any):
        if not isinstance(queue_frames, int) or queue_frames < 1:
            raise ValueError(f"queue_frames is how many frames from outside may wait for the simulated bus, "
                             f"at least 1; got {queue_frames!r}")
        self.bus = bus
        self.name = name
        self.queue_frames = queue_frames
        self._config = config if outside is None else None     # how to open it again, if the link opened it
        self.outside = outside if outside is not None else can.Bus(**config)
        self.sent = 0
        self.received = 0           # frames from outside (not counting udp_multicast's echoes of our own)
        self.dropped = 0            # ... that found the queue full
        self.dropped_unread = 0     # frames python-can's queue held beyond PYTHON_QUEUE_FRAMES: dropped before reading
        self.echoes = 0
        self.echoes_lost = 0        # own frames whose echo never came (the kernel dropped it, or loopback is off)
        self.reopened = 0
        self.rejected: Counter[str] = Counter()
        self.send_failures: Counter[str] = Counter()
        self.receive_errors: Counter[str] = Counter()
        # udp_multicast: own frames whose echo is awaited, in the order sent (the echoes come back in that order),
        # and how many of each frame are among them
        self._awaited: deque[CanFrame] | None = deque() if echoes_own_frames(self.outside) else None
        self._echoes: Counter[CanFrame] = Counter()
        self._port = bus.attach_outside(self)
        self._reopen_at: float | None = None
        self._kernel_closed = 0     # drops counted on sockets closed since (an interface opened again, the link closed)
        self._watch_kernel()
        self._lost_told, self._told_at_ps = (0, 0), bus.sim.now     # drops told so far (queue, kernel), and when

    # ------------------------------------------------------------------ counts
    @property
    def delivered(self) -> int:
        """Frames from outside that went through on the simulated bus."""
        return self._port.delivered

    @property
    def queued(self) -> int:
        """Frames from outside still waiting for the simulated bus (at most `queue_frames`)."""
        return len(self._port.queue)

    @property
    def kernel_dropped(self) -> int | None:
        """Frames the kernel dropped before the link could read them (its socket's buffer was full);
        None if this outside bus does not say (python-can's virtual bus, most adapters)."""
        if not self._kernel_known:
            return None
        return self._kernel_closed + self._kernel_count() - self._kernel_base

    def _kernel_count(self) -> int:
        return 0 if self._kernel_socket is None else socket_drops(self._kernel_socket)

    def _watch_kernel(self) -> None:
        self._kernel_socket = kernel_socket(self.outside)
        self._kernel_known = self._kernel_socket is not None
        self._kernel_base = self._kernel_count()
        self._python_queue = python_queue(self.outside)

    @property
    def unread(self) -> int:
        """Frames waiting in python-can's queue for the link to read them (0 if it has none the link can see)."""
        return 0 if self._python_queue is None else self._python_queue.qsize()

    # ------------------------------------------------------------------ to and from the outside bus
    def frame_from_simulation(self, frame: CanFrame) -> None:
        try:
            self.outside.send(to_message(frame), timeout=0)     # a bus that cannot take it now must not stall us
        except Exception as error:
            self._failed(self.send_failures, "could not send", error)
            return
        self.sent += 1
        if self._awaited is not None:
            self._awaited.append(frame)
            self._echoes[frame] += 1
            if len(self._awaited) > ECHOES_AWAITED:
                self._forget_oldest()
                self.echoes_lost += 1

    def poll(self) -> None:
        """Bring in what arrived outside since the last poll: each frame contends for the simulated bus now, or is
        counted as rejected or dropped. A bus whose kernel counts its drops (socketcan, udp_multicast) gives at most
        READ_PER_POLL frames a poll, the rest wait there; any other is read for READ_BUDGET_S, and what python-can's
        queue holds beyond PYTHON_QUEUE_FRAMES is dropped and counted, so memory stays flat. Never raises."""
        if self._reopen_at is not None and time.monotonic() >= self._reopen_at:
            self._reopen()
        until = None if self._kernel_known else time.perf_counter() + READ_BUDGET_S
        read = 0
        while read < READ_PER_POLL or (until is not None and time.perf_counter() < until):
            try:
                message = self.outside.recv(timeout=0)
            except Exception as error:
                self._failed(self.receive_errors, "could not receive", error)
                break
            if message is None:
                break
            self._take(message)
            read += 1
        self._trim_python_queue()
        self._warn_of_drops()

    def _trim_python_queue(self) -> None:
        """Drop, and count, the newest frames python-can's queue holds beyond PYTHON_QUEUE_FRAMES (a peer in this
        process sends faster than the link reads: as a kernel's socket buffer would, the queue stays bounded)."""
        waiting = self._python_queue
        if waiting is None or waiting.qsize() <= PYTHON_QUEUE_FRAMES:
            return
        with waiting.mutex:
            excess = len(waiting.queue) - PYTHON_QUEUE_FRAMES
            for _ in range(excess):
                waiting.queue.pop()
            waiting.not_full.notify_all()
        self.dropped_unread += max(excess, 0)

    def _take(self, message: object) -> None:
        frame = frame_or_rejection(message)
        if isinstance(frame, CanFrame) and self._is_echo(frame):
            return
        self.received += 1
        if isinstance(frame, str):
            self._tally(self.rejected, frame)
        elif len(self._port.queue) >= self.queue_frames:
            self.dropped += 1
        else:
            self.bus.from_outside(self, frame)

    def _is_echo(self, frame: CanFrame) -> bool:
        """Whether `frame` is the echo of one of the link's own frames. The echoes come back in the order sent, so
        the ones awaited before it, whose echoes did not come, are given up."""
        if self._awaited is None or not self._echoes[frame]:
            return False
        while self._forget_oldest() != frame:
            self.echoes_lost += 1
        self.echoes += 1
        return True

    def _forget_oldest(self) -> CanFrame:
        assert self._awaited is not None
        frame = self._awaited.popleft()
        self._echoes[frame] -= 1
        if not self._echoes[frame]:
            del self._echoes[frame]
        return frame

    # ------------------------------------------------------------------ trouble, told as it happens
    def _tally(self, counter: Counter[str], what: str) -> None:
        """Count `what`; the first of its kind is told at once."""
        if what not in counter and len(counter) >= KINDS_KEPT:
            what = OTHER_KINDS
        if not counter[what]:
            log.warning("%s: %s (counted in the link report)", self.name, what)
        counter[what] += 1

    def _failed(self, counter: Counter[str], doing: str, error: Exception) -> None:
        code = _integer(getattr(error, "error_code", None) or getattr(error, "errno", None))
        meaning = f": {MEANINGS[code]}" if code in MEANINGS else ""
        self._tally(counter, f"{doing}: {type(error).__name__}: {error}{meaning}")
        if code in GONE and self._config is not None and self._reopen_at is None:
            log.warning("%s: opening %s again every %g s until it is back", self.name,
                        self.outside.channel_info, REOPEN_EVERY_S)
            self._reopen_at = time.monotonic() + REOPEN_EVERY_S

    def _reopen(self) -> None:
        try:
            outside = can.Bus(**(self._config or {}))
        except Exception:
            self._reopen_at = time.monotonic() + REOPEN_EVERY_S
            return
        self._close_outside()
        self.outside, self._reopen_at = outside, None
        self._watch_kernel()
        self.reopened += 1
        log.warning("%s: %s is back, opened again", self.name, outside.channel_info)

    def _warn_of_drops(self) -> None:
        """Frames lost to a full queue or a full kernel buffer are told as they happen: a line a second at most."""
        now = self.bus.sim.now
        dropped, kernel = self.dropped, (self.kernel_dropped or 0) + self.dropped_unread
        if (dropped, kernel) == self._lost_told or (any(self._lost_told) and now - self._told_at_ps < WARN_EVERY_PS):
            return
        log.warning("%s: outside sends faster than the simulated %d kbit/s bus carries: in the last %.1f s %d frames "
                    "found the link's queue of %d frames full and %d the kernel's socket buffer or python-can's "
                    "queue (%d lost in all)",
                    self.name, self.bus.bit_rate // 1000, (now - self._told_at_ps) / PS_PER_SECOND,
                    dropped - self._lost_told[0], self.queue_frames, kernel - self._lost_told[1], dropped + kernel)
        self._lost_told, self._told_at_ps = (dropped, kernel), now

    # ------------------------------------------------------------------ the account
    def report(self) -> str:
        """What crossed the link, every frame from outside accounted for."""
        lines = [f"link {self.name} ({self.outside.channel_info}): {self.sent} frames sent outside, "
                 f"{self.received} received = {self.delivered} delivered + {sum(self.rejected.values())} rejected "
                 f"+ {self.dropped} dropped + {self.queued} still queued"]
        lines += [f"  rejected {count} x {why}" for why, count in self.rejected.items()]
        if self.dropped:
            lines.append(f"  dropped {self.dropped}: the link's queue of {self.queue_frames} frames was full (outside "
                         f"sends faster than the simulated {self.bus.bit_rate // 1000} kbit/s bus carries)")
        kernel = self.kernel_dropped
        if self._python_queue is not None:
            if self.dropped_unread:
                lines.append(f"  {self.dropped_unread} more were dropped before the link read them: python-can's "
                             f"queue held {PYTHON_QUEUE_FRAMES} frames (a peer in this process sent faster than the "
                             "link reads)")
            if self.unread:
                lines.append(f"  {self.unread} more are still in python-can's queue, not read")
        elif kernel is None:
            lines.append("  (this outside bus does not say whether it dropped frames before the link read them)")
        elif kernel:
            lines.append(f"  the kernel dropped {kernel} more before the link could read them "
                         "(the socket's receive buffer was full)")
        if self.echoes:
            lines.append(f"  {self.echoes} of the link's own frames came back (multicast loopback) and were skipped")
        if self.echoes_lost:
            lines.append(f"  {self.echoes_lost} of the link's own frames never came back (their multicast echo was "
                         "dropped, or loopback is off): no longer awaited, so an identical frame from outside is taken")
        lines += [f"  {count} x {what}" for what, count in (self.receive_errors + self.send_failures).items()]
        if self.reopened:
            lines.append(f"  the outside bus was gone and opened again {self.reopened} time(s)")
        return "\n".join(lines)

    def _close_outside(self) -> None:
        if self._kernel_socket is not None:
            self._kernel_closed += socket_drops(self._kernel_socket) - self._kernel_base
            self._kernel_socket.close()
            self._kernel_socket, self._kernel_base = None, 0
        try:
            self.outside.shutdown()
        except Exception as error:
            log.warning("%s: closing %s: %s", self.name, self.outside.channel_info, error)

    def close(self) -> None:
        self._close_outside()

    def __enter__(self) -> BusLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
