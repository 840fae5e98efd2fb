"""Each exercise's solution in the classroom does what the workshop expects; each starter runs; no frame from outside
stops a board, and reading past a short frame's data is reported in the workshop's words."""
from __future__ import annotations

import itertools
import random
from collections import Counter

import pytest
from outside import Outside, every_frame
from workshop import KIT, MS, classroom, payload, sent

from appsim.bus.controller import Mode
from appsim.can.frame import CanFrame
from appsim.sim import ps
from appsim.workshop.classroom import Classroom
from appsim.workshop.faults import board_fault

TIMER1_PERIOD_PS = 65536 * 8 * 100_000        # 1:8 of Fosc/4 at 40 MHz: 52.4288 ms


def station_names(room: Classroom) -> set[str]:
    return {board.name for board in room.stations.values()}


# ------------------------------------------------------------------ Ex1
def test_ex1_solution_shows_tx_id_ad_and_rx_id_of_its_own_frame():
    room = classroom(1, seed=1)
    room.run(0.05)
    for k, board in room.stations.items():
        own = 0x100 + 0x10 * (k - 1)
        assert board.glcd.line(1) == "EX1 LOOPBACK"
        assert board.glcd.line(2) == f"TX ID  0x{own:03X}"
        assert board.glcd.line(3) == f"A/D    {board.adc.potentiometer:4d}"
        assert board.glcd.line(4) == f"RX ID  0x{own:03X}"
    assert not sent(room, "station1"), "loopback never drives the bus"


def test_ex1_starter_shows_only_its_tx_id_because_nothing_is_received():
    room = classroom(1, firmware_dir=KIT / "exercises")
    room.run(0.05)
    assert [room.station(1).glcd.line(n) for n in (2, 3, 4)] == ["TX ID  0x100", "", ""]


# ------------------------------------------------------------------ Ex2
def test_ex2_every_station_sends_its_potentiometer_every_timer1_overflow():
    room = classroom(2, seed=21)
    room.run(1.02)
    for k, board in room.stations.items():
        frames = sent(room, board.name)
        assert len(frames) == 19                                    # 1 s / 52.4288 ms
        assert {e.frame.can_id for e in frames} == {0x100 + 0x10 * (k - 1)}
        assert {e.frame.data for e in frames} == {payload(board.adc.potentiometer)}
        starts = [e.start_ps for e in frames]
        gaps = [b - a for a, b in itertools.pairwise(starts)]
        assert all(abs(gap - TIMER1_PERIOD_PS) < 6 * MS for gap in gaps), \
            "queued on each overflow, sent when the bus is free"
        assert abs(sum(gaps) / len(gaps) - TIMER1_PERIOD_PS) < MS // 2


def test_ex2_a_station_never_receives_its_own_frames_only_the_masters_poll_for_its_id():
    room = classroom(2)
    room.run(0.7)
    board = room.station(1)
    taken = [(e.sender, e.frame.remote) for e in room.bus.frames()
             for name, what in e.received if name == "station1" and what.startswith("RXB")]
    assert taken == [("master", True)], "RXF0 = MESSAGE_ID1 takes the master's RTR for 0x100, never its own data"
    assert board.glcd.line(3) == ""
    assert board.glcd.line(4) == "RX ID  0x100 RTR"
    assert board.ecan.opmode == Mode.NORMAL


def test_ex2_starter_still_in_loopback_stays_off_the_bus():
    room = classroom(2, firmware_dir=KIT / "exercises")
    room.run(0.2)
    assert not any(e.sender in station_names(room) for e in room.bus.trace)
    assert {e.sender for e in room.bus.loopback_trace} == station_names(room)


# ------------------------------------------------------------------ Ex3
def test_ex3_stations_show_the_masters_ad_and_follow_its_potentiometer():
    master = random.Random(31)
    first, second = master.randrange(1024), master.randrange(1024)
    room = classroom(3, master_potentiometer=first)
    room.run(0.3)
    for board in room.stations.values():
        assert board.glcd.line(3) == f"A/D    {first:4d}"
        assert board.glcd.line(4) == "RX ID  0x088"
    room.master.adc.potentiometer = second
    room.run(0.2)
    assert {board.glcd.line(3) for board in room.stations.values()} == {f"A/D    {second:4d}"}
    assert all(sent(room, board.name) for board in room.stations.values()), "they keep sending"


# ------------------------------------------------------------------ Ex4
def test_ex4_stations_send_nothing_and_ack_nothing_before_the_first_0x088():
    room = classroom(4)
    room.run(0.5)
    trace = room.bus.trace
    first = next(i for i, e in enumerate(trace) if e.frame.can_id == 0x088 and e.ok)
    assert first == 0 and trace[first].acked_by == ("monitor",)
    received = {name: what for name, what in trace[first].received}
    assert all(received[name] == "RXB0 via RXF0" for name in station_names(room)), "listen-only still receives"
    for event in trace[first + 1:]:
        if event.sender == "master" and event.frame.can_id == 0x088:
            assert station_names(room) <= set(event.acked_by), "after joining, the stations ACK"
    for board in room.stations.values():
        assert sent(room, board.name) and board.ecan.opmode == Mode.NORMAL
        assert board.glcd.line(5) == "MODE NORMAL"


