/* DEMO1 solution - A simple CAN monitor (CAN Workshop 202, Demo1, project CAN_Monitor.mcp).
 *
 * "If your PC has no parallel port": the APP023 itself becomes a CAN monitor. The PIC18F8680 listens
 * to the bus in Listen-only mode (no ACK, no error flags: it cannot disturb anything), receives every
 * frame (RXM = 11, RXB0 rolling over into RXB1) and writes one text line per frame over its USART,
 * 19200 baud 8N1, to the PIC18F2550, which the PC sees as a USB-CDC serial port (DSW2 5 & 6 ON; with
 * DSW2 3 & 4 ON the same bytes go to CON9, the RS-232 port).
 *
 * A line (the kit's format, docs/monitor-format.md):
 *        12.345678  0x088  STD  DATA  DLC 5  01 02 03 02 9A
 * seconds since reset by Timer1 (Fosc/4, 1:8, overflows counted here), identifier, STD/XTD, DATA/RTR.
 *
 * A line for a 5-byte frame is 55 bytes: 29 ms at 19200 baud (8N1, 10 bits a byte), while the frame
 * held the bus for at most 0.84 ms, so a busy bus outruns the USART. Frames wait in a queue in RAM.
 * Once it is full, frames are only counted until it has emptied, and then one short line says how many
 * were lost there, so notes take a line in 17 at most, not every other line:
 *     # lost 61 frames (queue full)
 *
 * DSW2 switch 1 ON at reset (RJ0 reads 0): the board is an SLCAN (Lawicel) adapter instead, so a PC
 * program such as python-can (`interface="slcan"`) can receive and send frames through it. PC programs
 * write commands without waiting for answers (python-can writes C S4 CR O O, then V or a frame at once),
 * while opening or closing the channel waits for the bus to go idle (1 to 3 ms on a busy bus), longer
 * than the USART's 2-byte FIFO holds (1 ms at 19200 baud): the adapter keeps moving what the USART
 * receives into RAM meanwhile. Only a PC that keeps writing faster than the adapter carries out commands
 * fills that too: when the FIFO then overruns (OERR), the adapter resets its receiver, counts it, and
 * refuses the command that lost bytes with BELL, so it always answers the next one.
 */
#include <p18f8680.h>
#include "CAN18XX8.h"
#include <timers.h>
#include <usart.h>
#include <stdio.h>
#include <string.h>

#pragma config OSC = HSPLL, WDT = OFF, LVP = OFF    /* Fosc = 40 MHz: the 10 MHz crystal with the 4x PLL */

#define QUEUE_FRAMES    16      /* frames waiting for the USART (13 bytes of RAM each) */
#define QUEUE_NOTES     4       /* room for the notes the queue holds besides (lost frames, overflows) */
#define COMMAND_CHARS   32      /* longest SLCAN command: T + 8 + 1 + 16 = 26 characters */
#define RECEIVED_BYTES  32      /* bytes from the PC waiting to be carried out: 16 ms at 19200 baud */
#define LOST            0x100   /* among them: here the USART lost bytes (OERR) */
#define OUTPUT_BYTES    64      /* SLCAN answers and frame lines waiting for the USART */
#define LONGEST_ANSWER  6       /* V1013 CR */
#define CR              0x0D
#define BELL            0x07
#define CLOSED          0xFF    /* the adapter's mode while its channel is closed */

/* SLCAN status flags (F command), Lawicel's bits and names; bit 7 is Lawicel's 'bus error': set here while bus-off */
#define STATUS_RX_QUEUE_FULL    0x01
#define STATUS_TX_BUSY          0x02
#define STATUS_ERROR_WARNING    0x04
#define STATUS_OVERRUN          0x08
#define STATUS_ERROR_PASSIVE    0x20
#define STATUS_BUS_ERROR        0x80

/* A queue entry: a received frame with its time, or a note of frames lost there. */
#define ENTRY_FRAME     0
#define ENTRY_LOST      1       /* `count` frames dropped while the queue was full */
#define ENTRY_OVERFLOW  2       /* RXB0/RXB1 overflowed before this point */

struct entry {
    BYTE kind;
    unsigned long stamp;        /* Timer1 ticks (0.8 us) since it started */
    unsigned long id;
    BYTE data[8];
    BYTE length;                /* the raw DLC, as AN738 gives it */
    BYTE flags;
    unsigned int count;
};

