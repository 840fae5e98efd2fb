"""Bus-level behaviour the workshop relies on: ACK, arbitration, fault confinement, silent modes."""
from __future__ import annotations

from appsim.bus.controller import Mode
from appsim.chip.sfr import current_mcu
from appsim.firmware import *
from appsim.firmware.runtime import CALL_CYCLES

CLASSROOM = (4, 10, 8, 4, 3)



def wait_tenths_of_ms(units: int) -> None:
    """What Delay1KTCYx(units) waits, for any count: C18's takes 1..255 (0 means 256), these waits are longer."""
    current_mcu().spend_cycles(CALL_CYCLES + 1_000 * units)

def normal_node(sends=(), mode=CAN_OP_MODE_NORMAL, rxm=CAN_CONFIG_ALL_MSG, received=None, delay_ms=0.0):
    def main():
        CANInitialize(*CLASSROOM, rxm)
        if mode != CAN_OP_MODE_NORMAL:
            CANSetOperationMode(mode)
        wait_tenths_of_ms(round(delay_ms * 10))
        for can_id, flags in sends:
            CANSendMessage(can_id, [1, 2, 3], 3, flags)
        while True:
            if CANIsRxReady() and received is not None:
                received.append(CANReceiveMessage())
    return main


def test_lone_node_in_normal_mode_climbs_to_tec_128_and_stays_error_passive_never_bus_off(world):
    node = world.node("alone", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    world.run(0.5)
    assert node.ecan.tec == 128 and node.ecan.error_passive and not node.ecan.bus_off
    errors = [e.error for e in world.bus.trace]
    assert len(errors) > 100 and all(e.startswith("ACK error") for e in errors)


def test_normal_mode_never_receives_its_own_frame(world):
    got = []
    world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)], received=got))
    world.node("b", normal_node())
    world.run(0.05)
    assert [e.frame.can_id for e in world.bus.frames()] == [0x100] and got == []


def test_listen_only_node_never_acks_so_the_transmitter_sees_ack_errors(world):
    got = []
    # CANInitialize returns in Normal mode: until the listener reaches Listen-only it would ACK.
    sender = world.node("sender", normal_node([(0x088, CAN_TX_PRIORITY_0)], delay_ms=5))
    listener = world.node("listener", normal_node(mode=CAN_OP_MODE_LISTEN, received=got))
    world.run(0.1)
    assert all(not e.acked_by for e in world.bus.trace)
    assert sender.ecan.tec == 128 and listener.ecan.opmode == Mode.LISTEN_ONLY
    assert listener.ecan.tec == listener.ecan.rec == 0
    assert got and got[0].id == 0x088, (
        "once the sender is error-passive its recessive error flag leaves the frame valid for listeners")


def busy_bus(world):
    """A node whose 0x7FF frame holds the bus from 1.0 ms to about 1.6 ms: others queue meanwhile."""
    world.node("blocker", normal_node([(0x7FF, CAN_TX_PRIORITY_0)], delay_ms=1.0))


def test_arbitration_lowest_id_first_standard_before_extended_data_before_remote(world):
    busy_bus(world)
    sends = [(0x100, CAN_TX_PRIORITY_0), (0x088 << 18, CAN_TX_PRIORITY_0 & CAN_TX_XTD_FRAME)]
    world.node("a", normal_node(sends, delay_ms=1.2))
    world.node("b", normal_node([(0x088, CAN_TX_PRIORITY_0 & CAN_TX_RTR_FRAME)], delay_ms=1.2))
    world.node("c", normal_node([(0x088, CAN_TX_PRIORITY_0)], delay_ms=1.2))
    world.run(0.05)
    order = [(e.sender, e.frame.can_id, e.frame.extended, e.frame.remote) for e in world.bus.frames()]
    assert order == [("blocker", 0x7FF, False, False), ("c", 0x088, False, False), ("b", 0x088, False, True),
                     ("a", 0x088 << 18, True, False), ("a", 0x100, False, False)]


