"""DEMO1 solution - A simple CAN monitor (CAN Workshop 202, Demo1, project CAN_Monitor.mcp).

"If your PC has no parallel port": the APP023 itself becomes a CAN monitor. The PIC18F8680 listens
to the bus in Listen-only mode (no ACK, no error flags: it cannot disturb anything), receives every
frame (RXM = 11, RXB0 rolling over into RXB1) and writes one text line per frame over its USART,
19200 baud 8N1, to the PIC18F2550, which the PC sees as a USB-CDC serial port (DSW2 5 & 6 ON; with
DSW2 3 & 4 ON the same bytes go to CON9, the RS-232 port).

A line (the kit's format, docs/monitor-format.md):
       12.345678  0x088  STD  DATA  DLC 5  01 02 03 02 9A
seconds since reset by Timer1 (Fosc/4, 1:8, overflows counted here), identifier, STD/XTD, DATA/RTR.

A line for a 5-byte frame is 55 bytes: 29 ms at 19200 baud (8N1, 10 bits a byte), while the frame
held the bus for at most 0.84 ms, so a busy bus outruns the USART. Frames wait in a queue in RAM.
Once it is full, frames are only counted until it has emptied, and then one short line says how many
were lost there, so notes take a line in 17 at most, not every other line:
    # lost 61 frames (queue full)

DSW2 switch 1 ON at reset (RJ0 reads 0): the board is an SLCAN (Lawicel) adapter instead, so a PC
program such as python-can (`interface="slcan"`) can receive and send frames through it. PC programs
write commands without waiting for answers (python-can writes C S4 CR O O, then V or a frame at once),
while opening or closing the channel waits for the bus to go idle (1 to 3 ms on a busy bus), longer
than the USART's 2-byte FIFO holds (1 ms at 19200 baud): the adapter keeps moving what the USART
receives into RAM meanwhile. Only a PC that keeps writing faster than the adapter carries out commands
fills that too: when the FIFO then overruns (OERR), the adapter resets its receiver, counts it, and
refuses the command that lost bytes with BELL, so it always answers the next one.
"""
from appsim.can import slcan
from appsim.can.frame import CanFrame
from appsim.firmware import *

QUEUE_FRAMES = 16             # frames waiting for the USART (13 bytes of RAM each)
COMMAND_CHARS = 32            # longest SLCAN command: T + 8 + 1 + 16 = 26 characters
RECEIVED_BYTES = 32           # bytes from the PC waiting to be carried out: 16 ms at 19200 baud
LOST = 0x100                  # among them: here the USART lost bytes (OERR)
OUTPUT_BYTES = 64             # SLCAN answers and frame lines waiting for the USART
LONGEST_ANSWER = len(slcan.VERSION) + len(slcan.OK)     # V1013 CR

# SLCAN Sn -> CANSetBaudRate(SJW, BRP, PHSEG1, PHSEG2, PROPSEG) at Fosc = 40 MHz, BRP as AN738's divider:
# TQ = 2 * BRP / Fosc = 2 * (BRP<5:0> + 1) / Fosc.
# S0 (10 kbit/s) needs more than 64 x 25 TQ of 50 ns: the PIC at 40 MHz cannot go that slow.
SLCAN_TIMING = {
    1: (4, 50, 7, 4, 8),      # 20 kbit/s: 20 TQ of 2.5 us
    2: (4, 25, 8, 4, 3),      # 50 kbit/s: 16 TQ of 1.25 us
    3: (4, 10, 7, 4, 8),      # 100 kbit/s: 20 TQ of 0.5 us
    4: (4, 10, 8, 4, 3),      # 125 kbit/s: the classroom's setting
    5: (4, 5, 8, 4, 3),       # 250 kbit/s
    6: (4, 2, 7, 4, 8),       # 500 kbit/s: 20 TQ of 0.1 us
    7: (4, 1, 8, 8, 8),       # 800 kbit/s: 25 TQ of 50 ns
    8: (4, 1, 7, 4, 8),       # 1 Mbit/s: 20 TQ of 50 ns
}

# SLCAN status flags (F command), Lawicel's bits and names; bit 7 is Lawicel's 'bus error': set here while bus-off
STATUS_RX_QUEUE_FULL, STATUS_TX_BUSY, STATUS_ERROR_WARNING = 0x01, 0x02, 0x04
STATUS_OVERRUN, STATUS_ERROR_PASSIVE, STATUS_BUS_ERROR = 0x08, 0x20, 0x80

overflows = 0                 # Timer1 overflows since reset: the high part of the time
queue = []                    # received frames (time, CANMessage) and ("lost", count) notes
lost = 0                      # frames dropped since the last queued one
dropping = False              # the queue filled up: frames are counted, not queued, until it has emptied
output = bytearray()          # the line being sent, byte by byte
usart_overruns = 0            # times the USART's receiver overran (OERR): each lost at least one byte from the PC
received = []                 # SLCAN: bytes from the PC (and LOST marks), oldest first


