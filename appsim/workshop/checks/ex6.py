"""Ex6's checks: silent unless polled; an RTR for MESSAGE_ID1 (in RXB1) is answered with the A/D, RTRs for other
IDs are not, nor is a data frame with the own ID. A test node of the check's own puts those frames on the bus; the
data frames with the station's ID make it a faulty node, since only the station itself sends those on a correct bus.
"""
from __future__ import annotations

from appsim.bus.wire import BusEvent
from appsim.chip.sfr import current_mcu
from appsim.firmware import Delay1KTCYx
from appsim.firmware.an738 import (
    CAN_CONFIG_FLAGS,
    CAN_TX_MSG_FLAGS,
    CANInitialize,
    CANSendMessage,
)
from appsim.firmware.runtime import CALL_CYCLES
from appsim.workshop.checks.ex3 import master_frames
from appsim.workshop.checks.judging import data_frames, why_silent
from appsim.workshop.checks.trial import MS, Trial, count, describe, hex_id, listing, ms, took
from appsim.workshop.checks.verdict import CheckResult
from appsim.workshop.course import station_ids

ANSWERS = "answers an RTR for MESSAGE_ID1 with its A/D"
RXB1 = "RXB1 takes only MESSAGE_ID1"
SILENT = "silent unless polled"
DATA = "ignores a faulty node's data frame with its own ID"
NAMES = (ANSWERS, RXB1, SILENT, DATA)
SECONDS = 0.17                    # the test node's frames from 65 ms, the master's first poll at ~100 ms
ANSWER_WITHIN_PS = 2 * MS         # read RXB1, read the A/D, CANSendMessage: well under a millisecond
RTR_TEST = "the test RX_ID2 == MESSAGE_ID1 {and} CANMessageFlag & CAN_RX_RTR_FRAME"


def rtr_test(trial: Trial) -> str:
    return RTR_TEST.format(**{"and": trial.firmware.says("and", "&&")})
STANDARD, REMOTE = CAN_TX_MSG_FLAGS.CAN_TX_STD_FRAME, CAN_TX_MSG_FLAGS.CAN_TX_RTR_FRAME


def test_node(own_id: int, other_id: int):
    """The check's test node: a data frame with the station's ID, RTRs for another station, for the station
    (twice), and for an ID one bit away from it, 10-20 ms apart once the station is on the bus.

    The data frames with the station's ID are a fault case: on a correct bus one node sends the data frames of an
    identifier, here the station. They are timed away from the polls, so a correct station's answer and the test
    node's data frame never meet in arbitration."""
    schedule = ((65, own_id, False), (75, other_id, True), (85, own_id, True), (105, own_id | 1, True),
                (125, own_id, False), (135, own_id, True))

    def main() -> None:
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_FLAGS.CAN_CONFIG_ALL_MSG)
        now = 0
        for at_ms, can_id, remote in schedule:
            current_mcu().spend_cycles(CALL_CYCLES + 10_000 * (at_ms - now))    # Delay1KTCYx((at_ms - now) * 10)
            now = at_ms
            data = None if remote else [9, 9, 9, 9, 9]
            flags = STANDARD & REMOTE if remote else STANDARD
            while not CANSendMessage(can_id, data, 0 if remote else 5, flags):
                Delay1KTCYx(1)
        while True:
            Delay1KTCYx(250)
    return main


def run(trial: Trial) -> list[CheckResult]:
    room = trial.classroom(6, stations=2)
    other_id = next(station_ids(k)["MESSAGE_ID1"] for k in room.stations if k != trial.station)
    trial.node("tester", test_node(trial.own_id, other_id))
    trial.run(SECONDS)
    broadcasts = master_frames(trial)
    joined = broadcasts[0].end_ps if broadcasts else 0     # Listen-only until then, as in Ex4
    frames = [e for e in trial.bus.frames() if e.sender != trial.name and e.end_ps > joined]
    polls = [e for e in frames if e.frame.remote and e.frame.can_id == trial.own_id]
    mine = trial.sent()
    answers: dict[int, BusEvent] = {}
    for poll in polls:
        reply = next((s for s in mine if poll.end_ps <= s.start_ps < poll.end_ps + ANSWER_WITHIN_PS
                      and id(s) not in {id(a) for a in answers.values()}), None)
        if reply is not None:
            answers[id(poll)] = reply
    unasked = [(s, _trigger(trial, frames, s)) for s in mine if all(s is not a for a in answers.values())]
    if not mine:                        # silence is right only for a node that answers when asked
        idle = ("Nothing to judge: your node sent no frame at all, not one answer to the polls (see the first "
                "check). Silence is right only for a node that answers when asked.")
        return [_answers(trial, polls, answers), _rxb1(trial, frames), CheckResult(SILENT, False, idle),
                CheckResult(DATA, False, idle)]
    return [_answers(trial, polls, answers), _rxb1(trial, frames), _silent(trial, unasked), _data(trial, unasked)]


def _trigger(trial: Trial, frames: list[BusEvent], sent: BusEvent) -> BusEvent | None:
    """The frame the node took in just before it sent `sent` (what it was answering), if any."""
    before = [e for e in frames if sent.start_ps - ANSWER_WITHIN_PS <= e.end_ps <= sent.start_ps
              and took(trial.reception(e))]
    return before[-1] if before else None


