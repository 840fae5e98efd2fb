"""The tries that end notebooks 00 and 01, judged line by line as the exercises' checks are: your prediction of the
error counters against the kit's run, and a bit timing of your own (BRGCON1..3) on a bus at 250 kbit/s; and 01's SJW
try, two oscillators off in opposite directions.
"""
from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus, BusEvent, oscillator_tolerance
from appsim.can.bittiming import BitTiming
from appsim.chip.clock import FOSC_HZ
from appsim.chip.sfr import TMR1IF
from appsim.errors import BitTimingError
from appsim.firmware import SFR
from appsim.firmware.an738 import (
    CAN_CONFIG_FLAGS,
    CAN_OP_MODE,
    CAN_TX_MSG_FLAGS,
    CANInitialize,
    CANIsRxReady,
    CANReceiveMessage,
    CANSendMessage,
    CANSetOperationMode,
)
from appsim.firmware.timers import (
    T1_16BIT_RW,
    T1_OSC1EN_OFF,
    T1_PS_1_1,
    T1_PS_1_2,
    T1_PS_1_4,
    T1_PS_1_8,
    T1_SOURCE_INT,
    T1_SYNC_EXT_OFF,
    TIMER_INT_OFF,
    OpenTimer1,
)
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop.checks.trial import count
from appsim.workshop.checks.verdict import GREEN, RED, CheckResult, results_html, results_text

Counters = Mapping[str, tuple[int, int]]
"""Each board's (TEC, REC), by name."""
Prediction = Mapping[str, tuple[int | None, int | None]]
"""Your (TEC, REC) for each board, by name; None where you have not written one yet."""

BUS_RATE = 250_000                  # the bus of 01's try, bit/s
OTHERS = {"nodeA": 0x200, "nodeB": 0x210}
YOURS, YOUR_ID = "yours", 0x220
ALL_MSG = CAN_CONFIG_FLAGS.CAN_CONFIG_ALL_MSG
STANDARD = CAN_TX_MSG_FLAGS.CAN_TX_PRIORITY_0 & CAN_TX_MSG_FLAGS.CAN_TX_STD_FRAME
OTHERS_TIMING = BitTiming(sjw=4, brp=5, seg1ph=8, seg2ph=4, prseg=3)     # CANInitialize(4, 5, 8, 4, 3): 250 kbit/s
TRY_SECONDS = 0.3
TIMER1_PRESCALE = 2                 # Timer1 at Fosc/4, 1:2: a frame from each node every 13.1 ms


@dataclass(frozen=True, repr=False)
class Try:
    """What a try shows: one line per thing judged, and (01's try) the bus it ran on. Printed as the checks are."""

    title: str
    checks: tuple[CheckResult, ...]
    bus: Bus | None = None

    @property
    def score(self) -> int:
        return sum(check.passed for check in self.checks)

    @property
    def passed(self) -> bool:
        return all(check.passed for check in self.checks)

    def failed(self) -> list[CheckResult]:
        return [check for check in self.checks if not check.passed]

    def __str__(self) -> str:
        return f"{self.title}: {self.score}/{len(self.checks)}\n{results_text(self.checks)}"

    __repr__ = __str__

    def _repr_html_(self) -> str:
        colour = GREEN if self.passed else RED
        return (f"<div><b style='color:{colour}'>{html.escape(self.title)}: {self.score}/{len(self.checks)}</b>"
                f"{results_html(self.checks)}</div>")


# ---------------------------------------------------------------------------------------------------- 00: the counters
ERROR_HAPPENED = "the error you chose happened"
PREDICTED = "a prediction for every board"


def counters_line(board: str) -> str:
    return f"{board}'s TEC and REC"


