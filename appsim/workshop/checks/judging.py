"""Judgments several exercises share: is the node on the bus, does it send once per Timer1 overflow, right frames.

Each returns a `CheckResult` whose message says what was seen and what to look at, in the workshop's words.
"""
from __future__ import annotations

from itertools import pairwise

from appsim.bus.wire import BusEvent
from appsim.firmware.identity import shown
from appsim.workshop.checks.trial import (
    MS,
    TIMER1_PERIOD_PS,
    Trial,
    count,
    describe,
    hex_id,
    ms,
    payload,
)
from appsim.workshop.checks.verdict import CheckResult

TIMER1_SLACK_PS = 6 * MS          # a frame queued on the overflow may wait for a few frames on the bus
BURST_GAP_PS = 3 * MS             # closer than this, frames follow each other as fast as the bus allows


def why_silent(trial: Trial) -> str:
    """Why the student's node put no frame on the bus, from its mode and the loopback trace."""
    looped = [e for e in trial.bus.loopback_trace if e.sender == trial.name]
    if looped:
        return (f"{len(looped)} frame(s) ({describe(looped[0].frame)}) went round inside the node: it is in "
                "Loopback mode, where the ECAN never drives CANTX. CANInitialization() must end with "
                "CANSetOperationMode(CAN_OP_MODE_NORMAL)")
    mode = trial.mode()
    if mode == "Listen-only":
        return ("the node is in Listen-only mode, which receives but never sends nor ACKs: "
                "CANSetOperationMode(CAN_OP_MODE_NORMAL) puts it on the bus")
    if mode == "Normal":
        return ("the node is in Normal mode but never asked to send: is CANSendMessage() reached, "
                "on every TMR1 overflow (PIR1bits.TMR1IF)?")
    return (f"the node is in {mode} mode: CANInitialization() must end with "
            "CANSetOperationMode(CAN_OP_MODE_NORMAL)")


def master_kept_off(trial: Trial) -> str:
    """Why the master's 0x088 never went through the bus: the student's node kept it off, in the workshop's words."""
    mine = trial.sent()
    if mine:
        return (f"The master's 0x088 never went through the bus: your node sent {count(len(mine), 'frame')} "
                f"({describe(mine[0].frame)} first) back to back, each winning arbitration against 0x088 (the lower "
                "identifier wins) or destroying it, so no station heard the master. Send once per Timer1 overflow "
                "(clear PIR1bits.TMR1IF), with MESSAGE_ID1.")
    return "The master's 0x088 never went through the bus, so there was nothing to judge by."


def heard_nothing(trial: Trial, events: list[BusEvent]) -> bool:
    """The student's node took part in none of `events` (it was not on the bus, in Normal or Listen-only mode, when
    they went by): a check of what it leaves undone with them has nothing to judge."""
    return not any(trial.reception(e) for e in events)


def nothing_to_judge(trial: Trial, what: str) -> str:
    """Why a check of what the node leaves undone fails when the node never took part: doing nothing is no merit."""
    return (f"Nothing to judge: your node {what} (it is in {trial.mode()} mode), and a check of what a node leaves "
            "undone gives no point for doing nothing. See the checks above.")


def sent_anywhere(trial: Trial) -> list[BusEvent]:
    """The student's frames on the bus, or if none, the ones that went round inside it in Loopback mode."""
    return trial.sent() or [e for e in trial.bus.loopback_trace if e.sender == trial.name]


def on_the_bus(trial: Trial, name: str) -> CheckResult:
    """The node sends frames that go through on the bus (Normal mode, right bit rate)."""
    events = trial.sent()
    if not events:
        return CheckResult(name, False, f"No frame from your node reached the bus: {why_silent(trial)}.")
    errors = [e for e in events if not e.ok]
    if errors:
        return CheckResult(name, False, f"{len(errors)} of {len(events)} frames from your node ended in errors "
                                        f"({errors[0].error}). A node whose bit timing is not the bus's "
                                        "125 kbit/s cannot talk to it: CANInitialize(4, 10, 8, 4, 3, ...) at "
                                        "Fosc = 40 MHz gives 125 kbit/s.")
    acks = sorted({name for e in events for name in e.acked_by})
    return CheckResult(name, True, f"{count(len(events), 'frame')} on the bus in {trial.mode()} mode, ACKed by "
                                   f"{', '.join(acks)}.")