def _answers(trial: Trial, polls, answers) -> CheckResult:
    if not polls:
        return CheckResult(ANSWERS, False, "No RTR for MESSAGE_ID1 went through the bus to judge by.")
    missed = [p for p in polls if id(p) not in answers]
    if missed:
        poll = missed[0]
        outcome = trial.reception(poll)
        if not outcome:
            why = f"your node was not on the bus to receive it ({why_silent(trial)})"
        elif not took(outcome):
            why = (f"it never reached a receive buffer ({outcome}): {trial.acceptance('RXB1')}. One of "
                   f"RX_Filter2..RX_Filter5 must equal MESSAGE_ID1 = {hex_id(trial.own_id)} (see the TODO)")
        else:
            why = (f"it went into {outcome}, but the node sent nothing back: after CANReceiveMessage() from RXB1, "
                   f"if {rtr_test(trial)}, read the A/D and send MESSAGE_ID1 with 01 02 03 ADRESH ADRESL "
                   "(see the TODO)")
        return CheckResult(ANSWERS, False, f"{len(missed)} of {count(len(polls), 'RTR')} for {hex_id(trial.own_id)} "
                                           f"got no answer. The one from {poll.sender} at {ms(poll.start_ps)}: {why}.")
    content = data_frames(trial, ANSWERS, list(answers.values()))
    if not content.passed:
        return content
    return CheckResult(ANSWERS, True, f"Each of the {count(len(polls), 'RTR')} for {hex_id(trial.own_id)} (from "
                                      f"{', '.join(sorted({p.sender for p in polls}))}) was answered with "
                                      f"{describe(next(iter(answers.values())).frame)}.")


def _rxb1(trial: Trial, frames) -> CheckResult:
    own = trial.own_id
    misplaced = [e for e in frames if e.frame.remote and e.frame.can_id == own
                 and not trial.reception(e).startswith("RXB1")]
    intruders = [e for e in frames if e.frame.can_id != own and trial.reception(e).startswith("RXB1")]
    if intruders:
        return CheckResult(RXB1, False, f"RXB1 took {listing(intruders)}: {trial.acceptance('RXB1')}. RX_Mask1 "
                                        "must be a mask that tells your ID from every ID on this bus (0x7FF is the "
                                        "safe one; 0x0FF passes here by luck) and "
                                        f"RX_Filter2 = MESSAGE_ID1 = {hex_id(own)}: check that RXB1's MASK is set "
                                        "correctly (see the TODO).")
    if misplaced:
        outcome = trial.reception(misplaced[0]) or f"not received: {trial.mode()} mode"
        return CheckResult(RXB1, False, f"The RTR for {hex_id(own)} from {misplaced[0].sender} did not go into RXB1 "
                                        f"({outcome}): {trial.acceptance('RXB1')}. One of RX_Filter2..RX_Filter5 "
                                        f"must equal MESSAGE_ID1 (see the TODO).")
    return CheckResult(RXB1, True, f"RXB1 took only frames with ID {hex_id(own)} ({trial.acceptance('RXB1')}).")


def _silent(trial: Trial, unasked) -> CheckResult:
    wrong = [(s, t) for s, t in unasked
             if not (t is not None and not t.frame.remote and t.frame.can_id == trial.own_id)]
    if not wrong:
        return CheckResult(SILENT, True, "It sent nothing but answers to RTRs for its own ID.")
    sent, trigger = wrong[0]
    if trigger is not None and trigger.frame.remote and trigger.frame.can_id == trial.own_id:
        why = (f"as a second frame after the one RTR for {hex_id(trial.own_id)} from {trigger.sender}: answer "
               "each request once")
    elif trigger is not None and trigger.frame.remote:
        why = (f"right after taking the RTR {hex_id(trigger.frame.can_id)} from {trigger.sender}, which asks for "
               f"another node's data: answer only if {rtr_test(trial)}")
    else:
        why = ("without being asked: in Ex6 the node sends only to answer the master's RTR (no more sending on "
               "Timer1)")
    return CheckResult(SILENT, False, f"Sent {count(len(wrong), 'frame')} nobody asked for; {describe(sent.frame)} at "
                                      f"{ms(sent.start_ps)} {why}.")


def _data(trial: Trial, unasked) -> CheckResult:
    wrong = [(s, t) for s, t in unasked if t is not None and not t.frame.remote and t.frame.can_id == trial.own_id]
    if not wrong:
        return CheckResult(DATA, True, f"No answer to the data frames with ID {hex_id(trial.own_id)} that the test "
                                       "node sent, playing a faulty node (on a correct bus only you send them).")
    sent, trigger = wrong[0]
    return CheckResult(DATA, False, f"Answered the data frame {describe(trigger.frame)} from {trigger.sender} with "
                                    f"{describe(sent.frame)} at {ms(sent.start_ps)}. On a correct bus only you send "
                                    "data frames with your ID; the check's test node plays a faulty node that sends "
                                    "one, and a data frame is not a request. Test CANMessageFlag & CAN_RX_RTR_FRAME "
                                    "before answering.")
