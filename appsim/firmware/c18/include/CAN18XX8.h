/* CAN18XX8.h: the AN738 CAN library of CAN Workshop 202, as the kit provides it (its own text; Microchip's header is
 * not copied). The signatures, enumerations and macros are AN738's: flags are combined with '&', each field's
 * default is its all-ones value. The functions act only through the ECAN registers, as AN738's C does. */
#ifndef CAN18XX8_H
#define CAN18XX8_H

#include <p18f8680.h>

typedef unsigned char BYTE;
typedef enum _BOOL { FALSE = 0, TRUE } BOOL;

enum CAN_OP_MODE {
    CAN_OP_MODE_BITS   = 0b11100000,    /* mask of the mode bits */
    CAN_OP_MODE_NORMAL = 0b00000000,
    CAN_OP_MODE_SLEEP  = 0b00100000,
    CAN_OP_MODE_LOOP   = 0b01000000,
    CAN_OP_MODE_LISTEN = 0b01100000,
    CAN_OP_MODE_CONFIG = 0b10000000
};

enum CAN_CONFIG_FLAGS {
    CAN_CONFIG_DEFAULT         = 0b11111111,
    CAN_CONFIG_PHSEG2_PRG_BIT  = 0b00000001,
    CAN_CONFIG_PHSEG2_PRG_ON   = 0b11111111,    /* XXXXXXX1 */
    CAN_CONFIG_PHSEG2_PRG_OFF  = 0b11111110,    /* XXXXXXX0 */
    CAN_CONFIG_LINE_FILTER_BIT = 0b00000010,
    CAN_CONFIG_LINE_FILTER_ON  = 0b11111111,    /* XXXXXX1X */
    CAN_CONFIG_LINE_FILTER_OFF = 0b11111101,    /* XXXXXX0X */
    CAN_CONFIG_SAMPLE_BIT      = 0b00000100,
    CAN_CONFIG_SAMPLE_ONCE     = 0b11111111,    /* XXXXX1XX */
    CAN_CONFIG_SAMPLE_THRICE   = 0b11111011,    /* XXXXX0XX */
    CAN_CONFIG_MSG_TYPE_BIT    = 0b00001000,
    CAN_CONFIG_STD_MSG         = 0b11111111,    /* XXXX1XXX */
    CAN_CONFIG_XTD_MSG         = 0b11110111,    /* XXXX0XXX */
    CAN_CONFIG_DBL_BUFFER_BIT  = 0b00010000,
    CAN_CONFIG_DBL_BUFFER_ON   = 0b11111111,    /* XXX1XXXX */
    CAN_CONFIG_DBL_BUFFER_OFF  = 0b11101111,    /* XXX0XXXX */
    CAN_CONFIG_MSG_BITS        = 0b01100000,
    CAN_CONFIG_ALL_MSG         = 0b11111111,    /* X11XXXXX: RXM = 11 */
    CAN_CONFIG_VALID_XTD_MSG   = 0b11011111,    /* X10XXXXX: RXM = 10 */
    CAN_CONFIG_VALID_STD_MSG   = 0b10111111,    /* X01XXXXX: RXM = 01 */
    CAN_CONFIG_ALL_VALID_MSG   = 0b10011111     /* X00XXXXX: RXM = 00 */
};

enum CAN_TX_MSG_FLAGS {
    CAN_TX_PRIORITY_BITS = 0b00000011,
    CAN_TX_PRIORITY_0    = 0b11111100,          /* XXXXXX00 */
    CAN_TX_PRIORITY_1    = 0b11111101,          /* XXXXXX01 */
    CAN_TX_PRIORITY_2    = 0b11111110,          /* XXXXXX10 */
    CAN_TX_PRIORITY_3    = 0b11111111,          /* XXXXXX11 */
    CAN_TX_FRAME_BIT     = 0b00001000,
    CAN_TX_STD_FRAME     = 0b11111111,          /* XXXX1XXX */
    CAN_TX_XTD_FRAME     = 0b11110111,          /* XXXX0XXX */
    CAN_TX_RTR_BIT       = 0b01000000,
    CAN_TX_NO_RTR_FRAME  = 0b11111111,          /* X1XXXXXX */
    CAN_TX_RTR_FRAME     = 0b10111111           /* X0XXXXXX */
};

