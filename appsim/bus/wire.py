"""A CAN bus on the simulated clock: arbitration, ACK, error frames and fault confinement.

A frame holds the bus for its exact stuffed length plus intermission at the bus bit rate, decided at SOF; a frame
where a node's bit rate differs, nobody would ACK, two nodes send one identifier or an error is injected runs bit by
bit (`appsim.bus.bitlevel`), each node seeing the wire at its own sample points.
"""
from __future__ import annotations

import functools
from array import array
from collections import deque
from collections.abc import Hashable
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Protocol, TypeVar

from appsim.bus.bitlevel import Assembled, Injection, Outcome, Run, Station, run_frame
from appsim.bus.controller import Controller, Mode, Node
from appsim.bus.injections import Injections, Taking
from appsim.bus.trace import TRACE_WINDOW, Trace
from appsim.can.bits import INTERMISSION_BITS, frame_bits
from appsim.can.bittiming import BitTiming, BitTimingError
from appsim.can.frame import CanFrame
from appsim.sim import PS_PER_SECOND, Simulator, Timer

SUSPEND_TRANSMISSION_BITS = 8
BUS_IDLE_BITS = 11                  # mode changes, bus-off recovery: 11 consecutive recessive bits
MAX_OSCILLATOR_PPM = 100_000        # `Bus.set_oscillator_error` refuses more than 10 %

AnyNode = TypeVar("AnyNode", bound=Node)
AnyPart = TypeVar("AnyPart", bound=Hashable)


@dataclass(frozen=True, slots=True)
class BusEvent:
    """One entry of the bus trace: a frame that went through, or one that ended in an error frame."""

    start_ps: int
    end_ps: int                      # end of EOF (frame) or of the error delimiter (error)
    sender: str
    frame: CanFrame
    acked_by: tuple[str, ...] = ()
    error: str = ""                  # "" for a good frame, else what went wrong, in CAN terms
    received: tuple[tuple[str, str], ...] = ()   # (node, what its acceptance logic did)
    # Not part of the event's repr: the bus bit (SOF = 0) where the first error flag starts (None: no flag), and for
    # a frame run bit by bit, the wire as a logic analyser records it (`wire_changes`), kept small: the times (ps after
    # `start_ps`, 8-byte integers) at which its level changes, recessive before SOF, dominant after the first ...
    flag_at_bit: int | None = field(default=None, repr=False, compare=False)
    wire: bytes = field(default=b"", repr=False, compare=False)

    @property
    def ok(self) -> bool:
        return not self.error

    def wire_changes(self) -> list[tuple[int, int]]:
        """The wire of a frame run bit by bit as (time in ps, level) at each change, from SOF (dominant)."""
        return [(self.start_ps + offset, number % 2) for number, offset in enumerate(array("q", self.wire))]

    def __str__(self) -> str:
        time = f"{self.end_ps / PS_PER_SECOND:12.6f}"       # when receivers have it, as the trace and logs say
        if self.error:
            return f"{time}  {self.sender:>10}  {self.frame}  ** {self.error}, error flag at bit {self.flag_at_bit}"
        acks = ",".join(self.acked_by) or "-"
        return f"{time}  {self.sender:>10}  {self.frame}  ACK by {acks}"


