"""ISO 11898-1's error handling where the kit once departed from it, each test named after its clause: rule 8
counted at the ACK slot, a receiver's bit error in the ACK slot, a dominant third intermission bit as a start of
frame, a recessive SOF that is no frame yet, and a node that goes bus-off in the middle of a frame."""
from __future__ import annotations

from test_bus_gotchas import normal_node
from test_fault_confinement import ACK_DELIMITER, FRAME, counters, three_nodes, until_events

from appsim.can.bits import frame_bits
from appsim.firmware import *

ACK_SLOT = ACK_DELIMITER - 1
INTERMISSION = frame_bits(FRAME)            # a's 0x100 01 02 03: bits 0..72, intermission 73, 74, 75


def dominant_bits(event, bit_ps, after_bit):
    """The bus bits (SOF = 0) of `event` at or after `after_bit` where the wire was dominant."""
    changes = event.wire_changes() + [(event.end_ps + 30 * bit_ps, 1)]
    bits = set()
    for (time, level), (until, _) in zip(changes, changes[1:], strict=False):
        if level == 0:
            bits.update(range((time - event.start_ps) // bit_ps, (until - event.start_ps) // bit_ps))
    return sorted(bit for bit in bits if bit >= after_bit)


def test_12_1_4_2_h_rule_8_rec_counts_down_at_the_ack_slot_so_a_form_error_after_it_leaves_rec_1_at_1(world):
    """Rule 8: "reception without error up to the ACK slot and the successful sending of the ACK bit" counts REC
    down; a form error after the ACK slot counts it up again: -1 then +1."""
    a, b, c = three_nodes(world)
    world.bus.inject("b", "crc", frames=2)     # b flags at EOF 1 twice; c ACKed, then reads b's flag: a form error
    first = until_events(world, 1)
    assert dict(first.received)["c"].startswith(f"form error at bit {ACK_DELIMITER + 1}: end-of-frame bit 1")
    assert c.ecan.rec == 1, "from 0: -1 stays 0 (rule 8 counts 1..127 down), +1 (rule 1)"
    second = until_events(world, 2)
    assert dict(second.received)["c"].startswith(f"form error at bit {ACK_DELIMITER + 1}")
    assert c.ecan.rec == 1, "from 1: -1 at the ACK slot, +1 at the form error (the kit once counted 2)"
    assert counters(a, b) == [(16, 0), (0, 18)], "b never ACKed (its CRC failed): +9 twice, no rule 8"
    third = until_events(world, 3)
    assert third.ok and counters(a, b, c) == [(15, 0), (0, 17), (0, 0)], "the frame valid at EOF bit 6: -1 each"


def test_12_1_4_2_h_rule_8_a_passive_receiver_is_error_active_again_from_its_ack_slot(world):
    """REC above 127 goes back to 127 at the ACK slot: the receiver's flag for a form error after it is active."""
    a, b, c = three_nodes(world)
    c.ecan.rec = 130
    world.bus.inject("c", "form", ACK_DELIMITER + 3)       # EOF bit 3 read dominant, after c's ACK
    event = until_events(world, 1)
    assert event.error.startswith(f"form error at bit {ACK_DELIMITER + 3}") and "(c)" in event.error
    assert event.flag_at_bit == ACK_DELIMITER + 4, "an active flag: a and b see it and flag too"
    assert dict(event.received)["b"].startswith(f"form error at bit {ACK_DELIMITER + 4}")
    assert c.ecan.rec == 127 + 1 + 8, "127 at the ACK slot, +1 (rule 1), +8 (rule 2: b's flag after its own)"


def test_12_1_4_2_h_rule_8_frame_validity_stays_at_eof_bit_6_for_receivers(world):
    """A dominant last EOF bit: the frame stands for receivers (an overload frame follows), REC counted once."""
    a, b, c = three_nodes(world)
    c.ecan.rec = 5
    world.bus.inject("c", "form", ACK_DELIMITER + 7)        # EOF bit 7
    event = until_events(world, 1)
    assert event.ok and "c" in event.acked_by and c.ecan.rec == 4


def test_bit_monitoring_a_receiver_that_sends_its_ack_and_reads_recessive_has_a_bit_error_in_the_ack_slot(world):
    """Every node that sends a bit monitors it: a receiver's dominant ACK read recessive is a bit error, flag from
    the ACK delimiter (the next bit)."""
    a, b, c = three_nodes(world)
    world.bus.inject("b", "bit", ACK_SLOT)       # b drives its ACK and reads recessive
    event = until_events(world, 1)
    assert event.error.startswith(f"bit error at bit {ACK_SLOT}: sent dominant, read recessive (the ACK slot)")
    assert "(b)" in event.error and event.flag_at_bit == ACK_DELIMITER
    assert not event.ok and not dict(event.received)["c"].startswith("RX")
    # c's ACK reached a: no ACK error; a and c read b's flag in the ACK delimiter: a form error.
    assert dict(event.received)["c"].startswith(f"form error at bit {ACK_DELIMITER}")
    assert counters(a, b, c) == [(8, 0), (0, 9), (0, 1)], "a +8; b +1 +8 (a's flag after its own); c -1 (0) +1"
    assert until_events(world, 2).ok


def pending_behind(world):
    """a sends 0x100 and b 0x200 at the same SOF: b loses and waits; c receives."""
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)], delay_ms=1))
    b = world.node("b", normal_node([(0x200, CAN_TX_PRIORITY_0)], delay_ms=1))
    c = world.node("c", normal_node())
    world.run(0.0009)
    return a, b, c


