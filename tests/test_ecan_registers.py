"""The ECAN register file on its own: addresses, reset values, access rules, windows, ICODE."""
from __future__ import annotations

from appsim.bus.controller import Mode
from appsim.can.frame import CanFrame
from appsim.chip.ecan import registers as R
from appsim.chip.ecan.controller import ECAN


def addr(name: str) -> int:
    return R.BY_NAME[name].address


def test_register_map_matches_datasheet_addresses():
    expected = {"RXF0SIDH": 0xF00, "RXF5EIDL": 0xF17, "RXM0SIDH": 0xF18, "RXM1EIDL": 0xF1F,
                "TXB2CON": 0xF20, "TXB2EIDH": 0xF23, "TXB2EIDL": 0xF24, "CANSTATRO4": 0xF2E,
                "TXB1CON": 0xF30, "TXB0CON": 0xF40, "TXB0D7": 0xF4D, "RXB1CON": 0xF50,
                "RXB1EIDH": 0xF53, "RXB1EIDL": 0xF54, "RXB0CON": 0xF60, "RXB0D0": 0xF66,
                "RXB0D7": 0xF6D, "CANSTAT": 0xF6E, "CANCON": 0xF6F, "BRGCON1": 0xF70,
                "BRGCON3": 0xF72, "CIOCON": 0xF73, "COMSTAT": 0xF74, "RXERRCNT": 0xF75,
                "TXERRCNT": 0xF76, "PIE3": 0xFA3, "PIR3": 0xFA4, "IPR3": 0xFA5}
    assert {name: addr(name) for name in expected} == expected
    assert len(R.BY_ADDRESS) == len(R.REGISTERS), "two registers share an address"


def test_reset_state_is_configuration_mode_cancon_canstat_0x80():
    ecan = ECAN()
    assert ecan.read(addr("CANCON")) == 0x80
    assert ecan.read(addr("CANSTAT")) == 0x80
    assert ecan.opmode == Mode.CONFIGURATION
    assert ecan.read(addr("IPR3")) == 0xFF and ecan.read(addr("PIR3")) == 0


def test_config_mode_protection_writes_ignored_and_reads_zero_outside_configuration():
    ecan = ECAN()
    for name in ("BRGCON1", "RXF0SIDH", "RXM1SIDH"):
        ecan.write(addr(name), 0x55)
    assert ecan.read(addr("RXF0SIDH")) == 0x55
    ecan.write(addr("CANCON"), 0x00)        # request Normal ...
    assert ecan.opmode == Mode.CONFIGURATION, "OPMODE follows only when the bus allows"
    ecan.enter_requested_mode()              # ... which the bus grants after 11 recessive bits
    assert ecan.read(addr("CANSTAT")) >> 5 == Mode.NORMAL
    for name in ("BRGCON1", "RXF0SIDH", "RXM1SIDH"):
        assert ecan.read(addr(name)) == 0, f"{name} must read 0 outside Configuration mode"
        ecan.write(addr(name), 0xAA)
    assert ("RXF0SIDH", 0xAA) in ecan.ignored_writes
    ecan.write(addr("CANCON"), 0x80)
    ecan.enter_requested_mode()
    assert ecan.read(addr("RXF0SIDH")) == 0x55, "the write in Normal mode did not take"


def test_reqop_1xx_requests_configuration_and_reads_back_opmode_100():
    ecan = ECAN()
    ecan.write(addr("CANCON"), 0x00)
    ecan.enter_requested_mode()
    ecan.write(addr("CANCON"), 0xE0)
    ecan.enter_requested_mode()
    assert ecan.read(addr("CANSTAT")) >> 5 == 0b100


def test_unimplemented_bits_read_zero_and_read_only_bits_ignore_writes():
    ecan = ECAN()
    ecan.write(addr("RXF0SIDL"), 0xFF)
    assert ecan.read(addr("RXF0SIDL")) == 0xEB           # bits 4 and 2 unimplemented
    ecan.write(addr("RXM0SIDL"), 0xFF)
    assert ecan.read(addr("RXM0SIDL")) == 0xE3           # a mask has no EXIDEN bit
    ecan.write(addr("TXB0CON"), 0xFF & ~R.TXREQ)
    assert ecan.read(addr("TXB0CON")) == 0x03            # TXABT/TXLARB/TXERR are read-only
    ecan.write(addr("COMSTAT"), 0xFF)
    assert ecan.read(addr("COMSTAT")) == 0