def now_ticks():
    """Timer1 ticks (0.8 us) since it started, with the overflows counted in software."""
    global overflows
    ticks = ReadTimer1()
    if PIR1bits.TMR1IF and ticks < 0x8000:     # it rolled over since the main loop last looked
        PIR1bits.TMR1IF = 0
        overflows += 1
    return (overflows << 16) | ticks


def count_overflows():
    global overflows
    if PIR1bits.TMR1IF:
        PIR1bits.TMR1IF = 0
        overflows += 1


def receive():
    """Move a received frame from the ECAN to the queue; from the time the queue is full until it has emptied,
    count it as lost instead."""
    global lost, dropping
    message = CANReceiveMessage()
    if message.flags & CAN_RX_INVALID_MSG:     # RXM = 11 kept what came before an error: not a frame to show;
        while CANIsRxReady():                  # IRXIF is one flag for both buffers, so what waits beside it
            CANReceiveMessage()                # may be cut short too
        return
    if message.flags & CAN_RX_OVERFLOW:
        queue.append(("overflow", 1))          # the ECAN dropped at least one frame before this one
    if len(queue) >= QUEUE_FRAMES:
        dropping = True
    elif not queue:
        dropping = False
    if dropping:
        lost += 1
        return
    if lost:
        queue.append(("lost", lost))
        lost = 0
    queue.append((now_ticks(), message))


def send_next_byte():
    if output and PIR1bits.TXIF:               # TXREG is free
        WriteUSART(output.pop(0))


def seconds_text(ticks):
    micros = ticks * 4 // 5                     # 1 tick = 8 / 10 MHz = 0.8 us
    return f"{micros // 1_000_000:5d}.{micros % 1_000_000:06d}"


def monitor_line(entry):
    stamp, message = entry
    if stamp == "lost":
        return f"# lost {message} frame{'s' if message > 1 else ''} (queue full)\r\n"
    if stamp == "overflow":
        return "# lost frames (RXB0/RXB1 overflowed)\r\n"
    extended = message.flags & CAN_RX_XTD_FRAME
    remote = message.flags & CAN_RX_RTR_FRAME
    ident = f"0x{message.id:08X}" if extended else f"0x{message.id:03X}"
    line = (f"{seconds_text(stamp)}  {ident}  {'XTD' if extended else 'STD'}  "
            f"{'RTR ' if remote else 'DATA'}  DLC {message.length}")
    if message.data and not remote:
        line += "  " + " ".join(f"{b:02X}" for b in message.data)
    return line + "\r\n"


def monitor():
    global lost
    CANSetOperationMode(CAN_OP_MODE_LISTEN)    # never ACK, never flag errors: invisible on the bus
    output.extend(b"# APP023 CAN monitor (Demo1): listen-only, 125 kbit/s\r\n")
    while True:
        count_overflows()
        if CANIsRxReady():
            receive()
        if not output:
            if queue:
                output.extend(monitor_line(queue.pop(0)).encode())
            elif lost:
                output.extend(monitor_line(("lost", lost)).encode())
                lost = 0
        send_next_byte()


# ------------------------------------------------------------------ DSW2 switch 1 ON: SLCAN adapter

