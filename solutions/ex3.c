/* EX3 solution - GET Data From Bus (CAN Workshop 202, exercise 3).
 *
 * Goal: receive the master console's data. Start from EX2.C and set RX_Filter0 = 0x88: the master
 * broadcasts 01 02 03 ADRESH ADRESL with ID 0x088 every 100 ms, so every station receives it and
 * shows the master's A/D value (line 3) and its ID (line 4) on the LCD. The node keeps sending its
 * own data on every Timer1 overflow. Extension: set RX_Filter0 to a neighbour station's Message ID
 * and "control each other" (show each other's data).
 *
 * Question: which RX_Filter0 lets the master's frames into RXB0, and why does nothing else get in?
 *
 * Answer: RX_Filter0 = 0x088. RXB0 takes a frame only if its identifier equals RXF0 or RXF1 in every
 * bit that mask RXM0 compares; with RX_Mask0 = 0x7FF all 11 bits are compared, so exactly ID 0x088
 * passes and the stations' 0x100 .. 0x150 do not. (RXB1's filters are still 0 from CANInitialize
 * under the same mask: only an ID 0x000 would reach it.) For the extension, RX_Filter0 = 0x110 shows
 * station 2's potentiometer instead.
 */
#include <p18f8680.h>
#include "CAN18XX8.h"
#include <adc.h>
#include <timers.h>
#include <stdio.h>
#include "APP023_GLCD.h"

#pragma config OSC = HSPLL, WDT = OFF, LVP = OFF    /* Fosc = 40 MHz: the 10 MHz crystal with the 4x PLL */

#define MESSAGE_ID1 0x100        /* this node's transmit identifier: the one assigned to you, 0x100 .. 0x150 */
#define RX_Filter0  0x088        /* RXF0: the master console's ID */
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
    CANSetOperationMode(CAN_OP_MODE_NORMAL);        /* on the bus: send, ACK, receive other nodes' frames */
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
    putrsGLCD("EX3 DATA FROM BUS");
    setcurGLCD(2, 1);
    sprintf(LCD, "TX ID  0x%03X", MESSAGE_ID1);
    putsGLCD(LCD);
    CANInitialization();
    /* Fosc/4 with a 1:8 prescaler: TMR1 overflows every 65536 x 8 x 0.1 us = 52.4288 ms */
    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF);
    while (1) {
        if (PIR1bits.TMR1IF) {                         /* TMR1_OVERFLOW */
            PIR1bits.TMR1IF = 0;
            read_potentiometer();
            CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME);
        }
        if (CANIsRxReady()) {
            CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);
            setcurGLCD(4, 1);
            if (CANMessageFlag & CAN_RX_RTR_FRAME) {    /* a remote frame asks for data and carries none */
                sprintf(LCD, "RX ID  0x%03lX RTR", RX_ID1);
                putsGLCD(LCD);
            } else {
                sprintf(LCD, "RX ID  0x%03lX    ", RX_ID1);
                putsGLCD(LCD);
                if (DataLen >= 5) {     /* 01 02 03 ADRESH ADRESL: a shorter frame has no A/D value */
                    setcurGLCD(3, 1);
                    sprintf(LCD, "A/D    %4d", ((int)RxData[3] << 8) | RxData[4]);
                    putsGLCD(LCD);
                }
            }
        }
    }
}
