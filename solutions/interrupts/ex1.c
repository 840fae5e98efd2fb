/* EX1, interrupt-driven - Simple message in Loopback mode (CAN Workshop 202, exercise 1).
 *
 * The same node as solutions/ex1.c, off the bus in Loopback mode, but the frame it sends itself is taken in by the
 * receive interrupt: PIE3.RXB0IE enables it, INTCON.PEIE and INTCON.GIE let it through (RCON.IPEN = 0: every
 * interrupt goes to vector 0x08, where C18's GOTO leads to high_isr). The twin of solutions/interrupts/ex1.py.
 *
 * Question: the routine tests CANIsRxReady() in a loop. Would a plain `if` do?
 *
 * Answer: here, yes: one frame comes back. In general no: a routine is entered because a flag is set, and by the
 * time it runs another frame may have come into RXB1. Taking messages until none is left (or until CANSTAT.ICODE
 * reads 000) empties both buffers in one entry. What must never happen is a return with the flag still set: the
 * core would enter the routine again at once, for ever (CANReceiveMessage() clears RXBnIF).
 */
#include <p18f8680.h>
#include "CAN18XX8.h"
#include <adc.h>
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
volatile BOOL news = FALSE;     /* set by the routine */
volatile unsigned long rx_id = 0;
volatile int rx_ad = -1;

void high_isr(void);

#pragma code high_vector=0x08   /* the core jumps here on an interrupt: C18's GOTO to the routine */
void interrupt_at_high_vector(void)
{
    _asm GOTO high_isr _endasm
}
#pragma code                    /* back to the default code section */

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

#pragma interrupt high_isr
void high_isr(void)             /* a frame came into RXB0 or RXB1 (vector 0x08) */
{
    while (CANIsRxReady()) {
        CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);     /* clears RXFUL and RXBnIF */
        rx_id = RX_ID1;
        if (DataLen >= 5)       /* 01 02 03 ADRESH ADRESL: a shorter frame has no A/D value */
            rx_ad = ((int)RxData[3] << 8) | RxData[4];
        news = TRUE;
    }
}

void main(void)
{
    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS, ADC_1ANA);
    GLCD_Initial();
    setcurGLCD(1, 1);
    putrsGLCD("EX1 LOOPBACK (INT)");
    setcurGLCD(2, 1);
    sprintf(LCD, "TX ID  0x%03X", MESSAGE_ID1);
    putsGLCD(LCD);
    CANInitialization();
    PIE3bits.RXB0IE = 1;                            /* the receive interrupts */
    PIE3bits.RXB1IE = 1;
    INTCONbits.PEIE = 1;
    INTCONbits.GIE = 1;
    read_potentiometer();
    CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME);
    while (1) {
        while (!news);                              /* the routine sets it */
        news = FALSE;
        if (rx_ad >= 0) {
            setcurGLCD(3, 1);
            sprintf(LCD, "A/D    %4d", rx_ad);
            putsGLCD(LCD);
        }
        setcurGLCD(4, 1);
        sprintf(LCD, "RX ID  0x%03lX", rx_id);
        putsGLCD(LCD);
    }
}
