/* delays.h: MPLAB C18's delays, in instruction cycles (Fosc/4: 0.1 us at 40 MHz). A count of 0 means 256 units. */
#ifndef __DELAYS_H
#define __DELAYS_H

void Nop(void);                                 /* as p18f8680.h declares it */
#define Delay1TCY() Nop()                       /* exactly 1 cycle */
#define Delay10TCY() Delay10TCYx(1)             /* 10 cycles */
void Delay10TCYx(unsigned char unit);           /* 10 x unit cycles: 1 us a unit */
void Delay100TCYx(unsigned char unit);          /* 100 x unit cycles: 10 us a unit */
void Delay1KTCYx(unsigned char unit);           /* 1,000 x unit cycles: 0.1 ms a unit */
void Delay10KTCYx(unsigned char unit);          /* 10,000 x unit cycles: 1 ms a unit */

#endif