def predicted_counters(prediction: Prediction, trace: Sequence[BusEvent], counters: Counters) -> Try:
    """Your (TEC, REC) for each board against what the kit counted in the run `trace` came from. The kit's numbers
    show only once you have written a prediction for every board: predict first."""
    failed = [e for e in trace if e.error]
    if failed:
        first = failed[0]
        after = next((e for e in trace[len(failed):] if e.ok), None)
        happened = CheckResult(ERROR_HAPPENED, True,
                               f"{count(len(failed), 'frame')} failed; the first: {first.error}, error flag from bit "
                               f"{first.flag_at_bit}. "
                               + (f"Then {after.frame} from {after.sender} went through." if after else
                                  "No frame went through after it."))
    else:
        happened = CheckResult(ERROR_HAPPENED, False,
                               "No frame failed: the error you chose never happened (a bit past the frame's end, "
                               "or a kind that node cannot see there: see the table of the five kinds).")
    lines = [happened]
    wrong = _unfinished(prediction, counters)
    if wrong:
        lines.append(CheckResult(PREDICTED, False, f"{wrong}. The kit's numbers show once you have predicted them "
                                                   "all."))
        lines += [CheckResult(counters_line(b), False, "Not judged yet.") for b in counters]
        return Try("Your prediction", tuple(lines))
    lines.append(CheckResult(PREDICTED, True, f"You predicted all {len(counters)} boards' counters."))
    for board, (tec, rec) in counters.items():
        said = tuple(prediction[board])
        right = said == (tec, rec)
        lines.append(CheckResult(counters_line(board), right,
                                 f"You said TEC {said[0]}, REC {said[1]}; the kit counted TEC {tec}, REC {rec}."
                                 + ("" if right else " Which rule did you leave out? (the rules are above the "
                                                     "table of the five kinds)")))
    return Try("Your prediction", tuple(lines))


def _unfinished(prediction: object, counters: Counters) -> str:
    """What is missing from, or wrong with, a prediction: '' when it gives two whole numbers for every board."""
    boards = ", ".join(counters)
    if not isinstance(prediction, Mapping):
        return f"prediction is a dict, {{board: (TEC, REC)}}, for {boards}; got {type(prediction).__name__}"

    def numbers(value: object) -> bool:
        return (isinstance(value, (tuple, list)) and len(value) == 2
                and all(isinstance(n, int) and not isinstance(n, bool) for n in value))
    missing = [b for b in counters if not numbers(prediction.get(b))]
    unknown = sorted(str(b) for b in set(prediction) - set(counters))
    why = [f"Write (TEC, REC), two whole numbers, for {', '.join(missing)}"] if missing else []
    if unknown:
        why.append(f"there is no board {', '.join(unknown)} (the boards: {boards})")
    return "; ".join(why)


# ---------------------------------------------------------------------------------------------------- 01: a bit timing
RATE = "BRGCON1..3 give 250 kbit/s"
RULES = "the data sheet's timing rules hold"
JOINS = "your node's frames go through"
CLEAN = "the bus stays clean"
TIMING_LINES = (RATE, RULES, JOINS, CLEAN)


def _sending(can_id: int) -> None:
    """Send `can_id` at each Timer1 overflow and read every frame received, as the exercises' stations do."""
    prescale = {1: T1_PS_1_1, 2: T1_PS_1_2, 4: T1_PS_1_4, 8: T1_PS_1_8}[TIMER1_PRESCALE]
    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & prescale & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
    while True:
        if SFR.PIR1 & 1 << TMR1IF:               # PIR1bits.TMR1IF
            SFR.PIR1 = SFR.PIR1 & ~(1 << TMR1IF)
            CANSendMessage(can_id, [1, 2, 3, 0, can_id & 0xFF], 5, STANDARD)
        if CANIsRxReady():
            CANReceiveMessage()


def _other_node(can_id: int):
    def main():
        CANInitialize(*OTHERS_TIMING.an738_arguments, ALL_MSG)
        _sending(can_id)
    return main


def _your_node(brgcon1: int, brgcon2: int, brgcon3: int):
    def main():
        CANInitialize(*OTHERS_TIMING.an738_arguments, ALL_MSG)
        CANSetOperationMode(CAN_OP_MODE.CAN_OP_MODE_CONFIG)        # BRGCON1..3 take writes in Configuration mode only
        SFR.BRGCON1, SFR.BRGCON2, SFR.BRGCON3 = brgcon1, brgcon2, brgcon3
        CANSetOperationMode(CAN_OP_MODE.CAN_OP_MODE_NORMAL)        # on the bus with your timing
        _sending(YOUR_ID)
    return main


