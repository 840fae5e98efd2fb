"""A simulated board on python-can's own virtual bus: frames go both ways, misbehaving peers are counted."""
from __future__ import annotations

import itertools
import time

import can
import pytest

from appsim.bus.link import QUEUE_FRAMES, BusLink
from appsim.bus.realtime import WallClock
from appsim.firmware.an738 import *
from appsim.sim import PS_PER_SECOND
from appsim.workshop.classroom import Classroom

_channels = itertools.count()


@pytest.fixture
def channel() -> str:
    return f"appsim-test-{next(_channels)}"


def sender_firmware():
    """Normal mode, one frame 0x100 with 01 02 03 every time a frame arrives in RXB0 (and once at start)."""
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
    CANSendMessage(0x100, [1, 2, 3], 3, CAN_TX_STD_FRAME)
    while True:
        if CANIsRxReady():
            ident, data, length, flags = CANReceiveMessage()
            CANSendMessage(0x100, [ident & 0xFF, *data[:length]][:8], min(length + 1, 8), CAN_TX_STD_FRAME)


def test_frames_cross_both_ways_over_the_virtual_bus(world, channel):
    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(world.bus, interface="virtual", channel=channel) as link:
        world.node("station1", sender_firmware)
        world.run(0.01)
        link.poll()
        first = peer.recv(timeout=1)
        assert (first.arbitration_id, bytes(first.data), first.is_extended_id) == (0x100, b"\x01\x02\x03", False)
        assert world.bus.frames()[0].acked_by == ("outside",), "the outside world ACKs the board's frame"

        peer.send(can.Message(arbitration_id=0x088, data=[9, 8, 7], is_extended_id=False))
        link.poll()
        world.run(0.01)
        from_outside, echo = world.bus.frames()[1:3]
        assert (from_outside.sender, str(from_outside.frame)) == ("outside", "088 [3] 09 08 07")
        assert from_outside.acked_by == ("station1", "outside")
        reply = peer.recv(timeout=1)
        assert (reply.arbitration_id, bytes(reply.data)) == (0x100, b"\x88\x09\x08\x07")
        assert (link.sent, link.received) == (2, 1)


def test_remote_and_extended_frames_keep_their_kind(world, channel):
    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(world.bus, interface="virtual", channel=channel) as link:
        world.node("station1", sender_firmware)
        world.run(0.01)
        peer.send(can.Message(arbitration_id=0x1ABCDEF0, is_extended_id=True, is_remote_frame=True, dlc=5))
        link.poll()
        world.run(0.01)
        event = world.bus.frames()[1]
        assert event.frame.extended and event.frame.remote and event.frame.dlc == 5


def test_a_frame_from_outside_reaches_a_listen_only_node_without_an_ack_error(world, channel):
    """Out there the frame was ACKed already: a board that only listens still receives it."""
    received = []

    def listener():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        CANSetOperationMode(CAN_OP_MODE_LISTEN)
        while True:
            if CANIsRxReady():
                received.append(CANReceiveMessage().id)

    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(world.bus, interface="virtual", channel=channel) as link:
        world.node("station1", listener)
        world.run(0.01)
        peer.send(can.Message(arbitration_id=0x088, data=b"\x05", is_extended_id=False))
        link.poll()
        world.run(0.01)
    assert [e.error for e in world.bus.trace] == [""] and received == [0x088]


@pytest.mark.parametrize("message, reason", [
    (can.Message(arbitration_id=0x123, data=bytes(12), is_fd=True), "CAN FD"),
    (can.Message(arbitration_id=0x123, is_error_frame=True), "error frame"),
    (can.Message(arbitration_id=0x123, data=bytes(8), dlc=9, is_extended_id=False), "DLC above 8"),
    (can.Message(arbitration_id=0x7FF + 1, data=b"\x01", is_extended_id=False), "too wide"),
])
def test_frames_the_ecan_cannot_hold_are_counted_not_delivered(world, channel, message, reason):
    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(world.bus, interface="virtual", channel=channel) as link:
        board = world.node("station1", sender_firmware)
        world.run(0.01)
        peer.send(message)
        peer.send(can.Message(arbitration_id=0x088, data=b"\x05", is_extended_id=False))
        link.poll()
        world.run(0.01)
        assert [str(e.frame) for e in world.bus.frames()] == ["100 [3] 01 02 03", "088 [1] 05", "100 [2] 88 05"]
        assert sum(link.rejected.values()) == 1 and reason in next(iter(link.rejected))
        assert reason in link.report()
        assert board.ecan.rec == 0 and board.process.failure is None