enum CAN_RX_MSG_FLAGS {
    CAN_RX_FILTER_BITS  = 0b00000111,           /* the filter that took the message */
    CAN_RX_FILTER_1     = 0b00000000,           /* RXF0 */
    CAN_RX_FILTER_2     = 0b00000001,           /* RXF1 */
    CAN_RX_FILTER_3     = 0b00000010,           /* RXF2 */
    CAN_RX_FILTER_4     = 0b00000011,           /* RXF3 */
    CAN_RX_FILTER_5     = 0b00000100,           /* RXF4 */
    CAN_RX_FILTER_6     = 0b00000101,           /* RXF5 */
    CAN_RX_OVERFLOW     = 0b00001000,
    CAN_RX_INVALID_MSG  = 0b00010000,
    CAN_RX_XTD_FRAME    = 0b00100000,
    CAN_RX_RTR_FRAME    = 0b01000000,
    CAN_RX_DBL_BUFFERED = 0b10000000
};

enum CAN_MASK { CAN_MASK_B1, CAN_MASK_B2 };     /* RXM0 (of RXB0), RXM1 (of RXB1) */

enum CAN_FILTER {                               /* RXF0 .. RXF5 */
    CAN_FILTER_B1_F1, CAN_FILTER_B1_F2,
    CAN_FILTER_B2_F1, CAN_FILTER_B2_F2, CAN_FILTER_B2_F3, CAN_FILTER_B2_F4
};

/* Configuration: CANInitialize enters Configuration mode, programs the bit timing (1-based arguments: the registers
 * get value - 1), sets RXM of both buffers, both masks to 0, every filter to 0, and returns in NORMAL mode. */
void CANInitialize(BYTE SJW, BYTE BRP, BYTE PHSEG1, BYTE PHSEG2, BYTE PROPSEG, enum CAN_CONFIG_FLAGS config);
void CANSetOperationMode(enum CAN_OP_MODE mode);                    /* waits until CANSTAT shows the mode */
void CANSetBaudRate(BYTE SJW, BYTE BRP, BYTE PHSEG1, BYTE PHSEG2, BYTE PROPSEG, enum CAN_CONFIG_FLAGS flags);
void CANSetMask(enum CAN_MASK code, unsigned long val, enum CAN_CONFIG_FLAGS type);        /* Configuration mode */
void CANSetFilter(enum CAN_FILTER code, unsigned long val, enum CAN_CONFIG_FLAGS type);    /* Configuration mode */

/* Operation: the first free buffer, TXB0 -> TXB1 -> TXB2 (FALSE if all three are pending); RXB0 before RXB1. */
BOOL CANSendMessage(unsigned long id, BYTE *Data, BYTE DataLen, enum CAN_TX_MSG_FLAGS MsgFlags);
BOOL CANReceiveMessage(unsigned long *id, BYTE *Data, BYTE *DataLen, enum CAN_RX_MSG_FLAGS *MsgFlags);

/* AN738's macros: register accesses, no call. */
#define CANSetOperationModeNoWait(mode) (CANCON = (mode))
#define CANGetOperationMode()   (CANCON & CAN_OP_MODE_BITS)
#define CANIsTxReady()          (!TXB0CONbits.TXREQ || !TXB1CONbits.TXREQ || !TXB2CONbits.TXREQ)
#define CANIsRxReady()          (RXB0CONbits.RXFUL || RXB1CONbits.RXFUL)
#define CANIsBusOff()           (COMSTATbits.TXBO)
#define CANIsTxPassive()        (COMSTATbits.TXBP)
#define CANIsRxPassive()        (COMSTATbits.RXBP)
#define CANGetTxErrorCount()    (TXERRCNT)
#define CANGetRxErrorCount()    (RXERRCNT)
#define CANAbortAll()           (CANCONbits.ABAT = 1)

#endif
