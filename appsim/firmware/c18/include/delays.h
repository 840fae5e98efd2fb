/* delays.h: MPLAB C18's delays, in instruction cycles (Fosc/4: 0.1 us at 40 MHz). */
#ifndef __DELAYS_H
#define __DELAYS_H

void Delay1KTCYx(unsigned char unit);           /* 1,000 x unit cycles: 0.1 ms a unit */
void Delay10KTCYx(unsigned char unit);          /* 10,000 x unit cycles: 1 ms a unit */

#endif