class _Port(Protocol):
    """A node's attachment to the bus: what the protocol engine asks of a transmitter and a receiver."""

    rate_ok: bool
    suspend_until: int

    @property
    def name(self) -> str: ...

    @property
    def mode(self) -> Mode: ...
    @property
    def bus_off(self) -> bool: ...
    @property
    def error_passive(self) -> bool: ...
    @property
    def tec(self) -> int: ...
    @property
    def rec(self) -> int: ...
    def pending(self) -> tuple[str, CanFrame] | None:
        """The buffer and frame this node would send next, if any."""
    def started(self, buffer: str) -> None: ...
    def lost(self, buffer: str) -> None: ...
    def succeeded(self, buffer: str) -> None: ...
    def failed(self, buffer: str, tec_increment: int) -> None: ...
    def receive(self, frame: CanFrame) -> str:
        """A frame went through: take it; returns what the node did with it, for the trace."""
    def receive_error(self, rec_increment: int, assembled: Assembled | None, acknowledged: bool) -> None: ...
    def activity(self) -> None: ...
    def clock(self, bus_bit_ps: int) -> tuple[int, int]:
        """Its bit time and sample point in ps (the bus's bit time when its rate is within tolerance)."""
    def own_clock(self, bus_bit_ps: int) -> tuple[int, int, int, int]:
        """Its bit time, sample point and time quantum in ps, from its own oscillator, and its SJW in TQ."""


@dataclass(eq=False)
class _NodePort(_Port):
    """A node's controller on the bus, with what the wire keeps about it (its rate, its suspend and loopback times)."""

    node: Node
    rate_ok: bool = True
    suspend_until: int = 0
    ppm: float = 0                  # its oscillator's error (`Bus.set_oscillator_error`)
    loop_busy_until: int = 0
    mode_timer: Timer | None = None
    controller: Controller = field(init=False, repr=False)
    _clock_key: tuple[object, ...] = field(default=(), init=False, repr=False)     # what `clock` was last asked
    _clock: tuple[int, int] = field(default=(0, 0), init=False, repr=False)

    def __post_init__(self) -> None:
        self.controller = self.node.controller

    @property
    def name(self) -> str:
        return self.controller.name

    @property
    def mode(self) -> Mode:
        return self.controller.opmode

    @property
    def bus_off(self) -> bool:
        return self.controller.bus_off

    @property
    def error_passive(self) -> bool:
        return self.controller.error_passive

    @property
    def tec(self) -> int:
        return self.controller.tec

    @property
    def rec(self) -> int:
        return self.controller.rec

    def clock(self, bus_bit_ps: int) -> tuple[int, int]:
        key = (self.controller.bit_timing(), self.controller.fosc, bus_bit_ps, self.rate_ok)
        if key != self._clock_key:          # (the same timing object, mostly: compared by identity first)
            self._clock_key, self._clock = key, _clock(*key)
        return self._clock

    def own_clock(self, bus_bit_ps: int) -> tuple[int, int, int, int]:
        return oscillator_clock(self.controller.bit_timing(), self.controller.fosc, self.ppm)

    def pending(self) -> tuple[str, CanFrame] | None:
        buffer = self.controller.next_transmission()
        return None if buffer is None else (buffer, self.controller.frame_in(buffer))

    def started(self, buffer: str) -> None:
        self.controller.transmission_started(buffer)

    def lost(self, buffer: str) -> None:
        self.controller.arbitration_lost(buffer)

    def succeeded(self, buffer: str) -> None:
        self.controller.transmission_succeeded(buffer)

    def failed(self, buffer: str, tec_increment: int) -> None:
        self.controller.transmission_failed(buffer, tec_increment=tec_increment)

    def receive(self, frame: CanFrame) -> str:
        return str(self.controller.frame_received(frame))

    def receive_error(self, rec_increment: int, assembled: Assembled | None, acknowledged: bool) -> None:
        self.controller.receive_error(rec_increment=rec_increment, assembled=assembled, acknowledged=acknowledged)

    def activity(self) -> None:
        self.controller.bus_activity()


@functools.lru_cache(maxsize=256)
def _clock(timing: BitTiming, fosc: int, bus_bit_ps: int, rate_ok: bool) -> tuple[int, int]:
    """A node's bit time and sample point in ps: the bus's bit time when its rate is within tolerance."""
    bit_ps = bus_bit_ps if rate_ok else timing.bit_time_ps(fosc)
    return bit_ps, int(bit_ps * timing.sample_point)


