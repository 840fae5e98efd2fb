/* stdio.h: MPLAB C18's sprintf, as the kit provides it. The format is a string in program memory; the arguments after
 * it are passed as they are, not promoted (a char is one byte): %d %i %u %x %X %o %b %B read an int (2 bytes), with
 * hh a char, H a short long (3 bytes), l a long (4 bytes); %c a char; %s a string in RAM, %S one in program memory. */
#ifndef __STDIO_H
#define __STDIO_H

#ifndef NULL
#define NULL ((void *)0)
#endif

int sprintf(char *buf, const rom char *fmt, ...);

#endif
