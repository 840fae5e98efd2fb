/* EX6, interrupt-driven - Going deeper into REMOTE Transfer Request (CAN Workshop 202, exercise 6).
 *
 * The same node as solutions/ex6.c, written the way an embedded engineer often writes it in C18: the receive
 * interrupt answers the master's RTR for MESSAGE_ID1 at once, and main() only keeps the LCD up to date. The twin of
 * solutions/interrupts/ex6.py.
 *
 * How it works: after the Listen-only start (polled, as in EX4), PIE3.RXB0IE and PIE3.RXB1IE enable the two receive
 * interrupts, and INTCON.PEIE and INTCON.GIE let them through (RCON.IPEN = 0: one priority, every interrupt at 0x08,
 * where C18's GOTO leads to high_isr). When a frame lands in RXB0 or RXB1, the ECAN sets RXB0IF or RXB1IF, the core
 * finishes its instruction, clears GIE and jumps to 0x08. CANSTAT.ICODE names the highest-priority source pending
 * (110 RXB0, 101 RXB1, 000 none), for a routine that dispatches on it; this one takes messages until neither buffer
 * is full, which also empties a buffer whose flag a slow routine would see only after the next frame.
 * CANReceiveMessage() clears RXFUL and the RXBnIF flag: a routine that left the flag set would be entered again at
 * once, for ever. RETFIE (the routine's return) sets GIE again.
 *
 * Question: why does main() not write the LCD from inside the routine?
 *
 * Answer: a routine runs with GIE cleared, so nothing else is served while it runs; writing a 21-character line to
 * the GLCD takes about 0.3 ms of bit-banging. The answer to an RTR must leave within the check's 2 ms, and the next
 * frame may be in RXB0 by then: the routine does only what cannot wait (read the buffer, answer), sets `news`, and
 * main() does the slow part. `while (!news);` on a volatile flag: only the routine can end it, so the kit waits there
 * for the next interrupt.
 */
#include <p18f8680.h>
#include "CAN18XX8.h"
#include <adc.h>
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
unsigned long RX_ID1, RX_ID;
BYTE DataLen;
enum CAN_RX_MSG_FLAGS CANMessageFlag;
char LCD[22];                   /* one LCD line and its NUL */
volatile BOOL news = FALSE;     /* set by the routine: something new for the LCD */
volatile unsigned long master_id = 0, answered_id = 0;
volatile int master_ad = -1, answered_ad = -1;

void high_isr(void);

#pragma code high_vector=0x08   /* the core jumps here on an interrupt: C18's GOTO to the routine */
void interrupt_at_high_vector(void)
{
    _asm GOTO high_isr _endasm
}
#pragma code                    /* back to the default code section */

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

#pragma interrupt high_isr
void high_isr(void)             /* the receive interrupt: RXB0 holds the master's 0x088, RXB1 what RX_Filter2..5 let in */
{
    while (CANIsRxReady()) {
        CANReceiveMessage(&RX_ID, RxData, &DataLen, &CANMessageFlag);  /* RXB0 first; clears RXFUL and RXBnIF */
        if (RX_ID == MESSAGE_ID1 && (CANMessageFlag & CAN_RX_RTR_FRAME)) {     /* a request for this node's data */
            read_potentiometer();
            CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME);
            answered_id = RX_ID;
            answered_ad = ((int)TxData[3] << 8) | TxData[4];
        } else if (RX_ID == RX_Filter0 && DataLen >= 5) {  /* 01 02 03 ADRESH ADRESL from the master */
            master_id = RX_ID;
            master_ad = ((int)RxData[3] << 8) | RxData[4];
        }
        news = TRUE;
    }
}

void main(void)
{
    BOOL heard;

    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS, ADC_1ANA);
    GLCD_Initial();
    setcurGLCD(1, 1);
    putrsGLCD("EX6 ANSWER RTR (INT)");
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
    PIR3bits.RXB0IF = 0;
    PIR3bits.RXB1IF = 0;
    PIE3bits.RXB0IE = 1;                            /* the receive interrupts */
    PIE3bits.RXB1IE = 1;
    INTCONbits.PEIE = 1;                            /* peripheral interrupts (RCON.IPEN = 0: all at 0x08) */
    INTCONbits.GIE = 1;
    while (1) {
        while (!news);                              /* the routine sets it */
        news = FALSE;
        if (master_ad >= 0) {
            setcurGLCD(3, 1);
            sprintf(LCD, "A/D    %4d", master_ad);
            putsGLCD(LCD);
            setcurGLCD(4, 1);
            sprintf(LCD, "RX ID  0x%03lX", master_id);
            putsGLCD(LCD);
        }
        if (answered_ad >= 0) {
            setcurGLCD(6, 1);
            sprintf(LCD, "RTR ID 0x%03lX", answered_id);
            putsGLCD(LCD);
            setcurGLCD(7, 1);
            sprintf(LCD, "SENT A/D %4d", answered_ad);
            putsGLCD(LCD);
        }
    }
}
