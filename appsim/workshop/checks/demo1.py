"""Demo1's checks: the monitor firmware on a board of its own lists the classroom's frames through the USB-CDC end,
at 19200 baud, in the documented line format (docs/monitor-format.md), without touching the bus.
"""
from __future__ import annotations

import re
from itertools import pairwise

from appsim.bus.wire import BusEvent
from appsim.chip.usart import PC_BAUD
from appsim.sim import PS_PER_SECOND
from appsim.workshop.checks.judging import heard_nothing, nothing_to_judge
from appsim.workshop.checks.trial import Trial, count, listing, quoted, took_part
from appsim.workshop.checks.verdict import CheckResult

BAUD = "USART at 19200 baud"
INVISIBLE = "listen-only: invisible on the bus"
FORMAT = "lists the frames in the documented format"
LOST = "says when frames were lost"
TIME = "time column counts up with the bus"
NAMES = (BAUD, INVISIBLE, FORMAT, LOST, TIME)
SECONDS = 1.0                     # ~95 frames on the bus, ~34 lines through 19200 baud: the queue fills,
                                  # frames are lost
BITS_PER_BYTE = 10                # 8N1: a start bit, 8 data bits, a stop bit
BAUD_TOLERANCE = 0.02             # a UART receiver copes with about 2 %: 129 gives 19231 (+0.16 %)
BAUD_FIX = "With BRGH = 1, baud = Fosc / (16 x (SPBRG + 1)), so SPBRG = 129 at 40 MHz"
FEWEST_LINES = 5
TIME_SLACK_S = 0.035              # a line can wait for the one before it (the solution's 55 bytes: 29 ms)
FRAME_LINE = re.compile(r"^ *(\d+\.\d{6})  0x([0-9A-F]{3}|[0-9A-F]{8})  (STD|XTD)  (DATA|RTR )  DLC (\d+)"
                        r"((?:  [0-9A-F]{2}(?: [0-9A-F]{2})*)?)$")
LOST_COUNT = re.compile(r"lost (\d+) frames?")
FORMAT_HELP = ("docs/monitor-format.md: `    0.053946  0x088  STD  DATA  DLC 5  01 02 03 02 00`, time in "
               "seconds, 0x and 3 (or 8) hex digits, STD/XTD, DATA/RTR, DLC n, the data bytes")


def run(trial: Trial) -> list[CheckResult]:
    trial.classroom(2, stations=4, own_board="app023")
    received = bytearray()
    trial.board.usb.listeners.append(lambda byte, time_ps: received.append(byte))
    trial.run(SECONDS)
    text = received.decode("latin-1").replace("\0", "")       # C18's putsUSART sends the NUL too; terminals skip it
    lines = text.split("\r\n")[:-1]                              # the last one is not finished yet
    frames = trial.bus.frames()
    matched = _match(lines, frames)
    return [_baud(trial, received), _invisible(trial), _format(lines, matched),
            _lost(lines, matched, frames), _time(lines, matched, frames)]


def _match(lines: list[str], frames: list[BusEvent]) -> dict[int, int] | str:
    """Line number -> index of the bus frame it lists, in order; or what is wrong with the first bad line."""
    matched, position = {}, 0
    for number, line in enumerate(lines):
        if line.startswith("#"):
            continue
        found = FRAME_LINE.match(line)
        if found is None:
            return f"line {number + 1}, {quoted(line)}, is not in the documented format ({FORMAT_HELP})"
        _, ident, kind, what, dlc, data = found.groups()
        key = (int(ident, 16), kind == "XTD", what == "RTR ", int(dlc), bytes.fromhex(data.replace(" ", "")))
        while position < len(frames) and _key(frames[position]) != key:
            position += 1
        if position == len(frames):
            return f"line {number + 1}, {quoted(line)}, lists a frame that was not on the bus at that point"
        matched[number] = position
        position += 1
    return matched


def _key(event: BusEvent) -> tuple:
    frame = event.frame
    return frame.can_id, frame.extended, frame.remote, frame.dlc, frame.data


def _baud(trial: Trial, received: bytearray) -> CheckResult:
    usart = trial.board.usart
    if not received:
        return CheckResult(BAUD, False, "No byte came out of the USART to the PIC18F2550: OpenUSART(...) with "
                                        "the transmitter on, and putsUSART() for each line.")
    off = usart.baud / PC_BAUD - 1
    if abs(off) > BAUD_TOLERANCE:
        return CheckResult(BAUD, False, f"The USART sends at {usart.baud:.0f} baud ({off:+.0%}), but the PIC18F2550 "
                                        f"reads 19200 baud: the PC would see garbage. {BAUD_FIX} (TODO 1).")
    return CheckResult(BAUD, True, f"{len(received)} bytes at {usart.baud:.0f} baud ({off:+.2%} from 19200).")


