"""The classroom: the master console's timing, polls and RTR answers; per-station defines; joining your own board."""
from __future__ import annotations

import itertools
import random
import time
from pathlib import Path

import pytest
from workshop import KIT, MS, classroom, payload, sent

from appsim.bus.wire import Bus
from appsim.firmware.loader import FirmwareError, constants, load_firmware
from appsim.sim import Simulator
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import station_ids

STATION_IDS = [0x100, 0x110, 0x120, 0x130, 0x140, 0x150]


# ------------------------------------------------------------------ the master console
def test_master_broadcasts_0x088_every_100_ms_with_its_potentiometer():
    master_potentiometer = random.Random(11).randrange(1024)
    room = classroom(6, master_potentiometer=master_potentiometer)
    room.run(1.03)
    broadcasts = [e for e in sent(room, "master", remote=False) if e.frame.can_id == 0x088]
    assert len(broadcasts) == 10
    assert {e.frame.data for e in broadcasts} == {payload(master_potentiometer)}
    starts = [e.start_ps for e in broadcasts]
    assert all(abs(b - a - 100 * MS) < MS // 20 for a, b in itertools.pairwise(starts))
    # reloading TMR1 loses no time (what it counted since the overflow is added back): < 1 us per period
    assert abs(starts[-1] - starts[0] - 900 * MS) < 9 * MS // 1000
    assert room.master.glcd.line(1) == "MASTER CONSOLE"
    assert room.master.glcd.line(3) == f"A/D    {master_potentiometer:4d}"


def test_master_polls_the_stations_round_robin_50_ms_after_each_broadcast():
    room = classroom(6)
    room.run(1.33)
    master = sent(room, "master")
    polls = [e for e in master if e.frame.remote]
    assert [e.frame.can_id for e in polls] == STATION_IDS * 2 + STATION_IDS[:1]
    assert all(e.frame.dlc == 0 for e in polls)
    broadcasts = [e for e in master if e.frame.can_id == 0x088]
    for poll, broadcast in zip(polls, broadcasts):
        assert abs(poll.start_ps - broadcast.start_ps - 50 * MS) < MS // 20
    assert room.master.glcd.line(5) == "POLL   0x100"


def test_master_answers_rtr_0x81_to_0x86_only(tmp_path):
    """A student board of our own asks for 0x83 (answered), 0x80 and 0x87 (not the master's)."""
    asker = tmp_path / "asker.py"
    asker.write_text(
        "from appsim.firmware import *\n"
        "REQUESTS = (0x83, 0x80, 0x87)\n"
        "def main():\n"
        "    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)\n"
        "    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8)\n"
        "    n = 0\n"
        "    while True:\n"
        "        if PIR1bits.TMR1IF:\n"
        "            PIR1bits.TMR1IF = 0\n"
        "            CANSendMessage(REQUESTS[n % 3], None, 0, CAN_TX_STD_FRAME & CAN_TX_RTR_FRAME)\n"
        "            n += 1\n"
        "        if CANIsRxReady():\n"
        "            CANReceiveMessage()\n")
    master_potentiometer = random.Random(12).randrange(1024)
    room = classroom(6, master_potentiometer=master_potentiometer)
    room.join(asker, station=3)
    room.run(0.7)
    asked = [e.frame.can_id for e in sent(room, "station3", remote=True)]
    assert asked.count(0x83) >= 4 and 0x80 in asked and 0x87 in asked
    answers = [e for e in sent(room, "master", remote=False) if e.frame.can_id != 0x088]
    assert [e.frame.can_id for e in answers] == [0x83] * asked.count(0x83)
    assert {e.frame.data for e in answers} == {payload(master_potentiometer)}
    assert room.master.glcd.line(6) == "ANSWER 0x083"


def test_without_the_pc_monitor_nobody_acks_the_master_while_the_stations_listen():
    """Ex4 with every student in Listen-only mode: the master's 0x088 gets ACK errors (gotcha 3)."""
    room = classroom(4, monitor=False)
    room.run(0.2)
    broadcasts = [e for e in room.bus.trace if e.frame.can_id == 0x088]
    failed = next(k for k, e in enumerate(broadcasts) if e.ok)
    assert failed >= 16 and all(e.error.startswith("ACK error") for e in broadcasts[:failed]), \
        "16 ACK errors make the master error-passive (TEC 128)"
    # Error-passive, its ACK error flag is recessive: the listening stations take the frame as valid,
    # re-initialise in Normal mode (recessive bits end every error frame) and ACK from then on.
    assert set(broadcasts[-1].acked_by) == {f"station{k}" for k in range(1, 7)}
    assert room.master.ecan.tec < 128


# ------------------------------------------------------------------ stations and defines
def test_each_station_runs_the_solution_with_its_own_ids_and_potentiometer():
    room = classroom(2, seed=7)
    expected = random.Random(7)
    room.run(0.3)
    for k in range(1, 7):
        board = room.station(k)
        assert board.name == f"station{k}"
        assert board.adc.potentiometer == expected.randrange(1024)
        frames = sent(room, f"station{k}")
        assert frames and {e.frame.can_id for e in frames} == {station_ids(k)["MESSAGE_ID1"]}
        assert {e.frame.data for e in frames} == {payload(board.adc.potentiometer)}
        assert board.glcd.line(2) == f"TX ID  0x{0x100 + 0x10 * (k - 1):03X}"


def test_station_ids_follow_the_classroom_convention():
    assert [station_ids(k) for k in (1, 6)] == [{"MESSAGE_ID1": 0x100, "RTR_ID": 0x81},
                                                {"MESSAGE_ID1": 0x150, "RTR_ID": 0x86}]
    with pytest.raises(ValueError, match="numbered 1..6"):
        station_ids(7)


def test_ex5_stations_get_their_rtr_id_from_the_defines():
    room = classroom(5)
    room.run(0.2)
    for k in range(1, 7):
        assert {e.frame.can_id for e in sent(room, f"station{k}")} == {0x80 + k}


def test_a_define_replaces_the_constant_and_what_is_computed_from_it():
    module = load_firmware(KIT / "solutions" / "ex6.py", defines={"MESSAGE_ID1": 0x130})
    assert module.MESSAGE_ID1 == 0x130 and module.RX_Filter2 == 0x130
    plain = load_firmware(KIT / "solutions" / "ex6.py")
    assert plain.MESSAGE_ID1 == 0x100 and plain.RX_Filter2 == 0x100


def test_a_define_the_file_does_not_assign_is_refused_with_the_names_it_does():
    with pytest.raises(FirmwareError, match="RTR_ID.*It defines MESSAGE_ID1, RX_Filter0, RX_Mask0, TxData"):
        load_firmware(KIT / "solutions" / "ex3.py", defines={"RTR_ID": 0x83})
    with pytest.raises(FirmwareError, match="a define is an integer"):
        load_firmware(KIT / "solutions" / "ex3.py", defines={"MESSAGE_ID1": "0x110"})
    assert constants(KIT / "solutions" / "ex5.py") == ["RTR_ID", "RX_Filter0", "RX_Mask0"]


def test_the_classroom_refuses_what_the_workshop_does_not_have():
    bus = Bus(Simulator(), 125_000)
    with pytest.raises(ValueError, match="EX1.C .. EX6.C"):
        Classroom(bus, 7)
    with pytest.raises(ValueError, match="one potentiometer value per station"):
        Classroom(bus, 2, stations=3, potentiometers=[1, 2])
    with pytest.raises(ValueError, match="0..1023"):
        Classroom(bus, 2, stations=1, potentiometers=[1024])


# ------------------------------------------------------------------ your own board
def test_join_puts_your_file_on_a_station_and_it_runs_as_written(tmp_path):
    mine = tmp_path / "my_ex2.py"
    mine.write_text((KIT / "solutions" / "ex2.py").read_text().replace("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 0x120"))
    room = classroom(2)
    board = room.join(mine, station=3)
    room.run(0.2)
    assert board is room.station(3)
    assert {e.frame.can_id for e in sent(room, "station3")} == {0x120}
    assert board.firmware is not None and Path(board.firmware.__file__) == mine


def test_join_with_defines_and_with_a_loaded_module():
    room = classroom(3)
    room.join(KIT / "solutions" / "ex3.py", station=1, defines={"RX_Filter0": 0x110})   # the neighbour
    room.join(load_firmware(KIT / "solutions" / "ex3.py", defines={"MESSAGE_ID1": 0x150}), station=6)
    room.run(0.3)
    assert room.station(1).glcd.line(3) == f"A/D    {room.station(2).adc.potentiometer:4d}"
    assert room.station(1).glcd.line(4) == "RX ID  0x110"
    assert {e.frame.can_id for e in sent(room, "station6")} == {0x150}
    with pytest.raises(FirmwareError, match="give the path"):
        classroom(3).join(load_firmware(KIT / "solutions" / "ex3.py"), station=2, defines={"MESSAGE_ID1": 0x110})


def test_join_after_the_class_started_is_refused():
    room = classroom(2)
    room.run(0.01)
    with pytest.raises(RuntimeError, match="join before the classroom runs"):
        room.join(KIT / "solutions" / "ex2.py", station=2)
    with pytest.raises(ValueError, match="numbered 1..6"):
        room.join(KIT / "solutions" / "ex2.py", station=0)


def test_a_crashing_board_is_reported_with_its_traceback(tmp_path):
    broken = tmp_path / "broken.py"
    broken.write_text("from appsim.firmware import *\ndef main():\n    setcurGLCD(1, 1)\n")
    room = classroom(2)
    room.join(broken, station=2)
    with pytest.raises(FirmwareError, match="station2 crashed(.|\n)*GLCD_Initial"):
        room.run(0.01)


def test_two_classrooms_with_the_same_seed_give_the_same_trace():
    traces = []
    for _ in range(2):
        room = classroom(5, seed=99)
        room.run(0.3)
        traces.append([(e.start_ps, e.sender, e.frame, e.acked_by) for e in room.bus.trace])
    assert traces[0] == traces[1] and len(traces[0]) > 20


def test_benchmark_two_simulated_seconds_of_ex6():
    room = classroom(6)
    start = time.perf_counter()
    room.run(2.0)
    wall = time.perf_counter() - start
    print(f"\nEx6 classroom (master, 6 stations, PC monitor): 2.000 s simulated in {wall:.3f} s wall, "
          f"{len(room.bus.trace)} frames")
