"""The ECAN module of a PIC18F8680 in legacy Mode 0: a register file and what the silicon does on each event.

Firmware reads and writes registers; the wire calls the event methods (`appsim.bus.controller.Controller`).
"""
from __future__ import annotations

import functools
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from appsim.bus.bitlevel import Assembled, rule_8
from appsim.bus.controller import ErrorCounters, Mode, Wire
from appsim.can.bittiming import BitTiming
from appsim.can.frame import CanFrame
from appsim.chip.clock import FOSC_HZ
from appsim.chip.ecan import registers as R
from appsim.chip.ecan.acceptance import Filter, buffer_hit, pack_id, raw29, unpack_id
from appsim.errors import UnsupportedMode

# The mode each REQOP<2:0> requests: 1xx requests Configuration (101, 110 and 111 read back as OPMODE 100).
# Looked up rather than built: CANCON is written at every CANCON.WIN change, and enum construction is slow.
_MODE_OF_REQOP = tuple(Mode.CONFIGURATION if reqop & 0b100 else Mode(reqop) for reqop in range(8))


@dataclass(frozen=True, slots=True)
class Reception:
    """Where the acceptance logic put a frame: the buffer and filter, or the overflow it caused."""

    buffer: str | None          # "RXB0", "RXB1" or None (not accepted / lost)
    filter: int | None          # RXFn number that accepted it
    overflow: str | None = None  # "RXB0OVFL" or "RXB1OVFL" when the frame was lost

    def __str__(self) -> str:
        if self.overflow:
            return f"lost: {self.overflow} (RXF{self.filter} matched but the buffer was full)"
        if self.buffer is None:
            return "rejected by the masks and filters"
        return f"{self.buffer} via RXF{self.filter}"


_ICODE_ORDER = ((R.TXB0IF, 0b100), (R.TXB1IF, 0b011), (R.TXB2IF, 0b010),
                (R.RXB0IF, 0b110), (R.RXB1IF, 0b101), (R.WAKIF, 0b111))
_TX_ORDER = ("TXB2", "TXB1", "TXB0")     # on equal TXPRI the higher buffer number goes first
_RXF_OF = {"RXB0": (0, 1), "RXB1": (2, 3, 4, 5)}
_MASK_OF = {"RXB0": 0, "RXB1": 1}

# What a CPU access to each address does, decided once from the register map rather than on every access.
IGNORED_KEPT = 64                        # ignored writes the module keeps to show (ECAN.ignored_writes)
_CONFIGURATION = Mode.CONFIGURATION      # an enum member is slow to look up on its class (CPython 3.11)
_PLAIN, _PROTECTED, _CANSTAT, _COMSTAT, _TXERRCNT, _RXERRCNT, _UNMAPPED = range(7)


def _read_kind(address: int) -> int:
    register = R.BY_ADDRESS.get(address)
    if register is None:
        return _UNMAPPED
    if register.protected:
        return _PROTECTED
    if register.name.startswith("CANSTAT"):
        return _CANSTAT
    return {"COMSTAT": _COMSTAT, "TXERRCNT": _TXERRCNT, "RXERRCNT": _RXERRCNT}.get(register.name, _PLAIN)


_READ_KIND_AT = tuple(_read_kind(0xF00 + index) for index in range(0x100))     # by address - F00h
_WINDOW_FIRST, _WINDOW_LAST = R.WINDOW_FIRST - 0xF00, R.WINDOW_LAST - 0xF00    # as indexes
_WINDOW_SHIFT_BY_CANCON = tuple(R.BUFFER_BASE[R.WINDOW[(cancon & R.WIN_MASK) >> 1]] - R.WINDOW_FIRST
                                for cancon in range(0x100))


def _plain_indexes(shift: int) -> tuple[int, ...]:
    """By address - F00h, through the window shifted by `shift`: the index of the register a read returns as it is
    stored, -1 where a read does more (protected, computed or unmapped)."""
    indexes = []
    for index in range(0x100):
        seen = index + shift if _WINDOW_FIRST <= index <= _WINDOW_LAST else index
        indexes.append(seen if _READ_KIND_AT[seen] == _PLAIN else -1)
    return tuple(indexes)