def test_ex4_filters_are_applied_again_after_the_second_caninitialize():
    """After joining, RXB0 takes only 0x088, not the other stations' frames (masks are not left at 0)."""
    room = classroom(4)
    room.run(0.5)
    for board in room.stations.values():
        shown = {w.text for w in board.glcd.history if w.line == 4}
        assert shown == {"RX ID  0x088    "}
        assert board.glcd.line(3) == f"A/D    {room.master.adc.potentiometer:4d}"


# ------------------------------------------------------------------ Ex5
def test_ex5_stations_send_rtr_with_dlc_0_and_show_the_masters_answer():
    master_potentiometer = random.Random(51).randrange(1024)
    room = classroom(5, master_potentiometer=master_potentiometer)
    room.run(0.6)
    for k, board in room.stations.items():
        rtr_id = 0x81 + (k - 1)
        requests = sent(room, board.name)
        assert requests and all(e.frame.remote and e.frame.dlc == 0 and e.frame.can_id == rtr_id
                                for e in requests)
        answers = [e for e in sent(room, "master", remote=False) if e.frame.can_id == rtr_id]
        assert len(answers) == len(requests)
        assert {e.frame.data for e in answers} == {payload(master_potentiometer)}
        assert board.glcd.line(3) == f"A/D    {master_potentiometer:4d}"
        assert board.glcd.line(4) == f"RX ID  0x{rtr_id:03X}"


# ------------------------------------------------------------------ Ex6
def test_ex6_stations_are_silent_unless_polled_and_answer_with_their_ad():
    room = classroom(6, seed=61)
    room.run(1.33)
    frames = room.bus.frames()
    for k, board in room.stations.items():
        own = 0x100 + 0x10 * (k - 1)
        answers = [i for i, e in enumerate(frames) if e.sender == board.name]
        polls = [i for i, e in enumerate(frames) if e.frame.remote and e.frame.can_id == own]
        assert len(answers) == len(polls) >= 2
        for answer, poll in zip(answers, polls, strict=True):
            assert answer == poll + 1, "the answer follows its poll"
            assert frames[answer].frame.can_id == own and not frames[answer].frame.remote
            assert frames[answer].frame.data == payload(board.adc.potentiometer)
            assert dict(frames[poll].received)[board.name] == "RXB1 via RXF2"
        assert board.glcd.line(6) == f"RTR ID 0x{own:03X}"
        assert board.glcd.line(7) == f"SENT A/D {board.adc.potentiometer:4d}"


def test_ex6_ignores_data_frames_with_its_id_and_rtrs_for_other_ids(tmp_path):
    intruder = tmp_path / "intruder.py"
    intruder.write_text(
        "from appsim.firmware import *\n"
        "def main():\n"
        "    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)\n"
        "    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8)\n"
        "    while True:\n"
        "        if PIR1bits.TMR1IF:\n"
        "            PIR1bits.TMR1IF = 0\n"
        "            CANSendMessage(0x100, [9, 9, 9, 9, 9], 5, CAN_TX_STD_FRAME)\n"
        "            CANSendMessage(0x160, None, 0, CAN_TX_STD_FRAME & CAN_TX_RTR_FRAME)\n"
        "        if CANIsRxReady():\n"
        "            CANReceiveMessage()\n")
    room = classroom(6)
    room.join(intruder, station=6)
    room.run(0.75)
    station1 = sent(room, "station1")
    polls = [e for e in sent(room, "master", remote=True) if e.frame.can_id == 0x100]
    assert len(sent(room, "station6", remote=False)) >= 10
    assert len(station1) == len(polls) == 2
    joined = next(e.start_ps for e in room.bus.frames() if "station2" in e.acked_by)   # in Normal mode from then
    rejected = [dict(e.received)["station2"] for e in sent(room, "station6", remote=True) if e.start_ps > joined]
    assert rejected and set(rejected) == {"rejected by the masks and filters"}


def test_ex6_starter_runs_and_sends_nothing():
    room = classroom(6, firmware_dir=KIT / "exercises")
    room.run(0.7)
    assert not any(e.sender in station_names(room) for e in room.bus.trace)


# ------------------------------------------------------------------ every starter
@pytest.mark.parametrize("exercise", range(1, 7))
def test_each_starter_runs_in_the_classroom_without_crashing(exercise):
    room = classroom(exercise, firmware_dir=KIT / "exercises")
    room.run(0.5)      # raises with the traceback if any board's firmware crashed
    assert all(board.glcd.line(1).startswith(f"EX{exercise}") for board in room.stations.values())


