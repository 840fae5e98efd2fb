"""Resynchronisation within SJW (ISO 11898-1 bit timing): each node's bit clock from its own oscillator
(`Bus.set_oscillator_error`), hard synchronisation at SOF, each recessive-to-dominant edge pulling the sample point by
at most SJW. Two nodes whose oscillators are off in opposite directions by just under the standard's tolerance
exchange long frames without error; well beyond it, they cannot; SJW 1 against SJW 4 is the difference."""
from __future__ import annotations

import math
from fractions import Fraction

import pytest

from appsim.bus.bitlevel import Station, run_frame
from appsim.bus.wire import oscillator_clock, oscillator_tolerance
from appsim.can.bittiming import BitTiming, BitTimingError
from appsim.can.frame import CanFrame
from appsim.chip.clock import FOSC_HZ
from appsim.firmware import *
from appsim.workshop import tries

PAYLOADS, IDS = tries.DRIFT_PAYLOADS, tries.DRIFT_IDS     # long frames, the stuffing's worst cases among them
FRAMES = 12
ERROR_KINDS = ("bit error", "stuff error", "form error", "CRC error", "ACK error")


def classroom_timing(sjw):
    return BitTiming(sjw=sjw, brp=10, seg1ph=8, seg2ph=4, prseg=3)       # CANInitialize(sjw, 10, 8, 4, 3, ...)