def test_jtoff_is_a_read_only_copy_of_rxb0dben():
    ecan = ECAN()
    ecan.write(addr("RXB0CON"), R.RXB0DBEN)
    assert ecan.read(addr("RXB0CON")) & 0x07 == 0b110
    ecan.write(addr("RXB0CON"), R.JTOFF)
    assert ecan.read(addr("RXB0CON")) & 0x07 == 0b000


def test_win_maps_each_buffer_onto_the_rxb0_window():
    ecan = ECAN()
    for buffer, win in (("TXB0", 0b100), ("TXB1", 0b011), ("TXB2", 0b010)):
        ecan.write(addr("CANCON"), 0x80 | (win << 1))
        ecan.write(addr("RXB0SIDH"), win + 0x10)         # written through the window
        assert ecan.get(buffer + "SIDH") == win + 0x10
    ecan.write(addr("CANCON"), 0x80)
    ecan.write(addr("RXB0CON"), R.RXB0DBEN)
    ecan.frame_received(CanFrame(0x123, b"\x55"))         # RXM 00, filters and masks 0: into RXB0
    ecan.frame_received(CanFrame(0x456, b"\x66"))         # RXB0 full, double buffering: into RXB1
    ecan.write(addr("CANCON"), 0x80 | (0b101 << 1))
    assert ecan.read(addr("RXB0SIDH")) == 0x456 >> 3, "RXB1 read through the window"
    for win in (0b000, 0b001, 0b110, 0b111):
        ecan.write(addr("CANCON"), 0x80 | (win << 1))
        assert ecan.read(addr("RXB0SIDH")) == ecan.get("RXB0SIDH") == 0x123 >> 3


def test_writing_cancon_with_a_mode_value_clears_win_and_abat():
    ecan = ECAN()
    ecan.write(addr("CANCON"), 0x80 | (0b101 << 1))
    ecan.write(addr("CANCON"), 0x80)
    assert ecan.read(addr("CANCON")) == 0x80


def test_icode_priority_err_tx0_tx1_tx2_rx0_rx1_wak_only_when_enabled():
    ecan = ECAN()
    ecan.write(addr("PIR3"), 0xFF)
    assert ecan.read(addr("CANSTAT")) & R.ICODE_MASK == 0, "no enable bits: ICODE 000"
    expected = [(R.ERRIF, 0b001), (R.TXB0IF, 0b100), (R.TXB1IF, 0b011), (R.TXB2IF, 0b010),
                (R.RXB0IF, 0b110), (R.RXB1IF, 0b101), (R.WAKIF, 0b111)]
    ecan.write(addr("PIE3"), 0xFF)
    for flag, code in expected:
        assert (ecan.read(addr("CANSTAT")) >> 1) & 0b111 == code
        assert ecan.read(addr("CANSTATRO3")) == ecan.read(addr("CANSTAT"))
        ecan.write(addr("PIR3"), ecan.read(addr("PIR3")) & ~flag)
    ecan.write(addr("PIR3"), R.IRXIF)
    assert (ecan.read(addr("CANSTAT")) >> 1) & 0b111 == 0, "IRXIF never appears in ICODE"


def test_tx_buffer_is_locked_while_txreq_is_set():
    ecan = ECAN()
    ecan.write(addr("TXB0SIDH"), 0x20)
    ecan.write(addr("TXB0CON"), R.TXREQ)
    ecan.write(addr("TXB0SIDH"), 0x99)
    assert ecan.get("TXB0SIDH") == 0x20


def test_setting_txreq_clears_txabt_txlarb_txerr():
    ecan = ECAN()
    ecan.write(addr("TXB1CON"), R.TXREQ)
    ecan.transmission_started("TXB1")
    ecan.transmission_failed("TXB1")
    ecan.arbitration_lost("TXB1")
    assert ecan.get("TXB1CON") & (R.TXERR | R.TXLARB) == R.TXERR | R.TXLARB
    assert ecan.get("PIR3") & R.TXB1IF == 0, "losing arbitration raises no interrupt"
    ecan.transmission_succeeded("TXB1")
    ecan.write(addr("TXB1CON"), R.TXREQ)
    assert ecan.get("TXB1CON") & (R.TXABT | R.TXLARB | R.TXERR) == 0


def test_equal_txpri_leaves_txb2_then_txb1_then_txb0_and_txpri_beats_buffer_number():
    ecan = ECAN()
    for buffer in R.TX_BUFFERS:
        ecan.write(addr(buffer + "CON"), R.TXREQ)
    order = []
    while (buffer := ecan.next_transmission()) is not None:
        order.append(buffer)
        ecan.transmission_succeeded(buffer)
    assert order == ["TXB2", "TXB1", "TXB0"]
    ecan.write(addr("TXB0CON"), R.TXREQ | 0b11)
    ecan.write(addr("TXB2CON"), R.TXREQ | 0b01)
    assert ecan.next_transmission() == "TXB0"


