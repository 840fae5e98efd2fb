"""Fault confinement as ISO 11898-1 counts it (rules 1-12, CAN 2.0's numbering), each error type with the bit where
the error flag starts, two senders of one identifier, and wrong-rate frames that nobody takes as valid."""
from __future__ import annotations

from test_bus_gotchas import busy_bus, normal_node

from appsim.can.bits import encode, frame_bits
from appsim.can.frame import CanFrame
from appsim.chip.ecan import registers as R
from appsim.firmware import *

FRAME = CanFrame(0x100, bytes([1, 2, 3]))          # what normal_node sends: 73 bits, ACK delimiter at bit 65
ACK_DELIMITER = frame_bits(FRAME) - 8
COMSTAT = R.BY_NAME["COMSTAT"].address


def three_nodes(world):
    """a sends 0x100 at 1 ms; b and c receive (all error-active, Normal mode)."""
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)], delay_ms=1))
    b = world.node("b", normal_node())
    c = world.node("c", normal_node())
    world.run(0.0009)
    return a, b, c


def until_events(world, count):
    while world.bus.trace.total < count:
        world.run(0.0001)
    return world.bus.trace[count - 1]


def counters(*nodes):
    return [(n.ecan.tec, n.ecan.rec) for n in nodes]


def comstat(node):
    """COMSTAT's error-state bits (the overflow bits left out)."""
    return node.ecan.read(COMSTAT) & ~(R.RXB0OVFL | R.RXB1OVFL)


# ------------------------------------------------------------------ each error type, and where its flag starts
def test_crc_error_flag_starts_after_the_ack_delimiter_rule_1_plus_1_rule_2_plus_8_rule_3_plus_8(world):
    a, b, c = three_nodes(world)
    world.bus.inject("b", "crc")
    event = until_events(world, 1)
    assert event.error.startswith(f"CRC error at bit {ACK_DELIMITER}") and event.flag_at_bit == ACK_DELIMITER + 1
    # b flags at EOF1; a and c see that dominant EOF bit (form error) and flag one bit later, so b sees dominant
    # right after its own flag (rule 2: +8 on its +1); c only +1 (rule 1); a, the transmitter, +8 (rule 3).
    assert counters(a, b, c) == [(8, 0), (0, 9), (0, 1)]
    assert dict(event.received)["c"].startswith(f"form error at bit {ACK_DELIMITER + 1}")


def test_bit_error_flag_starts_at_the_next_bit_and_receivers_see_a_stuff_error(world):
    a, b, c = three_nodes(world)
    world.bus.inject("a", "bit", 20)
    event = until_events(world, 1)
    assert event.error.startswith("bit error at bit 20") and event.flag_at_bit == 21
    assert dict(event.received)["b"].startswith("stuff error at bit 26")     # 6 dominant bits from 21
    assert counters(a, b, c) == [(8, 0), (0, 1), (0, 1)]


def test_stuff_error_flag_starts_at_the_next_bit(world):
    a, b, c = three_nodes(world)
    world.bus.inject("c", "stuff", 30)
    event = until_events(world, 1)
    assert event.error.startswith("stuff error at bit 30") and event.flag_at_bit == 31
    assert counters(a, b, c) == [(8, 0), (0, 1), (0, 9)]


def test_form_error_in_the_end_of_frame(world):
    a, b, c = three_nodes(world)
    world.bus.inject("b", "form", ACK_DELIMITER + 2)       # EOF bit 2 read dominant
    event = until_events(world, 1)
    assert event.error.startswith(f"form error at bit {ACK_DELIMITER + 2}: end-of-frame bit 2")
    assert event.flag_at_bit == ACK_DELIMITER + 3 and counters(a, b, c) == [(8, 0), (0, 9), (0, 1)]


def test_ack_error_flag_starts_at_the_ack_delimiter(world):
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    event = until_events(world, 1)
    assert event.error.startswith(f"ACK error at bit {ACK_DELIMITER - 1}") and event.flag_at_bit == ACK_DELIMITER
    assert event.end_ps - event.start_ps == (ACK_DELIMITER + 6 + 8) * world.bus.bit_ps
    assert a.ecan.tec == 8


# ------------------------------------------------------------------ the rules
def test_rule_3_exception_1_passive_transmitter_ack_error_without_dominant_bit_is_not_counted(world):
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    world.run(0.1)
    assert a.ecan.tec == 128 and world.bus.trace.total > 50, "16 ACK errors: +8 each, then passive: +0 each"
    assert comstat(a) & (R.TXBP | R.TXWARN | R.EWARN) == R.TXBP | R.TXWARN | R.EWARN


