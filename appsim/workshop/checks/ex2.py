"""Ex2's checks: in Normal mode the node sends MESSAGE_ID1 with its A/D on every Timer1 overflow, and never receives
its own frames.

The classroom around it: the master, the PC monitor interface (it ACKs) and one more station.
"""
from __future__ import annotations

from appsim.workshop.checks.judging import (
    data_frames,
    nothing_to_judge,
    on_the_bus,
    once_per_overflow,
    sent_anywhere,
)
from appsim.workshop.checks.trial import Trial, count, hex_id, took
from appsim.workshop.checks.verdict import CheckResult

ON_BUS = "sends on the bus in Normal mode"
FRAMES = "frames carry MESSAGE_ID1 and 01 02 03 ADRESH ADRESL"
PERIOD = "one frame per Timer1 overflow (52.4288 ms)"
NOT_OWN = "does not receive its own frames"
NAMES = (ON_BUS, FRAMES, PERIOD, NOT_OWN)
SECONDS = 0.35                    # six Timer1 overflows


def run(trial: Trial) -> list[CheckResult]:
    trial.classroom(2, stations=2)
    trial.run(SECONDS)
    events = sent_anywhere(trial)       # judged even in Loopback: the mode is a check of its own
    return [on_the_bus(trial, ON_BUS), data_frames(trial, FRAMES, events), once_per_overflow(PERIOD, events),
            _not_own(trial)]


def _not_own(trial: Trial) -> CheckResult:
    if not sent_anywhere(trial):
        return CheckResult(NOT_OWN, False, nothing_to_judge(trial, "sent no frame, so none could come back to it"))
    own = [e for e in trial.bus.loopback_trace if e.sender == trial.name and took(trial.reception(e))]
    if own:
        return CheckResult(NOT_OWN, False, f"{trial.reception(own[0])} received the node's own "
                                           f"{count(len(own), 'frame')} ({hex_id(own[0].frame.can_id)}): that "
                                           "happens only in Loopback mode. On the bus a node never stores what it "
                                           "sends: CANSetOperationMode(CAN_OP_MODE_NORMAL) (see the TODO).")
    taken = [e for e in trial.bus.frames() if took(trial.reception(e))]
    return CheckResult(NOT_OWN, True, f"None of its own frames came back; it took {count(len(taken), 'frame')} "
                                      "of other nodes.")