def test_wall_clock_pacing_with_an_outside_peer(world, channel):
    """Linked, the simulation runs in real time: a peer that talks back while it runs is served."""
    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(world.bus, interface="virtual", channel=channel) as link:
        world.node("station1", sender_firmware)
        clock = WallClock(world.sim)
        clock.add_poller(link.poll)
        replies = []

        def peer_turn():
            for message in iter(lambda: peer.recv(timeout=0), None):
                replies.append(message)
                if len(replies) < 5:
                    peer.send(can.Message(arbitration_id=0x088, data=[len(replies)], is_extended_id=False))

        clock.add_poller(peer_turn)
        started = time.perf_counter()
        clock.run(0.2)
        elapsed = time.perf_counter() - started
        assert [bytes(m.data) for m in replies] == [b"\x01\x02\x03"] + [bytes([0x88, k]) for k in range(1, 5)]
        print(f"0.2 s simulated took {elapsed:.3f} s wall; largest lag {clock.max_lag_s * 1e3:.2f} ms")


@pytest.mark.parametrize("message, reason", [
    (can.Message(arbitration_id=-5, data=b"\x01", is_extended_id=False, check=False), "negative identifier"),
    (can.Message(arbitration_id=0x123, data=b"\x01", dlc=16, is_extended_id=False, check=False), "DLC outside 0..15"),
    (can.Message(arbitration_id=0x123, data=b"\x01", dlc=3, is_extended_id=False, check=False), "fewer data bytes"),
])
def test_invalid_fields_from_a_peer_are_rejected_with_the_reason(world, channel, message, reason):
    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(world.bus, interface="virtual", channel=channel) as link:
        peer.send(message)
        link.poll()
        world.run(0.01)
    assert (link.received, link.delivered, world.bus.trace) == (1, 0, [])
    assert f"rejected 1 x {reason}" in link.report()


def test_a_burst_faster_than_the_bus_fills_a_bounded_queue_drops_are_told_as_they_happen(world, channel, caplog):
    """1,500 frames/s from outside for a second into the 125 kbit/s bus, which carries about 1,000 of them: the
    queue stays at its size, so an RTR sent as the burst ends waits behind at most that many frames."""
    classroom = Classroom(world.bus, 6, seed=3, monitor=False)
    burst = can.Message(arbitration_id=0x7F0, data=bytes(8), is_extended_id=False)     # lowest priority
    poll = can.Message(arbitration_id=0x130, is_remote_frame=True, is_extended_id=False)
    with can.Bus(interface="virtual", channel=channel) as peer, \
            BusLink(world.bus, interface="virtual", channel=channel) as link:
        for ms in range(1200):
            for _ in range(1 + ms % 2 if ms < 1000 else 0):
                peer.send(burst)
            if ms == 1002:                              # a frame has left the full queue since the burst ended
                assert any("faster than the simulated 125 kbit/s bus" in r.message for r in caplog.records), \
                    "drops are told while the run goes on, not at the end"
                peer.send(poll)
                asked_ps = world.sim.now
            link.poll()
            assert link.queued <= QUEUE_FRAMES
            world.run(0.001)
    asked = next(e for e in world.bus.frames() if e.frame.remote and e.sender == "outside")
    answer = next(e for e in world.bus.frames() if e.start_ps > asked.start_ps and e.frame.can_id == 0x130)
    assert asked.start_ps - asked_ps < QUEUE_FRAMES * 1.1e-3 * PS_PER_SECOND, "it waited behind a queue's worth"
    assert answer.sender == "station4" and classroom.station(4).mcu.process.failure is None
    assert link.received == 1501 == link.delivered + link.dropped + link.queued and link.dropped > 400
    assert f"{link.received} received = {link.delivered} delivered + 0 rejected + {link.dropped} dropped" in link.report()


def test_a_queue_of_no_frames_is_refused_with_what_it_means(world):
    with pytest.raises(ValueError, match="how many frames from outside may wait"):
        BusLink(world.bus, can.Bus(interface="virtual", channel="appsim-refused"), queue_frames=0)
