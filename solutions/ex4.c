/* EX4 solution - The correct On-Bus procedure (CAN Workshop 202, exercise 4).
 *
 * Goal: before sending, first enter LISTEN ONLY mode, so that a wrong setting cannot disturb the
 * network. Only after receiving at least one correct message, switch to NORMAL and start sending.
 * Start from EX3.C:
 *   1. put the PIC18F8680 in LISTEN ONLY mode with CANSetOperationMode();
 *   2. pass CAN_CONFIG_ALL_MSG to CANInitialize(), to turn off filter and mask checking (RXM = 11);
 *   3. loop on CANIsRxReady() until a message with ID 0x088 (the master console's) is received;
 *      a correct one: with RXM = 11 the buffers also take frames with errors, which
 *      CANReceiveMessage() flags with CAN_RX_INVALID_MSG;
 *   4. enter CONFIGURATION mode;
 *   5. run CANInitialize() again with CAN_CONFIG_VALID_STD_MSG, so that only valid standard
 *      messages pass filter/mask checking;
 *   6. set NORMAL mode, and send and receive as EX3 does.
 *
 * Question: why listen first, and what must be done again after the second CANInitialize()?
 *
 * Answer: Listen-only receives but never drives the bus: no frames, no ACK, no error flags. A node
 * with a wrong bit rate or a wrong setting stays harmless there, and a correct 0x088 from the master
 * proves the bit timing matches the bus before the node sends anything. Correct, because with
 * CAN_CONFIG_ALL_MSG (RXM = 11) the buffers also take frames with errors: the loop does not count a
 * frame whose flags have CAN_RX_INVALID_MSG. CANInitialize() itself ends in NORMAL mode and sets both
 * masks to 0 (accept everything), so the Listen request must come after it, and after the second
 * CANInitialize() the masks and RX_Filter0 = 0x088 must be set again in CONFIGURATION mode, or RXB0
 * takes every valid standard frame on the bus. One more reason to keep the order strict: from
 * CANInitialize()'s return until the next mode request takes effect, the module is in NORMAL mode.
 * On an idle bus that is a few instruction cycles, but a mode changes only when the bus is idle, so a
 * frame that starts meanwhile keeps it in NORMAL mode to the frame's end: it ACKs the frame if it
 * reads it right, and with a wrong bit timing it sends error flags that destroy it.
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

void CANInitialization(enum CAN_CONFIG_FLAGS config, enum CAN_OP_MODE mode)
{
    /* 125 kbit/s at Fosc = 40 MHz: SJW 4, BRP 10, PHSEG1 8, PHSEG2 4, PROPSEG 3 (16 TQ, sample point 75 %) */
    CANInitialize(4, 10, 8, 4, 3, config);
    CANSetOperationMode(CAN_OP_MODE_CONFIG);        /* CANInitialize returns in NORMAL mode, masks at 0 */
    CANSetMask(CAN_MASK_B1, RX_Mask0, CAN_CONFIG_STD_MSG);
    CANSetMask(CAN_MASK_B2, RX_Mask0, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B1_F1, RX_Filter0, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B1_F2, RX_Filter0, CAN_CONFIG_STD_MSG);
    CANSetOperationMode(mode);
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
    BOOL heard;

    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS, ADC_1ANA);
    GLCD_Initial();
    setcurGLCD(1, 1);
    putrsGLCD("EX4 LISTEN FIRST");
    setcurGLCD(2, 1);
    sprintf(LCD, "TX ID  0x%03X", MESSAGE_ID1);
    putsGLCD(LCD);
    setcurGLCD(5, 1);
    putrsGLCD("MODE LISTEN ONLY");
    CANInitialization(CAN_CONFIG_ALL_MSG, CAN_OP_MODE_LISTEN);      /* 1, 2: hear everything, send nothing */
    heard = FALSE;                                                  /* 3: wait for a correct frame from the */
    while (!heard) {                                                /*    master: with RXM = 11 the buffers */
        if (CANIsRxReady()) {                                       /*    also take frames with errors */
            CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);
            heard = RX_ID1 == 0x088 && !(CANMessageFlag & CAN_RX_INVALID_MSG);
        }
    }
    CANSetOperationMode(CAN_OP_MODE_CONFIG);                        /* 4 */
    CANInitialization(CAN_CONFIG_VALID_STD_MSG, CAN_OP_MODE_NORMAL); /* 5, 6: filters set again */
    setcurGLCD(5, 1);
    putrsGLCD("MODE NORMAL     ");
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