def _invisible(trial: Trial) -> CheckResult:
    sent = trial.sent()
    acked = trial.acked()
    if sent or acked:
        return CheckResult(INVISIBLE, False, f"The monitor {took_part(sent, acked)}: in {trial.mode()} mode it takes "
                                             "part in the bus it watches (a sender alone on the bus would think "
                                             "someone heard it). CANSetOperationMode(CAN_OP_MODE_LISTEN) after "
                                             "CANInitialize(): it never ACKs nor flags errors (TODO 2).")
    if heard_nothing(trial, trial.bus.frames()):
        return CheckResult(INVISIBLE, False, nothing_to_judge(trial, "heard none of the bus's frames, as a monitor "
                                                                     "must: in Listen-only mode it hears every one"))
    return CheckResult(INVISIBLE, True, f"No frame sent, no ACK given, in {trial.mode()} mode.")


def _format(lines: list[str], matched: dict[int, int] | str) -> CheckResult:
    if isinstance(matched, str):
        return CheckResult(FORMAT, False, matched[0].upper() + matched[1:] + ".")
    if len(matched) < FEWEST_LINES:
        return CheckResult(FORMAT, False, f"Only {count(len(matched), 'frame line')} in {SECONDS * 1000:.0f} ms "
                                          "(the USART at 19200 baud carries about 34 a second): one line per frame "
                                          "received (CANIsRxReady(), CANReceiveMessage(), putsUSART()).")
    return CheckResult(FORMAT, True, f"{count(len(matched), 'frame line')}, each the next frame on the bus "
                                     f"(the first: {quoted(lines[min(matched)].strip())}).")


def _lost(lines: list[str], matched: dict[int, int] | str, frames: list[BusEvent]) -> CheckResult:
    if isinstance(matched, str) or not matched:
        return CheckResult(LOST, False, "Not judged: no frame line could be matched to the bus (see the format check).")
    previous_line, previous_frame, total = None, -1, 0
    for number, index in matched.items():
        missing = frames[previous_frame + 1:index]
        notes = [line for line in lines[(previous_line or -1) + 1:number] if line.startswith("#") and "lost" in line]
        counts = [int(c) for note in notes for c in LOST_COUNT.findall(note)]
        after = f"after {quoted(lines[previous_line])}" if previous_line is not None else "before the first line"
        if missing and not notes:
            size = len(lines[previous_line]) + 2 if previous_line is not None else None     # with CR LF
            sending = (f"that line's {size} bytes take {size * BITS_PER_BYTE / PC_BAUD * 1000:.0f} ms"
                       if size is not None else "a line takes tens of ms")
            return CheckResult(LOST, False, f"{count(len(missing), 'frame')} ({listing(missing, 2)}) went by on the "
                                            f"bus {after} and the monitor neither printed nor reported them as "
                                            f"lost. While putsUSART() sends a line ({sending} at 19200 baud, 8N1) "
                                            "RXB0 and RXB1 overflow: report CANMessageFlag & CAN_RX_OVERFLOW (TODO 3), "
                                            "or keep frames in a queue and count what it cannot hold.")
        if counts and sum(counts) != len(missing):
            return CheckResult(LOST, False, f"{quoted(notes[0])} {after}, but {count(len(missing), 'frame')} went "
                                            "missing there: the count must be exact, or say only that frames were "
                                            "lost.")
        if not missing and notes:
            return CheckResult(LOST, False, f"{quoted(notes[0])} {after}, but no frame went missing there.")
        total += len(missing)
        previous_line, previous_frame = number, index
    if not total:
        return CheckResult(LOST, True, "No frame went missing between the lines printed.")
    return CheckResult(LOST, True, f"{count(total, 'frame')} went missing, each time reported where it happened.")


def _time(lines: list[str], matched: dict[int, int] | str, frames: list[BusEvent]) -> CheckResult:
    stamps = [(number, float(m.group(1))) for number, line in enumerate(lines)
              if not line.startswith("#") and (m := re.match(r"^\s*(\d+\.\d+)", line))]
    if len(stamps) < 2:
        return CheckResult(TIME, False, "Not judged: fewer than two lines with a time.")
    for (a, earlier), (b, later) in pairwise(stamps):
        if later < earlier:
            return CheckResult(TIME, False, f"The time goes back from {earlier} (line {a + 1}) to {later} (line "
                                            f"{b + 1}): Timer1 (Fosc/4, 1:8) wraps every 52.4288 ms, so count its "
                                            "overflows (PIR1bits.TMR1IF) for the seconds since start.")
    if isinstance(matched, str) or not matched:
        return CheckResult(TIME, True, "The time counts up (the lines could not be matched to the bus to compare; "
                                       "see the format check).")
    stamp = dict(stamps)
    first_line, first_frame = next(iter(matched.items()))
    worst = 0.0
    for number, index in matched.items():
        printed = stamp[number] - stamp[first_line]
        on_bus = (frames[index].end_ps - frames[first_frame].end_ps) / PS_PER_SECOND
        if abs(printed - on_bus) > TIME_SLACK_S:
            return CheckResult(TIME, False, f"Line {number + 1} says {printed:.6f} s after line {first_line + 1}, "
                                            f"but its frame ended {on_bus:.6f} s after that line's: the time is "
                                            "seconds since start by Timer1 (0.8 us per count at Fosc/4 with 1:8).")
        worst = max(worst, abs(printed - on_bus))
    return CheckResult(TIME, True, f"The time counts up with the bus: each line within {worst * 1000:.1f} ms of "
                                   "its frame's end, counted from the first line.")
