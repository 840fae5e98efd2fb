/* stdlib.h: the few MPLAB C18 conversions the kit provides. */
#ifndef __STDLIB_H
#define __STDLIB_H

#ifndef NULL
#define NULL ((void *)0)
#endif

int atoi(const char *s);
char *itoa(int value, char *string);            /* C18's order: the value, then where to write it */
char *ultoa(unsigned long value, char *string);
int abs(int value);

#endif
