/* EX6 solution - Going deeper into REMOTE Transfer Request (CAN Workshop 202, exercise 6).
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
 *
 * Answer: an RTR frame carries the identifier of the data being requested: the master asks for your
 * data with an RTR whose ID is your MESSAGE_ID1. RXB1 accepts only frames that match one of its
 * filters RXF2..RXF5 under mask RXM1, so one of them must equal MESSAGE_ID1 for the request to reach
 * RXB1 at all. The mask must compare every ID bit that tells your ID from the others on the bus:
 * with mask 0 RXB1 would take every frame, and only the software test RX_ID2 == MESSAGE_ID1 would
 * keep the node from answering the other stations' requests; 0x7FF compares all 11 bits. The
 * CAN_RX_RTR_FRAME test matters too, though on a correct bus it never meets a data frame with your
 * ID: only one node sends the data frames of an identifier, and that is you. A faulty node might send
 * one (the check plays such a node), and a data frame is not a request. RXB1CONbits.RXFUL says a
 * frame waits in RXB1, but CANReceiveMessage() always takes RXB0 first: if the master's 0x088 came
 * into RXB0 in between, that is what the RXB1 branch reads, and RX_ID2 == MESSAGE_ID1 keeps it from
 * being answered (RXB1 is read on the next turn).
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
#define RX_Filter2  MESSAGE_ID1  /* RXF2..RXF5: RTR frames asking for this node's data */
#define RX_Mask1    0x7FF        /* RXM1 compares every ID bit: only MESSAGE_ID1 reaches RXB1 */

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
            if (RX_ID2 == MESSAGE_ID1 && (CANMessageFlag & CAN_RX_RTR_FRAME)) {
                read_potentiometer();
                CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME);
                setcurGLCD(6, 1);
                sprintf(LCD, "RTR ID 0x%03lX", RX_ID2);
                putsGLCD(LCD);
                setcurGLCD(7, 1);
                sprintf(LCD, "SENT A/D %4d", ((int)TxData[3] << 8) | TxData[4]);
                putsGLCD(LCD);
            }
        }
    }
}