# ------------------------------------------------------------------ what an outside node sends
@pytest.mark.parametrize("folder", ["solutions", "exercises"])
@pytest.mark.parametrize("exercise", range(1, 7))
def test_every_frame_an_outside_node_can_send_leaves_the_classroom_running(folder, exercise):
    """Short frames, long DLCs, remote frames, extended IDs, on every ID a filter lets in: no board stops, and the
    master's polls are answered after them as before (the starters guard RxData as the solutions do)."""
    room = classroom(exercise, firmware_dir=KIT / folder)
    outside = Outside(room.bus)
    room.run(0.12)                                  # Ex4..Ex6 stations have heard 0x088 and gone on the bus
    frames = every_frame()
    outside.send(*frames)
    room.run(2.0)                                   # raises with the traceback if any board's firmware stopped
    carried = Counter(e.frame for e in room.bus.frames())
    assert not Counter(frames) - carried, "every outside frame went through (one the master sent too counts once)"
    from_outside = [e for e in room.bus.frames() if e.sender == "outside"]
    assert all(board.mcu.process is not None and not board.mcu.process.finished for board in room.boards)
    if folder == "solutions" and exercise == 6:
        after = max(e.end_ps for e in from_outside)
        answered = {e.frame.can_id for e in sent(room, "master", remote=True) if e.start_ps > after} & {
            e.frame.can_id for e in room.bus.frames() if e.start_ps > after and not e.frame.remote}
        assert answered, "the master's polls are answered after the outside frames"


def test_reading_past_a_short_frame_is_reported_in_the_workshops_words(tmp_path):
    unguarded = tmp_path / "ex3.py"
    unguarded.write_text((KIT / "solutions" / "ex3.py").read_text().replace("if DataLen >= 5:", "if True:"))
    room = classroom(3)
    room.join(unguarded, station=1)
    outside = Outside(room.bus)
    room.run(0.12)
    outside.send(CanFrame(0x088, b"\x01"))
    room.bus.sim.run(until=ps(0.2))
    line = next(n for n, text in enumerate(unguarded.read_text().splitlines(), 1) if "RxData[3]" in text)
    fault = board_fault(room.station(1).mcu.process)
    assert fault is not None and fault.kind == "exception"
    assert fault.message.startswith(f"main() crashed at line {line} of ex3.py (`putsGLCD(\"A/D    %4d\" % ((RxData[3] "
                                    "<< 8) | RxData[4]))`): IndexError: the frame had 1 data byte; check DataLen "
                                    "before reading RxData[3]")
    assert all(board.mcu.process.failure is None for board in room.boards[2:]), "the other stations go on"


# ------------------------------------------------------------------ the interrupt-driven solutions
def test_a_classroom_of_interrupt_driven_ex6_stations_answers_every_poll_from_the_receive_routine():
    from appsim.workshop.course import SOLUTIONS

    room = classroom(6, seed=61, firmware_dir=SOLUTIONS / "interrupts")
    room.run(1.33)
    frames = room.bus.frames()
    for k, board in room.stations.items():
        own = 0x100 + 0x10 * (k - 1)
        answers = [i for i, e in enumerate(frames) if e.sender == board.name]
        polls = [i for i, e in enumerate(frames) if e.frame.remote and e.frame.can_id == own]
        assert len(answers) == len(polls) >= 2
        for answer, poll in zip(answers, polls, strict=True):
            assert answer == poll + 1, "the answer follows its poll"
            assert frames[answer].frame.data == payload(board.adc.potentiometer)
        assert board.glcd.line(7) == f"SENT A/D {board.adc.potentiometer:4d}"
        assert board.mcu.interrupts.armed, "GIE set: it runs interrupt-driven"


@pytest.mark.parametrize("seed", [202, 7])
@pytest.mark.parametrize("exercise", ["ex1", "ex3", "ex6"])
def test_the_interrupt_driven_solutions_pass_every_check_of_their_exercise(exercise, seed, monkeypatch):
    from appsim.workshop.checks import check
    from appsim.workshop.course import SOLUTIONS

    monkeypatch.chdir(SOLUTIONS / "interrupts")
    verdict = check(exercise, f"{exercise}.py", seed=seed)
    assert verdict.score == verdict.max_score, verdict


def test_grading_the_solutions_folder_reads_its_own_files_and_not_the_interrupt_driven_ones_below():
    """`appsim grade solutions/` is one submission of solutions/ex1.py .. (solutions/interrupts/ is not a classmate
    nor a second copy); `appsim grade solutions/interrupts` is one of its three. Each holds every exercise in Python and
    in C, twins, so each exercise is `ambiguous` between its two files there, as a student's would be."""
    from appsim.workshop.course import C_FILES, EXERCISE_FILES, SOLUTIONS
    from appsim.workshop.grading.submissions import find_submissions

    [regular] = find_submissions([SOLUTIONS])
    assert regular.files == {}
    for exercise, name in EXERCISE_FILES.items():
        fault = regular.problems[exercise]
        assert fault.kind == "ambiguous" and fault.message.startswith(f"{C_FILES[exercise]} and {name} were both"), \
            fault
    [interrupts] = find_submissions([SOLUTIONS / "interrupts"])
    assert {exercise: fault.kind for exercise, fault in interrupts.problems.items()} == {
        "ex1": "ambiguous", "ex3": "ambiguous", "ex6": "ambiguous"}
    assert "ex6.c and ex6.py were both handed in" in interrupts.problems["ex6"].message
