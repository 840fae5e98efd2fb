"""A link from the simulated bus to any python-can bus: a Linux vcan, python-can's virtual or
udp_multicast bus, or a real adapter. The outside world is one more node on the simulated bus.

Frames that go through on the simulated bus are sent outside; frames from outside contend for the
simulated bus and are ACKed like any frame. Frames the ECAN cannot hold are counted, never delivered.
"""
from __future__ import annotations

import logging
from collections import Counter
from typing import Any

import can

from appsim.bus.wire import Bus
from appsim.can.frame import CanFrame

log = logging.getLogger(__name__)


def to_message(frame: CanFrame) -> can.Message:
    return can.Message(arbitration_id=frame.can_id, data=frame.data, dlc=frame.dlc,
                       is_extended_id=frame.extended, is_remote_frame=frame.remote)


def rejection(message: can.Message) -> str | None:
    """Why the PIC18F8680's ECAN could not hold this frame from outside, or None if it can."""
    if message.is_error_frame:
        return "error frame reported by the outside bus (the ECAN sees only its own wire's errors)"
    if message.is_fd:
        return "CAN FD frame (the ECAN is classic CAN 2.0B: it cannot receive FD frames)"
    if message.dlc > 8 or len(message.data) > 8:
        return "DLC above 8 (RXBnDLC codes 1001..1111 are reserved: at most 8 data bytes)"
    if message.arbitration_id >= (1 << (29 if message.is_extended_id else 11)):
        width = "29-bit extended" if message.is_extended_id else "11-bit standard"
        return f"identifier too wide for a {width} frame"
    return None


def _key(frame: CanFrame) -> tuple:
    return frame.can_id, frame.extended, frame.remote, frame.dlc, frame.data


def echoes_own_frames(outside: can.BusABC) -> bool:
    """python-can's udp_multicast hands a bus its own frames back (multicast loopback, which other
    programs on the same PC need): those echoes must not re-enter the simulated bus."""
    from can.interfaces.udp_multicast import UdpMulticastBus
    return isinstance(outside, UdpMulticastBus)


def to_frame(message: can.Message) -> CanFrame:
    if message.is_remote_frame:
        return CanFrame(message.arbitration_id, extended=message.is_extended_id, remote=True, dlc=message.dlc)
    return CanFrame(message.arbitration_id, bytes(message.data[:message.dlc]), extended=message.is_extended_id)


class BusLink:
    """Joins `bus` to a python-can bus: pass a `can.BusABC`, or python-can's own settings
    (`interface=..., channel=...`, else `~/.canrc` and the CAN_INTERFACE/CAN_CHANNEL environment).

    Call `poll()` often (a `WallClock` does, between slices) to bring in what arrived outside.
    """

    def __init__(self, bus: Bus, outside: can.BusABC | None = None, *, name: str = "outside", **config: Any):
        self.bus = bus
        self.name = name
        self.outside = outside if outside is not None else can.Bus(**config)
        self.sent = 0
        self.received = 0
        self.rejected: Counter[str] = Counter()
        self.send_failures: Counter[str] = Counter()
        self._echoes: Counter[tuple] | None = Counter() if echoes_own_frames(self.outside) else None
        bus.attach_outside(self)

    def frame_from_simulation(self, frame: CanFrame) -> None:
        try:
            self.outside.send(to_message(frame))
            self.sent += 1
            if self._echoes is not None:
                self._echoes[_key(frame)] += 1
        except can.CanError as error:     # e.g. a full transmit queue on the adapter: counted, reported
            self._count(self.send_failures, f"could not send {frame} outside: {error}")

    def poll(self) -> None:
        """Every frame that arrived outside since the last poll contends for the simulated bus now."""
        while (message := self.outside.recv(timeout=0)) is not None:
            why = rejection(message)
            if why is not None:
                self._count(self.rejected, why)
                continue
            frame = to_frame(message)
            if self._echoes is not None and self._echoes[_key(frame)]:
                self._echoes[_key(frame)] -= 1
                continue
            self.received += 1
            self.bus.from_outside(self, frame)

    def _count(self, counter: Counter[str], what: str) -> None:
        if not counter[what]:
            log.warning("%s: %s (counted in the link report)", self.name, what)
        counter[what] += 1

    def report(self) -> str:
        lines = [f"link {self.name} ({self.outside.channel_info}): "
                 f"{self.sent} frames sent outside, {self.received} received"]
        lines += [f"  rejected {count} x {why}" for why, count in self.rejected.items()]
        lines += [f"  failed {count} x {why}" for why, count in self.send_failures.items()]
        return "\n".join(lines)

    def close(self) -> None:
        self.outside.shutdown()

    def __enter__(self) -> BusLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
