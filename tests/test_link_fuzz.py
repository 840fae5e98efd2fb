"""Outside input never crashes, hangs or silently loses anything: random frames (every invalid field, FD, error
frames, bursts) and random errors of the outside bus go into a linked classroom; it goes on, and every frame is
accounted for in the link's report.
"""
from __future__ import annotations

import errno
import inspect
import itertools
import json
import struct
from collections import deque
from collections.abc import Callable, Iterable

import can
import pytest
from can.interfaces.udp_multicast import UdpMulticastBus
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from netns import namespaces  # noqa: F401 - a fixture

from appsim.bus.link import QUEUE_FRAMES, BusLink
from appsim.bus.wire import Bus
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import MASTER_ID, STATIONS, station_ids

MS = PS_PER_SECOND // 1000
_channels = itertools.count()


class ScriptedBus(can.BusABC):
    """An outside bus that hands over what the test scripted, in order: messages (with any fields) or errors to
    raise; None ends what one poll gets. `send` raises the scripted errors in turn (None: that send works)."""

    def __init__(self, arrivals: Iterable[object], send_errors: Iterable[Exception | None] = ()):
        self.arrivals = deque(arrivals)
        self.send_errors = deque(send_errors)
        self.handed = self.raised = self.send_raised = 0
        super().__init__(channel="scripted")
        self.channel_info = "a scripted test bus"

    def _recv_internal(self, timeout: float | None) -> tuple[object, bool]:
        item = self.arrivals.popleft() if self.arrivals else None
        if isinstance(item, Exception):
            self.raised += 1
            raise item
        self.handed += item is not None
        return item, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        error = self.send_errors.popleft() if self.send_errors else None
        if error is not None:
            self.send_raised += 1
            raise error


# ------------------------------------------------------------------ what comes from outside
def message(can_id: int, payload: bytes = b"", *, extended: bool = False, remote: bool = False,
            length: int | None = None, **fields: object) -> can.Message:
    """A python-can message (DLC `length`, else the payload's), then `fields` set as an interface or a peer
    could leave them: unchecked."""
    built = can.Message(arbitration_id=can_id, data=payload, is_extended_id=extended, is_remote_frame=remote,
                        dlc=len(payload) if length is None else length, check=False)
    for name, value in fields.items():
        setattr(built, name, value)
    return built


