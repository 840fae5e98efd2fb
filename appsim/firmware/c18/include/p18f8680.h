/* p18f8680.h: the PIC18F8680's special function registers, as the kit models them (CAN Workshop 202).
 * Written by the kit from its register map (appsim.chip.sfr), in the style of MPLAB C18's device header:
 * each register an `extern volatile near unsigned char` (the linker places it at the address shown), and for
 * each register with named bits a `NAMEbits` union of structs, lowest bit first. */
#ifndef __18F8680_H
#define __18F8680_H

extern volatile near unsigned char RXF0SIDH;    /* 0xF00 */
extern volatile near unsigned char RXF0SIDL;    /* 0xF01 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDEN:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXF0SIDLbits;
extern volatile near unsigned char RXF0EIDH;    /* 0xF02 */
extern volatile near unsigned char RXF0EIDL;    /* 0xF03 */
extern volatile near unsigned char RXF1SIDH;    /* 0xF04 */
extern volatile near unsigned char RXF1SIDL;    /* 0xF05 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDEN:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXF1SIDLbits;
extern volatile near unsigned char RXF1EIDH;    /* 0xF06 */
extern volatile near unsigned char RXF1EIDL;    /* 0xF07 */
extern volatile near unsigned char RXF2SIDH;    /* 0xF08 */
extern volatile near unsigned char RXF2SIDL;    /* 0xF09 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDEN:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXF2SIDLbits;
extern volatile near unsigned char RXF2EIDH;    /* 0xF0A */
extern volatile near unsigned char RXF2EIDL;    /* 0xF0B */
extern volatile near unsigned char RXF3SIDH;    /* 0xF0C */
extern volatile near unsigned char RXF3SIDL;    /* 0xF0D */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDEN:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXF3SIDLbits;
extern volatile near unsigned char RXF3EIDH;    /* 0xF0E */
extern volatile near unsigned char RXF3EIDL;    /* 0xF0F */
extern volatile near unsigned char RXF4SIDH;    /* 0xF10 */
extern volatile near unsigned char RXF4SIDL;    /* 0xF11 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDEN:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXF4SIDLbits;
extern volatile near unsigned char RXF4EIDH;    /* 0xF12 */
extern volatile near unsigned char RXF4EIDL;    /* 0xF13 */
extern volatile near unsigned char RXF5SIDH;    /* 0xF14 */
extern volatile near unsigned char RXF5SIDL;    /* 0xF15 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDEN:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXF5SIDLbits;
extern volatile near unsigned char RXF5EIDH;    /* 0xF16 */
extern volatile near unsigned char RXF5EIDL;    /* 0xF17 */
extern volatile near unsigned char RXM0SIDH;    /* 0xF18 */
extern volatile near unsigned char RXM0SIDL;    /* 0xF19 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :3;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXM0SIDLbits;
extern volatile near unsigned char RXM0EIDH;    /* 0xF1A */
extern volatile near unsigned char RXM0EIDL;    /* 0xF1B */
extern volatile near unsigned char RXM1SIDH;    /* 0xF1C */
extern volatile near unsigned char RXM1SIDL;    /* 0xF1D */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :3;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXM1SIDLbits;
extern volatile near unsigned char RXM1EIDH;    /* 0xF1E */
extern volatile near unsigned char RXM1EIDL;    /* 0xF1F */
extern volatile near unsigned char TXB2CON;     /* 0xF20 */
extern volatile near union {
  struct {
    unsigned TXPRI:2;
    unsigned :1;
    unsigned TXREQ:1;
    unsigned TXERR:1;
    unsigned TXLARB:1;
    unsigned TXABT:1;
  };
  struct {
    unsigned TXPRI0:1;
    unsigned TXPRI1:1;
  };
} TXB2CONbits;
extern volatile near unsigned char TXB2SIDH;    /* 0xF21 */
extern volatile near unsigned char TXB2SIDL;    /* 0xF22 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDE:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} TXB2SIDLbits;
extern volatile near unsigned char TXB2EIDH;    /* 0xF23 */
extern volatile near unsigned char TXB2EIDL;    /* 0xF24 */
extern volatile near unsigned char TXB2DLC;     /* 0xF25 */
extern volatile near union {
  struct {
    unsigned DLC:4;
    unsigned :2;
    unsigned TXRTR:1;
  };
  struct {
    unsigned DLC0:1;
    unsigned DLC1:1;
    unsigned DLC2:1;
    unsigned DLC3:1;
  };
} TXB2DLCbits;
extern volatile near unsigned char TXB2D0;      /* 0xF26 */
extern volatile near unsigned char TXB2D1;      /* 0xF27 */
extern volatile near unsigned char TXB2D2;      /* 0xF28 */
extern volatile near unsigned char TXB2D3;      /* 0xF29 */
extern volatile near unsigned char TXB2D4;      /* 0xF2A */
extern volatile near unsigned char TXB2D5;      /* 0xF2B */
extern volatile near unsigned char TXB2D6;      /* 0xF2C */
extern volatile near unsigned char TXB2D7;      /* 0xF2D */
extern volatile near unsigned char CANSTATRO4;  /* 0xF2E */
extern volatile near unsigned char TXB1CON;     /* 0xF30 */
extern volatile near union {
  struct {
    unsigned TXPRI:2;
    unsigned :1;
    unsigned TXREQ:1;
    unsigned TXERR:1;
    unsigned TXLARB:1;
    unsigned TXABT:1;
  };
  struct {
    unsigned TXPRI0:1;
    unsigned TXPRI1:1;
  };
} TXB1CONbits;
extern volatile near unsigned char TXB1SIDH;    /* 0xF31 */
extern volatile near unsigned char TXB1SIDL;    /* 0xF32 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDE:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} TXB1SIDLbits;
extern volatile near unsigned char TXB1EIDH;    /* 0xF33 */
extern volatile near unsigned char TXB1EIDL;    /* 0xF34 */
extern volatile near unsigned char TXB1DLC;     /* 0xF35 */
extern volatile near union {
  struct {
    unsigned DLC:4;
    unsigned :2;
    unsigned TXRTR:1;
  };
  struct {
    unsigned DLC0:1;
    unsigned DLC1:1;
    unsigned DLC2:1;
    unsigned DLC3:1;
  };
} TXB1DLCbits;
extern volatile near unsigned char TXB1D0;      /* 0xF36 */
extern volatile near unsigned char TXB1D1;      /* 0xF37 */
extern volatile near unsigned char TXB1D2;      /* 0xF38 */
extern volatile near unsigned char TXB1D3;      /* 0xF39 */
extern volatile near unsigned char TXB1D4;      /* 0xF3A */
extern volatile near unsigned char TXB1D5;      /* 0xF3B */
extern volatile near unsigned char TXB1D6;      /* 0xF3C */
extern volatile near unsigned char TXB1D7;      /* 0xF3D */
extern volatile near unsigned char CANSTATRO3;  /* 0xF3E */
extern volatile near unsigned char TXB0CON;     /* 0xF40 */
extern volatile near union {
  struct {
    unsigned TXPRI:2;
    unsigned :1;
    unsigned TXREQ:1;
    unsigned TXERR:1;
    unsigned TXLARB:1;
    unsigned TXABT:1;
  };
  struct {
    unsigned TXPRI0:1;
    unsigned TXPRI1:1;
  };
} TXB0CONbits;
extern volatile near unsigned char TXB0SIDH;    /* 0xF41 */
extern volatile near unsigned char TXB0SIDL;    /* 0xF42 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXIDE:1;
    unsigned :1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} TXB0SIDLbits;
extern volatile near unsigned char TXB0EIDH;    /* 0xF43 */
extern volatile near unsigned char TXB0EIDL;    /* 0xF44 */
extern volatile near unsigned char TXB0DLC;     /* 0xF45 */
extern volatile near union {
  struct {
    unsigned DLC:4;
    unsigned :2;
    unsigned TXRTR:1;
  };
  struct {
    unsigned DLC0:1;
    unsigned DLC1:1;
    unsigned DLC2:1;
    unsigned DLC3:1;
  };
} TXB0DLCbits;
extern volatile near unsigned char TXB0D0;      /* 0xF46 */
extern volatile near unsigned char TXB0D1;      /* 0xF47 */
extern volatile near unsigned char TXB0D2;      /* 0xF48 */
extern volatile near unsigned char TXB0D3;      /* 0xF49 */
extern volatile near unsigned char TXB0D4;      /* 0xF4A */
extern volatile near unsigned char TXB0D5;      /* 0xF4B */
extern volatile near unsigned char TXB0D6;      /* 0xF4C */
extern volatile near unsigned char TXB0D7;      /* 0xF4D */
extern volatile near unsigned char CANSTATRO2;  /* 0xF4E */
extern volatile near unsigned char RXB1CON;     /* 0xF50 */
extern volatile near union {
  struct {
    unsigned FILHIT:3;
    unsigned RXRTRRO:1;
    unsigned :1;
    unsigned RXM:2;
    unsigned RXFUL:1;
  };
  struct {
    unsigned FILHIT0:1;
    unsigned FILHIT1:1;
    unsigned FILHIT2:1;
    unsigned :2;
    unsigned RXM0:1;
    unsigned RXM1:1;
  };
} RXB1CONbits;
extern volatile near unsigned char RXB1SIDH;    /* 0xF51 */
extern volatile near unsigned char RXB1SIDL;    /* 0xF52 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXID:1;
    unsigned SRR:1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXB1SIDLbits;
extern volatile near unsigned char RXB1EIDH;    /* 0xF53 */
extern volatile near unsigned char RXB1EIDL;    /* 0xF54 */
extern volatile near unsigned char RXB1DLC;     /* 0xF55 */
extern volatile near union {
  struct {
    unsigned DLC:4;
    unsigned RB0:1;
    unsigned RB1:1;
    unsigned RXRTR:1;
  };
  struct {
    unsigned DLC0:1;
    unsigned DLC1:1;
    unsigned DLC2:1;
    unsigned DLC3:1;
  };
} RXB1DLCbits;
extern volatile near unsigned char RXB1D0;      /* 0xF56 */
extern volatile near unsigned char RXB1D1;      /* 0xF57 */
extern volatile near unsigned char RXB1D2;      /* 0xF58 */
extern volatile near unsigned char RXB1D3;      /* 0xF59 */
extern volatile near unsigned char RXB1D4;      /* 0xF5A */
extern volatile near unsigned char RXB1D5;      /* 0xF5B */
extern volatile near unsigned char RXB1D6;      /* 0xF5C */
extern volatile near unsigned char RXB1D7;      /* 0xF5D */
extern volatile near unsigned char CANSTATRO1;  /* 0xF5E */
extern volatile near unsigned char RXB0CON;     /* 0xF60 */
extern volatile near union {
  struct {
    unsigned FILHIT0:1;
    unsigned JTOFF:1;
    unsigned RXB0DBEN:1;
    unsigned RXRTRRO:1;
    unsigned :1;
    unsigned RXM:2;
    unsigned RXFUL:1;
  };
  struct {
    unsigned :5;
    unsigned RXM0:1;
    unsigned RXM1:1;
  };
} RXB0CONbits;
extern volatile near unsigned char RXB0SIDH;    /* 0xF61 */
extern volatile near unsigned char RXB0SIDL;    /* 0xF62 */
extern volatile near union {
  struct {
    unsigned EID16:1;
    unsigned EID17:1;
    unsigned :1;
    unsigned EXID:1;
    unsigned SRR:1;
    unsigned SID:3;
  };
  struct {
    unsigned :5;
    unsigned SID0:1;
    unsigned SID1:1;
    unsigned SID2:1;
  };
} RXB0SIDLbits;
extern volatile near unsigned char RXB0EIDH;    /* 0xF63 */
extern volatile near unsigned char RXB0EIDL;    /* 0xF64 */
extern volatile near unsigned char RXB0DLC;     /* 0xF65 */
extern volatile near union {
  struct {
    unsigned DLC:4;
    unsigned RB0:1;
    unsigned RB1:1;
    unsigned RXRTR:1;
  };
  struct {
    unsigned DLC0:1;
    unsigned DLC1:1;
    unsigned DLC2:1;
    unsigned DLC3:1;
  };
} RXB0DLCbits;
extern volatile near unsigned char RXB0D0;      /* 0xF66 */
extern volatile near unsigned char RXB0D1;      /* 0xF67 */
extern volatile near unsigned char RXB0D2;      /* 0xF68 */
extern volatile near unsigned char RXB0D3;      /* 0xF69 */
extern volatile near unsigned char RXB0D4;      /* 0xF6A */
extern volatile near unsigned char RXB0D5;      /* 0xF6B */
extern volatile near unsigned char RXB0D6;      /* 0xF6C */
extern volatile near unsigned char RXB0D7;      /* 0xF6D */
extern volatile near unsigned char CANSTAT;     /* 0xF6E */
extern volatile near union {
  struct {
    unsigned :1;
    unsigned ICODE:3;
    unsigned :1;
    unsigned OPMODE:3;
  };
  struct {
    unsigned :1;
    unsigned ICODE0:1;
    unsigned ICODE1:1;
    unsigned ICODE2:1;
    unsigned :1;
    unsigned OPMODE0:1;
    unsigned OPMODE1:1;
    unsigned OPMODE2:1;
  };
} CANSTATbits;
extern volatile near unsigned char CANCON;      /* 0xF6F */
extern volatile near union {
  struct {
    unsigned :1;
    unsigned WIN:3;
    unsigned ABAT:1;
    unsigned REQOP:3;
  };
  struct {
    unsigned :1;
    unsigned WIN0:1;
    unsigned WIN1:1;
    unsigned WIN2:1;
    unsigned :1;
    unsigned REQOP0:1;
    unsigned REQOP1:1;
    unsigned REQOP2:1;
  };
} CANCONbits;
extern volatile near unsigned char BRGCON1;     /* 0xF70 */
extern volatile near union {
  struct {
    unsigned BRP:6;
    unsigned SJW:2;
  };
  struct {
    unsigned BRP0:1;
    unsigned BRP1:1;
    unsigned BRP2:1;
    unsigned BRP3:1;
    unsigned BRP4:1;
    unsigned BRP5:1;
    unsigned SJW0:1;
    unsigned SJW1:1;
  };
} BRGCON1bits;
extern volatile near unsigned char BRGCON2;     /* 0xF71 */
extern volatile near union {
  struct {
    unsigned PRSEG:3;
    unsigned SEG1PH:3;
    unsigned SAM:1;
    unsigned SEG2PHTS:1;
  };
  struct {
    unsigned PRSEG0:1;
    unsigned PRSEG1:1;
    unsigned PRSEG2:1;
    unsigned SEG1PH0:1;
    unsigned SEG1PH1:1;
    unsigned SEG1PH2:1;
  };
} BRGCON2bits;
extern volatile near unsigned char BRGCON3;     /* 0xF72 */
extern volatile near union {
  struct {
    unsigned SEG2PH:3;
    unsigned :3;
    unsigned WAKFIL:1;
    unsigned WAKDIS:1;
  };
  struct {
    unsigned SEG2PH0:1;
    unsigned SEG2PH1:1;
    unsigned SEG2PH2:1;
  };
} BRGCON3bits;
extern volatile near unsigned char CIOCON;      /* 0xF73 */
extern volatile near union {
  struct {
    unsigned :4;
    unsigned CANCAP:1;
    unsigned ENDRHI:1;
  };
} CIOCONbits;
extern volatile near unsigned char COMSTAT;     /* 0xF74 */
extern volatile near union {
  struct {
    unsigned EWARN:1;
    unsigned RXWARN:1;
    unsigned TXWARN:1;
    unsigned RXBP:1;
    unsigned TXBP:1;
    unsigned TXBO:1;
    unsigned RXB1OVFL:1;
    unsigned RXB0OVFL:1;
  };
} COMSTATbits;
extern volatile near unsigned char RXERRCNT;    /* 0xF75 */
extern volatile near unsigned char TXERRCNT;    /* 0xF76 */
extern volatile near unsigned char ECANCON;     /* 0xF77 */
extern volatile near union {
  struct {
    unsigned EWIN:5;
    unsigned FIFOWM:1;
    unsigned MDSEL:2;
  };
  struct {
    unsigned EWIN0:1;
    unsigned EWIN1:1;
    unsigned EWIN2:1;
    unsigned EWIN3:1;
    unsigned EWIN4:1;
    unsigned :1;
    unsigned MDSEL0:1;
    unsigned MDSEL1:1;
  };
} ECANCONbits;
extern volatile near unsigned char BAUDCON;     /* 0xF7E */
extern volatile near union {
  struct {
    unsigned ABDEN:1;
    unsigned WUE:1;
    unsigned :1;
    unsigned BRG16:1;
    unsigned SCKP:1;
    unsigned :1;
    unsigned RCIDL:1;
  };
} BAUDCONbits;
extern volatile near unsigned char SPBRGH;      /* 0xF7F */
extern volatile near unsigned char PORTJ;       /* 0xF88 */
extern volatile near union {
  struct {
    unsigned RJ0:1;
    unsigned RJ1:1;
    unsigned RJ2:1;
    unsigned RJ3:1;
    unsigned RJ4:1;
    unsigned RJ5:1;
    unsigned RJ6:1;
    unsigned RJ7:1;
  };
} PORTJbits;
extern volatile near unsigned char LATJ;        /* 0xF91 */
extern volatile near union {
  struct {
    unsigned LATJ0:1;
    unsigned LATJ1:1;
    unsigned LATJ2:1;
    unsigned LATJ3:1;
    unsigned LATJ4:1;
    unsigned LATJ5:1;
    unsigned LATJ6:1;
    unsigned LATJ7:1;
  };
} LATJbits;
extern volatile near unsigned char TRISJ;       /* 0xF9A */
extern volatile near union {
  struct {
    unsigned TRISJ0:1;
    unsigned TRISJ1:1;
    unsigned TRISJ2:1;
    unsigned TRISJ3:1;
    unsigned TRISJ4:1;
    unsigned TRISJ5:1;
    unsigned TRISJ6:1;
    unsigned TRISJ7:1;
  };
} TRISJbits;
extern volatile near unsigned char PIE1;        /* 0xF9D */
extern volatile near union {
  struct {
    unsigned TMR1IE:1;
    unsigned TMR2IE:1;
    unsigned CCP1IE:1;
    unsigned SSPIE:1;
    unsigned TXIE:1;
    unsigned RCIE:1;
    unsigned ADIE:1;
    unsigned PSPIE:1;
  };
} PIE1bits;
extern volatile near unsigned char PIR1;        /* 0xF9E */
extern volatile near union {
  struct {
    unsigned TMR1IF:1;
    unsigned TMR2IF:1;
    unsigned CCP1IF:1;
    unsigned SSPIF:1;
    unsigned TXIF:1;
    unsigned RCIF:1;
    unsigned ADIF:1;
    unsigned PSPIF:1;
  };
} PIR1bits;
extern volatile near unsigned char IPR1;        /* 0xF9F */
extern volatile near union {
  struct {
    unsigned TMR1IP:1;
    unsigned TMR2IP:1;
    unsigned CCP1IP:1;
    unsigned SSPIP:1;
    unsigned TXIP:1;
    unsigned RCIP:1;
    unsigned ADIP:1;
    unsigned PSPIP:1;
  };
} IPR1bits;
extern volatile near unsigned char PIE3;        /* 0xFA3 */
extern volatile near union {
  struct {
    unsigned RXB0IE:1;
    unsigned RXB1IE:1;
    unsigned TXB0IE:1;
    unsigned TXB1IE:1;
    unsigned TXB2IE:1;
    unsigned ERRIE:1;
    unsigned WAKIE:1;
    unsigned IRXIE:1;
  };
} PIE3bits;
extern volatile near unsigned char PIR3;        /* 0xFA4 */
extern volatile near union {
  struct {
    unsigned RXB0IF:1;
    unsigned RXB1IF:1;
    unsigned TXB0IF:1;
    unsigned TXB1IF:1;
    unsigned TXB2IF:1;
    unsigned ERRIF:1;
    unsigned WAKIF:1;
    unsigned IRXIF:1;
  };
} PIR3bits;
extern volatile near unsigned char IPR3;        /* 0xFA5 */
extern volatile near union {
  struct {
    unsigned RXB0IP:1;
    unsigned RXB1IP:1;
    unsigned TXB0IP:1;
    unsigned TXB1IP:1;
    unsigned TXB2IP:1;
    unsigned ERRIP:1;
    unsigned WAKIP:1;
    unsigned IRXIP:1;
  };
} IPR3bits;
extern volatile near unsigned char RCSTA;       /* 0xFAB */
extern volatile near union {
  struct {
    unsigned RX9D:1;
    unsigned OERR:1;
    unsigned FERR:1;
    unsigned ADDEN:1;
    unsigned CREN:1;
    unsigned SREN:1;
    unsigned RX9:1;
    unsigned SPEN:1;
  };
  struct {
    unsigned :3;
    unsigned ADEN:1;
  };
} RCSTAbits;
extern volatile near unsigned char TXSTA;       /* 0xFAC */
extern volatile near union {
  struct {
    unsigned TX9D:1;
    unsigned TRMT:1;
    unsigned BRGH:1;
    unsigned SENDB:1;
    unsigned SYNC:1;
    unsigned TXEN:1;
    unsigned TX9:1;
    unsigned CSRC:1;
  };
} TXSTAbits;
extern volatile near unsigned char TXREG;       /* 0xFAD */
extern volatile near unsigned char RCREG;       /* 0xFAE */
extern volatile near unsigned char SPBRG;       /* 0xFAF */
extern volatile near unsigned char ADCON2;      /* 0xFC0 */
extern volatile near union {
  struct {
    unsigned ADCS:3;
    unsigned ACQT:3;
    unsigned :1;
    unsigned ADFM:1;
  };
  struct {
    unsigned ADCS0:1;
    unsigned ADCS1:1;
    unsigned ADCS2:1;
    unsigned ACQT0:1;
    unsigned ACQT1:1;
    unsigned ACQT2:1;
  };
} ADCON2bits;
extern volatile near unsigned char ADCON1;      /* 0xFC1 */
extern volatile near union {
  struct {
    unsigned PCFG:4;
    unsigned VCFG0:1;
    unsigned VCFG1:1;
  };
  struct {
    unsigned PCFG0:1;
    unsigned PCFG1:1;
    unsigned PCFG2:1;
    unsigned PCFG3:1;
  };
} ADCON1bits;
extern volatile near unsigned char ADCON0;      /* 0xFC2 */
extern volatile near union {
  struct {
    unsigned ADON:1;
    unsigned GO_DONE:1;
    unsigned CHS:4;
  };
  struct {
    unsigned :1;
    unsigned GO:1;
    unsigned CHS0:1;
    unsigned CHS1:1;
    unsigned CHS2:1;
    unsigned CHS3:1;
  };
  struct {
    unsigned :1;
    unsigned DONE:1;
  };
} ADCON0bits;
extern volatile near unsigned char ADRESL;      /* 0xFC3 */
extern volatile near unsigned char ADRESH;      /* 0xFC4 */
extern volatile near unsigned char T1CON;       /* 0xFCD */
extern volatile near union {
  struct {
    unsigned TMR1ON:1;
    unsigned TMR1CS:1;
    unsigned T1SYNC:1;
    unsigned T1OSCEN:1;
    unsigned T1CKPS:2;
    unsigned :1;
    unsigned RD16:1;
  };
  struct {
    unsigned :2;
    unsigned NOT_T1SYNC:1;
    unsigned :1;
    unsigned T1CKPS0:1;
    unsigned T1CKPS1:1;
  };
  struct {
    unsigned :2;
    unsigned T1INSYNC:1;
  };
} T1CONbits;
extern volatile near unsigned char TMR1L;       /* 0xFCE */
extern volatile near unsigned char TMR1H;       /* 0xFCF */
extern volatile near unsigned char RCON;        /* 0xFD0 */
extern volatile near union {
  struct {
    unsigned BOR:1;
    unsigned POR:1;
    unsigned PD:1;
    unsigned TO:1;
    unsigned RI:1;
    unsigned :2;
    unsigned IPEN:1;
  };
  struct {
    unsigned NOT_BOR:1;
    unsigned NOT_POR:1;
    unsigned NOT_PD:1;
    unsigned NOT_TO:1;
    unsigned NOT_RI:1;
  };
} RCONbits;
extern volatile near unsigned char INTCON3;     /* 0xFF0 */
extern volatile near union {
  struct {
    unsigned INT1IF:1;
    unsigned INT2IF:1;
    unsigned INT3IF:1;
    unsigned INT1IE:1;
    unsigned INT2IE:1;
    unsigned INT3IE:1;
    unsigned INT1IP:1;
    unsigned INT2IP:1;
  };
  struct {
    unsigned INT1F:1;
    unsigned INT2F:1;
    unsigned INT3F:1;
    unsigned INT1E:1;
    unsigned INT2E:1;
    unsigned INT3E:1;
    unsigned INT1P:1;
    unsigned INT2P:1;
  };
} INTCON3bits;
extern volatile near unsigned char INTCON2;     /* 0xFF1 */
extern volatile near union {
  struct {
    unsigned RBIP:1;
    unsigned INT3IP:1;
    unsigned TMR0IP:1;
    unsigned INTEDG3:1;
    unsigned INTEDG2:1;
    unsigned INTEDG1:1;
    unsigned INTEDG0:1;
    unsigned RBPU:1;
  };
  struct {
    unsigned :1;
    unsigned INT3P:1;
    unsigned T0IP:1;
    unsigned :4;
    unsigned NOT_RBPU:1;
  };
} INTCON2bits;
extern volatile near unsigned char INTCON;      /* 0xFF2 */
extern volatile near union {
  struct {
    unsigned RBIF:1;
    unsigned INT0IF:1;
    unsigned TMR0IF:1;
    unsigned RBIE:1;
    unsigned INT0IE:1;
    unsigned TMR0IE:1;
    unsigned PEIE:1;
    unsigned GIE:1;
  };
  struct {
    unsigned :1;
    unsigned INT0F:1;
    unsigned T0IF:1;
    unsigned :1;
    unsigned INT0E:1;
    unsigned T0IE:1;
    unsigned GIEL:1;
    unsigned GIEH:1;
  };
} INTCONbits;

/* The instructions C18 offers as functions: one cycle each (ClrWdt: the watchdog timer is not simulated). */
void Nop(void);
void ClrWdt(void);
void Reset(void);

#endif
