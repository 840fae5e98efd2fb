/* APP023_GLCD.h: the APP023 board's graphic LCD library of CAN Workshop 202, as the kit provides it. The screen shows
 * 8 lines of 21 characters: setcurGLCD(line 1..8, column 1..21). */
#ifndef __APP023_GLCD_H
#define __APP023_GLCD_H

void GLCD_Initial(void);                        /* clear, cursor to line 1 column 1 */
void setcurGLCD(unsigned char line, unsigned char column);
void putsGLCD(char *string);                    /* a string in data memory (RAM) */
void putrsGLCD(const rom char *string);         /* a string in program memory (ROM): a literal such as "EX1" */
void putcGLCD(unsigned char character);

#endif