standard_id = st.integers(0, 0x7FF)          # the master's 0x088 too: the stations check DataLen before RxData
valid = st.one_of(
    st.builds(lambda i, d: message(i, d), standard_id, st.binary(max_size=8)),
    st.builds(lambda i, d: message(i, d, extended=True), st.integers(0, 0x1FFF_FFFF), st.binary(max_size=8)),
    st.builds(lambda i, n, x: message(i, remote=True, length=n, extended=x), standard_id, st.integers(0, 8),
              st.booleans()),
)
not_a_number = st.sampled_from(["0x100", 1.5, b"\x01", [1]])
invalid_copyable = st.one_of(                    # every field a peer or an interface can get wrong, a copy keeps it
    st.builds(lambda i: message(0, b"\x01", arbitration_id=i), st.integers(max_value=-1)),
    st.builds(lambda i: message(0, arbitration_id=i), st.integers(0x800, 2**64)),
    st.builds(lambda i: message(0, extended=True, arbitration_id=i), st.integers(0x2000_0000, 2**64)),
    st.builds(lambda i: message(0, arbitration_id=i), st.one_of(not_a_number, st.none())),
    st.builds(lambda n: message(0x123, bytes(8), length=n), st.integers(9, 15)),                 # DLC above 8
    st.builds(lambda n: message(0x123, dlc=n), st.one_of(st.integers(max_value=-1), st.integers(16, 2**40))),
    st.builds(lambda n: message(0x123, dlc=n), not_a_number),
    st.builds(lambda d, more: message(0x123, d, length=len(d) + more), st.binary(max_size=7), st.integers(1, 8)),
    st.builds(lambda d, less: message(0x123, d, length=max(len(d) - less, 0)), st.binary(min_size=1, max_size=8),
              st.integers(1, 8)),
    st.builds(lambda d: message(0x123, bytes(9 + len(d))), st.binary(max_size=60)),           # more than 8 bytes
    st.builds(lambda d: message(0x123, d, is_fd=True), st.binary(max_size=64)),
    st.builds(lambda i: message(i, is_error_frame=True), st.integers(0, 0x7FF)),
    st.builds(lambda f: message(0x123, is_extended_id=f), st.sampled_from([2, -1, "yes", None, 0.5])),
)
invalid = st.one_of(    # python-can's virtual bus hands over a copy, a new Message, which would not keep these
    invalid_copyable,
    st.builds(lambda d: message(0x123, b"\x01", data=d), st.sampled_from(["abc", [1], None, 7, (1, 2)])),
    st.just(message(0x123, dlc=None)),                                  # a copy makes it the data's length
    st.builds(lambda n: message(0x123, remote=True, length=n, data=bytearray(n)), st.integers(1, 8)),  # RTR with data
    st.just("not a frame at all"),
)
error = st.sampled_from([
    can.CanOperationError("Error receiving: Network is down", error_code=errno.ENETDOWN),
    can.CanOperationError("could not unpack received message"),
    can.CanError("the adapter's driver failed"),
    OSError(errno.ENOBUFS, "No buffer space available"),
    OSError(errno.ENODEV, "No such device"),
    ValueError("a broken interface"),
    struct.error("unpack requires a buffer of 16 bytes"),
    RuntimeError("anything at all"),
])
arrival = st.one_of(valid.map(lambda m: (m, True)), invalid.map(lambda m: (m, False)), error.map(lambda e: (e, None)))
polls = st.lists(st.lists(arrival, max_size=3 * QUEUE_FRAMES), min_size=1, max_size=40)   # bursts beyond the queue
send_errors = st.lists(st.one_of(st.none(), error), max_size=60)


def run_polled(sim: Simulator, link: BusLink, steps: int = 0, *, until: Callable[[], bool] | None = None) -> None:
    """`steps` milliseconds of the classroom (or more, `until` it is true), the link polled before each as a
    WallClock does, but fast."""
    while steps > 0 or (until is not None and not until()):
        link.poll()
        assert link.queued <= link.queue_frames, "the queue from outside is bounded"
        sim.run(until=sim.now + MS)
        steps -= 1


def assert_every_station_answers_the_master(bus: Bus, since_ps: int) -> None:
    answered = {e.sender for e in bus.frames() if e.start_ps >= since_ps and not e.frame.remote
                and e.sender.startswith("station") and e.frame.can_id == station_ids(int(e.sender[7:]))["MESSAGE_ID1"]}
    assert answered == {f"station{k}" for k in range(1, STATIONS + 1)}, f"only {sorted(answered)} answered the master"


def assert_report_adds_up(link: BusLink, bus: Bus) -> None:
    rejected = sum(link.rejected.values())
    assert link.received == link.delivered + rejected + link.dropped + link.queued
    assert link.delivered == sum(e.sender == link.name for e in bus.frames()), "delivered: on the simulated bus"
    report = link.report()
    assert f"{link.received} received = {link.delivered} delivered + {rejected} rejected + {link.dropped} dropped " \
           f"+ {link.queued} still queued" in report
    for why, count in link.rejected.items():
        assert f"rejected {count} x {why}" in report


def classroom() -> tuple[Simulator, Bus, Classroom]:
    sim = Simulator()
    bus = Bus(sim, 125_000)
    return sim, bus, Classroom(bus, 6, seed=13, monitor=False)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(polls=polls, send_errors=send_errors)
