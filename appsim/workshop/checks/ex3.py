"""Ex3's checks: RXB0 takes the master's 0x088 and the LCD shows its A/D; the other stations' frames never get in.

The master's potentiometer moves halfway through, so the LCD must follow every frame, not show one value.
"""
from __future__ import annotations

from appsim.workshop.checks.judging import data_frames, heard_nothing, master_kept_off, nothing_to_judge, on_the_bus
from appsim.workshop.checks.trial import (
    MASTER_ID,
    Trial,
    count,
    decimal_values,
    hex_values,
    listing,
    took,
)
from appsim.workshop.checks.verdict import CheckResult

RECEIVES = "RXB0 receives the master's 0x088"
LCD = "LCD shows the master's A/D and ID"
REJECTS = "rejects the other stations' frames"
SENDS = "keeps sending MESSAGE_ID1 on Timer1"
NAMES = (RECEIVES, LCD, REJECTS, SENDS)
HALF_SECONDS = 0.2                # two broadcasts of 0x088 before the master's potentiometer moves, two after


def run(trial: Trial) -> list[CheckResult]:
    room = trial.classroom(3, stations=2)
    trial.run(HALF_SECONDS)
    room.master.adc.potentiometer = trial.master_potentiometers[1]
    trial.run(HALF_SECONDS)
    sending = on_the_bus(trial, SENDS)
    if sending.passed:
        sending = data_frames(trial, SENDS, trial.sent())
    return [_receives(trial), _lcd(trial), _rejects(trial), sending]


def master_frames(trial: Trial):
    return [e for e in trial.bus.frames() if e.sender == "master" and e.frame.can_id == MASTER_ID
            and not e.frame.remote]


def _receives(trial: Trial) -> CheckResult:
    frames = master_frames(trial)
    if not frames:
        return CheckResult(RECEIVES, False, master_kept_off(trial))
    missed = [e for e in frames if not trial.reception(e).startswith("RXB0")]
    if not missed:
        return CheckResult(RECEIVES, True, f"All {count(len(frames), 'broadcast')} of 0x088 went into RXB0 "
                                           f"({trial.acceptance('RXB0')}).")
    outcome = trial.reception(missed[0])
    if not outcome:
        return CheckResult(RECEIVES, False, f"Your node did not take part in the bus ({trial.mode()} mode), so the "
                                            "master's 0x088 never reached it: CANInitialization() ends with "
                                            "CANSetOperationMode(CAN_OP_MODE_NORMAL).")
    return CheckResult(RECEIVES, False, f"{len(missed)} of {len(frames)} master's 0x088 frames did not reach RXB0 "
                                        f"({outcome}): {trial.acceptance('RXB0')}. The master console broadcasts "
                                        "with ID 0x088: RX_Filter0 = 0x088 under RX_Mask0 = 0x7FF (see the TODO).")


def _lcd(trial: Trial) -> CheckResult:
    first, now = trial.master_potentiometers[:2]
    line3, line4 = trial.lcd(3), trial.lcd(4)
    shown = decimal_values(line3)
    problems = []
    if now not in shown:
        if first in shown:
            problems.append(f"line 3 still shows {line3!r}: the master's A/D moved from {first} to {now} and the "
                            "LCD did not follow. Write line 3 on every frame received from the master")
        elif trial.board.adc.potentiometer in shown:
            problems.append(f"line 3 shows {line3!r}, your own potentiometer: show the master's A/D from the "
                            "received data, (RxData[3] << 8) | RxData[4]")
        else:
            received = any(took(trial.reception(e)) for e in master_frames(trial))
            problems.append(f"line 3 shows {line3!r}, not the master's A/D {now} in decimal"
                            + ("" if received else " (no frame of the master's was received: see the RXB0 check)"))
    if MASTER_ID not in hex_values(line4):
        problems.append(f"line 4 shows {line4!r}, not the RX ID 0x088 in hex")
    if problems:
        return CheckResult(LCD, False, "; ".join(problems) + ".")
    return CheckResult(LCD, True, f"Line 3 {line3!r} followed the master's A/D ({first}, then {now}); "
                                  f"line 4 {line4!r}.")


def _rejects(trial: Trial) -> CheckResult:
    stations = {board.name for board in trial.room.stations.values()} - {trial.name}
    others = [e for e in trial.bus.frames() if e.sender in stations]
    if not others:
        return CheckResult(REJECTS, False, "No other station's frame went through the bus to judge by "
                                           "(see the other checks).")
    if heard_nothing(trial, others):
        return CheckResult(REJECTS, False, nothing_to_judge(trial, "heard none of the other stations' frames"))
    taken = [e for e in others if took(trial.reception(e))]
    if taken:
        return CheckResult(REJECTS, False, f"RXB0/RXB1 took {listing(taken)}: {trial.acceptance('RXB0')}. "
                                           "Only 0x088 must pass: RX_Mask0 = 0x7FF compares every ID bit and "
                                           "RX_Filter0 = 0x088 (with RXB0CON.RXM = 01, CAN_CONFIG_VALID_STD_MSG).")
    return CheckResult(REJECTS, True, f"All {count(len(others), 'frame')} of the other stations were rejected by "
                                      "the masks and filters.")