@functools.lru_cache(maxsize=256)
def oscillator_clock(timing: BitTiming, fosc: int, ppm: float) -> tuple[int, int, int, int]:
    """A node's bit time, sample point and TQ in ps, its oscillator `ppm` fast (a shorter TQ) or slow, and its SJW."""
    tq_ps = round(timing.tq_seconds(fosc) * PS_PER_SECOND / (1 + Fraction(ppm) / 10**6))
    return tq_ps * timing.tq_per_bit, tq_ps * (timing.tq_per_bit - timing.effective_seg2ph), tq_ps, timing.sjw


class Outside(Protocol):
    """The far side of a link: the rest of a bus that is not simulated (see `appsim.bus.link`)."""

    name: str

    def frame_from_simulation(self, frame: CanFrame) -> None:
        """A frame that went through on the simulated bus, to send outside."""


@dataclass(eq=False)
class _LinkPort(_Port):
    """The outside world seen from the simulated bus: one error-active node that ACKs every frame
    and sends the frames that arrive from outside, retrying them as any node would."""

    outside: Outside
    queue: deque[CanFrame] = field(default_factory=deque)     # the link keeps it bounded
    delivered: int = 0                                         # frames from outside that went through
    rate_ok: bool = True
    suspend_until: int = 0
    mode: Mode = Mode.NORMAL
    bus_off: bool = False
    error_passive: bool = False
    tec: int = 0
    rec: int = 0

    @property
    def name(self) -> str:
        return self.outside.name

    def pending(self) -> tuple[str, CanFrame] | None:
        return ("outside", self.queue[0]) if self.queue else None

    def started(self, buffer: str) -> None: ...
    def lost(self, buffer: str) -> None: ...
    def failed(self, buffer: str, tec_increment: int) -> None: ...
    def receive_error(self, rec_increment: int, assembled: Assembled | None, acknowledged: bool) -> None: ...
    def activity(self) -> None: ...

    def clock(self, bus_bit_ps: int) -> tuple[int, int]:
        return bus_bit_ps, bus_bit_ps * 3 // 4

    def own_clock(self, bus_bit_ps: int) -> tuple[int, int, int, int]:
        """An exact oscillator, 16 TQ with the sample point at 12 and SJW 4, as the classroom's nodes."""
        tq_ps = bus_bit_ps // 16
        return bus_bit_ps, 12 * tq_ps, tq_ps, 4

    def succeeded(self, buffer: str) -> None:
        self.queue.popleft()
        self.delivered += 1

    def receive(self, frame: CanFrame) -> str:
        self.outside.frame_from_simulation(frame)
        return "sent outside"


def oscillator_tolerance(timing: BitTiming) -> Fraction:
    """The largest bit-rate deviation a node tolerates (CAN 2.0: min of the SJW and phase-segment limits)."""
    n, ps2 = timing.tq_per_bit, timing.effective_seg2ph
    return min(Fraction(timing.sjw, 20 * n),
               Fraction(min(timing.seg1ph, ps2), 2 * (13 * n - ps2)))


