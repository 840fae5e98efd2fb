/* EX6 - Going deeper into REMOTE Transfer Request (CAN Workshop 202, exercise 6).
 *
 * Goal: write EX6.C, which receives RTR frames and responds correctly. Start from EX4.C (listen
 * first, then NORMAL) and stop sending on Timer1. Use RXB1 to receive incoming RTR frames: if RXB1
 * holds a message, RX_ID2 == MESSAGE_ID1 and CANMessageFlag & CAN_RX_RTR_FRAME, send your own A/D
 * value (01 02 03 ADRESH ADRESL with ID MESSAGE_ID1). The master console chooses among 0x100 .. 0x150
 * to send RTR frames; when the master has not requested a node, the CAN monitor must not show any
 * data from that node. RXB0 still shows the master's broadcast 0x088 on LCD lines 3 and 4.
 *
 * Question: one of RX_Filter2 to RX_Filter5 must be set equal to your own MESSAGE_ID1! Why?? And
 * check that RXB1's MASK is set correctly!
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
#define RX_Filter2  0x000        /* TODO: RXF2..RXF5 must let the RTR frames asking for your data into RXB1 */
#define RX_Mask1    0x000        /* TODO: check that RXB1's MASK is set correctly! */

BYTE TxData[5] = {0x01, 0x02, 0x03, 0x00, 0x00};
BYTE RxData[8];
unsigned long RX_ID1, RX_ID2;
BYTE DataLen;
enum CAN_RX_MSG_FLAGS CANMessageFlag;
char LCD[22];                   /* one LCD line and its NUL */

void CANInitialization(enum CAN_CONFIG_FLAGS config, enum CAN_OP_MODE mode)
{
    /* 125 kbit/s at Fosc = 40 MHz: SJW 4, BRP 10, PHSEG1 8, PHSEG2 4, PROPSEG 3 (16 TQ, sample point 75 %) */
    CANInitialize(4, 10, 8, 4, 3, config);
    CANSetOperationMode(CAN_OP_MODE_CONFIG);        /* CANInitialize returns in NORMAL mode, masks at 0 */
    CANSetMask(CAN_MASK_B1, RX_Mask0, CAN_CONFIG_STD_MSG);
    CANSetMask(CAN_MASK_B2, RX_Mask1, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B1_F1, RX_Filter0, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B1_F2, RX_Filter0, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B2_F1, RX_Filter2, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B2_F2, RX_Filter2, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B2_F3, RX_Filter2, CAN_CONFIG_STD_MSG);
    CANSetFilter(CAN_FILTER_B2_F4, RX_Filter2, CAN_CONFIG_STD_MSG);
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
    putrsGLCD("EX6 ANSWER RTR");
    setcurGLCD(2, 1);
    sprintf(LCD, "TX ID  0x%03X", MESSAGE_ID1);
    putsGLCD(LCD);
    setcurGLCD(5, 1);
    putrsGLCD("MODE LISTEN ONLY");
    CANInitialization(CAN_CONFIG_ALL_MSG, CAN_OP_MODE_LISTEN);      /* hear everything, send nothing */
    heard = FALSE;                                                  /* wait for a correct frame from the */
    while (!heard) {                                                /*  master: with RXM = 11 the buffers */
        if (CANIsRxReady()) {                                       /*  also take frames with errors */
            CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);
            heard = RX_ID1 == 0x088 && !(CANMessageFlag & CAN_RX_INVALID_MSG);
        }
    }
    CANSetOperationMode(CAN_OP_MODE_CONFIG);              
    CANInitialization(CAN_CONFIG_VALID_STD_MSG, CAN_OP_MODE_NORMAL); /* filters set again */
    setcurGLCD(5, 1);
    putrsGLCD("MODE NORMAL     ");
    while (1) {
        if (RXB0CONbits.RXFUL) {                       /* RXB0: the master's broadcast (RX_Filter0) */
            CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);
            if (DataLen >= 5) {                        /* 01 02 03 ADRESH ADRESL: a shorter frame has no A/D value */
                setcurGLCD(3, 1);
                sprintf(LCD, "A/D    %4d", ((int)RxData[3] << 8) | RxData[4]);
                putsGLCD(LCD);
            }
            setcurGLCD(4, 1);
            sprintf(LCD, "RX ID  0x%03lX", RX_ID1);
            putsGLCD(LCD);
        } else if (RXB1CONbits.RXFUL) {                /* RXB1: what RX_Filter2..5 let in under RX_Mask1 */
            CANReceiveMessage(&RX_ID2, RxData, &DataLen, &CANMessageFlag);
            /* TODO: if RX_ID2 == MESSAGE_ID1 and CANMessageFlag has CAN_RX_RTR_FRAME set, read the
             *       potentiometer and send your data: ID MESSAGE_ID1, 01 02 03 ADRESH ADRESL */
        }
    }
}
