"""Ex5's checks: on each Timer1 overflow an RTR for the station's RTR_ID (0x81..0x86), not data, with the workshop's
DLC 0 or the standard's 5 (the length of the data it asks for); the master's answer is received and shown on the LCD.
"""
from __future__ import annotations

from appsim.firmware.identity import shown
from appsim.workshop.checks.judging import once_per_overflow, sent_anywhere, why_silent
from appsim.workshop.checks.trial import (
    MASTER_ID,
    Trial,
    count,
    decimal_values,
    describe,
    hex_id,
    hex_values,
    ms,
    payload,
    took,
)
from appsim.workshop.checks.verdict import CheckResult

REQUESTS = "sends RTR frames for RTR_ID (DLC 0 or 5)"
PERIOD = "one RTR per Timer1 overflow (52.4288 ms)"
ANSWER = "receives the master's answer"
LCD = "LCD shows the master's A/D and RTR_ID"
NAMES = (REQUESTS, PERIOD, ANSWER, LCD)
SECONDS = 0.4                     # listen until ~50 ms, then six Timer1 overflows
HOW = "CANSendMessage(RTR_ID, {none}, 0, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_RTR_FRAME)"

ANSWER_BYTES = 5                  # the master answers with 01 02 03 ADRESH ADRESL
REQUEST_DLCS = (0, ANSWER_BYTES)  # the workshop's DataLen 0; CAN 2.0's advice: the DLC of the data frame asked for


def how(trial: Trial) -> str:
    """The call that sends the request, in the firmware's language (None or NULL)."""
    return HOW.format(none=trial.firmware.says("None", "NULL"))


def run(trial: Trial) -> list[CheckResult]:
    trial.classroom(5, stations=2)
    trial.run(SECONDS)
    mine = sent_anywhere(trial)
    return [_requests(trial, mine), once_per_overflow(PERIOD, mine), _answer(trial),
            _lcd(trial)]


def _requests(trial: Trial, mine) -> CheckResult:
    if not trial.sent():
        return CheckResult(REQUESTS, False, f"No frame from your node reached the bus: {why_silent(trial)}.")
    rtr_id = trial.rtr_id
    for event in mine:
        frame = event.frame
        if not event.ok:
            problem = (f"it ended in an error ({event.error}): the bit timing must give 125 kbit/s, "
                       "CANInitialize(4, 10, 8, 4, 3, ...)")
        elif not frame.remote:
            problem = (f"a data frame, not a remote transmission request: on TMR1_OVERFLOW do not send your data, "
                       f"send {how(trial)} (see the TODO)")
        elif frame.can_id != rtr_id and trial.identity_problem:
            problem = f"it asks for {hex_id(frame.can_id)}, not for RTR_ID = {shown(rtr_id)}. {trial.identity_problem}"
        elif frame.can_id != rtr_id:
            problem = f"it asks for {hex_id(frame.can_id)}; station {trial.station} asks for RTR_ID = {hex_id(rtr_id)}"
        elif frame.dlc not in REQUEST_DLCS:
            problem = (f"DLC {frame.dlc}: a remote frame carries no data, but its DLC (CANSendMessage's DataLen, "
                       f"into TXB0DLC) still goes on the wire. The workshop sends DataLen 0; CAN 2.0 advises the "
                       f"length of the data frame asked for, {ANSWER_BYTES} here. Any other value is a mistake: two "
                       "nodes asking for the same ID with different DLCs both win arbitration (the DLC comes after "
                       "it) and destroy each other's request with a bit error")
        else:
            continue
        return CheckResult(REQUESTS, False, f"Sent {describe(frame)} at {ms(event.start_ps)}: {problem}"
                                            + ("" if problem.endswith(".") else "."))
    if trial.identity_problem:
        return CheckResult(REQUESTS, False, f"{trial.identity_problem} Otherwise right: {count(len(mine), 'frame')} "
                                            f"{describe(mine[0].frame)}.")
    return CheckResult(REQUESTS, True, f"{count(len(mine), 'frame')} {describe(mine[0].frame)}.")


def _answer(trial: Trial) -> CheckResult:
    answers = [e for e in trial.bus.frames() if e.sender == "master" and e.frame.can_id == trial.rtr_id
               and not e.frame.remote]
    if not answers:
        return CheckResult(ANSWER, False, f"The master never sent {hex_id(trial.rtr_id)}: it answers only remote "
                                          f"frames (RTR) for 0x81..0x86, with the same ID. Send {how(trial)}.")
    missed = [e for e in answers if not took(trial.reception(e))]
    if missed:
        return CheckResult(ANSWER, False, f"{len(missed)} of the master's {count(len(answers), 'answer')} "
                                          f"({describe(missed[0].frame)}) did not get in "
                                          f"({trial.reception(missed[0]) or trial.mode() + ' mode'}): "
                                          f"{trial.acceptance('RXB0')}. The answer has the ID of the request, so "
                                          f"RX_Filter0 = RTR_ID = {hex_id(trial.rtr_id)} (see the TODO).")
    return CheckResult(ANSWER, True, f"All {count(len(answers), 'answer')} of the master "
                                     f"({describe(answers[0].frame)}) went into {trial.reception(answers[0])}.")


def _lcd(trial: Trial) -> CheckResult:
    master = trial.room.master.adc.potentiometer
    line3, line4 = trial.lcd(3), trial.lcd(4)
    problems = []
    if master not in decimal_values(line3):
        problems.append(f"line 3 shows {line3!r}, not the master's A/D {master} in decimal")
    shown = hex_values(line4)
    if trial.rtr_id not in shown:
        hint = (": the master's broadcast, not the answer to your request; RX_Filter0 must be RTR_ID (see the TODO)"
                if MASTER_ID in shown else "")
        problems.append(f"line 4 shows {line4!r}, not the RX ID {hex_id(trial.rtr_id)} in hex{hint}")
    if problems:
        return CheckResult(LCD, False, "; ".join(problems) + ".")
    expected = payload(master)
    return CheckResult(LCD, True, f"Line 3 {line3!r} (the master sent {expected.hex(' ').upper()}), line 4 {line4!r}.")
