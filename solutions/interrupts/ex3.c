/* EX3, interrupt-driven - GET Data From Bus (CAN Workshop 202, exercise 3), with two interrupt priorities.
 *
 * The same node as solutions/ex3.c: it shows the master console's A/D (ID 0x088) and sends its own on every Timer1
 * overflow. Here both happen in interrupt routines, with RCON.IPEN = 1 (two priorities), as C18 writes them:
 * `#pragma interrupt high_isr` (vector 0x08: RXB0 received, IPR3.RXB0IP = 1) and `#pragma interruptlow low_isr`
 * (vector 0x18: Timer1 overflowed, IPR1.TMR1IP = 0), each vector holding C18's GOTO to its routine. The twin of
 * solutions/interrupts/ex3.py.
 *
 * Receiving is high priority: a frame must leave RXB0 before the next one arrives, or it is lost (RXB0OVFL). Sending
 * on Timer1 can wait, so it is low priority, and the high-priority routine may interrupt it. INTCON.GIEH enables the
 * high priority, INTCON.GIEL the low one; entering a routine clears the enable of its priority (GIEH or GIEL) and its
 * return (RETFIE) sets it again, so a routine is never entered again while it runs.
 *
 * Question: the high-priority routine saves CANCON.WIN and puts it back before it returns. Why?
 *
 * Answer: AN738 reaches every buffer through the RXB0 window: CANSendMessage() sets CANCON.WIN to the TX buffer it
 * fills, then writes "RXB0" addresses, and CANReceiveMessage() sets WIN to the RX buffer it reads and leaves it at
 * 000. If a frame arrives while the low-priority routine is in the middle of CANSendMessage(), the high-priority
 * routine's CANReceiveMessage() moves the window: without the restore, the rest of the TX buffer would be written
 * into RXB0, which the CPU cannot write, and a broken frame would be sent. Any state two priorities share needs the
 * same care: on a real PIC18, C18's own temporaries too (`#pragma interruptlow low_isr save=section(".tmpdata")`;
 * the kit's routines run in plain Python and share none).
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
volatile BOOL news = FALSE;     /* set by the receive routine */
volatile unsigned long rx_id = 0;
volatile int rx_ad = -1;
volatile BOOL rx_rtr = FALSE;

void high_isr(void);
void low_isr(void);

#pragma code high_vector=0x08   /* high priority: C18's GOTO to the routine */
void interrupt_at_high_vector(void)
{
    _asm GOTO high_isr _endasm
}
#pragma code low_vector=0x18    /* low priority */
void interrupt_at_low_vector(void)
{
    _asm GOTO low_isr _endasm
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
    CANSetOperationMode(CAN_OP_MODE_NORMAL);        /* on the bus: send, ACK, receive other nodes' frames */
}

void read_potentiometer(void)
{
    ConvertADC();
    while (BusyADC());
    TxData[3] = ADRESH;
    TxData[4] = ADRESL;
}

#pragma interrupt high_isr
void high_isr(void)             /* RXB0 received a frame (vector 0x08): take it out at once, leave the LCD to main() */
{
    unsigned char window = CANCONbits.WIN;          /* the window the interrupted code was using */

    while (CANIsRxReady()) {
        CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);     /* clears RXFUL and RXB0IF */
        rx_id = RX_ID1;
        rx_rtr = (CANMessageFlag & CAN_RX_RTR_FRAME) != 0;
        if (!rx_rtr && DataLen >= 5)    /* 01 02 03 ADRESH ADRESL: a shorter frame has no A/D value */
            rx_ad = ((int)RxData[3] << 8) | RxData[4];
        news = TRUE;
    }
    CANCONbits.WIN = window;
}

#pragma interruptlow low_isr
void low_isr(void)              /* Timer1 overflowed (vector 0x18, every 52.4288 ms): send this node's A/D */
{
    PIR1bits.TMR1IF = 0;                            /* or the routine is entered again at once */
    read_potentiometer();
    CANSendMessage(MESSAGE_ID1, TxData, 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME & CAN_TX_NO_RTR_FRAME);
}

void main(void)
{
    OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_0_TAD,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS, ADC_1ANA);
    GLCD_Initial();
    setcurGLCD(1, 1);
    putrsGLCD("EX3 DATA (INT)");
    setcurGLCD(2, 1);
    sprintf(LCD, "TX ID  0x%03X", MESSAGE_ID1);
    putsGLCD(LCD);
    CANInitialization();
    RCONbits.IPEN = 1;                              /* two priorities */
    IPR3bits.RXB0IP = 1;                            /* receiving: high priority, vector 0x08 */
    PIE3bits.RXB0IE = 1;
    IPR1bits.TMR1IP = 0;                            /* Timer1: low priority, vector 0x18 */
    /* Fosc/4 with a 1:8 prescaler: TMR1 overflows every 65536 x 8 x 0.1 us = 52.4288 ms; TIMER_INT_ON sets TMR1IE */
    OpenTimer1(TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF);
    INTCONbits.GIEL = 1;
    INTCONbits.GIEH = 1;
    while (1) {
        while (!news);                              /* the receive routine sets it */
        news = FALSE;
        setcurGLCD(4, 1);
        if (rx_rtr) {                               /* a remote frame asks for data and carries none */
            sprintf(LCD, "RX ID  0x%03lX RTR", rx_id);
            putsGLCD(LCD);
        } else {
            sprintf(LCD, "RX ID  0x%03lX    ", rx_id);
            putsGLCD(LCD);
            if (rx_ad >= 0) {
                setcurGLCD(3, 1);
                sprintf(LCD, "A/D    %4d", rx_ad);
                putsGLCD(LCD);
            }
        }
    }
}
