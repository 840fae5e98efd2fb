/* adc.h: MPLAB C18's A/D library for the PIC18F8680, as the kit provides it. Masks are combined with '&'; a field
 * left out keeps its all-ones value. The functions act on the A/D only through ADCON0..2, ADRESH and ADRESL. */
#ifndef __ADC_H
#define __ADC_H

#include <p18f8680.h>

#define ADC_FOSC_2           0b10001111
#define ADC_FOSC_4           0b11001111
#define ADC_FOSC_8           0b10011111
#define ADC_FOSC_16          0b11011111
#define ADC_FOSC_32          0b10101111
#define ADC_FOSC_64          0b11101111
#define ADC_FOSC_RC          0b11111111
#define ADC_0_TAD            0b11110001   /* acquisition time, ADCON2.ACQT: 0 TAD (manual acquisition) */
#define ADC_2_TAD            0b11110011
#define ADC_4_TAD            0b11110101
#define ADC_6_TAD            0b11110111
#define ADC_8_TAD            0b11111001
#define ADC_12_TAD           0b11111011
#define ADC_16_TAD           0b11111101
#define ADC_20_TAD           0b11111111
#define ADC_RIGHT_JUST       0b11111111
#define ADC_LEFT_JUST        0b01111111
#define ADC_INT_ON           0b11111111
#define ADC_INT_OFF          0b01111111
#define ADC_VREFPLUS_VDD     0b11111110
#define ADC_VREFPLUS_EXT     0b11111111
#define ADC_VREFMINUS_VSS    0b11111101
#define ADC_VREFMINUS_EXT    0b11111111
#define ADC_0ANA             0b11111111
#define ADC_1ANA             0b11111110
#define ADC_2ANA             0b11111101
#define ADC_3ANA             0b11111100
#define ADC_4ANA             0b11111011
#define ADC_5ANA             0b11111010
#define ADC_6ANA             0b11111001
#define ADC_7ANA             0b11111000
#define ADC_8ANA             0b11110111
#define ADC_9ANA             0b11110110
#define ADC_10ANA            0b11110101
#define ADC_11ANA            0b11110100
#define ADC_12ANA            0b11110011
#define ADC_13ANA            0b11110010
#define ADC_14ANA            0b11110001
#define ADC_16ANA            0b11110000
#define ADC_CH0              0b10000111
#define ADC_CH1              0b10001111
#define ADC_CH2              0b10010111
#define ADC_CH3              0b10011111
#define ADC_CH4              0b10100111
#define ADC_CH5              0b10101111
#define ADC_CH6              0b10110111
#define ADC_CH7              0b10111111
#define ADC_CH8              0b11000111
#define ADC_CH9              0b11001111
#define ADC_CH10             0b11010111
#define ADC_CH11             0b11011111
#define ADC_CH12             0b11100111
#define ADC_CH13             0b11101111
#define ADC_CH14             0b11110111
#define ADC_CH15             0b11111111

/* Configure and switch on (ADCON0..2), as C18's adc.h has it for the PIC18F8680 (a part with ACQT): config is
 * ADC_FOSC_* & ADC_*_JUST & ADC_n_TAD, config2 ADC_CH* & ADC_INT_* & ADC_VREF*, portconfig ADC_*ANA. */
void OpenADC(unsigned char config, unsigned char config2, unsigned char portconfig);
void SetChanADC(unsigned char channel);                          /* ADC_CH0 .. ADC_CH15 */
void ConvertADC(void);                                           /* ADCON0bits.GO = 1 */
char BusyADC(void);                                              /* 1 while a conversion runs */
int ReadADC(void);                                               /* ADRESH:ADRESL */
void CloseADC(void);

#endif