def test_intermission_a_dominant_third_bit_is_a_start_of_frame_the_pending_frame_starts_its_identifier_next(world):
    """ISO 11898-1, intermission: a node with a frame waiting that reads dominant in the third intermission bit takes
    it as SOF and sends its identifier from the next bit: no overload frame."""
    a, b, c = pending_behind(world)
    world.bus.inject("c", "dominant", INTERMISSION + 2)     # c's transceiver: the third intermission bit dominant
    first = until_events(world, 1)
    assert first.ok and first.sender == "a"
    assert "overload" not in " ".join(what for _, what in first.received)
    second = until_events(world, 2)
    assert second.ok and second.sender == "b" and second.frame.can_id == 0x200
    assert (second.start_ps - first.start_ps) // world.bus.bit_ps == INTERMISSION + 2, \
        "b's SOF is the dominant bit: its identifier from the next bit (not 18 bits later, after an overload frame)"
    assert counters(a, b, c) == [(0, 0), (0, 0), (0, 0)]


def test_intermission_a_dominant_first_bit_is_still_an_overload_condition(world):
    a, b, c = pending_behind(world)
    world.bus.inject("c", "dominant", INTERMISSION)
    first = until_events(world, 1)
    assert first.ok
    second = until_events(world, 2)
    # an overload flag from the next bit (6), its delimiter (8), the intermission (3): b's SOF after them
    assert (second.start_ps - first.start_ps) // world.bus.bit_ps == INTERMISSION + 1 + 6 + 8 + 3


def test_sof_a_receiver_that_reads_sof_recessive_sees_no_frame_yet(world):
    """A receiver that samples SOF recessive has not seen a frame begin: no error there (the kit once reported "form
    error: a recessive SOF"); it takes the next dominant bit as the SOF."""
    a, b, c = three_nodes(world)
    world.bus.inject("b", "bit", 0)
    event = until_events(world, 1)
    said = dict(event.received)["b"]
    assert "SOF" not in said and "at bit 0" not in said and "form error at bit 0" not in event.error
    assert event.flag_at_bit is None or event.flag_at_bit > 1


def test_12_1_4_2_j_a_node_that_goes_bus_off_in_a_frame_has_no_influence_on_the_bus_from_then_on(world):
    """Bus-off at its 32nd bit error: from that bit it drives nothing, not even an overload flag where it would read
    dominant in its intermission."""
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    world.node("listener", normal_node())
    world.bus.inject("a", "bit", 20, frames=32)
    until_events(world, 31)
    assert a.ecan.tec == 248
    # a's passive flag 21..30 (six equal bits: the listener's flag 25..30), delimiter 31..38, intermission 39..41
    world.bus.inject("a", "form", 39)
    event = until_events(world, 32)
    assert a.ecan.bus_off
    assert dominant_bits(event, world.bus.bit_ps, 31) == [], "nobody drives dominant after the listener's flag"
    assert "overload" not in dict(event.received)["listener"]
    not_fired = world.bus.injections.not_fired()
    assert len(not_fired) == 1 and "never fired" in not_fired[0], "bus-off, a reads nothing any more"