def sender(sjw):
    def main():
        CANInitialize(sjw, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        Delay1KTCYx(10)                     # 1 ms: the oscillators are set meanwhile
        for n in range(FRAMES):
            while not CANSendMessage(IDS[n % len(IDS)], list(PAYLOADS[n % len(PAYLOADS)]), 8, CAN_TX_PRIORITY_0):
                pass
        while True:
            CANIsRxReady()
    return main


def receiver(sjw, got):
    def main():
        CANInitialize(sjw, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        while True:
            if CANIsRxReady():
                got.append(CANReceiveMessage())
    return main


def exchange(world, sjw, ppm_sender, ppm_receiver):
    """A sends FRAMES long frames to b, their oscillators off by these ppm; the data of the valid frames b received
    and the bus's errors."""
    got = []
    world.node("a", sender(sjw))
    world.node("b", receiver(sjw, got))
    world.run(0.0005)                       # both initialised, nothing sent yet
    world.bus.set_oscillator_error("a", ppm_sender)
    world.bus.set_oscillator_error("b", ppm_receiver)
    world.run(0.03)
    valid = [message.data for message in got if not message.flags & CAN_RX_INVALID_MSG]
    return valid, [event.error for event in world.bus.trace if not event.ok]


def tolerance_ppm(timing):
    """ISO 11898-1's oscillator tolerance: df <= SJW / (20 x bit) and df <= min(PS1, PS2) / (2 x (13 x bit - PS2)),
    bit and segments in TQ; each node may be off by df, so two nodes by 2 df from each other."""
    n, ps2 = timing.tq_per_bit, timing.effective_seg2ph
    df = min(Fraction(timing.sjw, 20 * n), Fraction(min(timing.seg1ph, ps2), 2 * (13 * n - ps2)))
    assert df == oscillator_tolerance(timing)
    return float(df) * 1e6


@pytest.mark.parametrize("sjw", [1, 4])
def test_bit_timing_two_nodes_just_inside_the_oscillator_tolerance_exchange_long_frames_without_error(world, sjw):
    df = tolerance_ppm(classroom_timing(sjw))
    assert round(df) == (3125 if sjw == 1 else 9804)        # SJW 1: the SJW rule; SJW 4: the phase-segment rule
    got, errors = exchange(world, sjw, 0.98 * df, -0.98 * df)
    assert errors == [] and sorted(got) == sorted(PAYLOADS[n % len(PAYLOADS)] for n in range(FRAMES))


@pytest.mark.parametrize("sjw", [1, 4])
def test_bit_timing_two_nodes_well_beyond_the_oscillator_tolerance_get_bit_stuff_form_errors(world, sjw):
    df = tolerance_ppm(classroom_timing(sjw))
    got, errors = exchange(world, sjw, 1.5 * df, -1.5 * df)
    assert len(errors) > FRAMES // 2 and len(got) < FRAMES
    assert all(error.startswith(ERROR_KINDS) for error in errors)
    assert all("oscillators off: a +" in error for error in errors)


def test_bit_timing_sjw_4_keeps_in_step_where_sjw_1_cannot(world):
    """At 5,000 ppm each way (1 % between the two) SJW 4 TQ catches the drift at every edge; 1 TQ does not."""
    got, errors = exchange(world, 4, 5000, -5000)
    assert errors == [] and len(got) == FRAMES
    other = type(world)()
    got, errors = exchange(other, 1, 5000, -5000)
    assert errors and len(got) < FRAMES


def test_bit_timing_without_resynchronisation_the_same_drift_breaks_the_frame():
    """What SJW buys: at 0.98 of the tolerance each way the two bit clocks drift 2 x 0.98 % of a bit apart a bit,
    more than a bit over a 130-bit frame. The bit engine with the resynchronisation (SJW 4) carries the frame; the
    same clocks kept on the grid of their SOF (`Station.sjw_tq` 0) do not."""
    timing = classroom_timing(4)
    df = tolerance_ppm(timing)
    assert 2 * 0.98 * df / 1e6 * 130 > 1
    frame = CanFrame(0x7F0, PAYLOADS[0])
    outcomes = {}
    for sjw in (4, 0):
        stations = []
        for name, ppm, sends in (("a", 0.98 * df, frame), ("b", -0.98 * df, None)):
            bit_ps, sample_ps, tq_ps, _ = oscillator_clock(timing, FOSC_HZ, ppm)
            stations.append(Station(name, False, bit_ps, sample_ps, 0, 0, sends, (), tq_ps, sjw))
        outcomes[sjw] = run_frame(0, stations).outcomes
    assert outcomes[4]["a"].transmitted and outcomes[4]["b"].received == frame and not outcomes[4]["b"].errors
    assert not outcomes[0]["a"].transmitted and outcomes[0]["b"].errors


def test_every_frame_runs_bit_by_bit_while_an_oscillator_is_off_and_whole_again_at_0_ppm(world):
    got = []
    world.node("a", sender(4))
    world.node("b", receiver(4, got))
    world.run(0.0005)
    world.bus.set_oscillator_error("a", 300)
    world.run(0.005)
    assert world.bus.trace[0].ok and world.bus.trace[0].wire, "run bit by bit: the wire recorded"
    seen = world.bus.trace.total
    world.bus.set_oscillator_error("a", 0)
    exact_from = world.sim.now
    world.run(0.005)
    later = [event for event in world.bus.trace if event.start_ps > exact_from]
    assert world.bus.trace.total > seen and later and not any(event.wire for event in later), \
        "exact again: simulated whole"


@pytest.mark.parametrize("ppm", ["300", math.nan, math.inf, 100_001, -200_000, True, None])
def test_an_oscillator_error_no_oscillator_has_is_refused_in_words(world, ppm):
    world.node("a", receiver(4, []))
    with pytest.raises(BitTimingError, match="an oscillator error is a number of ppm"):
        world.bus.set_oscillator_error("a", ppm)


def test_an_oscillator_error_for_a_node_not_on_the_bus_is_refused(world):
    with pytest.raises(KeyError, match="no node named 'nobody'"):
        world.bus.set_oscillator_error("nobody", 10)


@pytest.mark.parametrize(("sjw", "ppm", "said"), [(7, 100, "SJW = 7 TQ cannot be programmed"),
                                                  ("4", 100, "sjw must be an int"),
                                                  (4, "5000", "an oscillator error is a number of ppm")])
def test_01s_sjw_try_refuses_what_cannot_be_tried_in_words_not_a_traceback(sjw, ppm, said):
    drift = tries.oscillator_drift(sjw, ppm)
    assert str(drift).startswith("Not tried: ") and said in str(drift) and drift.sent == 0


@pytest.mark.parametrize("ppm", [100_000, -100_000])
def test_the_largest_oscillator_error_accepted_still_ends_every_frame(ppm):
    drift = tries.oscillator_drift(4, ppm)
    assert drift.received == 0 and drift.errors, "10 % off: nothing gets through, and the bus goes on"
