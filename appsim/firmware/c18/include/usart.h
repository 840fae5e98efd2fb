/* usart.h: MPLAB C18's USART library, as the kit provides it. Masks are combined with '&'; a field left out keeps its
 * all-ones value. It acts through TXSTA, RCSTA, SPBRG, SPBRGH, TXREG and RCREG. */
#ifndef __USART_H
#define __USART_H

#include <p18f8680.h>

#define USART_ASYNCH_MODE    0b11111110
#define USART_BRGH_HIGH      0b11111111
#define USART_BRGH_LOW       0b11101111
#define USART_CONT_RX        0b11111111
#define USART_EIGHT_BIT      0b11111101
#define USART_NINE_BIT       0b11111111
#define USART_RX_INT_OFF     0b10111111
#define USART_RX_INT_ON      0b11111111
#define USART_SINGLE_RX      0b11110111
#define USART_SYNCH_MODE     0b11111111
#define USART_SYNC_MASTER    0b11111111
#define USART_SYNC_SLAVE     0b11111011
#define USART_TX_INT_OFF     0b01111111
#define USART_TX_INT_ON      0b11111111

void OpenUSART(unsigned char config, unsigned int spbrg);   /* 129 with USART_BRGH_HIGH: 19200 baud at 40 MHz */
char BusyUSART(void);                           /* 1 while the transmitter shifts a byte out (TXSTAbits.TRMT = 0) */
void WriteUSART(char data);                     /* into TXREG, without waiting */
char DataRdyUSART(void);                        /* 1 when a received byte waits (PIR1bits.RCIF) */
char ReadUSART(void);                           /* the next byte from RCREG */
void putsUSART(char *data);                     /* a string in RAM, waiting before each byte; sends its NUL too */
void putrsUSART(const rom char *data);          /* a string in program memory, the same way */
void CloseUSART(void);
#define putcUSART WriteUSART
#define getcUSART ReadUSART

#endif
