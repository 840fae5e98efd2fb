"""A simulated board on python-can's own virtual bus: frames go both ways, misbehaving peers are counted."""
from __future__ import annotations

import itertools
import time

import can
import pytest

from appsim.firmware.an738 import *  # noqa: F403
from appsim.bus.link import BusLink
from appsim.bus.realtime import WallClock

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