class Bus:
    """The wire and its protocol engine: every attached node's controller is driven from here.

    `trace` (and `loopback_trace`) keep the last `trace_window` events in memory (every one if None), with counts over
    the whole run; a log listening to `trace.listeners` keeps every event."""

    def __init__(self, sim: Simulator, bit_rate: int = 125_000, *, trace_window: int | None = TRACE_WINDOW):
        if PS_PER_SECOND % bit_rate:
            raise ValueError(f"a bus bit rate of {bit_rate} bit/s has no whole bit time in picoseconds")
        self.sim = sim
        self.bit_rate = bit_rate
        self.bit_ps = PS_PER_SECOND // bit_rate
        sim.quantum_ps = max(sim.quantum_ps, self.bit_ps)
        # While a frame or error frame holds the bus, what a node does (TXREQ, aborts, mode requests)
        # takes effect at the next SOF at the earliest: no other node can see it before busy_until.
        sim.quiet_until = lambda: self.busy_until
        self.ports: list[_Port] = []
        self._by_controller: dict[int, _NodePort] = {}
        self.trace = Trace(trace_window)
        self.loopback_trace = Trace(trace_window)        # frames a node in Loopback mode sent itself
        self.busy_until = 0          # end of the intermission after the last frame or error frame
        self._arbitration: Timer | None = None
        self._idle_timer: Timer | None = None
        self.injections = Injections()
        self._drifting = 0          # nodes whose oscillator is off: every frame then runs bit by bit
        self._kept: dict[object, object] = {}   # what events repeat (frames, outcomes, wires), stored once

    # ------------------------------------------------------------------ nodes
    def attach(self, node: AnyNode) -> AnyNode:
        """Put a node on the bus: the wire drives its controller, which tells the wire what it wants."""
        port = _NodePort(node)
        self.ports.append(port)
        self._by_controller[id(port.controller)] = port
        port.controller.wire = self
        return node

    def node(self, name: str) -> Node:
        for port in self.ports:
            if port.name == name and isinstance(port, _NodePort):
                return port.node
        raise KeyError(f"no node named {name!r} on this bus")

    def boards(self) -> list[Node]:
        """The simulated nodes on this bus, in the order they were attached."""
        return [port.node for port in self.ports if isinstance(port, _NodePort)]

    def attach_outside(self, outside: Outside) -> _LinkPort:
        """Join the rest of a real bus (see `appsim.bus.link`): it ACKs every frame and sends its own.
        The port returned tells the link how many of its frames wait (`queue`) and went through (`delivered`)."""
        port = _LinkPort(outside)
        self.ports.append(port)
        return port

    def from_outside(self, outside: Outside, frame: CanFrame) -> None:
        """A frame arrived from outside at the simulated present: it contends for the bus."""
        port = next(p for p in self.ports if isinstance(p, _LinkPort) and p.outside is outside)
        port.queue.append(frame)
        self._schedule_arbitration(max(self.sim.time(), self.busy_until))

    def set_oscillator_error(self, node: str, ppm: float) -> None:
        """Make `node`'s oscillator `ppm` parts per million fast (positive) or slow: its bit clock, so every time
        quantum, is that much shorter or longer (the rest of its chip keeps the kit's exact clock). While any node's
        oscillator is off, every frame runs bit by bit, each node resynchronising within SJW (docs/errors.md); 0 puts
        it back. An error no oscillator has (not a number, or more than 10 %) is refused (`BitTimingError`)."""
        port = next((p for p in self.ports if p.name == node and isinstance(p, _NodePort)), None)
        if port is None:
            raise KeyError(f"no node named {node!r} on this bus")
        if isinstance(ppm, bool) or not isinstance(ppm, int | float) or not abs(ppm) <= MAX_OSCILLATOR_PPM:
            raise BitTimingError(f"an oscillator error is a number of ppm within +-{MAX_OSCILLATOR_PPM:,} (10 %): "
                                 f"a quartz crystal is off by 100 ppm at most, a ceramic resonator by 5,000; got "
                                 f"{ppm!r}")
        port.ppm = ppm
        self._drifting = sum(1 for p in self.ports if isinstance(p, _NodePort) and p.ppm)

    def _rate_ok(self, port: _NodePort) -> bool:
        try:
            timing = port.controller.bit_timing()
        except BitTimingError:
            return False
        if timing.problems():
            return False
        error = abs(timing.bit_rate(port.controller.fosc) - self.bit_rate) / self.bit_rate
        return error <= oscillator_tolerance(timing)

    def _node_bit_ps(self, port: _NodePort) -> int:
        return port.controller.bit_timing().bit_time_ps(port.controller.fosc)

    # ------------------------------------------------------------------ what a controller asks for
    def mode_requested(self, controller: Controller) -> None:
        """OPMODE follows REQOP after 11 consecutive recessive bits. A module that has been on the bus
        counts the recessive bits that end every frame (ACK delimiter, EOF, intermission) or error frame
        (delimiter, intermission): it switches when the bus goes idle. One coming from Configuration,
        Disable or Loopback mode (off the bus) starts counting at the request, or when its own loopback frame
        ends, at its own bit time."""
        port = self._by_controller[id(controller)]
        if port.mode_timer is not None:
            return
        now = self.sim.time()
        if port.mode in (Mode.CONFIGURATION, Mode.DISABLE, Mode.LOOPBACK):
            when = max(now, self.busy_until, port.loop_busy_until) + BUS_IDLE_BITS * self._node_bit_ps(port)
        else:
            when = max(now, self.busy_until)
        port.mode_timer = self.sim.call_at(when, lambda: self._change_mode(port))

    def _change_mode(self, port: _NodePort) -> None:
        """OPMODE follows REQOP once the bus is idle (a frame in progress is finished first)."""
        port.mode_timer = None
        if self.busy_until > self.sim.now:
            port.mode_timer = self.sim.call_at(self.busy_until, lambda: self._change_mode(port))
            return
        port.controller.enter_requested_mode()
        if port.mode in (Mode.NORMAL, Mode.LISTEN_ONLY):
            port.rate_ok = self._rate_ok(port)
        self.transmit_requested(port.controller)

    def transmit_requested(self, controller: Controller) -> None:
        port = self._by_controller[id(controller)]
        if port.mode == Mode.LOOPBACK:
            self._loopback(port)
        elif port.mode == Mode.NORMAL:
            self._schedule_arbitration(max(self.sim.time(), self.busy_until, port.suspend_until))

    # ------------------------------------------------------------------ loopback: off the bus
    def _loopback(self, port: _NodePort) -> None:
        """TX buffer -> MAB -> filters -> RX buffer, at the node's own bit rate, never on the bus."""
        controller = port.controller
        buffer = controller.next_transmission()
        start = self.sim.time()
        if buffer is None or controller.on_wire is not None or port.loop_busy_until > start:
            return
        frame = controller.frame_in(buffer)
        controller.transmission_started(buffer)
        end = start + frame_bits(frame) * self._node_bit_ps(port)
        port.loop_busy_until = end + INTERMISSION_BITS * self._node_bit_ps(port)

        def done() -> None:
            controller.transmission_succeeded(buffer)       # the ACK comes from the module itself
            reception = controller.frame_received(frame)
            self.loopback_trace.append(BusEvent(start, end, port.name, self._once(frame), self._once((port.name,)),
                                                "", self._once(((port.name, str(reception)),))))
            self.sim.call_at(port.loop_busy_until, lambda: self._loopback(port))

        self.sim.call_at(end, done)

    # ------------------------------------------------------------------ on the bus
    def _schedule_arbitration(self, time: int) -> None:
        if self._arbitration is not None and not self._arbitration.cancelled:
            if self._arbitration.time <= time:
                return
            self._arbitration.cancel()
        self._arbitration = self.sim.call_at(time, self._start_of_frame)

    def _on_bus(self, port: _Port, *modes: Mode) -> bool:
        return port.mode in modes and not port.bus_off

    def _start_of_frame(self) -> None:
        """SOF: the pending frames arbitrate; the outcome of the frame is fixed here."""
        self._arbitration = None
        now = self.sim.now
        if self.busy_until > now:
            self._schedule_arbitration(self.busy_until)
            return
        contenders, waiting = [], []
        for port in self.ports:
            if not self._on_bus(port, Mode.NORMAL):
                continue
            pending = port.pending()
            if pending is None:
                continue
            if port.suspend_until <= now:
                contenders.append((port, pending))
            else:
                waiting.append(port)
        if not contenders:
            if waiting:
                self._schedule_arbitration(min(p.suspend_until for p in waiting))
            return
        self._stop_idle_count()
        for port in self.ports:
            port.activity()
        entries = []
        for port, (buffer, frame) in contenders:
            port.started(buffer)
            entries.append((_arbitration_key(frame), port, buffer, frame))
        entries.sort(key=lambda e: e[0])
        key, sender, buffer, frame = entries[0]
        same_id = [e for e in entries[1:] if e[0] == key]
        senders = {id(sender)} | {id(e[1]) for e in same_id}
        listeners = [p for p in self.ports if id(p) not in senders and self._on_bus(p, Mode.NORMAL, Mode.LISTEN_ONLY)]
        ackers = tuple(p.name for p in listeners if p.mode == Mode.NORMAL)
        if type(sender) is _LinkPort:   # isinstance is slow for a Protocol's subclass, at every frame
            ackers += (sender.name,)     # it went through out there already: the outside nodes ACKed it
        plain = (bool(ackers) and not self._drifting and all(e[3] == frame for e in same_id)
                 and all(p.rate_ok for p in listeners) and all(e[1].rate_ok for e in entries))
        armed = self.injections.nodes
        injections = {} if not self.injections else self.injections.offer(
            frame, [Taking(e[1].name, True, True) for e in entries if e[1].name in armed]
            + [Taking(p.name, p.mode == Mode.NORMAL, False) for p in listeners if id(p) not in senders
               and p.name in armed], plain=plain)
        if injections or not plain:
            self._bit_by_bit(now, entries, listeners, injections)
            return
        for loser_key, port, lost_buffer, _ in entries[1:]:
            if loser_key != key:     # same identifier and contents: both send the same bits to the end
                lost_at = now + _first_difference(key, loser_key) * self.bit_ps
                self.sim.call_at(lost_at, functools.partial(port.lost, lost_buffer))
        self._transmit(now, sender, buffer, frame, same_id, listeners, ackers)

    def _transmit(self, start: int, sender: _Port, buffer: str, frame: CanFrame,
                  same_id: list[tuple[int, _Port, str, CanFrame]], good: list[_Port], ackers: tuple[str, ...]) -> None:
        """A frame that goes through: every node at the bus bit rate, nobody sees an error."""
        end = start + frame_bits(frame) * self.bit_ps
        self.busy_until = end + INTERMISSION_BITS * self.bit_ps

        def end_of_frame() -> None:
            received = [(port.name, port.receive(frame)) for port in good]
            for _, port, twin, _ in [(None, sender, buffer, None)] + same_id:
                port.succeeded(twin)
                self._after_transmit(port)
            self.trace.append(BusEvent(start, end, sender.name, self._once(frame), self._once(ackers), "",
                                       self._once(tuple(received))))
            self._bus_idle()

        self.sim.call_at(end, end_of_frame)

    # ------------------------------------------------------------------ bit by bit
    def inject(self, node: str, kind: str, bit: int = 0, *, can_id: int | None = None, frames: int = 1,
               length: int = 1) -> Injection:
        """Make `node` see an error of `kind` ("bit", "stuff", "crc", "form", "ack") at bit `bit` (SOF = 0), or drive
        `length` dominant bits from there ("dominant"), in the next `frames` frames it takes part in in Normal mode
        (with identifier `can_id`, if given); see `appsim.bus.bitlevel.Injection`. Several for one node fire in turn,
        in successive frames, unless each is at a later bit than the one before (docs/errors.md); one that could never
        happen is refused (`InjectionError`), and `injections.not_fired()` says which never fired, and why."""
        if all(port.name != node for port in self.ports):
            raise KeyError(f"no node named {node!r} on this bus")
        injection = Injection(node, kind, bit, can_id, frames, length)
        self.injections.arm(injection)
        return injection

    def _bit_by_bit(self, start: int, entries: list[tuple[int, _Port, str, CanFrame]], listeners: list[_Port],
                    injections: dict[str, tuple[Injection, ...]]) -> None:
        """The frame and any error frames bit by bit (`appsim.bus.bitlevel`); the controllers learn the outcome
        when the last error delimiter ends, a node that lost arbitration at the bit where it lost."""
        contending = {id(e[1]) for e in entries}
        ports = [e[1] for e in entries] + [p for p in listeners if id(p) not in contending]
        frames = {id(e[1]): e[3] for e in entries}
        stations = []
        for port in ports:
            tq_ps = sjw = 0
            if self._drifting:
                bit_ps, sample_ps, tq_ps, sjw = port.own_clock(self.bit_ps)
            else:
                bit_ps, sample_ps = port.clock(self.bit_ps)
            stations.append(Station(port.name, port.mode == Mode.LISTEN_ONLY, bit_ps, sample_ps, port.tec, port.rec,
                                    frames.get(id(port)), injections.get(port.name, ()), tq_ps, sjw))
        run = run_frame(start, stations)
        self.injections.fired(injections, run.outcomes)
        buffers = {id(e[1]): e[2] for e in entries}
        for _, port, buffer, _ in entries:
            lost_at = run.outcomes[port.name].lost_at_ps
            if lost_at is not None:
                self.sim.call_at(lost_at, functools.partial(port.lost, buffer))
        sender, frame = next(((e[1], e[3]) for e in entries if run.outcomes[e[1].name].lost_at_ps is None),
                             (entries[0][1], entries[0][3]))
        end = run.end_ps
        self.busy_until = (run.idle_ps if run.sof_in_intermission
                           else max(run.idle_ps, end + INTERMISSION_BITS * self.bit_ps))
        error = self._describe(run, entries, ports)
        flag_at_bit = None if run.first_error_ps is None else (run.first_error_ps - start) // self.bit_ps

        def end_of_frame() -> None:
            received = []
            for port in ports:
                outcome = run.outcomes[port.name]
                if id(port) in buffers and outcome.lost_at_ps is None:
                    if outcome.transmitted:
                        port.succeeded(buffers[id(port)])
                        if outcome.errors:       # in a frame nobody sent, begun in its intermission
                            port.receive_error(outcome.rec_increment, outcome.assembled, False)
                    else:
                        port.failed(buffers[id(port)], tec_increment=outcome.tec_increment)
                    self._after_transmit(port)
                    continue
                received.append((port.name, self._deliver(port, outcome)))
            acked = () if error else tuple(p.name for p in ports if p is not sender and p.mode == Mode.NORMAL
                                           and run.outcomes[p.name].received is not None)
            if type(sender) is _LinkPort and not error:
                acked += (sender.name,)
            self.trace.append(BusEvent(start, end, sender.name, self._once(frame), self._once(acked),
                                       self._once(error), self._once(tuple(received)), flag_at_bit,
                                       self._once(run.wire)))
            self._bus_idle()

        self.sim.call_at(end, end_of_frame)

    KEPT = 4096             # distinct parts of events `_once` keeps at most; then it starts again

    def _once(self, part: AnyPart) -> AnyPart:
        """`part` of an event (a frame, who ACKed, what each node did, the wire), as stored the first time it came:
        a trace of 20,000 events holds each thing they repeat once."""
        if len(self._kept) >= self.KEPT:
            self._kept.clear()
        return self._kept.setdefault(part, part)        # type: ignore[return-value]

    @staticmethod
    def _deliver(port: _Port, outcome: Outcome) -> str:
        """A receiver's outcome to its controller: a valid frame, errors it detected, or both (overload)."""
        done = []
        if outcome.received is not None:
            done.append(port.receive(outcome.received))
        if outcome.errors:
            port.receive_error(outcome.rec_increment, outcome.assembled,
                               outcome.acknowledged and outcome.received is None)
            done.append("; ".join(outcome.errors))
        return "; ".join(done) or "nothing"

    def _describe(self, run: Run, entries: list[tuple[int, _Port, str, CanFrame]], ports: list[_Port]) -> str:
        """The trace's words for a frame that failed, "" for one that went through."""
        if any(run.outcomes[e[1].name].transmitted for e in entries):
            return ""
        why = f"{run.first_error} ({run.first_error_by})" if run.first_error else "no error flag"
        sending = [e for e in entries if run.outcomes[e[1].name].lost_at_ps is None]
        names = ", ".join(e[1].name for e in sending)
        if len(sending) > 1 and len({e[3].can_id for e in sending}) == 1:
            count = "two" if len(sending) == 2 else str(len(sending))
            why += (f"; {count} nodes sent identifier 0x{sending[0][3].can_id:X} at once with different contents "
                    f"({names})")
        elif len(sending) > 1:
            why += f"; still sending when it came: {names}"
        wrong = [p.name for p in ports if not p.rate_ok]
        if wrong:
            why += f"; bit timing does not match the bus: {', '.join(wrong)}"
        drifting = ([f"{p.name} {p.ppm:+,g} ppm" for p in ports if type(p) is _NodePort and p.ppm]
                    if self._drifting else [])
        if drifting:
            why += f"; oscillators off: {', '.join(drifting)}"
        return why

    def _after_transmit(self, port: _Port) -> None:
        """An error-passive transmitter waits 8 more bits (suspend transmission) before its next SOF."""
        if port.error_passive:
            port.suspend_until = self.busy_until + SUSPEND_TRANSMISSION_BITS * self.bit_ps

    # ------------------------------------------------------------------ idle bus, bus-off recovery
    def _bus_idle(self) -> None:
        """After each frame or error frame: one sequence of 11 recessive bits; next SOF if anyone waits."""
        for port in self.ports:
            if port.bus_off:
                self._recover(port, 1)
        pending = [p for p in self.ports if self._on_bus(p, Mode.NORMAL) and p.pending() is not None]
        if pending:
            self._schedule_arbitration(max(self.busy_until, min(p.suspend_until for p in pending)))
        self._start_idle_count()

    def _start_idle_count(self) -> None:
        if self._idle_timer is not None:
            self._idle_timer.cancel()
            self._idle_timer = None
        if any(p.bus_off for p in self.ports):
            self._idle_timer = self.sim.call_at(self.busy_until + BUS_IDLE_BITS * self.bit_ps,
                                                self._idle_sequence)

    def _idle_sequence(self) -> None:
        self._idle_timer = None
        for port in self.ports:
            if port.bus_off:
                self._recover(port, 1)
        if any(p.bus_off for p in self.ports):
            self._idle_timer = self.sim.call_after(BUS_IDLE_BITS * self.bit_ps, self._idle_sequence)

    def _stop_idle_count(self) -> None:
        """A SOF ends the idle period: stop counting recessive sequences for bus-off nodes."""
        if self._idle_timer is not None:
            self._idle_timer.cancel()
            self._idle_timer = None

    def _recover(self, port: _Port, sequences: int) -> None:
        if isinstance(port, _NodePort):
            port.controller.bus_off_recovery(sequences)
            if not port.bus_off:
                self.transmit_requested(port.controller)

    # ------------------------------------------------------------------ reading the trace
    def frames(self) -> list[BusEvent]:
        """The frames that went through (ACKed, no error), of those the trace keeps (see `Trace`)."""
        return [event for event in self.trace if event.ok]


def _arbitration_key(frame: CanFrame) -> int:
    """The arbitration field as the wire sends it, left-aligned in 32 bits: lower wins.

    Standard: ID10..0, RTR, IDE=0. Extended: ID28..18, SRR=1, IDE=1, ID17..0, RTR. So at equal base
    ID a standard data frame beats an extended one, and a data frame beats a remote one.
    """
    if frame.extended:
        return (frame.base_id << 21) | (1 << 20) | (1 << 19) | ((frame.can_id & 0x3FFFF) << 1) | frame.remote
    return (frame.can_id << 21) | (frame.remote << 20)


def _first_difference(a: int, b: int) -> int:
    """Bits from SOF to the arbitration bit where two keys first differ (SOF is bit 0)."""
    return 1 + (32 - (a ^ b).bit_length())