def data_frames(trial: Trial, name: str, events: list[BusEvent]) -> CheckResult:
    """Every frame is a data frame with MESSAGE_ID1 and 01 02 03 ADRESH ADRESL of the potentiometer. With a MESSAGE_ID1
    that is no station's the frames are judged against it all the same, and the check fails for it."""
    potentiometer = trial.board.adc.potentiometer
    expected = payload(potentiometer)
    problem = trial.identity_problem
    if not events:
        return CheckResult(name, False, "No frame from your node to look at (see the check above)."
                           + (f" {problem}" if problem else ""))
    for event in events:
        frame = event.frame
        if frame.remote or frame.can_id != trial.own_id or frame.data != expected:
            return CheckResult(name, False, f"Sent {describe(frame)} at {ms(event.start_ps)}; expected "
                                            f"{shown(trial.own_id)} DATA {expected.hex(' ').upper()}: "
                                            f"{_what_differs(trial, frame, expected)}" + (f". {problem}" if problem
                                                                                          else ""))
    frames = f"{count(len(events), 'frame')} {shown(trial.own_id)} DATA {expected.hex(' ').upper()}"
    if problem:
        return CheckResult(name, False, f"{problem} Otherwise right: {frames} (the potentiometer reads "
                                        f"{potentiometer}).")
    return CheckResult(name, True, f"{frames} (the potentiometer reads {potentiometer}).")


def _what_differs(trial: Trial, frame, expected: bytes) -> str:
    if frame.remote:
        return "a remote frame (RTR) carries no data; send with CAN_TX_NO_RTR_FRAME and DataLen 5"
    if frame.can_id != trial.own_id and trial.identity_problem:
        return f"the identifier is MESSAGE_ID1, {shown(trial.own_id)} in your file"
    if frame.can_id != trial.own_id:
        return (f"the identifier is MESSAGE_ID1, {hex_id(trial.own_id)} for station {trial.station} "
                f"(0x100 + 0x10 per station)")
    if frame.data[:3] != expected[:3] or len(frame.data) != 5:
        return "the payload is 5 bytes, 01 02 03 then ADRESH ADRESL (TxData with DataLen 5)"
    value = (frame.data[3] << 8) | frame.data[4]
    if frame.data[3:] == expected[:2:-1]:
        return "ADRESH and ADRESL are swapped: byte 3 is ADRESH (the top 2 bits), byte 4 ADRESL"
    return (f"bytes 3 and 4 say {value}, but the potentiometer reads {trial.board.adc.potentiometer}: read "
            "the A/D (ConvertADC(), wait while BusyADC(), then ADRESH and ADRESL) before each send")


def once_per_overflow(name: str, events: list[BusEvent], what: str = "frame") -> CheckResult:
    """Frames 52.4288 ms apart (one per Timer1 overflow), give or take the wait for a busy bus.

    Frames that ended in errors are left out of `events`' period: the ECAN sends them again by itself.
    """
    errors = [e for e in events if not e.ok]
    if errors:
        return CheckResult(name, False, f"{count(len(errors), what)} ended in errors and the ECAN sent them again by "
                                        "itself, so the period cannot be seen (see the check on the bus).")
    if len(events) < 2:
        return CheckResult(name, False, f"{count(len(events), what)} sent: not enough to see a period "
                                        "(see the checks above).")
    gaps = [b.start_ps - a.start_ps for a, b in pairwise(events)]
    period = TIMER1_PERIOD_PS
    shortest, longest = min(gaps), max(gaps)
    spread = ms(shortest) if ms(shortest) == ms(longest) else f"{ms(shortest)} .. {ms(longest)}"
    seen = f"{count(len(events), what)}, {spread} apart"
    if all(abs(gap - period) <= TIMER1_SLACK_PS for gap in gaps):
        return CheckResult(name, True, f"{seen} (Timer1 overflows every {ms(period)}).")
    if shortest < BURST_GAP_PS:
        return CheckResult(name, False, f"{seen}: a burst, as fast as the bus takes them. PIR1bits.TMR1IF stays 1 "
                                        "until the firmware clears it, so every turn of the loop sends again: write "
                                        "PIR1bits.TMR1IF = 0 right after testing it (TMR1_OVERFLOW).")
    return CheckResult(name, False, f"{seen}; expected one per Timer1 overflow, every 52.4288 ms: Timer1 on "
                                    "Fosc/4 with a 1:8 prescaler (OpenTimer1(... T1_SOURCE_INT & T1_PS_1_8 ...)), "
                                    "one send each time PIR1bits.TMR1IF is 1, then clear it.")
