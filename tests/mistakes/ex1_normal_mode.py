"""Typical mistake: EX1 with CAN_OP_MODE_NORMAL instead of CAN_OP_MODE_LOOP: the frame goes out on the classroom bus, and a node never receives its own frame there.

A copy of solutions/ex1.py with that one change."""
from appsim.firmware import *

MESSAGE_ID1 = 0x100     # this node's transmit identifier
RX_Filter0 = MESSAGE_ID1  # RXF0 equals the own ID, so RXB0 takes the looped-back frame
RX_Mask0 = 0x7FF          # every ID bit is compared

TxData = [0x01, 0x02, 0x03, 0x00, 0x00]


def CANInitialization():
    # 125 kbit/s at Fosc = 40 MHz: SJW 4, BRP 10, PHSEG1 8, PHSEG2 4, PROPSEG 3 (16 TQ, sample point 75 %)
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)
    CANSetOperationMode(CAN_OP_MODE_CONFIG)         # CANInitialize returns in NORMAL mode
    CANSetMask(CAN_MASK_B1, RX_Mask0, CAN_CONFIG_STD_MSG)
    CANSetMask(CAN_MASK_B2, RX_Mask0, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B1_F1, RX_Filter0, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B1_F2, RX_Filter0, CAN_CONFIG_STD_MSG)
    CANSetOperationMode(CAN_OP_MODE_NORMAL)


def read_potentiometer():
    ConvertADC()
    while BusyADC():
        pass
    TxData[3] = SFR.ADRESH
    TxData[4] = SFR.ADRESL


def main():
    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_1ANA,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS)
    GLCD_Initial()
    setcurGLCD(1, 1)
    putrsGLCD("EX1 LOOPBACK")
    setcurGLCD(2, 1)
    putsGLCD("TX ID  0x%03X" % MESSAGE_ID1)
    CANInitialization()
    read_potentiometer()
    CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME)
    while True:
        if CANIsRxReady():                          # is your TX data in the RX buffer?
            RX_ID1, RxData, DataLen, CANMessageFlag = CANReceiveMessage()
            setcurGLCD(3, 1)
            putsGLCD("A/D    %4d" % ((RxData[3] << 8) | RxData[4]))
            setcurGLCD(4, 1)
            putsGLCD("RX ID  0x%03X" % RX_ID1)
