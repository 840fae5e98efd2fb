/* string.h: MPLAB C18's string functions, as the kit provides them (RAM strings; ...pgm... ones for program memory). */
#ifndef __STRING_H
#define __STRING_H

#ifndef NULL
#define NULL ((void *)0)
#endif

void *memcpy(void *dest, const void *src, unsigned int n);
void *memset(void *dest, unsigned char value, unsigned int n);
int memcmp(const void *a, const void *b, unsigned int n);
unsigned int strlen(const char *s);
char *strcpy(char *dest, const char *src);
char *strncpy(char *dest, const char *src, unsigned int n);
char *strcat(char *dest, const char *src);
int strcmp(const char *a, const char *b);
int strncmp(const char *a, const char *b, unsigned int n);
char *strcpypgm2ram(char *dest, const rom char *src);
int strcmppgm2ram(const char *a, const rom char *b);
unsigned int strlenpgm(const rom char *s);

#endif