/* SLCAN Sn -> CANSetBaudRate(SJW, BRP, PHSEG1, PHSEG2, PROPSEG) at Fosc = 40 MHz, BRP as AN738's divider:
 * TQ = 2 * BRP / Fosc = 2 * (BRP<5:0> + 1) / Fosc. S0 (10 kbit/s) needs more than 64 x 25 TQ of 50 ns: the PIC at
 * 40 MHz cannot go that slow. */
rom const BYTE SLCAN_TIMING[9][5] = {
    {0, 0, 0, 0, 0},            /* S0: none */
    {4, 50, 7, 4, 8},           /* 20 kbit/s: 20 TQ of 2.5 us */
    {4, 25, 8, 4, 3},           /* 50 kbit/s: 16 TQ of 1.25 us */
    {4, 10, 7, 4, 8},           /* 100 kbit/s: 20 TQ of 0.5 us */
    {4, 10, 8, 4, 3},           /* 125 kbit/s: the classroom's setting */
    {4, 5, 8, 4, 3},            /* 250 kbit/s */
    {4, 2, 7, 4, 8},            /* 500 kbit/s: 20 TQ of 0.1 us */
    {4, 1, 8, 8, 8},            /* 800 kbit/s: 25 TQ of 50 ns */
    {4, 1, 7, 4, 8}             /* 1 Mbit/s: 20 TQ of 50 ns */
};

unsigned int overflows;         /* Timer1 overflows since reset: the high part of the time */
struct entry queue[QUEUE_FRAMES + QUEUE_NOTES];     /* received frames and notes, oldest first */
BYTE queued;
unsigned int lost;              /* frames dropped since the last queued one */
BOOL dropping;                  /* the queue filled up: frames are counted, not queued, until it has emptied */
char output[OUTPUT_BYTES + 8];  /* the line being sent, byte by byte */
BYTE output_length;
unsigned int usart_overruns;    /* times the USART's receiver overran (OERR): each lost at least one byte */
unsigned int received[RECEIVED_BYTES];  /* SLCAN: bytes from the PC (and LOST marks), oldest first */
BYTE received_length;
char line[64];                  /* a line being written */

unsigned long rx_id;            /* what CANReceiveMessage gives */
BYTE rx_data[8];
BYTE rx_length;
enum CAN_RX_MSG_FLAGS rx_flags;

/* The SLCAN adapter: the command being received, and the settings. */
char command[COMMAND_CHARS + 1];
BYTE command_length;
BOOL spoiled;                   /* bytes of it were lost, or it is too long: refuse it */
BYTE mode;                      /* CLOSED, or the CAN_OP_MODE it is open in */
BYTE code;                      /* the last Sn (as an adapter remembers its setting) */
BOOL timestamps;
BYTE status;

unsigned long now_ticks(void)
{
    unsigned int ticks = ReadTimer1();
    if (PIR1bits.TMR1IF && ticks < 0x8000) {        /* it rolled over since the main loop last looked */
        PIR1bits.TMR1IF = 0;
        overflows++;
    }
    return ((unsigned long)overflows << 16) | ticks;
}

void count_overflows(void)
{
    if (PIR1bits.TMR1IF) {
        PIR1bits.TMR1IF = 0;
        overflows++;
    }
}

void append(const char *text, BYTE length)
{
    memcpy(output + output_length, text, length);
    output_length += length;
}

void queue_note(BYTE kind, unsigned int count)
{
    if (queued < QUEUE_FRAMES + QUEUE_NOTES) {
        queue[queued].kind = kind;
        queue[queued].count = count;
        queued++;
    }
}

/* Move a received frame from the ECAN to the queue; from the time the queue is full until it has emptied, count it
 * as lost instead. */