_PLAIN_BY_SHIFT = {shift: _plain_indexes(shift) for shift in set(_WINDOW_SHIFT_BY_CANCON)}
_PLAIN_INDEX_BY_CANCON = tuple(_PLAIN_BY_SHIFT[shift] for shift in _WINDOW_SHIFT_BY_CANCON)
_TXREQ_LOCK = {r.address: R.BUFFER_BASE[r.name[:4]] - 0xF00 for r in R.REGISTERS   # TXBn data: CON index
               if r.name[:3] == "TXB" and r.name[4:] != "CON"}
_RESETS_ACCEPTANCE = frozenset(r.address for r in R.REGISTERS if r.protected)   # filters and masks among them
_SIDE_EFFECTS = frozenset(R.BY_NAME[n].address for n in ("CANCON", "TXB0CON", "TXB1CON", "TXB2CON", "RXB0CON",
                                                        "ECANCON"))

_timing = functools.lru_cache(maxsize=64)(BitTiming.from_registers)     # asked at every frame the bus runs bit by bit


class ECAN(ErrorCounters):
    """One ECAN module. Registers are the truth; everything else is derived from them or is counters.

    `changed` is called whenever an event of the bus changes what the firmware can read (the MCU wakes a waiting
    firmware). `mode_change_aborts_tx`: the workshop says "when CANSetOperationMode() runs, a pending message
    is aborted!!" while the AN738 header says it has no side effects; the kit follows the workshop by default.
    """

    def __init__(self, name: str = "ECAN", fosc: int = FOSC_HZ, *, changed: Callable[[], None] = lambda: None,
                 mode_change_aborts_tx: bool = True):
        self.name = name
        self.fosc = fosc
        self.wire: Wire | None = None
        self.changed = changed
        self.mode_change_aborts_tx = mode_change_aborts_tx
        # Writes the silicon ignored (a filter outside Configuration mode, a TX buffer while TXREQ = 1), as (register,
        # value): the latest IGNORED_KEPT of them, and how many in all (a loop may make millions).
        self.ignored_writes: deque[tuple[str, int]] = deque(maxlen=IGNORED_KEPT)
        self.ignored_count = 0
        self.reset()

    # ----------------------------------------------------------------- reset and state
    def reset(self) -> None:
        """Power-on reset: every register to its reset value, counters 0, Configuration mode."""
        self._sfr = bytearray(0x100)
        for reg in R.REGISTERS:
            self._sfr[reg.address - 0xF00] = reg.reset
        self.opmode = Mode.CONFIGURATION
        self.tec = 0
        self.rec = 0
        self.on_wire: str | None = None          # TX buffer whose frame is on the bus now
        self._abort_requested: set[str] = set()
        self._recovery_sequences = 0
        self._acceptance: dict[str, tuple[tuple[Filter, ...], int]] | None = None
        self._tx_frames: dict[int, CanFrame] = {}   # TX buffer (CON index) -> its frame, until its registers change

    @property
    def requested_mode(self) -> Mode:
        """The mode asked for in CANCON.REQOP (OPMODE follows once the bus allows)."""
        return _MODE_OF_REQOP[self._sfr[0x6F] >> 5]

    @property
    def error_state(self) -> str:
        return "bus-off" if self.bus_off else "error-passive" if self.error_passive else "error-active"

    def bit_timing(self) -> BitTiming:
        """The bit timing BRGCON1..3 hold (whatever the mode; the registers only read 0 to firmware)."""
        sfr = self._sfr
        return _timing(sfr[0x70], sfr[0x71], sfr[0x72])

    def get(self, name: str) -> int:
        """A register's stored value by datasheet name, without side effects or protection."""
        return self._sfr[R.BY_NAME[name].address - 0xF00]

    def _set(self, name: str, value: int) -> None:
        self._sfr[R.BY_NAME[name].address - 0xF00] = value

    def _setbits(self, name: str, bits: int) -> None:
        self._sfr[R.BY_NAME[name].address - 0xF00] |= bits

    def _clearbits(self, name: str, bits: int) -> None:
        self._sfr[R.BY_NAME[name].address - 0xF00] &= ~bits & 0xFF

    # ----------------------------------------------------------------- firmware side
    def read(self, address: int) -> int:
        """What the CPU reads at an SFR address (after the CANCON.WIN window)."""
        index = address - 0xF00
        if 0 <= index <= 0xFF:
            sfr = self._sfr
            plain = _PLAIN_INDEX_BY_CANCON[sfr[0x6F]][index]
            if plain >= 0:
                return sfr[plain]
        if _WINDOW_FIRST <= index <= _WINDOW_LAST:
            index += _WINDOW_SHIFT_BY_CANCON[self._sfr[0x6F]]
        elif not 0 <= index <= 0xFF:
            return 0
        kind = _READ_KIND_AT[index]
        if kind == _PLAIN:
            return self._sfr[index]
        if kind == _UNMAPPED:
            return 0
        if kind == _PROTECTED:
            return self._sfr[index] if self.opmode == _CONFIGURATION else 0
        if kind == _CANSTAT:
            return (self.opmode << 5) | (self._icode() << 1)
        if kind == _COMSTAT:
            return self._sfr[0x74] | self._status_bits()
        return min(self.tec if kind == _TXERRCNT else self.rec, 255)

    def write(self, address: int, value: int) -> None:
        """What the CPU's write does, with the access rules of each bit and its side effects."""
        address = self._windowed(address)
        reg = R.BY_ADDRESS.get(address)
        if reg is None:
            return
        if (reg.protected or reg.locked) and self.opmode != _CONFIGURATION:
            self._ignored(reg.name, value)
            return
        index = address - 0xF00
        old = self._sfr[index]
        lock = _TXREQ_LOCK.get(address)
        if lock is not None:
            if self._sfr[lock] & R.TXREQ:
                self._ignored(reg.name, value)     # locked while TXREQ = 1
                return
            self._tx_frames.pop(lock, None)
        new = (old & ~reg.writable & 0xFF) | (value & reg.writable)
        new &= ~(reg.clear_only & ~value) & 0xFF
        self._sfr[index] = new
        if address in _RESETS_ACCEPTANCE:
            self._acceptance = None
        if address in _SIDE_EFFECTS:
            self._after_write(reg.name, old, new)

    def _ignored(self, name: str, value: int) -> None:
        self.ignored_writes.append((name, value & 0xFF))
        self.ignored_count += 1

    def _windowed(self, address: int) -> int:
        if _WINDOW_FIRST <= address - 0xF00 <= _WINDOW_LAST:
            return address + _WINDOW_SHIFT_BY_CANCON[self._sfr[0x6F]]
        return address

    def _after_write(self, name: str, old: int, new: int) -> None:
        if name == "CANCON":
            if new & R.ABAT:
                for buffer in R.TX_BUFFERS:
                    if self.get(buffer + "CON") & R.TXREQ:
                        self._request_abort(buffer)
                self._abort_done()
            if _MODE_OF_REQOP[new >> 5] != self.opmode and self.wire:
                self.wire.mode_requested(self)
        elif name in ("TXB0CON", "TXB1CON", "TXB2CON"):
            buffer = name[:4]
            if new & R.TXREQ and not old & R.TXREQ:
                self._set(name, new & ~(R.TXABT | R.TXLARB | R.TXERR))
                self._abort_requested.discard(buffer)
                if self.wire:
                    self.wire.transmit_requested(self)
            elif old & R.TXREQ and not new & R.TXREQ:
                self._setbits(name, R.TXREQ)          # the hardware, not software, ends a request
                self._request_abort(buffer)
        elif name == "RXB0CON":
            dben = bool(new & R.RXB0DBEN)
            self._set(name, (new & ~R.JTOFF) | (R.JTOFF if dben else 0))
        elif name == "ECANCON" and new & R.MDSEL_MASK:
            self._set(name, old)
            raise UnsupportedMode(
                f"ECANCON.MDSEL = {new >> 6:02b} selects ECAN Mode {new >> 6}; this kit models the "
                "PIC18F8680 in legacy Mode 0 only, the mode the workshop and AN738 use (MDSEL = 00)")

    def _abort_done(self) -> None:
        """ABAT clears itself once every abort is carried out: at once, or when the frame on the wire ends."""
        if not self._abort_requested:
            self._clearbits("CANCON", R.ABAT)

    def _request_abort(self, buffer: str) -> None:
        """A frame not on the wire aborts at once; one on the wire is allowed to finish."""
        if buffer == self.on_wire:
            self._abort_requested.add(buffer)
        else:
            self._clearbits(buffer + "CON", R.TXREQ)
            self._setbits(buffer + "CON", R.TXABT)

    # ----------------------------------------------------------------- status and interrupts
    def _status_bits(self) -> int:
        tec, rec = self.tec, self.rec
        bits = ((R.TXBO if tec > 255 else 0) | (R.TXBP if tec > 127 else 0)
                | (R.RXBP if rec > 127 else 0) | (R.TXWARN if tec > 95 else 0)
                | (R.RXWARN if rec > 95 else 0))
        return bits | (R.EWARN if bits & (R.TXWARN | R.RXWARN) else 0)

    def interrupt_registers(self) -> tuple[int, int, int]:
        """PIR3, PIE3 and IPR3, as the core's interrupt logic reads them."""
        sfr = self._sfr
        return sfr[0xA4], sfr[0xA3], sfr[0xA5]

    def _icode(self) -> int:
        pending = self._sfr[0xA4] & self._sfr[0xA3]    # PIR3 & PIE3
        if pending & R.ERRIF:
            return 0b001
        for flag, code in _ICODE_ORDER:
            if pending & flag:
                return code
        return 0b000

    def _set_counters(self, tec: int, rec: int) -> None:
        """Change TEC/REC; a rising warning, passive or bus-off status bit raises ERRIF."""
        before = self._status_bits()
        self.tec, self.rec = tec, min(rec, 255)
        rising = self._status_bits() & ~before & (R.TXBO | R.TXBP | R.RXBP | R.TXWARN | R.RXWARN)
        if rising:
            self._setbits("PIR3", R.ERRIF)

    # ----------------------------------------------------------------- mode changes (bus side)
    def enter_requested_mode(self) -> None:
        """OPMODE takes the REQOP value (the bus calls this once it has seen the bus idle)."""
        mode = self.requested_mode
        if mode != self.opmode:
            self._enter(mode)
        self.changed()

    def _enter(self, mode: Mode) -> None:
        if self.mode_change_aborts_tx or mode == Mode.CONFIGURATION:
            for buffer in R.TX_BUFFERS:
                if self.get(buffer + "CON") & R.TXREQ and buffer != self.on_wire:
                    self._request_abort(buffer)
        if mode in (Mode.CONFIGURATION, Mode.LISTEN_ONLY):   # both reset the error counters
            self._set_counters(0, 0)
            self._recovery_sequences = 0
        self.opmode = mode

    # ----------------------------------------------------------------- transmit (bus side)
    def next_transmission(self) -> str | None:
        """The TX buffer the module would start next: highest TXPRI, then the highest buffer number."""
        best, best_pri = None, -1
        for buffer in _TX_ORDER:
            con = self._sfr[R.BUFFER_BASE[buffer] - 0xF00]
            if con & R.TXREQ and buffer not in self._abort_requested and (con & R.TXPRI_MASK) > best_pri:
                best, best_pri = buffer, con & R.TXPRI_MASK
        return best

    def frame_in(self, buffer: str) -> CanFrame:
        """The frame a TX or RX buffer holds, decoded from its registers (a TX buffer's once per content:
        it waits through arbitrations unchanged, and only the CPU writes its identifier, DLC and data)."""
        base = R.BUFFER_BASE[buffer] - 0xF00
        frame = self._tx_frames.get(base)
        if frame is None:
            frame = self._decode(base)
            if buffer in R.TX_BUFFERS:
                self._tx_frames[base] = frame
        return frame

    def _decode(self, base: int) -> CanFrame:
        sfr = self._sfr
        can_id, extended = unpack_id(sfr[base + 1], sfr[base + 2], sfr[base + 3], sfr[base + 4])
        dlc_reg = sfr[base + 5]
        dlc = dlc_reg & 0x0F
        if dlc_reg & R.TXRTR:
            return CanFrame(can_id, extended=extended, remote=True, dlc=dlc)
        return CanFrame(can_id, bytes(sfr[base + 6: base + 6 + min(dlc, 8)]), extended=extended, dlc=dlc)

    def transmission_started(self, buffer: str) -> None:
        self.on_wire = buffer

    def transmission_succeeded(self, buffer: str) -> None:
        """EOF reached with an ACK: TXREQ clears, TXBnIF sets, TEC counts down by one."""
        self.on_wire = None
        self._abort_requested.discard(buffer)
        self._abort_done()
        self._clearbits(buffer + "CON", R.TXREQ)
        self._setbits("PIR3", R.TXBIF[buffer])
        self._set_counters(max(self.tec - 1, 0), self.rec)
        self.changed()

    def arbitration_lost(self, buffer: str) -> None:
        """TXLARB sets (no interrupt) and the frame waits for the next bus idle, unless aborted."""
        self.on_wire = None
        self._setbits(buffer + "CON", R.TXLARB)
        self._finish_abort(buffer)
        self.changed()

    def transmission_failed(self, buffer: str, *, tec_increment: int = 8) -> None:
        """A bit, form, stuff or ACK error while sending: TXERR and IRXIF set, TEC += 8, retry later.

        The bus passes `tec_increment=0` for the CAN exception: an error-passive transmitter with an
        ACK error that sees no dominant bit during its passive error flag.
        """
        self.on_wire = None
        self._setbits(buffer + "CON", R.TXERR)
        self._setbits("PIR3", R.IRXIF)
        self._set_counters(self.tec + tec_increment, self.rec)
        self._finish_abort(buffer)
        self.changed()

    def _finish_abort(self, buffer: str) -> None:
        if buffer in self._abort_requested:
            self._abort_requested.discard(buffer)
            self._clearbits(buffer + "CON", R.TXREQ)
            self._setbits(buffer + "CON", R.TXABT)
            self._abort_done()

    def bus_off_recovery(self, sequences: int) -> None:
        """Count occurrences of 11 recessive bits while bus-off; at 128 the node is error-active again."""
        if not self.bus_off or self.requested_mode == Mode.CONFIGURATION:
            return
        self._recovery_sequences += sequences
        if self._recovery_sequences >= 128:
            self._recovery_sequences = 0
            self._set_counters(0, 0)
            self.changed()

    # ----------------------------------------------------------------- receive (bus side)
    def _acceptance_config(self) -> dict[str, tuple[tuple[Filter, ...], int]]:
        """Filters and masks of each buffer, decoded from the registers once per change."""
        if self._acceptance is None:
            sfr = self._sfr

            def bits(offset: int) -> int:
                return raw29(sfr[offset], sfr[offset + 1], sfr[offset + 2], sfr[offset + 3])

            self._acceptance = {
                buffer: (tuple(Filter(n, bits(4 * n), bool(sfr[4 * n + 1] & R.EXIDE))
                               for n in _RXF_OF[buffer]),
                         bits(0x18 + 4 * _MASK_OF[buffer]))
                for buffer in R.RX_BUFFERS
            }
        return self._acceptance

    def frame_received(self, frame: CanFrame) -> Reception:
        """A valid frame has reached the MAB: filter it and route it to RXB0, RXB1 or overflow."""
        rec = self.rec
        if rec:
            self._set_counters(self.tec, rule_8(rec))
        reception = self._accept(frame)
        if reception.filter is not None or self.rec != rec:     # a rejected frame changes nothing else
            self.changed()
        return reception

    def _accept(self, frame: CanFrame) -> Reception:
        config = self._acceptance_config()
        sfr = self._sfr
        filters, mask = config["RXB0"]
        hit0 = buffer_hit(frame.can_id, frame.extended, (sfr[0x60] & R.RXM_MASK) >> 5, filters, mask)
        if hit0 is not None:
            if not sfr[0x60] & R.RXFUL:
                return self._load("RXB0", frame, hit0)
            if not sfr[0x60] & R.RXB0DBEN:
                return self._overflow("RXB0OVFL", hit0)
            if not sfr[0x50] & R.RXFUL:
                return self._load("RXB1", frame, hit0)
            return self._overflow("RXB1OVFL", hit0)
        filters, mask = config["RXB1"]
        hit1 = buffer_hit(frame.can_id, frame.extended, (sfr[0x50] & R.RXM_MASK) >> 5, filters, mask)
        if hit1 is None:
            return Reception(None, None)
        if sfr[0x50] & R.RXFUL:
            return self._overflow("RXB1OVFL", hit1)
        return self._load("RXB1", frame, hit1)

    def _overflow(self, flag: str, filter_number: int) -> Reception:
        self._setbits("COMSTAT", R.RXB0OVFL if flag == "RXB0OVFL" else R.RXB1OVFL)
        self._setbits("PIR3", R.ERRIF)
        return Reception(None, filter_number, flag)

    def _load(self, buffer: str, frame: CanFrame | Assembled, filter_number: int) -> Reception:
        """MAB -> RXBn: ID, DLC and data, RXRTRRO, FILHIT; then RXFUL and RXBnIF."""
        base = R.BUFFER_BASE[buffer] - 0xF00
        sfr = self._sfr
        sidh, sidl, eidh, eidl = pack_id(frame.can_id, frame.extended)
        if frame.extended:
            sfr[base + 1: base + 5] = bytes((sidh, sidl, eidh, eidl))
        else:   # SRR mirrors RXRTRRO for a standard frame (0 when EXID = 1); EIDH/EIDL keep their value
            sfr[base + 1] = sidh
            sfr[base + 2] = sidl | (R.SRR if frame.remote else 0)
        sfr[base + 5] = (R.RXRTR if frame.remote else 0) | frame.dlc
        sfr[base + 6: base + 6 + len(frame.data)] = frame.data
        if buffer == "RXB0":
            con = (sfr[base] & (R.RXM_MASK | R.RXB0DBEN | R.JTOFF)) | (filter_number & 0x01)
        else:
            con = (sfr[base] & R.RXM_MASK) | filter_number
        sfr[base] = con | R.RXFUL | (R.RXRTRRO if frame.remote else 0)
        self._setbits("PIR3", R.RXBIF[buffer])
        return Reception(buffer, filter_number)

    def bus_activity(self) -> None:
        """A SOF on the bus: in Disable mode it sets WAKIF (when WAKIE is set, as DS39500 says)."""
        if self.opmode == Mode.DISABLE and self._sfr[0xA3] & R.WAKIF:
            self._setbits("PIR3", R.WAKIF)
            self.changed()

    def receive_error(self, *, rec_increment: int = 1, assembled: Assembled | None = None,
                      acknowledged: bool = False) -> None:
        """A receiver detected a CRC, stuff, form or bit error: IRXIF sets, REC += the rules' increment (after rule 8's
        count down when it had ACKed the frame). A buffer in error-recognition mode (RXM = 11) stores what was
        assembled up to the error (DS39500 §5.5)."""
        self._setbits("PIR3", R.IRXIF)
        self._set_counters(self.tec, (rule_8(self.rec) if acknowledged else self.rec) + rec_increment)
        if assembled is not None:
            self._store_invalid(assembled)
        self.changed()

    def _store_invalid(self, assembled: Assembled) -> None:
        """Error recognition: the first free buffer with RXM = 11 (RXB0 first) takes the identifier, DLC and the
        whole data bytes received; the data registers after them keep what they held."""
        sfr = self._sfr
        for buffer in R.RX_BUFFERS:
            base = R.BUFFER_BASE[buffer] - 0xF00
            if (sfr[base] & R.RXM_MASK) != R.RXM_MASK or sfr[base] & R.RXFUL:
                continue
            filters, mask = self._acceptance_config()[buffer]
            hit = buffer_hit(assembled.can_id, assembled.extended, 0b11, filters, mask)
            self._load(buffer, assembled, hit if hit is not None else filters[0].number)
            return