def test_abort_of_a_frame_not_on_the_wire_sets_txabt_at_once_without_txbnif():
    ecan = ECAN()
    ecan.write(addr("TXB0CON"), R.TXREQ)
    ecan.write(addr("TXB0CON"), 0)
    assert ecan.get("TXB0CON") & (R.TXREQ | R.TXABT) == R.TXABT
    assert ecan.get("PIR3") & R.TXB0IF == 0


def test_abort_of_a_frame_on_the_wire_lets_it_finish_and_txabt_stays_clear():
    ecan = ECAN()
    ecan.write(addr("TXB0CON"), R.TXREQ)
    ecan.transmission_started("TXB0")
    ecan.write(addr("CANCON"), 0x80 | R.ABAT)
    assert ecan.read(addr("CANCON")) & R.ABAT, "ABAT stays set while its abort waits for the frame on the wire"
    assert ecan.get("TXB0CON") & R.TXREQ, "the frame on the wire is still being sent"
    ecan.transmission_succeeded("TXB0")
    assert ecan.get("TXB0CON") & (R.TXREQ | R.TXABT) == 0 and ecan.get("PIR3") & R.TXB0IF
    assert ecan.read(addr("CANCON")) & R.ABAT == 0, "ABAT clears itself once the abort is acted upon"


def test_abat_with_nothing_on_the_wire_aborts_and_clears_at_once():
    ecan = ECAN()
    ecan.write(addr("TXB1CON"), R.TXREQ)
    ecan.write(addr("CANCON"), 0x80 | R.ABAT)
    assert ecan.read(addr("CANCON")) & R.ABAT == 0 and ecan.get("TXB1CON") & (R.TXREQ | R.TXABT) == R.TXABT


def test_abat_on_a_frame_on_the_wire_that_fails_sets_txabt_and_clears():
    ecan = ECAN()
    ecan.write(addr("TXB0CON"), R.TXREQ)
    ecan.transmission_started("TXB0")
    ecan.write(addr("CANCON"), 0x80 | R.ABAT)
    ecan.transmission_failed("TXB0")
    assert ecan.get("TXB0CON") & (R.TXREQ | R.TXABT) == R.TXABT and ecan.read(addr("CANCON")) & R.ABAT == 0


def test_receive_buffer_identifier_dlc_and_data_are_read_only_to_the_cpu():
    ecan = ECAN()
    ecan.frame_received(CanFrame(0x123, b"\x55\x66"))
    before = [ecan.read(addr(f"RXB0{field}")) for field in R.BUFFER_FIELDS[1:]]
    for field in R.BUFFER_FIELDS[1:]:
        ecan.write(addr(f"RXB0{field}"), 0xA5)
        ecan.write(addr(f"RXB1{field}"), 0xA5)
    assert [ecan.read(addr(f"RXB0{field}")) for field in R.BUFFER_FIELDS[1:]] == before
    assert all(ecan.get(f"RXB1{field}") == 0 for field in R.BUFFER_FIELDS[1:])


def test_ciocon_is_written_only_in_configuration_mode_and_reads_in_any_mode():
    ecan = ECAN()
    ecan.write(addr("CIOCON"), 0x20)
    ecan.write(addr("CANCON"), 0x00)
    ecan.enter_requested_mode()
    ecan.write(addr("CIOCON"), 0x10)
    assert ecan.read(addr("CIOCON")) == 0x20 and ("CIOCON", 0x10) in ecan.ignored_writes


def test_abort_of_a_frame_on_the_wire_that_fails_is_not_retried_and_sets_txabt():
    ecan = ECAN()
    ecan.write(addr("TXB0CON"), R.TXREQ)
    ecan.transmission_started("TXB0")
    ecan.write(addr("TXB0CON"), 0)
    ecan.arbitration_lost("TXB0")
    assert ecan.get("TXB0CON") & (R.TXREQ | R.TXABT | R.TXLARB) == R.TXABT | R.TXLARB
    assert ecan.next_transmission() is None