void receive(void)
{
    BYTE k;

    CANReceiveMessage(&rx_id, rx_data, &rx_length, &rx_flags);
    if (rx_flags & CAN_RX_INVALID_MSG) {            /* RXM = 11 kept what came before an error: not a frame to show; */
        while (CANIsRxReady())                      /* IRXIF is one flag for both buffers, so what waits beside it */
            CANReceiveMessage(&rx_id, rx_data, &rx_length, &rx_flags);  /* may be cut short too */
        return;
    }
    if (rx_flags & CAN_RX_OVERFLOW)
        queue_note(ENTRY_OVERFLOW, 1);              /* the ECAN dropped at least one frame before this one */
    if (queued >= QUEUE_FRAMES)
        dropping = TRUE;
    else if (queued == 0)
        dropping = FALSE;
    if (dropping) {
        lost++;
        return;
    }
    if (lost) {
        queue_note(ENTRY_LOST, lost);
        lost = 0;
    }
    queue[queued].kind = ENTRY_FRAME;
    queue[queued].stamp = now_ticks();
    queue[queued].id = rx_id;
    for (k = 0; k < 8; k++)
        queue[queued].data[k] = rx_data[k];
    queue[queued].length = rx_length;
    queue[queued].flags = rx_flags;
    queued++;
}

void take_first(struct entry *first)
{
    BYTE k;

    *first = queue[0];
    for (k = 1; k < queued; k++)
        queue[k - 1] = queue[k];
    queued--;
}

void send_next_byte(void)
{
    if (output_length && PIR1bits.TXIF) {           /* TXREG is free */
        WriteUSART(output[0]);
        memcpy(output, output + 1, output_length - 1);
        output_length--;
    }
}

/* The monitor's line for a queue entry (docs/monitor-format.md), into `line`; its length. */
BYTE monitor_line(struct entry *e)
{
    unsigned long micros;
    BYTE k, n, shown;

    if (e->kind == ENTRY_LOST)
        return sprintf(line, "# lost %u frame%S (queue full)\r\n", e->count, e->count > 1 ? "s" : "");
    if (e->kind == ENTRY_OVERFLOW)
        return sprintf(line, "# lost frames (RXB0/RXB1 overflowed)\r\n");
    micros = 4 * (e->stamp / 5) + 4 * (e->stamp % 5) / 5;          /* 1 tick = 8 / 10 MHz = 0.8 us */
    n = sprintf(line, e->flags & CAN_RX_XTD_FRAME ? "%5lu.%06lu  0x%08lX  XTD  %S  DLC %hhu"
                                                 : "%5lu.%06lu  0x%03lX  STD  %S  DLC %hhu",
                micros / 1000000, micros % 1000000, e->id, e->flags & CAN_RX_RTR_FRAME ? "RTR " : "DATA", e->length);
    shown = e->length < 8 ? e->length : 8;
    if (shown && !(e->flags & CAN_RX_RTR_FRAME)) {
        n += sprintf(line + n, " ");
        for (k = 0; k < shown; k++)
            n += sprintf(line + n, " %02hhX", e->data[k]);
    }
    n += sprintf(line + n, "\r\n");
    return n;
}

void monitor(void)
{
    struct entry first;
    BYTE n;

    CANSetOperationMode(CAN_OP_MODE_LISTEN);        /* never ACK, never flag errors: invisible on the bus */
    n = sprintf(line, "# APP023 CAN monitor (Demo1): listen-only, 125 kbit/s\r\n");
    append(line, n);
    while (1) {
        count_overflows();
        if (CANIsRxReady())
            receive();
        if (!output_length) {
            if (queued) {
                take_first(&first);
                append(line, monitor_line(&first));
            } else if (lost) {
                first.kind = ENTRY_LOST;
                first.count = lost;
                append(line, monitor_line(&first));
                lost = 0;
            }
        }
        send_next_byte();
    }
}

/* ------------------------------------------------------------------ DSW2 switch 1 ON: SLCAN adapter */

/* Move a byte the USART received into `received`, while it has room (else the FIFO fills and overruns). */
void listen(void)
{
    if (received_length >= RECEIVED_BYTES)
        return;
    if (DataRdyUSART()) {
        received[received_length++] = (BYTE)ReadUSART();
    } else if (RCSTAbits.OERR) {                    /* a byte came with the FIFO full: lost, and reception stopped */
        RCSTAbits.CREN = 0;                         /* the data sheet's recovery: clearing CREN clears OERR, */
        RCSTAbits.CREN = 1;                         /* setting it receives again */
        usart_overruns++;
        received[received_length++] = LOST;
    }
}