def own_bit_timing(brgcon1: int, brgcon2: int, brgcon3: int, *, seconds: float = TRY_SECONDS) -> Try:
    """Your BRGCON1..3 on a board that joins a bus at 250 kbit/s, where two nodes (`CANInitialize(4, 5, 8, 4, 3)`)
    send at each Timer1 overflow (every 13.1 ms), for `seconds`: the bit rate and rules your registers give, and
    what your node did to the bus."""
    try:
        timing = BitTiming.from_registers(brgcon1, brgcon2, brgcon3)
    except (BitTimingError, TypeError) as error:
        reason = f"{error}: write each one as a byte, such as 0xC4"
        return Try("Your bit timing", (CheckResult(RATE, False, reason),
                                       *(CheckResult(n, False, "Not judged.") for n in TIMING_LINES[1:])))
    bus = Bus(Simulator(), BUS_RATE)
    for name, can_id in OTHERS.items():
        APP023(bus, name).run(_other_node(can_id))
    APP023(bus, YOURS).run(_your_node(brgcon1, brgcon2, brgcon3))
    bus.sim.run(until=round(seconds * PS_PER_SECOND))
    return Try("Your bit timing", (_rate(timing), _rules(timing), _joins(bus), _clean(bus)), bus)


def _rate(timing: BitTiming) -> CheckResult:
    rate = timing.bit_rate(FOSC_HZ)
    tq_us = float(timing.tq_seconds(FOSC_HZ)) * 1e6
    how = (f"TQ = 2 x (BRP<5:0> + 1) / 40 MHz = 2 x {timing.brp} / 40 MHz = {tq_us:g} µs, {timing.tq_per_bit} TQ a bit "
           f"({timing})")
    if not timing.seg2phts:
        how += (f"; SEG2PHTS (BRGCON2 bit 7) is 0, so Phase2 is max(Phase1, 2) = {timing.effective_seg2ph} TQ, not "
                f"SEG2PH + 1 = {timing.seg2ph}")
    if rate == BUS_RATE:
        return CheckResult(RATE, True, f"{float(rate) / 1000:g} kbit/s: {how}.")
    return CheckResult(RATE, False, f"{float(rate) / 1000:g} kbit/s, not {BUS_RATE // 1000}: {how}. The bit must be "
                                    f"{10**6 // BUS_RATE} µs: 2 x BRP x N / Fosc.")


def _rules(timing: BitTiming) -> CheckResult:
    problems = timing.problems()
    if problems:
        return CheckResult(RULES, False, "; ".join(problems) + ".")
    return CheckResult(RULES, True, "8 <= N <= 25, PS2 >= SJW, Prop + PS1 >= PS2, PS2 >= 2 TQ.")


def _joins(bus: Bus) -> CheckResult:
    mine = [e for e in bus.trace if e.sender == YOURS]
    through = [e for e in mine if e.ok]
    if mine and len(through) == len(mine):
        return CheckResult(JOINS, True, f"All {len(mine)} of its frames 0x{YOUR_ID:03X} went through, ACKed by "
                                        f"{', '.join(through[0].acked_by)}.")
    if through:
        return CheckResult(JOINS, False, f"{len(through)} of its {len(mine)} attempts went through.")
    return CheckResult(JOINS, False, f"None of its {len(mine)} attempts went through: "
                                     + (mine[0].error if mine else "it sent nothing") + ".")


def _clean(bus: Bus) -> CheckResult:
    errors = [e for e in bus.trace if e.error]
    counters = {b.name: (b.controller.tec, b.controller.rec) for b in bus.boards()}
    moved = {name: n for name, n in counters.items() if n != (0, 0)}
    if not errors and not moved:
        return CheckResult(CLEAN, True, f"No error frame in {len(bus.trace)} frames; every TEC and REC is 0.")
    first = f" The first: {errors[0].error}, in a frame from {errors[0].sender}." if errors else ""
    return CheckResult(CLEAN, False, f"{len(errors)} error frames in {len(bus.trace)};" + " ".join(
        f" {name} TEC {tec} REC {rec}" for name, (tec, rec) in moved.items()) + "." + first)


# ------------------------------------------------------------------ 01's SJW try: two oscillators off, long frames
DRIFT_FRAMES = 12
CLASSROOM_TIMING = BitTiming(sjw=4, brp=10, seg1ph=8, seg2ph=4, prseg=3)     # CANInitialize(4, 10, 8, 4, 3, ...)
DRIFT_PAYLOADS = (bytes([0x07, 0xC1, 0xF0, 0x7C, 0x1F, 0x07, 0xC1, 0xF0]),
                  bytes([0x0F, 0x83, 0xE0, 0xF8, 0x3E, 0x0F, 0x83, 0xE0]),
                  b"\xff" * 8, bytes(8), b"\x55" * 8, b"\x3c" * 8)