def test_rule_3_exception_1_does_not_hold_when_a_dominant_bit_comes_in_the_passive_flag(world):
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    world.run(0.1)
    seen = world.bus.trace.total
    world.node("b", normal_node())
    world.bus.inject("b", "crc")        # b will not ACK (bad CRC) and flags at EOF1, inside a's passive flag
    event = until_events(world, seen + 1)
    while "b" not in dict(event.received):
        seen += 1
        event = until_events(world, seen + 1)
    assert event.error.startswith("ACK error") and a.ecan.tec == 136


def test_rule_3_exception_2_stuff_error_in_arbitration_on_a_recessive_stuff_bit_is_not_counted(world):
    a, b, c = three_nodes(world)
    stuff_bit = 9                       # 0x100: SOF, 0 0 1, five 0s, then a recessive stuff bit
    assert encode(FRAME)[stuff_bit] == 1
    world.bus.inject("a", "bit", stuff_bit)
    event = until_events(world, 1)
    assert event.error.startswith(f"stuff error at bit {stuff_bit}") and a.ecan.tec == 0


def test_rule_4_bit_error_in_the_transmitters_own_active_error_flag_adds_8(world):
    a, b, c = three_nodes(world)
    world.bus.inject("a", "bit", 20)
    world.bus.inject("a", "bit", 23)    # inside its flag (bits 21-26): it reads recessive where it drives dominant
    until_events(world, 1)
    assert a.ecan.tec == 16


def test_rule_5_bit_error_in_a_receivers_own_active_error_flag_adds_8(world):
    a, b, c = three_nodes(world)
    world.bus.inject("b", "stuff", 30)
    world.bus.inject("b", "bit", 33)
    until_events(world, 1)
    assert b.ecan.rec == 1 + 8 + 8, "rule 1, rule 5, then rule 2 (c's flag after b's restarted one)"


def test_rule_6_more_than_7_dominant_bits_after_a_flag_add_8_each_8_bits(world):
    a, b, c = three_nodes(world)
    world.bus.inject("c", "stuff", 30)                       # c flags at 31..36
    world.bus.inject("b", "dominant", 40, length=30)         # b's transceiver holds the bus dominant 40..69
    until_events(world, 1)
    # c: +1, +8 (rule 2), then the 14th, 22nd, 30th and 38th dominant bits from its flag's start (31..69): 4 x 8.
    # a (bit error at 35, flag 36..): +8, then the 14th, 22nd and 30th: 3 x 8. b (stuff error at 35): 1 + 8 + 3 x 8.
    assert counters(a, b, c) == [(8 + 24, 0), (0, 1 + 8 + 24), (0, 1 + 8 + 32)]


def test_rule_7_and_8_success_counts_down_by_one(world):
    a, b, c = three_nodes(world)
    world.bus.inject("b", "crc")
    until_events(world, 2)
    assert world.bus.trace[1].ok and counters(a, b, c) == [(7, 0), (0, 8), (0, 0)]


def test_rule_8_9_11_a_passive_receiver_that_receives_a_frame_goes_back_to_127_and_error_active(world):
    a, b, c = three_nodes(world)
    world.bus.inject("b", "crc", frames=15)
    until_events(world, 15)
    # c ACKs each frame, then reads b's flag in EOF: -1 at the ACK slot, +1 (rule 8 before rule 1): it stays at 1
    assert counters(a, b, c) == [(120, 0), (0, 135), (0, 1)]
    assert b.ecan.error_passive and comstat(b) == R.RXBP | R.RXWARN | R.EWARN
    assert comstat(a) == R.TXWARN | R.EWARN
    until_events(world, 16)
    assert world.bus.trace[15].ok and counters(a, b, c) == [(119, 0), (0, 127), (0, 0)]
    assert not b.ecan.error_passive and comstat(b) == R.RXWARN | R.EWARN