def test_three_queued_equal_priority_frames_leave_txb2_txb1_txb0(world):
    busy_bus(world)
    world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0), (0x200, CAN_TX_PRIORITY_0),
                                 (0x300, CAN_TX_PRIORITY_0)], delay_ms=1.2))
    world.run(0.05)
    assert [e.frame.can_id for e in world.bus.frames()] == [0x7FF, 0x300, 0x200, 0x100], (
        "TXB0=0x100, TXB1=0x200, TXB2=0x300 queued while the bus was busy: the higher buffer "
        "number goes first, whatever the identifiers")


def test_node_at_the_wrong_bit_rate_cannot_talk_and_its_error_counter_climbs(world):
    def wrong():
        CANInitialize(4, 8, 8, 4, 3, CAN_CONFIG_ALL_MSG)      # BRP 8: 156.25 kbit/s on a 125 kbit/s bus
        while True:
            CANIsRxReady()
    world.node("master", normal_node([(0x088, CAN_TX_PRIORITY_0)]))
    world.node("station", normal_node())
    odd = world.node("odd", wrong)
    world.run(0.05)
    assert odd.ecan.rec > 127, "it destroys frames with error flags until it is error-passive"
    assert world.bus.frames() and world.bus.frames()[-1].frame.can_id == 0x088
    assert any("bit timing does not match" in e.error for e in world.bus.trace)


def test_trace_is_identical_when_the_same_scenario_runs_twice():
    from conftest import World

    def scenario():
        w = World()
        for k in range(7):
            w.node(f"n{k}", normal_node([(0x100 + 0x10 * k, CAN_TX_PRIORITY_0), (0x081 + k, CAN_TX_PRIORITY_1)]))
        w.run(0.05)
        return w.bus.trace
    first, second = scenario(), scenario()
    assert len(first) == 14 and first == second


def test_bus_off_after_repeated_errors_and_recovery_after_128_sequences_of_11_recessive_bits(world):
    """A node that sees a bit error in each of its frames (injected): TEC += 8 each time, error-passive at 128,
    bus-off at 256 (32 frames). Bus-off ends after 128 x 11 recessive bits, with TEC = REC = 0."""
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    world.node("listener", normal_node())
    world.bus.inject("a", "bit", 20, frames=32)
    while not a.ecan.bus_off:
        world.run(0.001)
        assert world.sim.now < 100 * world.bus.bit_ps * 32 * 2, "never went bus-off"
    trace = world.bus.trace
    assert len(trace) == 32 and all(e.error.startswith("bit error at bit 20") for e in trace)
    assert a.ecan.tec == 256
    recessive_from = trace[-1].end_ps - 8 * world.bus.bit_ps     # the error delimiter is recessive
    world.run(0.012)
    back = world.bus.trace[32]
    assert (back.start_ps - recessive_from) // world.bus.bit_ps == 128 * 11
    assert back.ok and a.ecan.tec == 0 and not a.ecan.error_passive, "recovered error-active, counters reset"


def test_leaving_loopback_waits_for_11_recessive_bits_as_leaving_configuration_does(world):
    times = {}

    def main():
        CANInitialize(*CLASSROOM, CAN_CONFIG_ALL_MSG)
        for mode in (CAN_OP_MODE_LOOP, CAN_OP_MODE_NORMAL):
            asked = world.sim.time()
            CANSetOperationMode(mode)           # returns once OPMODE shows the mode
            times[mode] = world.sim.time() - asked
        while True:
            CANIsRxReady()

    world.node("n", main)
    world.run(0.01)
    bit = world.bus.bit_ps
    assert times[CAN_OP_MODE_LOOP] < bit, "from Normal on an idle bus: the bus's recessive bits were counted"
    assert 11 * bit <= times[CAN_OP_MODE_NORMAL] < 12 * bit
