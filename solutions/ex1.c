/* EX1 solution - Simple message in Loopback mode (CAN Workshop 202, exercise 1).
 *
 * Goal: practise sending and receiving without disturbing the CAN bus. In Loopback mode the ECAN
 * does not drive CANTX: the frame goes from TXB0 straight to the message assembly buffer (MAB),
 * and from there through the acceptance masks and filters into RXB0 or RXB1.
 *
 * Send a standard data frame with ID MESSAGE_ID1 and 5 bytes: 01 02 03 ADRESH ADRESL
 * (the A/D result of channel 0, the potentiometer). Then wait for it with CANIsRxReady(). The LCD
 * shows the transmitted ID on line 2 (hex) and, once the frame is received, its A/D value on line 3
 * (decimal, 0..1023) and the received ID on line 4 (hex).
 *
 * Question: will RXB0 receive the data you sent? Normally, no! Why?
 *
 * Answer: Loopback keeps the acceptance logic. A frame reaches RXB0 only if it passes RXF0 or RXF1
 * under mask RXM0 (or RXB1 through RXF2..RXF5 under RXM1). With mask 0x7FF every identifier bit is
 * compared, and the starter's RX_Filter0 = 0x088 is not MESSAGE_ID1 = 0x100, so the frame is dropped.
 * The workshop's three fixes each work: (a) set the mask and filter correctly (a filter equal to
 * MESSAGE_ID1, or a mask that does not compare the bits where they differ); (b) set RXBnCON.RXM = 11
 * (CAN_CONFIG_ALL_MSG), which overrides masks and filters; (c) set MESSAGE_ID1 and RX_Filter0 to the
 * same value: the filter to MESSAGE_ID1 (as this file does), or MESSAGE_ID1 to 0x088, the filter's
 * value. Off the bus, in Loopback mode, any 11-bit identifier will do; from EX2 on, MESSAGE_ID1 is
 * the station's (0x100 .. 0x150), since 0x088 is the master console's and one identifier's data
 * frames come from one node only.
 */
#include <p18f8680.h>
#include "CAN18XX8.h"
#include <adc.h>
#include <timers.h>
#include <stdio.h>
#include "APP023_GLCD.h"

#pragma config OSC = HSPLL, WDT = OFF, LVP = OFF    /* Fosc = 40 MHz: the 10 MHz crystal with the 4x PLL */

#define MESSAGE_ID1 0x100        /* this node's transmit identifier */
#define RX_Filter0  MESSAGE_ID1  /* RXF0 equals the own ID, so RXB0 takes the looped-back frame */
#define RX_Mask0    0x7FF        /* every ID bit is compared */

BYTE TxData[5] = {0x01, 0x02, 0x03, 0x00, 0x00};
BYTE RxData[8];
unsigned long RX_ID1;
BYTE DataLen;
enum CAN_RX_MSG_FLAGS CANMessageFlag;
char LCD[22];                   /* one LCD line and its NUL */

void CANInitialization(void)
{
    /* 125 kbit/s at Fosc = 40 MHz: SJW 4, BRP 10, PHSEG1 8, PHSEG2 4, PROPSEG 3 (16 TQ, sample point 75 %) */
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG);
    CANSetOperationMode(CAN_OP_MODE_CONFIG);        /* CANInitialize returns in NORMAL mode */
    CANSetMask(CAN_MASK_B1, RX_Mask0, CAN_CONFIG_STD_MSG);
    CANSetMask(CAN_MASK_B2, RX_Mask0, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B1_F1, RX_Filter0, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B1_F2, RX_Filter0, CAN_CONFIG_STD_MSG);
    CANSetOperationMode(CAN_OP_MODE_LOOP);
}

void read_potentiometer(void)
{
    ConvertADC();
    while (BusyADC());
    TxData[3] = ADRESH;
    TxData[4] = ADRESL;
}

void main(void)
{
    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS, ADC_1ANA);
    GLCD_Initial();
    setcurGLCD(1, 1);
    putrsGLCD("EX1 LOOPBACK");
    setcurGLCD(2, 1);
    sprintf(LCD, "TX ID  0x%03X", MESSAGE_ID1);
    putsGLCD(LCD);
    CANInitialization();
    read_potentiometer();
    CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME);
    while (1) {
        if (CANIsRxReady()) {                          /* is your TX data in the RX buffer? */
            CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);
            if (DataLen >= 5) {                        /* 01 02 03 ADRESH ADRESL: a shorter frame has no A/D value */
                setcurGLCD(3, 1);
                sprintf(LCD, "A/D    %4d", ((int)RxData[3] << 8) | RxData[4]);
                putsGLCD(LCD);
            }
            setcurGLCD(4, 1);
            sprintf(LCD, "RX ID  0x%03lX", RX_ID1);
            putsGLCD(LCD);
        }
    }
}