/* CANSetOperationMode, listening to the PC while it waits: the ECAN changes mode only when the bus is idle (1 to 3 ms
 * on a busy bus), and the USART's FIFO holds 1 ms of what the PC writes meanwhile. */
void set_mode(BYTE new_mode)
{
    CANSetOperationModeNoWait(new_mode);
    while ((CANSTAT & CAN_OP_MODE_BITS) != new_mode)
        listen();
}

BYTE hex_value(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return 0xFF;
}

/* A transmit command (t, T, r, R) into the frame it names: FALSE if it is not one (BELL). */
BOOL parse_frame(unsigned long *id, BYTE *data, BYTE *dlc)
{
    BYTE digits, k, value;
    BOOL remote = command[0] == 'r' || command[0] == 'R';

    digits = (command[0] == 'T' || command[0] == 'R') ? 8 : 3;
    if (command_length < 1 + digits + 1)
        return FALSE;
    *id = 0;
    for (k = 1; k <= digits; k++) {
        value = hex_value(command[k]);
        if (value == 0xFF)
            return FALSE;
        *id = (*id << 4) | value;
    }
    if (command[digits + 1] < '0' || command[digits + 1] > '8')
        return FALSE;
    *dlc = command[digits + 1] - '0';
    if (remote)
        return command_length == digits + 2;
    if (command_length != digits + 2 + 2 * *dlc)
        return FALSE;
    for (k = 0; k < *dlc; k++) {
        value = hex_value(command[digits + 2 + 2 * k]);
        if (value == 0xFF || hex_value(command[digits + 3 + 2 * k]) == 0xFF)
            return FALSE;
        data[k] = (value << 4) | hex_value(command[digits + 3 + 2 * k]);
    }
    return digits == 8 ? *id <= 0x1FFFFFFF : *id <= 0x7FF;
}

/* F: the sticky flags since the last F, and the error state now; reading clears the sticky ones. */
BYTE read_status(void)
{
    BYTE now = status;
    BYTE comstat;

    status = 0;
    comstat = COMSTAT;
    if (comstat & 0x01)                             /* EWARN */
        now |= STATUS_ERROR_WARNING;
    if (comstat & 0x18)                             /* RXBP, TXBP */
        now |= STATUS_ERROR_PASSIVE;
    if (comstat & 0x20)                             /* TXBO */
        now |= STATUS_BUS_ERROR;
    return now;
}

/* Carry out the command line in `command`; the reply, into `line`: its length. */
BYTE execute(void)
{
    char head = command[0];
    unsigned long id;
    BYTE data[8];
    BYTE dlc;
    enum CAN_TX_MSG_FLAGS flags;

    if (command_length == 0)
        return sprintf(line, "\r");
    if (head == 't' || head == 'T' || head == 'r' || head == 'R') {
        if (!parse_frame(&id, data, &dlc) || mode != CAN_OP_MODE_NORMAL)    /* closed or listen-only cannot send */
            return sprintf(line, "\a");
        flags = CAN_TX_PRIORITY_0 & (head == 'T' || head == 'R' ? CAN_TX_XTD_FRAME : CAN_TX_STD_FRAME)
                & (head == 'r' || head == 'R' ? CAN_TX_RTR_FRAME : CAN_TX_NO_RTR_FRAME);
        if (!CANSendMessage(id, data, dlc, flags)) {
            status |= STATUS_TX_BUSY;
            return sprintf(line, "\a");
        }
        return sprintf(line, head == 'T' || head == 'R' ? "Z\r" : "z\r");
    }
    if (head == 'S' && command_length == 2 && command[1] >= '0' && command[1] <= '8') {
        if (mode != CLOSED || command[1] == '0')
            return sprintf(line, "\a");
        code = command[1] - '0';
        return sprintf(line, "\r");
    }
    if ((head == 'O' || head == 'L') && command_length == 1) {
        if (mode != CLOSED)
            return sprintf(line, "\a");
        CANSetBaudRate(SLCAN_TIMING[code][0], SLCAN_TIMING[code][1], SLCAN_TIMING[code][2], SLCAN_TIMING[code][3],
                       SLCAN_TIMING[code][4], CAN_CONFIG_DEFAULT);
        mode = head == 'L' ? CAN_OP_MODE_LISTEN : CAN_OP_MODE_NORMAL;
        set_mode(mode);
        return sprintf(line, "\r");
    }
    if (head == 'C' && command_length == 1) {
        if (mode == CLOSED)
            return sprintf(line, "\a");
        set_mode(CAN_OP_MODE_CONFIG);
        mode = CLOSED;
        queued = 0;
        lost = 0;
        return sprintf(line, "\r");
    }
    if (head == 'Z' && command_length == 2 && (command[1] == '0' || command[1] == '1')) {
        if (mode != CLOSED)
            return sprintf(line, "\a");
        timestamps = command[1] == '1';
        return sprintf(line, "\r");
    }
    if ((head == 'V' || head == 'N' || head == 'F') && command_length == 1) {
        if (head == 'V')
            return sprintf(line, "V1013\r");
        if (head == 'N')
            return sprintf(line, "NA023\r");
        if (mode == CLOSED)
            return sprintf(line, "\a");
        return sprintf(line, "F%02hhX\r", read_status());
    }
    return sprintf(line, "\a");
}

