"""Typical student mistakes, each a small edit of a reference solution in solutions/, and the verdict it deserves.

To add one: copy a row, give it a new name (exercise first: "ex2_..."), name the solution file it edits, write
the edit as (text in the solution, text the student wrote) pairs (each old text must occur exactly once, so
include indentation and "\\n" to add or delete whole lines), then the checks that must fail and words their
messages must contain. Put one comment line above it saying what the student did. tests/test_mistakes.py runs it.
"""
from __future__ import annotations

from typing import NamedTuple

from appsim.workshop.checks import check_names


class Mistake(NamedTuple):
    name: str                      # "<exercise>_<what went wrong>"
    solution: str                  # the file in solutions/ it edits, without ".py"
    edits: list[tuple[str, str]]   # (old, new), applied in order; each old occurs exactly once
    failing: set[str]              # exactly the checks that fail
    words: list[str]               # each occurs in the failing checks' messages

    @property
    def exercise(self) -> str:
        """The exercise `check()` judges it as: "ex1".."ex6", or "demo1" (solutions/demo1_monitor.py)."""
        return self.solution.split("_")[0]


# check names, as short keys
EX1_OFF_BUS, EX1_SENDS, EX1_RXB0, EX1_LCD = check_names("ex1")[1:]
EX2_ON_BUS, EX2_FRAMES, EX2_PERIOD, EX2_NOT_OWN = check_names("ex2")[1:]
EX3_RXB0, EX3_LCD, EX3_REJECTS, EX3_SENDS = check_names("ex3")[1:]
EX4_LISTENS, EX4_JOINS, EX4_FILTERS = check_names("ex4")[1:]
EX5_RTR, EX5_PERIOD, EX5_ANSWER, EX5_LCD = check_names("ex5")[1:]
EX6_ANSWERS, EX6_RXB1, EX6_SILENT, EX6_DATA = check_names("ex6")[1:]
DEMO1_BAUD, DEMO1_INVISIBLE, DEMO1_FORMAT, DEMO1_LOST, DEMO1_TIME = check_names("demo1")[1:]

