"""Ex1's checks: in Loopback mode the node sends MESSAGE_ID1 once, receives it in RXB0 and shows it on the LCD.

Nothing may appear on the bus; the own frame must pass RXB0's mask and filters (the workshop's "normally, no!").
"""
from __future__ import annotations

from appsim.workshop.checks.judging import data_frames
from appsim.workshop.checks.trial import (
    Trial,
    decimal_values,
    hex_id,
    hex_values,
    ms,
    took,
    took_part,
)
from appsim.workshop.checks.verdict import CheckResult

OFF_BUS = "stays off the bus (Loopback mode)"
SENDS = "sends MESSAGE_ID1 with 01 02 03 ADRESH ADRESL"
RECEIVES = "RXB0 receives its own frame"
LCD = "LCD lines 2-4: TX ID, A/D, RX ID"
NAMES = (OFF_BUS, SENDS, RECEIVES, LCD)
SECONDS = 0.03                    # GLCD_Initial 2.6 ms, three mode changes, one frame: done in ~5 ms


def run(trial: Trial) -> list[CheckResult]:
    trial.classroom(1, stations=1)
    trial.run(SECONDS)
    looped = [e for e in trial.bus.loopback_trace if e.sender == trial.name]
    on_bus = trial.sent()
    return [_off_bus(trial, looped, on_bus), data_frames(trial, SENDS, looped + on_bus),
            _receives(trial, looped, on_bus), _lcd(trial, looped)]


def _off_bus(trial: Trial, looped, on_bus) -> CheckResult:
    acked = trial.acked()
    if on_bus or acked:
        return CheckResult(OFF_BUS, False, f"Your node {took_part(on_bus, acked)} on the classroom bus: it is in "
                                           f"{trial.mode()} mode. Ex1 must not disturb the bus: CANInitialization() "
                                           "ends with "
                                           "CANSetOperationMode(CAN_OP_MODE_LOOP), where the frame goes from TXB0 "
                                           "to the MAB and never to CANTX.")
    if not looped:
        return CheckResult(OFF_BUS, False, f"Nothing was sent at all (the ECAN is in {trial.mode()} mode): call "
                                           "CANSendMessage(MESSAGE_ID1, TxData, 5, ...) after CANInitialization().")
    return CheckResult(OFF_BUS, True, f"Nothing on the bus, no ACK given; the frame went round in Loopback mode "
                                      f"at {ms(looped[0].start_ps)}.")


def _receives(trial: Trial, looped, on_bus) -> CheckResult:
    if not looped:
        why = ("in Normal mode a node never receives its own frame" if on_bus
               else "nothing was sent")
        return CheckResult(RECEIVES, False, f"RXB0 never received a frame: {why}. In Loopback mode the frame "
                                            "comes back through the masks and filters.")
    outcome = trial.reception(looped[0])
    if outcome.startswith("RXB0"):
        return CheckResult(RECEIVES, True, f"{hex_id(looped[0].frame.can_id)} came back into {outcome} "
                                           f"({trial.acceptance('RXB0')}).")
    if outcome.startswith("RXB1"):
        return CheckResult(RECEIVES, False, f"The own frame went to {outcome}, not RXB0: it must pass RXF0 or "
                                            f"RXF1 under RXM0 ({trial.acceptance('RXB0')}). Set RX_Filter0 "
                                            "(see the TODO).")
    return CheckResult(RECEIVES, False, f"RXB0 never received a frame ({outcome}). In Loopback mode the frame still "
                                        "goes through the masks and filters: "
                                        f"{trial.acceptance('RXB0')}, and MESSAGE_ID1 = {hex_id(trial.own_id)} "
                                        "matches no filter in the bits the mask compares. Set RX_Filter0 "
                                        "to MESSAGE_ID1 (or MESSAGE_ID1 to RX_Filter0), or relax RX_Mask0, or "
                                        "receive everything with CAN_CONFIG_ALL_MSG (see the TODO).")


def _lcd(trial: Trial, looped) -> CheckResult:
    own, potentiometer = trial.own_id, trial.board.adc.potentiometer
    lines = {n: trial.lcd(n) for n in (2, 3, 4)}
    wrong = []
    if own not in hex_values(lines[2]):
        wrong.append(f"line 2 shows {lines[2]!r}, not the TX ID {hex_id(own)} in hex")
    received = bool(looped) and took(trial.reception(looped[0]))
    if potentiometer not in decimal_values(lines[3]):
        wrong.append(f"line 3 shows {lines[3]!r}, not the A/D {potentiometer} in decimal (RxData[3] * 256 + RxData[4])"
                     + ("" if received else ": nothing was received to show"))
    if own not in hex_values(lines[4]):
        wrong.append(f"line 4 shows {lines[4]!r}, not the RX ID {hex_id(own)} in hex"
                     + ("" if received else ": nothing was received to show"))
    if wrong:
        return CheckResult(LCD, False, "; ".join(wrong) + ".")
    return CheckResult(LCD, True, f"Line 2 {lines[2]!r}, line 3 {lines[3]!r}, line 4 {lines[4]!r}.")