/* One byte from the PC (or LOST); at the CR that ends a command, the answer to send, into `line`: its length. */
BYTE take(unsigned int c)
{
    BYTE n;

    if (c == LOST) {                                /* the command being received lost bytes (after the FIFO's two) */
        spoiled = TRUE;
        return 0;
    }
    if (c != CR) {
        if (command_length < COMMAND_CHARS)
            command[command_length++] = c;
        else
            spoiled = TRUE;
        return 0;
    }
    n = spoiled ? sprintf(line, "\a") : execute();
    command_length = 0;
    spoiled = FALSE;
    return n;
}

/* A received frame (or note) as the SLCAN line to send, into `line`: its length (0 for a note: F says it). */
BYTE frame_line(struct entry *e)
{
    BYTE n, k, shown;
    BOOL remote = (e->flags & CAN_RX_RTR_FRAME) != 0;
    BOOL extended = (e->flags & CAN_RX_XTD_FRAME) != 0;

    if (e->kind != ENTRY_FRAME) {                   /* SLCAN has no line for it: the F status says it */
        status |= STATUS_OVERRUN | (e->kind == ENTRY_LOST ? STATUS_RX_QUEUE_FULL : 0);
        return 0;
    }
    shown = e->length < 8 ? e->length : 8;
    if (extended)
        n = sprintf(line, remote ? "R%08lX%hhu" : "T%08lX%hhu", e->id, shown);
    else
        n = sprintf(line, remote ? "r%03lX%hhu" : "t%03lX%hhu", e->id, shown);
    if (!remote)
        for (k = 0; k < shown; k++)
            n += sprintf(line + n, "%02hhX", e->data[k]);
    if (timestamps)
        n += sprintf(line + n, "%04X", (unsigned int)(e->stamp / 1250 % 60000));
    n += sprintf(line + n, "\r");
    return n;
}

void adapter(void)
{
    struct entry first;
    BYTE k, n;

    mode = CLOSED;
    code = 4;
    set_mode(CAN_OP_MODE_CONFIG);                   /* closed until the PC sends O or L */
    while (1) {
        count_overflows();
        listen();
        if (received_length && output_length + LONGEST_ANSWER <= OUTPUT_BYTES) {   /* room for an answer */
            n = take(received[0]);
            for (k = 1; k < received_length; k++)
                received[k - 1] = received[k];
            received_length--;
            append(line, n);
        }
        if (mode != CLOSED && CANIsRxReady())
            receive();
        if (queued && !output_length) {
            take_first(&first);
            append(line, frame_line(&first));
        }
        send_next_byte();
    }
}

void main(void)
{
    OpenUSART(USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT
              & USART_CONT_RX & USART_BRGH_HIGH, 129);      /* 40 MHz / (16 x 130) = 19231 baud */
    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF);
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG);      /* returns in Normal mode */
    CANSetOperationMode(CAN_OP_MODE_CONFIG);
    RXB0CONbits.RXB0DBEN = 1;                       /* a full RXB0 rolls over into RXB1 */
    if (PORTJbits.RJ0 == 0)                         /* DSW2 switch 1 ON */
        adapter();
    else
        monitor();
}