def test_rule_10_bus_off_above_255_and_rule_12_recovery_after_128_times_11_recessive_bits(world):
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    world.node("listener", normal_node())
    world.bus.inject("a", "bit", 20, frames=32)
    until_events(world, 31)
    assert a.ecan.tec == 248 and not a.ecan.bus_off
    until_events(world, 32)
    assert a.ecan.bus_off and comstat(a) & R.TXBO and a.ecan.read(R.BY_NAME["TXERRCNT"].address) == 255
    idle_from = world.bus.trace[31].end_ps - 8 * world.bus.bit_ps
    back = until_events(world, 33)
    assert (back.start_ps - idle_from) // world.bus.bit_ps == 128 * 11 and back.ok
    assert counters(a) == [(0, 0)] and comstat(a) == 0


# ------------------------------------------------------------------ two senders, one identifier
def sender(data):
    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        Delay1KTCYx(12)                  # 1.2 ms: both queue while the blocker's frame is on the bus
        CANSendMessage(0x100, data, len(data), CAN_TX_PRIORITY_0)
        while True:
            CANIsRxReady()
    return main


def same_identifier(world, b_passive):
    """a sends 0x100 AA and b 0x100 BB at the same SOF, after a blocker's frame; c receives."""
    busy_bus(world)
    a = world.node("a", sender(b"\xAA"))
    b = world.node("b", sender(b"\xBB"))
    c = world.node("c", normal_node())
    world.run(0.0011)
    if b_passive:
        b.ecan.tec = 128               # as after 16 ACK errors alone on the bus
    return a, b, c


def first_difference(one, other):
    return next(k for k, (x, y) in enumerate(zip(encode(one), encode(other), strict=False)) if x != y)


def test_two_active_nodes_same_identifier_bit_error_at_the_first_differing_bit(world):
    a, b, c = same_identifier(world, b_passive=False)
    frame_a, frame_b = CanFrame(0x100, b"\xAA"), CanFrame(0x100, b"\xBB")
    differ = first_difference(frame_a, frame_b)
    assert encode(frame_b)[differ] == 1 and differ > 13, "b sends recessive there, after arbitration"
    event = until_events(world, 2)
    assert event.error.startswith(f"bit error at bit {differ}") and "(b)" in event.error
    assert event.flag_at_bit == differ + 1 and "two nodes sent identifier 0x100" in event.error
    assert a.ecan.tec == 8 and b.ecan.tec == 8


def test_a_passive_node_that_loses_on_data_does_not_destroy_the_other_frame(world):
    a, b, c = same_identifier(world, b_passive=True)
    event = until_events(world, 2)
    assert event.ok and event.sender == "a" and event.frame.data == b"\xAA" and "c" in event.acked_by
    assert a.ecan.tec == 0 and b.ecan.tec == 136, "b's passive flag saw the ACK slot dominant: +8"
    following = until_events(world, 3)
    assert following.ok and following.sender == "b" and b.ecan.tec == 135


# ------------------------------------------------------------------ a node at another bit rate
def wrong_rate_sender():
    CANInitialize(4, 8, 8, 4, 3, CAN_CONFIG_ALL_MSG)       # BRP 8: 156.25 kbit/s on a 125 kbit/s bus
    CANSendMessage(0x088, [1, 2, 3], 3, CAN_TX_PRIORITY_0)
    while True:
        CANIsRxReady()


def test_a_wrong_rate_frame_is_never_valid_for_a_listen_only_node_even_once_the_sender_is_passive(world):
    stored, invalid_only = [], []
    world.node("odd", wrong_rate_sender)
    world.node("quiet", normal_node(mode=CAN_OP_MODE_LISTEN, rxm=CAN_CONFIG_VALID_STD_MSG, received=stored))
    world.node("all", normal_node(mode=CAN_OP_MODE_LISTEN, received=invalid_only))
    world.run(0.04)
    assert world.bus.trace.total > 30 and not world.bus.frames()
    assert stored == [], "valid messages only: nothing"
    assert invalid_only and all(m.flags & CAN_RX_INVALID_MSG for m in invalid_only), \
        "error recognition (RXM = 11) keeps what it assembled, flagged invalid"


def test_a_passive_normal_node_neither_acks_nor_stores_a_wrong_rate_frame(world):
    stored = []
    world.node("odd", wrong_rate_sender)
    station = world.node("station", normal_node(rxm=CAN_CONFIG_VALID_STD_MSG, received=stored))
    world.run(0.0005)
    station.ecan.rec = 128             # error-passive, as after a run of receive errors
    world.run(0.04)
    assert world.bus.trace.total > 30 and station.ecan.error_passive
    assert stored == [] and not world.bus.frames()
    assert all(not e.acked_by for e in world.bus.trace)