class Adapter:
    """The SLCAN adapter: the command being received, and the settings (channel closed / open / listen-only,
    S code, time stamps, status)."""

    def __init__(self):
        self.command = bytearray()              # the command line so far
        self.spoiled = False                    # bytes of it were lost, or it is too long: refuse it
        self.mode = None                        # None: closed; else the CAN_OP_MODE it is open in
        self.code = 4                           # the last Sn (as an adapter remembers its setting)
        self.timestamps = False
        self.status = 0

    def take(self, char):
        """One byte from the PC (or LOST); at the CR that ends a command, the answer to send."""
        if char == LOST:                        # the command being received lost bytes (after the FIFO's two)
            self.spoiled = True
            return b""
        if char != 0x0D:
            if len(self.command) < COMMAND_CHARS:
                self.command.append(char)
            else:
                self.spoiled = True
            return b""
        answer = slcan.ERROR if self.spoiled else self.execute(bytes(self.command))
        self.command.clear()
        self.spoiled = False
        return answer

    def execute(self, line):
        """Carry out one command line; the reply to send."""
        global lost
        try:
            command = slcan.parse_command(line)
        except slcan.SlcanError:
            return slcan.ERROR
        if isinstance(command, slcan.Nothing):
            return slcan.OK
        if isinstance(command, slcan.SetBitRate):
            if self.mode is not None or command.code not in SLCAN_TIMING:
                return slcan.ERROR
            self.code = command.code
            return slcan.OK
        if isinstance(command, slcan.Open):
            if self.mode is not None:
                return slcan.ERROR
            CANSetBaudRate(*SLCAN_TIMING[self.code])
            self.mode = CAN_OP_MODE_LISTEN if command.listen_only else CAN_OP_MODE_NORMAL
            set_mode(self.mode)
            return slcan.OK
        if isinstance(command, slcan.Close):
            if self.mode is None:
                return slcan.ERROR
            set_mode(CAN_OP_MODE_CONFIG)
            self.mode = None
            queue.clear()
            lost = 0
            return slcan.OK
        if isinstance(command, slcan.Timestamps):
            if self.mode is not None:
                return slcan.ERROR
            self.timestamps = command.on
            return slcan.OK
        if isinstance(command, slcan.Query):
            if command.what == "V":
                return slcan.VERSION.encode() + slcan.OK
            if command.what == "N":
                return b"NA023" + slcan.OK
            if self.mode is None:
                return slcan.ERROR
            return slcan.status_reply(self.read_status())
        if self.mode != CAN_OP_MODE_NORMAL:     # Transmit: closed or listen-only cannot send
            return slcan.ERROR
        frame = command.frame
        flags = CAN_TX_PRIORITY_0 & (CAN_TX_XTD_FRAME if frame.extended else CAN_TX_STD_FRAME) \
            & (CAN_TX_RTR_FRAME if frame.remote else CAN_TX_NO_RTR_FRAME)
        if not CANSendMessage(frame.can_id, frame.data, frame.dlc, flags):
            self.status |= STATUS_TX_BUSY
            return slcan.ERROR
        return slcan.transmit_reply(frame)

    def read_status(self):
        """F: the sticky flags since the last F, and the error state now; reading clears the sticky ones."""
        status = self.status
        self.status = 0
        comstat = SFR.COMSTAT
        if comstat & 0x01:                     # EWARN
            status |= STATUS_ERROR_WARNING
        if comstat & 0x18:                     # RXBP, TXBP
            status |= STATUS_ERROR_PASSIVE
        if comstat & 0x20:                     # TXBO
            status |= STATUS_BUS_ERROR
        return status

    def frame_line(self, entry):
        stamp, message = entry
        if stamp in ("lost", "overflow"):      # SLCAN has no line for it: the F status says it
            self.status |= STATUS_OVERRUN | (STATUS_RX_QUEUE_FULL if stamp == "lost" else 0)
            return b""
        frame = CanFrame(message.id, b"" if message.flags & CAN_RX_RTR_FRAME else message.data,
                               extended=bool(message.flags & CAN_RX_XTD_FRAME),
                               remote=bool(message.flags & CAN_RX_RTR_FRAME), dlc=message.length)
        millis = stamp * 4 // 5000 if self.timestamps else None
        return slcan.encode_frame(frame, millis)


def listen():
    """Move a byte the USART received into `received`, while it has room (else the FIFO fills and overruns)."""
    global usart_overruns
    if len(received) >= RECEIVED_BYTES:
        return
    if DataRdyUSART():
        received.append(ReadUSART())
    elif RCSTAbits.OERR:                       # a byte came with the FIFO full: lost, and reception stopped
        RCSTAbits.CREN = 0                     # the data sheet's recovery: clearing CREN clears OERR,
        RCSTAbits.CREN = 1                     # setting it receives again
        usart_overruns += 1
        received.append(LOST)


def set_mode(mode):
    """CANSetOperationMode, listening to the PC while it waits: the ECAN changes mode only when the bus is
    idle (1 to 3 ms on a busy bus), and the USART's FIFO holds 1 ms of what the PC writes meanwhile."""
    CANSetOperationModeNoWait(mode)
    while (SFR.CANSTAT & CAN_OP_MODE_BITS) != mode:
        listen()


def adapter():
    state = Adapter()
    set_mode(CAN_OP_MODE_CONFIG)               # closed until the PC sends O or L
    while True:
        count_overflows()
        listen()
        if received and len(output) + LONGEST_ANSWER <= OUTPUT_BYTES:   # room for an answer: the PC's next byte
            output.extend(state.take(received.pop(0)))
        if state.mode is not None and CANIsRxReady():
            receive()
        if queue and not output:
            output.extend(state.frame_line(queue.pop(0)))
        send_next_byte()


def main():
    OpenUSART(USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT
              & USART_CONT_RX & USART_BRGH_HIGH, 129)           # 40 MHz / (16 x 130) = 19231 baud
    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)           # returns in Normal mode
    CANSetOperationMode(CAN_OP_MODE_CONFIG)
    RXB0CONbits.RXB0DBEN = 1                   # a full RXB0 rolls over into RXB1
    if PORTJbits.RJ0 == 0:                     # DSW2 switch 1 ON
        adapter()
    else:
        monitor()
