"""EX1, interrupt-driven - Simple message in Loopback mode (CAN Workshop 202, exercise 1).

The same node as solutions/ex1.py, off the bus in Loopback mode, but the frame it sends itself is taken in by the
receive interrupt: PIE3.RXB0IE enables it, INTCON.PEIE and INTCON.GIE let it through (RCON.IPEN = 0: every interrupt
goes to the routine at vector 0x08, `#pragma interrupt high_isr` in C18, @interrupt here).

Question: the routine tests CANIsRxReady() in a loop. Would a plain `if` do?

Answer: here, yes: one frame comes back. In general no: a routine is entered because a flag is set, and by the time
it runs another frame may have come into RXB1. Taking messages until none is left (or until CANSTAT.ICODE reads 000)
empties both buffers in one entry. What must never happen is a return with the flag still set: the core would enter
the routine again at once, for ever (CANReceiveMessage() clears RXBnIF).
"""
from appsim.firmware import *

MESSAGE_ID1 = 0x100     # this node's transmit identifier
RX_Filter0 = MESSAGE_ID1  # RXF0 equals the own ID, so RXB0 takes the looped-back frame
RX_Mask0 = 0x7FF          # every ID bit is compared

TxData = [0x01, 0x02, 0x03, 0x00, 0x00]
news = False              # volatile, set by the routine
rx_id, rx_ad = 0, -1


def CANInitialization():
    # 125 kbit/s at Fosc = 40 MHz: SJW 4, BRP 10, PHSEG1 8, PHSEG2 4, PROPSEG 3 (16 TQ, sample point 75 %)
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)
    CANSetOperationMode(CAN_OP_MODE_CONFIG)         # CANInitialize returns in NORMAL mode
    CANSetMask(CAN_MASK_B1, RX_Mask0, CAN_CONFIG_STD_MSG)
    CANSetMask(CAN_MASK_B2, RX_Mask0, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B1_F1, RX_Filter0, CAN_CONFIG_STD_MSG)
    CANSetFilter(CAN_FILTER_B1_F2, RX_Filter0, CAN_CONFIG_STD_MSG)
    CANSetOperationMode(CAN_OP_MODE_LOOP)


def read_potentiometer():
    ConvertADC()
    while BusyADC():
        pass
    TxData[3] = SFR.ADRESH
    TxData[4] = SFR.ADRESL


@interrupt
def high_isr():
    """A frame came into RXB0 or RXB1 (vector 0x08)."""
    global news, rx_id, rx_ad
    while CANIsRxReady():
        RX_ID1, RxData, DataLen, CANMessageFlag = CANReceiveMessage()    # clears RXFUL and RXBnIF
        rx_id = RX_ID1
        if DataLen >= 5:                            # 01 02 03 ADRESH ADRESL: a shorter frame has no A/D value
            rx_ad = (RxData[3] << 8) | RxData[4]
        news = True


def main():
    global news
    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD, ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS,
            ADC_1ANA)
    GLCD_Initial()
    setcurGLCD(1, 1)
    putrsGLCD("EX1 LOOPBACK (INT)")
    setcurGLCD(2, 1)
    putsGLCD("TX ID  0x%03X" % MESSAGE_ID1)
    CANInitialization()
    PIE3bits.RXB0IE = 1                             # the receive interrupts
    PIE3bits.RXB1IE = 1
    INTCONbits.PEIE = 1
    INTCONbits.GIE = 1
    read_potentiometer()
    CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME)
    while True:
        while not news:                             # while (!news); - the routine sets it
            pass
        news = False
        if rx_ad >= 0:
            setcurGLCD(3, 1)
            putsGLCD("A/D    %4d" % rx_ad)
        setcurGLCD(4, 1)
        putsGLCD("RX ID  0x%03X" % rx_id)