MISTAKES = [
    # Normal mode instead of Loopback: the frame goes out on the classroom bus, and a node never receives its own.
    Mistake("ex1_normal_mode", "ex1",
            [("CANSetOperationMode(CAN_OP_MODE_LOOP)", "CANSetOperationMode(CAN_OP_MODE_NORMAL)")],
            {EX1_OFF_BUS, EX1_RXB0, EX1_LCD}, ["Normal mode", "CAN_OP_MODE_LOOP", "never receives its own"]),
    # RX_Filter0 = 0x010, a typo for MESSAGE_ID1 = 0x100: under mask 0x7FF the own frame is rejected.
    Mistake("ex1_filter_typo", "ex1",
            [("RX_Filter0 = MESSAGE_ID1", "RX_Filter0 = 0x010")],
            {EX1_RXB0, EX1_LCD}, ["RXF0 = 0x010", "RX_Filter0", "nothing was received"]),
    # ADRESH and ADRESL swapped in TxData: the payload is 01 02 03 ADRESL ADRESH.
    Mistake("ex1_adc_bytes_swapped", "ex1",
            [("TxData[3] = SFR.ADRESH", "TxData[3] = SFR.ADRESL"),
             ("TxData[4] = SFR.ADRESL", "TxData[4] = SFR.ADRESH")],
            {EX1_SENDS, EX1_LCD}, ["ADRESH and ADRESL are swapped", "line 3"]),
    # The A/D value in hex on LCD line 3 instead of decimal.
    Mistake("ex1_lcd_ad_in_hex", "ex1",
            [('putsGLCD("A/D    %4d"', 'putsGLCD("A/D    0x%03X"')],
            {EX1_LCD}, ["line 3 shows 'A/D    0x", "in decimal"]),

    # PIR1bits.TMR1IF never cleared: after the first overflow it sends on every turn of the loop.
    Mistake("ex2_tmr1if_not_cleared", "ex2",
            [("            PIR1bits.TMR1IF = 0\n", "")],
            {EX2_PERIOD}, ["a burst", "PIR1bits.TMR1IF = 0"]),
    # Listen-only mode instead of Normal: it hears the bus but never sends, so no frame of its own can come back.
    Mistake("ex2_listen_only", "ex2",
            [("CANSetOperationMode(CAN_OP_MODE_NORMAL)", "CANSetOperationMode(CAN_OP_MODE_LISTEN)")],
            {EX2_ON_BUS, EX2_FRAMES, EX2_PERIOD, EX2_NOT_OWN}, ["Listen-only mode", "CAN_OP_MODE_NORMAL",
                                                               "Nothing to judge"]),
    # Timer1 at 1:1 instead of 1:8: it overflows every 6.5536 ms, not 52.4288 ms.
    Mistake("ex2_prescaler_1_1", "ex2",
            [("T1_PS_1_8", "T1_PS_1_1")],
            {EX2_PERIOD}, ["6.5 ms", "1:8 prescaler"]),
    # The A/D never read before sending: ADRESH ADRESL stay 00 00 in TxData.
    Mistake("ex2_ad_never_read", "ex2",
            [("            read_potentiometer()\n", "")],
            {EX2_FRAMES}, ["bytes 3 and 4 say 0", "ConvertADC()"]),
    # BRP 5 instead of 10: 250 kbit/s on a 125 kbit/s bus, every frame ends in an error frame.
    Mistake("ex2_wrong_bit_rate", "ex2",
            [("CANInitialize(4, 10, 8, 4, 3,", "CANInitialize(4, 5, 8, 4, 3,")],
            {EX2_ON_BUS, EX2_PERIOD}, ["ended in errors", "125 kbit/s", "CANInitialize(4, 10, 8, 4, 3"]),

    # RX_Mask0 = 0: no ID bit is compared, so RXB0 takes every frame on the bus.
    Mistake("ex3_mask_zero", "ex3",
            [("RX_Mask0 = 0x7FF          # every ID bit is compared", "RX_Mask0 = 0x000")],
            {EX3_REJECTS, EX3_LCD}, ["RXM0 = 0x000", "RX_Mask0 = 0x7FF", "from station2",
                                     "line 4 shows 'RX ID  0x110'"]),
    # The LCD redrawn only when the received ID changes: the master's A/D is shown once and never updated.
    Mistake("ex3_lcd_only_on_new_id", "ex3",
            [("    while True:\n",
              ("    last_id = -1\n"
               "    while True:\n")),
             ("CANMessageFlag = CANReceiveMessage()\n",
              ("CANMessageFlag = CANReceiveMessage()\n"
               "            if RX_ID1 == last_id:\n"
               "                continue\n"
               "            last_id = RX_ID1\n"))],
            {EX3_LCD}, ["still shows", "did not follow", "every frame"]),
    # Its own A/D (TxData) on line 3 instead of the received data.
    Mistake("ex3_own_ad_on_lcd", "ex3",
            [("((RxData[3] << 8) | RxData[4])", "((TxData[3] << 8) | TxData[4])")],
            {EX3_LCD}, ["your own potentiometer", "RxData"]),
    # Left in Loopback mode (the EX1 setting): it neither sends on the bus nor receives the master.
    Mistake("ex3_loopback", "ex3",
            [("CANSetOperationMode(CAN_OP_MODE_NORMAL)", "CANSetOperationMode(CAN_OP_MODE_LOOP)")],
            {EX3_RXB0, EX3_LCD, EX3_REJECTS, EX3_SENDS}, ["Loopback mode", "CAN_OP_MODE_NORMAL",
                                                          "heard none of the other stations' frames"]),

    # CANInitialize() again after the first 0x088, without setting the mask and filter again: the masks stay 0.
    Mistake("ex4_filters_not_set_again", "ex4",
            [("CANInitialization(CAN_CONFIG_VALID_STD_MSG, CAN_OP_MODE_NORMAL)",
              "CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)")],
            {EX4_FILTERS}, ["RXM0 = 0x000", "sets the masks to 0", "RX_Filter0 = 0x088 again"]),
    # Normal mode from the start instead of Listen-only: it ACKs the master's 0x088 before it has checked anything.
    Mistake("ex4_normal_from_start", "ex4",
            [("CANInitialization(CAN_CONFIG_ALL_MSG, CAN_OP_MODE_LISTEN)",
              "CANInitialization(CAN_CONFIG_ALL_MSG, CAN_OP_MODE_NORMAL)")],
            {EX4_LISTENS}, ["ACKed 0x088", "Listen-only", "CAN_OP_MODE_LISTEN"]),
    # Listen-only requested before CANInitialize(), which then returns in Normal mode.
    Mistake("ex4_listen_before_initialize", "ex4",
            [("CANInitialization(CAN_CONFIG_ALL_MSG, CAN_OP_MODE_LISTEN)",
              ("CANSetOperationMode(CAN_OP_MODE_LISTEN)\n"
               "    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)"))],
            {EX4_LISTENS}, ["ACKed 0x088", "CANInitialize() returns in Normal mode"]),
    # Listen-only asked for again in step 6: it never goes on the bus.
    Mistake("ex4_stays_listening", "ex4",
            [("CANInitialization(CAN_CONFIG_VALID_STD_MSG, CAN_OP_MODE_NORMAL)",
              "CANInitialization(CAN_CONFIG_VALID_STD_MSG, CAN_OP_MODE_LISTEN)")],
            {EX4_JOINS, EX4_FILTERS}, ["Still in Listen-only mode", "CAN_OP_MODE_NORMAL", "never joined"]),
    # CAN_CONFIG_ALL_MSG passed to the second CANInitialize() too: RXM = 11 takes every frame.
    Mistake("ex4_all_msg_again", "ex4",
            [("CANInitialization(CAN_CONFIG_VALID_STD_MSG, CAN_OP_MODE_NORMAL)",
              "CANInitialization(CAN_CONFIG_ALL_MSG, CAN_OP_MODE_NORMAL)")],
            {EX4_FILTERS}, ["RXB0CON.RXM = 11", "CAN_CONFIG_VALID_STD_MSG"]),

    # DataLen 3 in the request: neither the workshop's 0 nor the requested length 5 (CAN 2.0's advice).
    Mistake("ex5_rtr_dlc_3", "ex5",
            [("CANSendMessage(RTR_ID, None, 0,", "CANSendMessage(RTR_ID, None, 3,")],
            {EX5_RTR}, ["RTR DLC 3", "DataLen 0", "5 here", "bit error"]),
    # No CAN_TX_RTR_FRAME: an empty data frame with RTR_ID, which the master does not answer.
    Mistake("ex5_data_not_rtr", "ex5",
            [("CAN_TX_STD_FRAME & CAN_TX_RTR_FRAME", "CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME")],
            {EX5_RTR, EX5_ANSWER, EX5_LCD}, ["a data frame, not a remote transmission request",
                                             "CAN_TX_RTR_FRAME", "answers only remote frames"]),
    # RX_Filter0 still 0x088 (from EX4): the master's answer to the request is rejected.
    Mistake("ex5_filter_still_088", "ex5",
            [("RX_Filter0 = RTR_ID", "RX_Filter0 = 0x088")],
            {EX5_ANSWER, EX5_LCD}, ["RXF0 = 0x088", "RX_Filter0 = RTR_ID = 0x081", "the master's broadcast"]),
    # PIR1bits.TMR1IF never cleared: RTR frames in a burst.
    Mistake("ex5_tmr1if_not_cleared", "ex5",
            [("            PIR1bits.TMR1IF = 0\n", "")],
            {EX5_PERIOD}, ["a burst", "PIR1bits.TMR1IF = 0"]),

    # RX_Mask1 = 0 and no test of RX_ID2: it answers every RTR, whoever it asks.
    Mistake("ex6_answers_every_rtr", "ex6",
            [("RX_Mask1 = 0x7FF", "RX_Mask1 = 0x000"),
             ("if RX_ID2 == MESSAGE_ID1 and CANMessageFlag", "if CANMessageFlag")],
            {EX6_RXB1, EX6_SILENT}, ["RXM1 = 0x000", "asks for another node's data", "RX_ID2 == MESSAGE_ID1"]),
    # No CAN_RX_RTR_FRAME test: a data frame with its own ID is answered as if it were a request.
    Mistake("ex6_answers_data_frames", "ex6",
            [("if RX_ID2 == MESSAGE_ID1 and CANMessageFlag & CAN_RX_RTR_FRAME:", "if RX_ID2 == MESSAGE_ID1:")],
            {EX6_DATA}, ["Answered the data frame 0x100 DATA 09 09 09 09 09", "CAN_RX_RTR_FRAME"]),
    # RX_Mask1 = 0 (the software test is kept): RXB1 takes every frame RXB0 does not.
    Mistake("ex6_mask_zero", "ex6",
            [("RX_Mask1 = 0x7FF", "RX_Mask1 = 0x000")],
            {EX6_RXB1}, ["RXB1 took 0x110", "RXM1 = 0x000", "RXB1's MASK"]),
    # EX4's sending on every Timer1 overflow kept: it talks without being asked.
    Mistake("ex6_still_sends_on_timer1", "ex6",
            [("    while True:\n",
              ("    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8"
               " & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)\n"
               "    while True:\n"
               "        if PIR1bits.TMR1IF:\n"
               "            PIR1bits.TMR1IF = 0\n"
               "            read_potentiometer()\n"
               "            CANSendMessage(MESSAGE_ID1, TxData, 5,"
               " CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME)\n"))],
            {EX6_SILENT}, ["without being asked", "Timer1"]),

    # The monitor in Normal mode instead of Listen-only: it ACKs every frame it watches.
    Mistake("demo1_normal_mode", "demo1_monitor",
            [("CANSetOperationMode(CAN_OP_MODE_LISTEN)", "CANSetOperationMode(CAN_OP_MODE_NORMAL)")],
            {DEMO1_INVISIBLE}, ["ACKed", "Normal mode", "CAN_OP_MODE_LISTEN"]),
    # SPBRG computed for the 10 MHz crystal (31) instead of Fosc = 40 MHz (129): 78125 baud.
    Mistake("demo1_spbrg_for_10mhz", "demo1_monitor",
            [("USART_BRGH_HIGH, 129)", "USART_BRGH_HIGH, 31)")],
            {DEMO1_BAUD}, ["78125 baud", "SPBRG = 129 at 40 MHz"]),
    # Frames dropped when the queue is full without counting them: no '# lost' line.
    Mistake("demo1_lost_not_counted", "demo1_monitor",
            [("        lost += 1\n", "")],
            {DEMO1_LOST}, ["neither printed nor reported them as lost", "queue"]),
    # Lines stamped with TMR1 alone, without counting its overflows: the time wraps every 52.4 ms.
    Mistake("demo1_time_wraps", "demo1_monitor",
            [("return (overflows << 16) | ticks", "return ticks")],
            {DEMO1_TIME}, ["time goes back", "wraps every 52.4288 ms", "PIR1bits.TMR1IF"]),
]
