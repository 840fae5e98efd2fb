"""Typical student mistakes (tests/mistakes/, each a solution with one change) get exactly the verdict they deserve:
the checks that fail, and messages that name the cause in the workshop's words. The same on two seeds."""
from __future__ import annotations

from pathlib import Path

import pytest

from appsim.checks import check, check_names

MISTAKES = Path(__file__).resolve().parent / "mistakes"

# check names, as short keys
RUNS = "firmware runs"
EX1_OFF_BUS, EX1_SENDS, EX1_RXB0, EX1_LCD = check_names("ex1")[1:]
EX2_ON_BUS, EX2_FRAMES, EX2_PERIOD, EX2_NOT_OWN = check_names("ex2")[1:]
EX3_RXB0, EX3_LCD, EX3_REJECTS, EX3_SENDS = check_names("ex3")[1:]
EX4_LISTENS, EX4_JOINS, EX4_FILTERS = check_names("ex4")[1:]
EX5_RTR, EX5_PERIOD, EX5_ANSWER, EX5_LCD = check_names("ex5")[1:]
EX6_ANSWERS, EX6_RXB1, EX6_SILENT, EX6_DATA = check_names("ex6")[1:]
DEMO1_BAUD, DEMO1_INVISIBLE, DEMO1_FORMAT, DEMO1_LOST, DEMO1_TIME = check_names("demo1")[1:]

# (file, the checks that fail, words the failing messages must contain)
TABLE = [
    ("ex1_normal_mode", {EX1_OFF_BUS, EX1_RXB0, EX1_LCD}, ["Normal mode", "CAN_OP_MODE_LOOP", "never receives its own"]),
    ("ex1_filter_typo", {EX1_RXB0, EX1_LCD}, ["RXF0 = 0x010", "RX_Filter0", "nothing was received"]),
    ("ex1_adc_bytes_swapped", {EX1_SENDS, EX1_LCD}, ["ADRESH and ADRESL are swapped", "line 3"]),
    ("ex1_lcd_ad_in_hex", {EX1_LCD}, ["line 3 shows 'A/D    0x", "in decimal"]),
    ("ex2_tmr1if_not_cleared", {EX2_PERIOD}, ["a burst", "PIR1bits.TMR1IF = 0"]),
    ("ex2_listen_only", {EX2_ON_BUS, EX2_FRAMES, EX2_PERIOD}, ["Listen-only mode", "CAN_OP_MODE_NORMAL"]),
    ("ex2_prescaler_1_1", {EX2_PERIOD}, ["6.5 ms", "1:8 prescaler"]),
    ("ex2_ad_never_read", {EX2_FRAMES}, ["bytes 3 and 4 say 0", "ConvertADC()"]),
    ("ex2_wrong_bit_rate", {EX2_ON_BUS, EX2_PERIOD}, ["ended in errors", "125 kbit/s", "CANInitialize(4, 10, 8, 4, 3"]),
    ("ex3_mask_zero", {EX3_REJECTS, EX3_LCD}, ["RXM0 = 0x000", "RX_Mask0 = 0x7FF", "from station2", "line 4 shows 'RX ID  0x110'"]),
    ("ex3_lcd_only_on_new_id", {EX3_LCD}, ["still shows", "did not follow", "every frame"]),
    ("ex3_own_ad_on_lcd", {EX3_LCD}, ["your own potentiometer", "RxData"]),
    ("ex3_loopback", {EX3_RXB0, EX3_LCD, EX3_SENDS}, ["Loopback mode", "CAN_OP_MODE_NORMAL"]),
    ("ex4_filters_not_set_again", {EX4_FILTERS}, ["RXM0 = 0x000", "sets the masks to 0", "RX_Filter0 = 0x088 again"]),
    ("ex4_normal_from_start", {EX4_LISTENS}, ["ACKed 0x088", "Listen-only", "CAN_OP_MODE_LISTEN"]),
    ("ex4_listen_before_initialize", {EX4_LISTENS}, ["ACKed 0x088", "CANInitialize() returns in Normal mode"]),
    ("ex4_stays_listening", {EX4_JOINS, EX4_FILTERS}, ["Still in Listen-only mode", "CAN_OP_MODE_NORMAL", "never joined"]),
    ("ex4_all_msg_again", {EX4_FILTERS}, ["RXB0CON.RXM = 11", "CAN_CONFIG_VALID_STD_MSG"]),
    ("ex5_rtr_dlc_5", {EX5_RTR}, ["RTR DLC 5", "DataLen 0"]),
    ("ex5_data_not_rtr", {EX5_RTR, EX5_ANSWER, EX5_LCD}, ["a data frame, not a remote transmission request",
                                                          "CAN_TX_RTR_FRAME", "answers only remote frames"]),
    ("ex5_filter_still_088", {EX5_ANSWER, EX5_LCD}, ["RXF0 = 0x088", "RX_Filter0 = RTR_ID = 0x081",
                                                     "the master's broadcast"]),
    ("ex5_tmr1if_not_cleared", {EX5_PERIOD}, ["a burst", "PIR1bits.TMR1IF = 0"]),
    ("ex6_answers_every_rtr", {EX6_RXB1, EX6_SILENT}, ["RXM1 = 0x000", "asks for another node's data",
                                                       "RX_ID2 == MESSAGE_ID1"]),
    ("ex6_answers_data_frames", {EX6_DATA}, ["Answered the data frame 0x100 DATA 09 09 09 09 09",
                                             "CAN_RX_RTR_FRAME"]),
    ("ex6_mask_zero", {EX6_RXB1}, ["RXB1 took 0x110", "RXM1 = 0x000", "RXB1's MASK"]),
    ("ex6_still_sends_on_timer1", {EX6_SILENT}, ["without being asked", "Timer1"]),
    ("demo1_normal_mode", {DEMO1_INVISIBLE}, ["ACKed", "Normal mode", "CAN_OP_MODE_LISTEN"]),
    ("demo1_spbrg_for_10mhz", {DEMO1_BAUD}, ["78125 baud", "SPBRG = 129 at 40 MHz"]),
    ("demo1_lost_not_counted", {DEMO1_LOST}, ["neither printed nor reported them as lost", "queue"]),
    ("demo1_time_wraps", {DEMO1_TIME}, ["time goes back", "wraps every 52.4288 ms", "PIR1bits.TMR1IF"]),
]


@pytest.mark.parametrize("seed", [202, 7])
@pytest.mark.parametrize(("mistake", "failing", "words"), TABLE, ids=[row[0] for row in TABLE])
def test_a_typical_mistake_gets_the_verdict_it_deserves(mistake, failing, words, seed):
    exercise = mistake.split("_")[0]
    verdict = check(exercise, MISTAKES / f"{mistake}.py", seed=seed)
    assert {c.name for c in verdict.failed()} == failing, str(verdict)
    messages = "\n".join(c.message for c in verdict.failed())
    for word in words:
        assert word in messages, f"{word!r} not in:\n{messages}"


def test_every_mistake_file_is_in_the_table_and_every_exercise_has_enough():
    assert sorted(path.stem for path in MISTAKES.glob("*.py")) == sorted(row[0] for row in TABLE)
    for exercise, fewest in [("ex1", 3), ("ex2", 3), ("ex3", 3), ("ex4", 3), ("ex5", 3), ("ex6", 3), ("demo1", 2)]:
        assert sum(row[0].startswith(exercise + "_") for row in TABLE) >= fewest