def test_random_frames_and_errors_from_outside_never_stop_the_classroom_and_are_all_accounted_for(polls, send_errors):
    sim, bus, room = classroom()
    script = [item for poll in polls for item in [*(thing for thing, _ in poll), None]]
    outside = ScriptedBus(script, send_errors)
    with BusLink(bus, outside) as link:
        run_polled(sim, link, until=lambda: not outside.arrivals)
        quiet = sim.now
        run_polled(sim, link, 1000)

    for board in room.boards:
        assert board.mcu.process.failure is None, board.mcu.process.failure_text
    assert_every_station_answers_the_master(bus, since_ps=quiet)
    assert_report_adds_up(link, bus)
    arrivals = [kind for poll in polls for _, kind in poll]
    assert link.received == outside.handed == arrivals.count(True) + arrivals.count(False)
    assert sum(link.rejected.values()) == arrivals.count(False), "every invalid field is a rejection, with its reason"
    assert sum(link.receive_errors.values()) == outside.raised == arrivals.count(None)
    assert sum(link.send_failures.values()) == outside.send_raised
    sent_by_the_simulation = sum(e.sender != link.name for e in bus.frames())
    assert link.sent + outside.send_raised == sent_by_the_simulation


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(bursts=st.lists(st.lists(st.one_of(valid.map(lambda m: (m, True)), invalid_copyable.map(lambda m: (m, False))),
                                max_size=2 * QUEUE_FRAMES), min_size=1, max_size=10))
def test_random_bursts_over_python_cans_virtual_bus_are_all_accounted_for(bursts):
    """A peer on python-can's real virtual bus, sending bursts of valid and invalid frames."""
    sim, bus, room = classroom()
    channel = f"appsim-fuzz-{next(_channels)}"
    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(bus, interface="virtual", channel=channel) as link:
        for burst in bursts:
            for sent, _ in burst:
                peer.send(sent)
            run_polled(sim, link, 5)
        quiet = sim.now
        run_polled(sim, link, 1000)
    assert_every_station_answers_the_master(bus, since_ps=quiet)
    assert_report_adds_up(link, bus)
    kinds = [kind for burst in bursts for _, kind in burst]
    assert (link.received, sum(link.rejected.values())) == (len(kinds), kinds.count(False))
    assert link.kernel_dropped is None and link.dropped_unread == 0, "the link reads python-can's queue: it knows"
    assert "does not say whether it dropped" not in link.report()


def test_a_peer_that_never_reads_cannot_stall_the_link_its_frames_are_counted_as_not_sent():
    """python-can's virtual bus blocks a sender while a reader's queue is full, unless the send has a timeout."""
    sim, bus, room = classroom()
    channel = f"appsim-fuzz-{next(_channels)}"
    with can.Bus(interface="virtual", channel=channel, rx_queue_size=3) as peer, \
            BusLink(bus, interface="virtual", channel=channel) as link:
        run_polled(sim, link, 1000)
        assert peer.recv(timeout=0) is not None
    on_the_bus = len(bus.frames())
    assert link.sent == 3 and sum(link.send_failures.values()) == on_the_bus - 3 > 10
    assert "Could not send message to one or more recipients" in link.report()
    assert_every_station_answers_the_master(bus, since_ps=0)


# ------------------------------------------------------------------ a datagram python-can cannot decode, for real
PC = """
import json, sys
from appsim.board.app023 import APP023
from appsim.bus.link import BusLink
from appsim.bus.realtime import WallClock
from appsim.bus.wire import Bus
from appsim.firmware.loader import load_firmware
from appsim.sim import Simulator
from appsim.workshop.course import SOLUTIONS

sim = Simulator()
bus = Bus(sim, 125_000)
APP023(bus, "station1", potentiometer=321).run(load_firmware(SOLUTIONS / "ex6.py", {"MESSAGE_ID1": 0x100}))
with BusLink(bus, interface="udp_multicast", channel=sys.argv[1]) as link:
    clock = WallClock(sim)
    clock.add_poller(link.poll)
    print("ready", flush=True)
    clock.run(float(sys.argv[2]))
    print(json.dumps({"frames": [str(e.frame) for e in bus.frames()], "report": link.report(),
                      "errors": sum(link.receive_errors.values()), "received": link.received}))
"""

