/* DEMO1 - A simple CAN monitor (CAN Workshop 202, Demo1, project CAN_Monitor.mcp).
 *
 * "If your PC has no parallel port": make the APP023 a CAN monitor. Receive every frame on the bus
 * and write one line per frame over the USART (19200 baud, 8N1) to the PIC18F2550, which the PC opens
 * as a USB-CDC serial port (DSW2 5 & 6 ON). The line format is in docs/monitor-format.md.
 *
 * This starter prints frames, but it is not a good monitor yet. Run it, watch the port, then:
 *   TODO 1: SPBRG for 19200 baud at Fosc = 40 MHz with BRGH = 1: baud = Fosc / (16 x (SPBRG + 1)).
 *   TODO 2: a monitor must not change the bus it watches. In Normal mode this node ACKs every frame
 *           (a sender alone on the bus would think someone heard it). Which mode never drives the bus?
 *   TODO 3: putsUSART waits until the whole line is sent (this one's 44 bytes for a 5-byte frame: 23 ms
 *           at 19200 baud, 10 bits a byte). What happens to the frames that arrive meanwhile?
 *           CANReceiveMessage's flags say when RXB0/RXB1 overflowed: report it.
 *   TODO 4: the line format of docs/monitor-format.md: this starter prints neither STD/XTD
 *           (CANMessageFlag & CAN_RX_XTD_FRAME) nor DATA/RTR (CANMessageFlag & CAN_RX_RTR_FRAME).
 *   TODO 5: Timer1 wraps every 52.4288 ms: count its overflows (PIR1bits.TMR1IF), so that the time
 *           counts up, in seconds since the monitor started.
 * The solution (solutions/demo1_monitor.c) also keeps frames in a queue and counts exactly how many it lost.
 */
#include <p18f8680.h>
#include "CAN18XX8.h"
#include <timers.h>
#include <usart.h>
#include <stdio.h>

#pragma config OSC = HSPLL, WDT = OFF, LVP = OFF    /* Fosc = 40 MHz: the 10 MHz crystal with the 4x PLL */

#define USART_SPBRG 0           /* TODO 1 */

unsigned long RX_ID1;
BYTE RxData[8];
BYTE DataLen;
enum CAN_RX_MSG_FLAGS CANMessageFlag;
char line[64];

void main(void)
{
    unsigned long micros;
    BYTE k, n, shown;

    OpenUSART(USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT
              & USART_CONT_RX & USART_BRGH_HIGH, USART_SPBRG);
    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF);
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG);     /* 125 kbit/s, receive everything */
    /* TODO 2: CANSetOperationMode(...) */
    while (1) {
        if (CANIsRxReady()) {
            CANReceiveMessage(&RX_ID1, RxData, &DataLen, &CANMessageFlag);
            /* TODO 3: if (CANMessageFlag & CAN_RX_OVERFLOW) ... */
            micros = ((unsigned long)ReadTimer1() * 8 + 5) / 10;   /* µs. TODO 5: wraps every 52.4 ms: count PIR1bits.TMR1IF */
            /* TODO 4: the documented line format: STD/XTD and DATA/RTR after the ID */
            n = sprintf(line, "%5lu.%06lu  0x%03lX  DLC %hhu  ", micros / 1000000, micros % 1000000, RX_ID1, DataLen);
            shown = DataLen < 8 ? DataLen : 8;
            for (k = 0; k < shown; k++)
                n += sprintf(line + n, k ? " %02hhX" : "%02hhX", RxData[k]);
            sprintf(line + n, "\r\n");
            putsUSART(line);
        }
    }
}
