"""The master console's firmware: the 0x088 broadcast every 100 ms, answers to RTR 0x81..0x86, RTR polls of
0x100..0x150.

Firmware like the students' (load it with `appsim.firmware.loader.load_firmware`); Timer1 at 1:8 with a preload ticks
every 50 ms.
"""
from appsim.firmware import *

MESSAGE_ID1 = 0x088                                             # the master's broadcast
STATION_IDS = (0x100, 0x110, 0x120, 0x130, 0x140, 0x150)        # polled with RTR frames (Ex6)
FIRST_RTR_ID, LAST_RTR_ID = 0x81, 0x86                          # requests it answers (Ex5)
RX_Filter0, RX_Mask0 = 0x080, 0x7F8     # RXB0: IDs 0x080..0x087, the stations' RTR frames
RX_Filter2, RX_Mask1 = 0x100, 0x70F     # RXB1: IDs 0x1n0, the stations' answers to the polls
# 50 ms = 62500 counts of Fosc/4 / 8 (0.8 us each). Reloading must not lose time: the counts since the
# overflow are added back (ReadTimer1), and so are the 2 counts (16 Tcy) from that read to the write.
TIMER1_PRELOAD = 65536 - 62500 + 2

TxData = [0x01, 0x02, 0x03, 0x00, 0x00]


def CANInitialization():
    # 125 kbit/s at Fosc = 40 MHz: SJW 4, BRP 10, PHSEG1 8, PHSEG2 4, PROPSEG 3 (16 TQ, sample point 75 %)
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)
    CANSetOperationMode(CAN_OP_MODE_CONFIG)         # CANInitialize returns in NORMAL mode, masks at 0
    CANSetMask(CAN_MASK_B1, RX_Mask0, CAN_CONFIG_STD_MSG)
    CANSetMask(CAN_MASK_B2, RX_Mask1, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B1_F1, RX_Filter0, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B1_F2, RX_Filter0, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B2_F1, RX_Filter2, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B2_F2, RX_Filter2, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B2_F3, RX_Filter2, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B2_F4, RX_Filter2, CAN_CONFIG_STD_MSG)
    CANSetOperationMode(CAN_OP_MODE_NORMAL)


def read_potentiometer():
    ConvertADC()
    while BusyADC():
        pass
    TxData[3] = SFR.ADRESH
    TxData[4] = SFR.ADRESL


def send_data(id):
    read_potentiometer()
    CANSendMessage(id, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME)


def main():
    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS, ADC_1ANA)
    GLCD_Initial()
    setcurGLCD(1, 1)
    putrsGLCD("MASTER CONSOLE")
    setcurGLCD(2, 1)
    putsGLCD("TX ID  0x%03X" % MESSAGE_ID1)
    CANInitialization()
    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
    WriteTimer1(TIMER1_PRELOAD)
    broadcast = False
    station = 0
    while True:
        if PIR1bits.TMR1IF:                         # every 50 ms
            PIR1bits.TMR1IF = 0
            WriteTimer1(ReadTimer1() + TIMER1_PRELOAD)
            broadcast = not broadcast
            if broadcast:
                send_data(MESSAGE_ID1)
                setcurGLCD(3, 1)
                putsGLCD("A/D    %4d" % ((TxData[3] << 8) | TxData[4]))
            else:
                CANSendMessage(STATION_IDS[station], None, 0,
                               CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_RTR_FRAME)
                setcurGLCD(5, 1)
                putsGLCD("POLL   0x%03X" % STATION_IDS[station])
                station = (station + 1) % len(STATION_IDS)
        if CANIsRxReady():
            RX_ID1, RxData, DataLen, CANMessageFlag = CANReceiveMessage()
            setcurGLCD(4, 1)
            putsGLCD("RX ID  0x%03X" % RX_ID1)
            if CANMessageFlag & CAN_RX_RTR_FRAME:
                if FIRST_RTR_ID <= RX_ID1 <= LAST_RTR_ID:
                    send_data(RX_ID1)
                    setcurGLCD(6, 1)
                    putsGLCD("ANSWER 0x%03X" % RX_ID1)
            elif RX_ID1 in STATION_IDS and DataLen == 5:
                setcurGLCD(7, 1)
                putsGLCD("0x%03X A/D %4d" % (RX_ID1, (RxData[3] << 8) | RxData[4]))