PEER = """
import socket, sys, time, can
group, port = sys.argv[1], int(sys.argv[2])
with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as garbage:
    garbage.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
    for datagram in (b"not msgpack at all", bytes(300), b"\\x81\\xa3bad\\xc1"):
        garbage.sendto(datagram, (group, port))
time.sleep(0.2)
with can.Bus(interface="udp_multicast", channel=group) as bus:       # as the master: Ex6 waits for its 0x088
    bus.send(can.Message(arbitration_id=0x088, data=[1, 2, 3, 2, 0], is_extended_id=False))
    time.sleep(0.1)
    bus.send(can.Message(arbitration_id=0x100, is_remote_frame=True, is_extended_id=False))
"""


@pytest.mark.netns
def test_datagrams_udp_multicast_cannot_decode_are_counted_and_the_board_goes_on(namespaces):
    board_pc, other_pc = namespaces(2)
    group = UdpMulticastBus.DEFAULT_GROUP_IPv4
    port = str(inspect.signature(UdpMulticastBus).parameters["port"].default)
    board = board_pc.start_python(PC, group, "1.5")
    board.wait_for_line("ready")
    peer = other_pc.python(PEER, group, port)
    assert peer.returncode == 0, peer.stdout
    assert board.finish(timeout=30) == 0, board.output
    result = json.loads(board.lines[-1])
    assert result["errors"] == 3 and "could not unpack received message" in result["report"], result["report"]
    assert result["received"] == 2 and "100 [5] 01 02 03 01 41" in result["frames"], "the board answered the RTR"


ECHOES = """
import json, socket, sys, time
from appsim.bus.link import ECHOES_AWAITED, BusLink
from appsim.bus.wire import Bus
from appsim.can.frame import CanFrame
from appsim.sim import Simulator

bus = Bus(Simulator(), 125_000)
with BusLink(bus, interface="udp_multicast", channel=sys.argv[1]) as link:
    for n in range(10):                                 # loopback on: each echo comes back, in order, and is skipped
        link.frame_from_simulation(CanFrame(0x123, bytes([n])))
    deadline = time.monotonic() + 5
    while link.echoes < 10 and time.monotonic() < deadline:
        link.poll()
    came = (link.echoes, link.echoes_lost, link.received)
    link.outside._multicast._socket.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 0)    # echoes lost now
    for n in range(3 * ECHOES_AWAITED):
        link.frame_from_simulation(CanFrame(0x124, n.to_bytes(2, "big")))
    print(json.dumps({"came": came, "awaited": len(link._awaited), "lost": link.echoes_lost, "most": ECHOES_AWAITED,
                      "report": link.report()}))
"""


@pytest.mark.netns
def test_the_links_own_frames_whose_multicast_echo_never_comes_are_given_up_counted_not_kept(namespaces):
    """udp_multicast hands the link its own frames back, which it skips; an echo that never comes (the kernel dropped
    it, loopback is off) is awaited no longer than 4,096 frames: memory stays bounded, and the report counts them."""
    [pc] = namespaces(1)
    done = pc.python(ECHOES, UdpMulticastBus.DEFAULT_GROUP_IPv4, timeout=60)
    assert done.returncode == 0, done.stdout
    result = json.loads(done.stdout.splitlines()[-1])
    assert result["came"] == [10, 0, 0], "each echo came back and none was taken as a frame from outside"
    assert result["awaited"] == result["most"] and result["lost"] == 2 * result["most"]
    assert f"{2 * result['most']} of the link's own frames never came back" in result["report"]


def test_a_short_frame_with_the_masters_id_from_outside_does_not_stop_the_stations():
    sim, bus, room = classroom()
    outside = ScriptedBus([None] * 300 + [message(MASTER_ID, b"\x01\x02")])
    with BusLink(bus, outside) as link:
        run_polled(sim, link, 1000)
    assert [board.name for board in room.boards if board.mcu.process.failure is not None] == []
