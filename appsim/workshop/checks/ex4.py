"""Ex4's checks: Listen-only (no frame, no ACK) until the master's first 0x088 has ended, then Normal mode and
sending, with the mask and filter set again after the second CANInitialize() so only 0x088 gets in.
"""
from __future__ import annotations

from appsim.bus.wire import Bus, BusEvent
from appsim.workshop.checks.judging import data_frames, master_kept_off, why_silent
from appsim.workshop.checks.trial import MASTER_ID, Trial, count, describe, listing, ms, took, took_part
from appsim.workshop.checks.verdict import CheckResult

LISTENS = "listen-only until the first 0x088"
JOINS = "then Normal mode and sending"
FILTERS = "filters set again after the second CANInitialize"
NAMES = (LISTENS, JOINS, FILTERS)
SECONDS = 0.4                     # first 0x088 at ~50 ms; then six Timer1 overflows
STEPS_456 = ("after the first 0x088: CANSetOperationMode(CAN_OP_MODE_CONFIG), then "
             "CANInitialization(CAN_CONFIG_VALID_STD_MSG, CAN_OP_MODE_NORMAL) (TODO 4, 5, 6)")


def before_the_first_0x088(bus: Bus, node: str) -> tuple[BusEvent | None, list[BusEvent]]:
    """The master's first 0x088, and every frame `node` sent or ACKed that started before that 0x088 ended.

    That 0x088 is one of them if `node` ACKed it: a node in Listen-only mode never ACKs, so it was not listening
    when the 0x088 went by. A node that listens until then shows none. (The notebook shows the same list.) If no
    0x088 went through (a node that wins every arbitration keeps it off the bus), None and all of them.
    """
    first = next((e for e in bus.frames() if e.sender == "master" and e.frame.can_id == MASTER_ID
                  and not e.frame.remote), None)      # the PC monitor interface ACKs it whatever the stations do
    end = first.end_ps if first is not None else bus.sim.now
    return first, [e for e in bus.trace if e.start_ps < end and (e.sender == node or node in e.acked_by)]


def run(trial: Trial) -> list[CheckResult]:
    trial.classroom(4, stations=2)
    trial.run(SECONDS)
    first, before = before_the_first_0x088(trial.bus, trial.name)
    if first is None:
        why = master_kept_off(trial)
        return [CheckResult(LISTENS, False, why), CheckResult(JOINS, False, why), CheckResult(FILTERS, False, why)]
    mine = [e for e in trial.sent() if e.start_ps >= first.end_ps]
    return [_listens(trial, first, before), _joins(trial, first, mine), _filters(trial, mine)]


def _listens(trial: Trial, first: BusEvent, before: list[BusEvent]) -> CheckResult:
    sent = [e for e in before if e.sender == trial.name]
    acked = [e for e in before if trial.name in e.acked_by]
    if sent or acked:
        return CheckResult(LISTENS, False, f"Before the master's first 0x088 ended ({ms(first.end_ps)}) your node "
                                           f"{took_part(sent, acked)}: it was in Normal mode. A node in Listen-only "
                                           "mode sends nothing and never ACKs, not even the 0x088 it is waiting for. "
                                           "CANInitialize() returns in Normal mode, so call "
                                           "CANSetOperationMode(CAN_OP_MODE_LISTEN) after it, with CAN_CONFIG_ALL_MSG "
                                           "(TODO 1, 2).")
    heard = trial.reception(first)
    if not heard:
        return CheckResult(LISTENS, False, f"Your node was not on the bus when the master's first 0x088 went by "
                                           f"({ms(first.end_ps)}): it heard nothing, which is not listening. A node "
                                           "in Listen-only mode hears every frame, and sends and ACKs none: "
                                           "CANSetOperationMode(CAN_OP_MODE_LISTEN) after CANInitialize(), with "
                                           "CAN_CONFIG_ALL_MSG (TODO 1, 2).")
    return CheckResult(LISTENS, True, f"Nothing sent, nothing ACKed until the master's first 0x088 ended at "
                                      f"{ms(first.end_ps)}" + (f" (it went into {heard})." if took(heard) else "."))


def _joins(trial: Trial, first, mine) -> CheckResult:
    if not mine:
        if trial.mode() == "Listen-only":
            return CheckResult(JOINS, False, f"Still in Listen-only mode at {ms(trial.now)}, so nothing was sent: "
                                             + STEPS_456 + ".")
        return CheckResult(JOINS, False, f"No frame after the first 0x088: {why_silent(trial)}.")
    errors = [e for e in mine if not e.ok]
    if errors:
        return CheckResult(JOINS, False, f"{len(errors)} of {len(mine)} frames ended in errors ({errors[0].error}): "
                                         "the bit timing must give the bus's 125 kbit/s, CANInitialize(4, 10, 8, "
                                         "4, 3, ...) at 40 MHz.")
    content = data_frames(trial, JOINS, mine)
    if not content.passed:
        return content
    return CheckResult(JOINS, True, f"In {trial.mode()} mode after the first 0x088: {count(len(mine), 'frame')} "
                                    f"{describe(mine[0].frame)}, the first at {ms(mine[0].start_ps)}.")


def _filters(trial: Trial, mine) -> CheckResult:
    if not mine:
        return CheckResult(FILTERS, False, "Not judged: the node never joined the bus (see the check above).")
    joined = mine[0].start_ps
    later = [e for e in trial.bus.frames() if e.start_ps >= joined and e.sender != trial.name]
    wrong = [e for e in later if took(trial.reception(e)) != (e.frame.can_id == MASTER_ID and not e.frame.remote)]
    if not wrong:
        rejected = [e for e in later if not took(trial.reception(e))]
        return CheckResult(FILTERS, True, f"After joining only the master's 0x088 got in ({trial.acceptance('RXB0')}); "
                                          f"{count(len(rejected), 'other frame')} rejected.")
    return CheckResult(FILTERS, False, f"After joining, the acceptance logic took {listing(wrong)} "
                                       f"({trial.reception(wrong[0])}): {trial.acceptance('RXB0')}. CANInitialize() "
                                       "sets the masks to 0 (accept everything) and CAN_CONFIG_ALL_MSG sets RXM = 11: "
                                       "after the second CANInitialize(), with CAN_CONFIG_VALID_STD_MSG, set "
                                       "RX_Mask0 = 0x7FF and RX_Filter0 = 0x088 again in Configuration mode (step 5).")