"""Long frames: first the stuffing's worst cases for resynchronisation (a recessive-to-dominant edge only every 10
bits: 00000 11111 00000 ...), then all ones and all zeros (an edge at each stuff bit, every 6 bits), an edge every
2 bits, and every 8."""
DRIFT_IDS = tuple(range(0x7F0, 0x7E9, -1))         # one after another, each frame's own (AN738 fills TXB0..TXB2)


@dataclass(frozen=True)
class Drift:
    """Two nodes with `CANInitialize(sjw, 10, 8, 4, 3, ...)`, one's oscillator `ppm` fast, the other's as slow: the
    tolerance the standard gives each for that SJW, and how many of the fast one's long frames the slow one got."""

    sjw: int
    ppm: float
    timing: BitTiming
    sent: int
    received: int
    errors: tuple[str, ...]
    refused: str = ""                   # why this SJW or ppm cannot be tried, in the workshop's words

    def __str__(self) -> str:
        if self.refused:
            return self.refused
        return self._report()

    __repr__ = __str__

    @property
    def tolerance_ppm(self) -> float:
        return float(oscillator_tolerance(self.timing)) * 1e6

    def _report(self) -> str:
        timing = self.timing
        n, ps2 = timing.tq_per_bit, timing.effective_seg2ph
        sjw_rule = self.sjw / (20 * n)
        phase_rule = min(timing.seg1ph, ps2) / (2 * (13 * n - ps2))
        lines = [f"SJW {self.sjw} TQ, {n} TQ a bit: each oscillator may be off by "
                 f"min(SJW / (20 x {n}) = {sjw_rule:.2%}, min(PS1, PS2) / (2 x (13 x {n} - {ps2})) = "
                 f"{phase_rule:.2%}) = {self.tolerance_ppm:,.0f} ppm",
                 f"yours: one node {self.ppm:+,g} ppm, the other {-self.ppm:+,g} ppm "
                 f"({abs(self.ppm) / self.tolerance_ppm:.2f} x the tolerance each)",
                 f"{self.received} of {self.sent} long frames received, {len(self.errors)} error frames"]
        lines += [f"  {error}" for error in self.errors[:3]]
        if len(self.errors) > 3:
            lines.append(f"  ... and {len(self.errors) - 3} more")
        return "\n".join(lines)


def _drifting_sender(sjw: int) -> None:
    CANInitialize(sjw, 10, 8, 4, 3, ALL_MSG)
    for n in range(DRIFT_FRAMES):
        payload = DRIFT_PAYLOADS[n % len(DRIFT_PAYLOADS)]
        while not CANSendMessage(DRIFT_IDS[n % len(DRIFT_IDS)], list(payload), len(payload), STANDARD):
            pass
    while True:
        CANIsRxReady()


def _drifting_receiver(sjw: int, got: list[bytes]) -> None:
    CANInitialize(sjw, 10, 8, 4, 3, CAN_CONFIG_FLAGS.CAN_CONFIG_VALID_STD_MSG)
    while True:
        if CANIsRxReady():
            got.append(bytes(CANReceiveMessage().data))


def oscillator_drift(sjw: int, ppm: float) -> Drift:
    """`CANInitialize(sjw, 10, 8, 4, 3, ...)` on two nodes of the classroom's bus, the sender's oscillator `ppm`
    fast and the receiver's `ppm` slow (`Bus.set_oscillator_error`): 12 long frames from one to the other."""
    bus = Bus(Simulator())
    got: list[bytes] = []
    try:
        timing = BitTiming(sjw=sjw, brp=10, seg1ph=8, seg2ph=4, prseg=3)
        APP023(bus, "fast").run(lambda: _drifting_sender(sjw))
        APP023(bus, "slow").run(lambda: _drifting_receiver(sjw, got))
        bus.set_oscillator_error("fast", ppm)
        bus.set_oscillator_error("slow", -ppm)
    except (BitTimingError, TypeError) as error:
        return Drift(sjw, ppm, CLASSROOM_TIMING, 0, 0, (), f"Not tried: {error}.")
    bus.sim.run(until=PS_PER_SECOND * 3 // 100)                         # 30 ms: 12 frames of 8 bytes and retries
    return Drift(sjw, ppm, timing, DRIFT_FRAMES, len(got), tuple(e.error for e in bus.trace if e.error))