def test_error_counters_thresholds_warning_passive_bus_off_raise_errif():
    ecan = ECAN()
    ecan.write(addr("TXB0CON"), R.TXREQ)
    statuses = []
    for _ in range(33):
        ecan.transmission_failed("TXB0")
        statuses.append((ecan.tec, ecan.read(addr("COMSTAT"))))
    assert statuses[11] == (96, R.TXWARN | R.EWARN)
    assert statuses[15] == (128, R.TXBP | R.TXWARN | R.EWARN)
    assert statuses[32] == (264, R.TXBO | R.TXBP | R.TXWARN | R.EWARN)
    assert ecan.read(addr("TXERRCNT")) == 255 and ecan.bus_off
    assert ecan.get("PIR3") & R.ERRIF


def test_successful_reception_above_127_sets_rec_back_into_error_active_range():
    ecan = ECAN()
    for _ in range(130):
        ecan.receive_error()
    assert ecan.read(addr("COMSTAT")) & R.RXBP
    ecan.frame_received(CanFrame(0x123))
    assert 119 <= ecan.rec <= 127 and not ecan.read(addr("COMSTAT")) & R.RXBP


def test_configuration_mode_clears_the_error_counters():
    ecan = ECAN()
    ecan.write(addr("CANCON"), 0)
    ecan.enter_requested_mode()
    for _ in range(5):
        ecan.receive_error()
    ecan.write(addr("CANCON"), 0x80)
    ecan.enter_requested_mode()
    assert (ecan.tec, ecan.rec) == (0, 0)


def test_bus_off_recovers_after_128_sequences_of_11_recessive_bits():
    ecan = ECAN()
    ecan.write(addr("CANCON"), 0)
    ecan.enter_requested_mode()
    ecan.write(addr("TXB0CON"), R.TXREQ)
    for _ in range(32):
        ecan.transmission_failed("TXB0")
    assert ecan.bus_off
    ecan.bus_off_recovery(127)
    assert ecan.bus_off
    ecan.bus_off_recovery(1)
    assert not ecan.bus_off and (ecan.tec, ecan.rec) == (0, 0)


def test_ecancon_other_than_mode_0_is_refused_with_an_explanation():
    import pytest

    from appsim.chip.ecan.controller import UnsupportedMode
    ecan = ECAN()
    with pytest.raises(UnsupportedMode, match="legacy Mode 0"):
        ecan.write(addr("ECANCON"), 0x40)
    assert ecan.read(addr("ECANCON")) == 0


def test_rxm_01_rejects_extended_and_rxm_10_rejects_standard_frames():
    ecan = ECAN()                                         # masks 0: every filter bit is don't-care
    for n in range(6):
        ecan.write(addr(f"RXF{n}SIDL"), R.EXIDE if n % 2 else 0)
    ecan.write(addr("RXB0CON"), 0b01 << 5)
    ecan.write(addr("RXB1CON"), 0b01 << 5)
    assert ecan.frame_received(CanFrame(0x123, extended=True)).buffer is None
    assert ecan.frame_received(CanFrame(0x123)).buffer == "RXB0"
    ecan.write(addr("RXB0CON"), 0b10 << 5)
    ecan.write(addr("RXB1CON"), 0b10 << 5)
    assert ecan.frame_received(CanFrame(0x124)).buffer is None
    reception = ecan.frame_received(CanFrame(0x125, extended=True))
    assert (reception.buffer, reception.filter) == ("RXB0", 1), (
        "writing RXB0CON with bit 7 = 0 cleared RXFUL (R/C), so RXB0 was free; RXF1 is its extended filter")


def test_rxm_11_accepts_what_the_filters_reject():
    ecan = ECAN()
    for offset in range(4):
        ecan.write(addr("RXM0SIDH") + offset, 0xFF)
    ecan.write(addr("RXB0CON"), 0b11 << 5)
    assert str(ecan.frame_received(CanFrame(0x7AB, extended=False))) == "RXB0 via RXF0"


def test_mode_change_aborts_pending_transmissions_as_the_workshop_warns():
    for aborts in (True, False):
        ecan = ECAN(mode_change_aborts_tx=aborts)
        ecan.write(addr("CANCON"), 0)
        ecan.enter_requested_mode()
        ecan.write(addr("TXB0CON"), R.TXREQ)
        ecan.write(addr("CANCON"), 0x60)                  # to Listen-only
        ecan.enter_requested_mode()
        assert bool(ecan.get("TXB0CON") & R.TXABT) == aborts
    ecan.write(addr("CANCON"), 0x80)                      # Configuration always aborts
    ecan.enter_requested_mode()
    assert ecan.get("TXB0CON") & (R.TXREQ | R.TXABT) == R.TXABT
