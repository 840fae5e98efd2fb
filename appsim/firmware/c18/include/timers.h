/* timers.h: MPLAB C18's Timer1 functions, as the kit provides them (the APP023's workshop uses Timer1 only). Masks are
 * combined with '&'; a field left out keeps its all-ones value. They act through T1CON, TMR1H and TMR1L. */
#ifndef __TIMERS_H
#define __TIMERS_H

#include <p18f8680.h>

#define TIMER_INT_OFF        0b01111111
#define TIMER_INT_ON         0b11111111
#define T1_8BIT_RW           0b10111111
#define T1_16BIT_RW          0b11111111
#define T1_OSC1EN_OFF        0b11110111
#define T1_OSC1EN_ON         0b11111111
#define T1_PS_1_1            0b11001111
#define T1_PS_1_2            0b11011111
#define T1_PS_1_4            0b11101111
#define T1_PS_1_8            0b11111111
#define T1_SOURCE_EXT        0b11111111
#define T1_SOURCE_INT        0b11111101
#define T1_SYNC_EXT_OFF      0b11111111
#define T1_SYNC_EXT_ON       0b11111011

void OpenTimer1(unsigned char config);          /* configure, clear TMR1 and PIR1bits.TMR1IF, start */
unsigned int ReadTimer1(void);                  /* TMR1L first, then TMR1H */
void WriteTimer1(unsigned int timer);
void CloseTimer1(void);

#endif
