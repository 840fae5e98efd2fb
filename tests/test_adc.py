"""The PIC18F8680 A/D converter: registers, conversion timing on the simulated clock, and C18's adc.h."""
from __future__ import annotations

from collections.abc import Callable

import pytest

from appsim.chip.adc import ADC
from appsim.chip.mcu import PIC18F8680
from appsim.firmware import SFR, Delay10KTCYx, INTCONbits, PIE1bits, PIR1bits
from appsim.firmware.adc import (
    ADC_0_TAD,
    ADC_1ANA,
    ADC_4_TAD,
    ADC_6ANA,
    ADC_12_TAD,
    ADC_16ANA,
    ADC_CH0,
    ADC_CH3,
    ADC_CH5,
    ADC_CH15,
    ADC_FOSC_2,
    ADC_FOSC_4,
    ADC_FOSC_8,
    ADC_FOSC_16,
    ADC_FOSC_32,
    ADC_FOSC_64,
    ADC_FOSC_RC,
    ADC_INT_OFF,
    ADC_INT_ON,
    ADC_LEFT_JUST,
    ADC_RIGHT_JUST,
    ADC_VREFMINUS_EXT,
    ADC_VREFMINUS_VSS,
    ADC_VREFPLUS_EXT,
    ADC_VREFPLUS_VDD,
    BusyADC,
    CloseADC,
    ConvertADC,
    OpenADC,
    ReadADC,
    SetChanADC,
)
from appsim.sim import Simulator

TOSC_PS = 25_000                            # Fosc = 40 MHz
FOSC64_CONVERSION_PS = 11 * 64 * TOSC_PS    # 11 TAD of 1.6 µs = 17.6 µs
OPEN_CH0 = (ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_1ANA,
            ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS)


def make_board(potentiometer: int = 0) -> tuple[Simulator, PIC18F8680, ADC]:
    sim = Simulator()
    mcu = PIC18F8680(sim, "station0")
    adc = mcu.adc
    adc.potentiometer = potentiometer
    return sim, mcu, adc


def run(mcu: PIC18F8680, main: Callable[[], None], until: int = 10**9) -> None:
    mcu.run(main)
    mcu.sim.run(until=until)
    assert mcu.process is not None and mcu.process.failure is None, mcu.process.failure_text
    assert mcu.process.finished


def now(mcu: PIC18F8680) -> int:
    """The firmware's own time (it runs ahead of sim.now)."""
    assert mcu.process is not None
    return mcu.process.local_time


def registers(mcu: PIC18F8680) -> dict[str, int]:
    return {name: mcu.read_name(name) for name in ("ADRESH", "ADRESL", "ADCON0", "ADCON1", "ADCON2")}


# ------------------------------------------------------------------ registers
def test_reset_values_and_unimplemented_bits() -> None:
    _, mcu, _ = make_board()
    assert registers(mcu) == dict.fromkeys(("ADRESH", "ADRESL", "ADCON0", "ADCON1", "ADCON2"), 0)
    assert (mcu.address_of("ADRESH"), mcu.address_of("ADRESL"), mcu.address_of("ADCON0"),
            mcu.address_of("ADCON1"), mcu.address_of("ADCON2")) == (0xFC4, 0xFC3, 0xFC2, 0xFC1, 0xFC0)
    for name in ("ADRESH", "ADRESL", "ADCON1", "ADCON2"):
        mcu.write_name(name, 0xFF)
    mcu.write_name("ADCON0", 0xFD)          # everything but GO/DONE
    assert registers(mcu) == {"ADRESH": 0xFF, "ADRESL": 0xFF, "ADCON0": 0x3D, "ADCON1": 0x3F, "ADCON2": 0xBF}


def test_register_level_conversion_takes_11_tad() -> None:
    _, mcu, _ = make_board(666)
    seen = {}

    def main() -> None:
        mcu.write_name("ADCON2", 0x86)      # ADFM = 1, ADCS = Fosc/64
        mcu.write_name("ADCON0", 0x01)      # channel 0, ADON
        mcu.write_name("ADCON0", 0x03)      # GO
        seen["go"] = now(mcu)
        seen["at_go"] = registers(mcu)
        while mcu.read_name("ADCON0") & 0x02:
            pass
        seen["done"] = now(mcu)
        seen["at_done"] = registers(mcu)

    run(mcu, main)
    assert seen["at_go"]["ADCON0"] == 0x03
    assert (seen["at_go"]["ADRESH"], seen["at_go"]["ADRESL"]) == (0, 0)
    assert seen["go"] + FOSC64_CONVERSION_PS <= seen["done"] <= seen["go"] + FOSC64_CONVERSION_PS + 1_000_000
    assert seen["at_done"]["ADCON0"] == 0x01
    assert (seen["at_done"]["ADRESH"], seen["at_done"]["ADRESL"]) == (0x02, 0x9A)


def test_result_appears_exactly_at_the_end_of_the_conversion() -> None:
    sim, mcu, _ = make_board(666)
    go_at = []

    def main() -> None:
        mcu.write_name("ADCON2", 0x86)
        mcu.write_name("ADCON0", 0x01)
        mcu.write_name("ADCON0", 0x03)
        go_at.append(now(mcu))

    mcu.run(main)
    sim.run(until=1_000_000)                # 1 µs: the firmware has set GO and ended
    end = go_at[0] + FOSC64_CONVERSION_PS
    sim.run(until=end - 1)
    assert sim.now == end - 1
    assert registers(mcu)["ADCON0"] == 0x03 and mcu.read_name("ADRESL") == 0
    sim.run(until=end)
    assert registers(mcu)["ADCON0"] == 0x01
    assert (mcu.read_name("ADRESH"), mcu.read_name("ADRESL")) == (0x02, 0x9A)


@pytest.mark.parametrize("code", [0, 1, 3, 255, 256, 666, 1022, 1023])
@pytest.mark.parametrize("adfm", [1, 0])
def test_justification(code: int, adfm: int) -> None:
    _, mcu, _ = make_board(code)
    mcu.write_name("ADCON2", (adfm << 7) | 0x06)
    mcu.write_name("ADCON0", 0x01)
    mcu.write_name("ADCON0", 0x03)
    mcu.sim.run(until=10**9)
    high, low = mcu.read_name("ADRESH"), mcu.read_name("ADRESL")
    if adfm:
        assert (high, low) == (code >> 8, code & 0xFF)
        assert (high << 8) | low == code
    else:
        assert (high, low) == (code >> 2, (code & 3) << 6)
        assert ((high << 8) | low) >> 6 == code


def test_ex1_payload_bytes() -> None:
    """Ex1 sends 01 02 03 ADRESH ADRESL: right-justified 666 is 0x02, 0x9A."""
    _, mcu, _ = make_board(666)
    payload = []

    def main() -> None:
        OpenADC(*OPEN_CH0)
        ConvertADC()
        while BusyADC():
            pass
        payload.extend([1, 2, 3, mcu.read_name("ADRESH"), mcu.read_name("ADRESL")])

    run(mcu, main)
    assert bytes(payload) == bytes([0x01, 0x02, 0x03, 0x02, 0x9A])


def test_channel_select() -> None:
    _, mcu, adc = make_board(700)
    adc.inputs[5] = 300
    adc.inputs[15] = 1023
    results = []

    def convert() -> int:
        ConvertADC()
        while BusyADC():
            pass
        return ReadADC()

    def main() -> None:
        OpenADC(*OPEN_CH0)
        results.append(convert())
        SetChanADC(ADC_CH5)
        results.append(convert())
        SetChanADC(ADC_CH3)                 # nothing set on AN3
        results.append(convert())
        mcu.write_name("ADCON0", (15 << 2) | 0x01)
        results.append(convert())

    run(mcu, main)
    assert results == [700, 300, 0, 1023]


def test_input_is_sampled_when_go_is_set() -> None:
    sim, mcu, adc = make_board(666)
    sim.call_at(5_000_000, lambda: setattr(adc, "potentiometer", 100))     # mid-conversion
    results = []

    def main() -> None:
        OpenADC(*OPEN_CH0)
        for _ in range(2):
            ConvertADC()
            while BusyADC():
                pass
            results.append(ReadADC())

    run(mcu, main)
    assert results == [666, 100]


# ------------------------------------------------------------------ C18 adc.h
def test_open_adc_writes_the_registers() -> None:
    _, mcu, _ = make_board()
    seen = []

    def main() -> None:
        OpenADC(*OPEN_CH0)
        seen.append(registers(mcu))
        OpenADC(ADC_FOSC_RC & ADC_LEFT_JUST & ADC_16ANA,
                ADC_CH15 & ADC_INT_OFF & ADC_VREFPLUS_EXT & ADC_VREFMINUS_EXT)
        seen.append(registers(mcu))
        CloseADC()
        seen.append(registers(mcu))

    run(mcu, main)
    assert seen[0] == {"ADRESH": 0, "ADRESL": 0, "ADCON0": 0x01, "ADCON1": 0x0E, "ADCON2": 0x86}
    assert seen[1] == {"ADRESH": 0, "ADRESL": 0, "ADCON0": 0x3D, "ADCON1": 0x30, "ADCON2": 0x07}
    assert seen[2]["ADCON0"] == 0x3C


@pytest.mark.parametrize(("clock", "tad_ps"), [
    (ADC_FOSC_2, 2 * TOSC_PS), (ADC_FOSC_4, 4 * TOSC_PS), (ADC_FOSC_8, 8 * TOSC_PS),
    (ADC_FOSC_16, 16 * TOSC_PS), (ADC_FOSC_32, 32 * TOSC_PS), (ADC_FOSC_64, 64 * TOSC_PS),
    (ADC_FOSC_RC, 4_000_000)], ids=["Fosc/2", "Fosc/4", "Fosc/8", "Fosc/16", "Fosc/32", "Fosc/64", "RC"])
def test_c18_helpers_convert_in_11_tad(clock: int, tad_ps: int) -> None:
    _, mcu, adc = make_board(666)
    seen = {}

    def main() -> None:
        OpenADC(clock & ADC_RIGHT_JUST & ADC_1ANA, OPEN_CH0[1])
        seen["conversion"] = adc.conversion_ps()
        assert not BusyADC()
        ConvertADC()
        seen["go"] = now(mcu)
        while BusyADC():
            pass
        seen["done"] = now(mcu)
        seen["result"] = ReadADC()

    run(mcu, main)
    assert seen["conversion"] == 11 * tad_ps
    assert seen["go"] + 11 * tad_ps <= seen["done"] <= seen["go"] + 11 * tad_ps + 3_000_000
    assert seen["result"] == 666


def test_read_adc_left_justified_is_the_16_bit_pair() -> None:
    _, mcu, _ = make_board(666)
    result = []

    def main() -> None:
        OpenADC(ADC_FOSC_64 & ADC_LEFT_JUST & ADC_1ANA, OPEN_CH0[1])
        ConvertADC()
        while BusyADC():
            pass
        result.append(ReadADC())

    run(mcu, main)
    assert result == [666 << 6]


def test_firmware_busy_elsewhere_sees_the_conversion_done() -> None:
    """The firmware does not run past the end of the conversion unseen: after a 1 ms delay it is done."""
    _, mcu, _ = make_board(512)
    seen = []

    def main() -> None:
        OpenADC(*OPEN_CH0)
        ConvertADC()
        Delay10KTCYx(1)
        seen.append((BusyADC(), ReadADC()))

    run(mcu, main, until=10 * 10**9)
    assert seen == [(False, 512)]


def test_set_chan_adc_takes_c18_masks() -> None:
    _, mcu, _ = make_board()
    failures = []

    def main() -> None:
        OpenADC(*OPEN_CH0)
        for wrong in (5, -1, 256, 3.5):
            with pytest.raises(ValueError, match="ADC_CH0..ADC_CH15"):
                SetChanADC(wrong)
            failures.append(wrong)

    run(mcu, main)
    assert failures == [5, -1, 256, 3.5]


def test_open_adc_takes_bytes() -> None:
    _, mcu, _ = make_board()

    def main() -> None:
        with pytest.raises(ValueError, match="config2 is one byte"):
            OpenADC(OPEN_CH0[0], 0x100)

    run(mcu, main)


# ------------------------------------------------------------------ what does nothing, what is refused
def test_go_without_adon_does_nothing() -> None:
    sim, mcu, _ = make_board(666)
    seen = []

    def main() -> None:
        mcu.write_name("ADCON2", 0x86)
        mcu.write_name("ADCON0", 0x02)      # GO, ADON = 0
        seen.append((mcu.read_name("ADCON0"), BusyADC()))

    run(mcu, main)
    assert seen == [(0x00, False)]
    sim.run(until=sim.now + 10**9)         # 1 ms later: still no conversion has happened
    assert (mcu.read_name("ADRESH"), mcu.read_name("ADRESL")) == (0, 0)


@pytest.mark.parametrize("stop", [0x01, 0x00], ids=["clear GO", "clear ADON"])
def test_stopping_mid_conversion_aborts_it(stop: int) -> None:
    sim, mcu, _ = make_board(666)
    mcu.write_name("ADRESH", 0x55)
    mcu.write_name("ADRESL", 0xAA)
    mcu.write_name("ADCON2", 0x86)
    mcu.write_name("ADCON0", 0x03)
    sim.run(until=FOSC64_CONVERSION_PS // 2)
    mcu.write_name("ADCON0", stop)
    sim.run(until=10**9)
    assert registers(mcu)["ADCON0"] == stop
    assert (mcu.read_name("ADRESH"), mcu.read_name("ADRESL")) == (0x55, 0xAA)


@pytest.mark.parametrize("bad", [-1, 1024, 3.5, True, "512"])
def test_potentiometer_range(bad: object) -> None:
    _, _, adc = make_board(5)
    with pytest.raises(ValueError, match=r"the potentiometer on AN0 gives 0\.\.1023 \(10 bits\); got "):
        adc.potentiometer = bad
    with pytest.raises(ValueError, match="the potentiometer on AN0"):
        adc.inputs[0] = bad
    assert adc.potentiometer == 5


def test_other_inputs_range() -> None:
    _, _, adc = make_board()
    adc.potentiometer = 1023
    adc.inputs[7] = 0
    assert (adc.potentiometer, adc.inputs[7], adc.inputs[8], len(adc.inputs)) == (1023, 0, 0, 16)
    with pytest.raises(ValueError, match=r"AN7 gives 0\.\.1023 \(10 bits\); got 1024"):
        adc.inputs[7] = 1024
    with pytest.raises(IndexError, match="AN0..AN15"):
        adc.inputs[16] = 0


# ------------------------------------------------------------------ DS30491: acquisition time, ADIF; C18's OpenADC
ACQUISITION = [(0b000, 0), (0b001, 2), (0b010, 4), (0b011, 6), (0b100, 8), (0b101, 12), (0b110, 16), (0b111, 20)]


@pytest.mark.parametrize(("acqt", "tad"), ACQUISITION, ids=[f"ACQT={code:03b}" for code, _ in ACQUISITION])
def test_when_the_go_done_bit_is_set_the_a_d_module_continues_to_sample_for_the_selected_acquisition_time(acqt, tad):
    """DS30491, ADCON2.ACQT2:0: the programmed acquisition time (0 = manual: the conversion begins at once), then the
    11 TAD conversion: at Fosc/64 (TAD 1.6 us), 4 TAD give 15 TAD = 24.0 us from GO to DONE, 20 TAD 31 TAD = 49.6 us
    (the data sheet's diagrams allow up to one TAD more for the A/D clock's phase, which the kit does not model)."""
    _, mcu, _ = make_board(300)
    seen = {}

    def main() -> None:
        mcu.write_name("ADCON2", 0x86 | acqt << 3)  # ADFM, ACQT, Fosc/64
        mcu.write_name("ADCON0", 0x01)
        mcu.write_name("ADCON0", 0x03)
        seen["go"] = now(mcu)
        while mcu.read_name("ADCON0") & 0x02:
            pass
        seen["done"] = now(mcu)
        seen["result"] = (mcu.read_name("ADRESH") << 8) | mcu.read_name("ADRESL")

    run(mcu, main)
    tad_ps = 64 * TOSC_PS
    assert (tad + 11) * tad_ps <= seen["done"] - seen["go"] <= (tad + 12) * tad_ps
    assert seen["result"] == 300


def test_when_the_conversion_is_completed_the_adif_flag_is_set_whatever_adie_says() -> None:
    """DS30491: "the GO/DONE bit is cleared, the ADIF flag is set" at every conversion's end, with PIE1.ADIE = 0 (a
    polling firmware sees it in PIR1); firmware clears it; an aborted conversion does not set it."""
    _, mcu, _ = make_board(512)
    seen = []

    def main() -> None:
        OpenADC(*OPEN_CH0)
        seen.append(bool(PIR1bits.ADIF))
        ConvertADC()
        seen.append(bool(PIR1bits.ADIF))
        while BusyADC():
            pass
        seen.append(bool(PIR1bits.ADIF) and not PIE1bits.ADIE)
        PIR1bits.ADIF = 0
        ConvertADC()
        SFR.ADCON0 = SFR.ADCON0 & ~0x02             # abort it
        Delay10KTCYx(1)
        seen.append(bool(PIR1bits.ADIF))

    run(mcu, main, until=10 * 10**9)
    assert seen == [False, False, True, False]


def test_c18_open_adc_for_the_pic18f8680_takes_config_config2_and_portconfig_with_the_adc_n_tad_masks() -> None:
    """C18's adc.h for parts with ADCON2.ACQT: OpenADC(config, config2, portconfig). config: clock, justification and
    acquisition time (ADC_n_TAD); config2: channel, interrupt, references; portconfig: ADC_nANA (PCFG3:0)."""
    _, mcu, _ = make_board()
    seen = {}

    def main() -> None:
        OpenADC(ADC_FOSC_32 & ADC_RIGHT_JUST & ADC_12_TAD, ADC_CH5 & ADC_INT_OFF & ADC_VREFPLUS_EXT
                & ADC_VREFMINUS_VSS, ADC_6ANA)
        seen["three"] = registers(mcu)
        OpenADC(ADC_FOSC_RC & ADC_LEFT_JUST & ADC_0_TAD, ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD
                & ADC_VREFMINUS_VSS, ADC_1ANA)
        seen["manual"] = registers(mcu)
        OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_1ANA, OPEN_CH0[1])   # the two-argument form, as before
        seen["two"] = registers(mcu)

    run(mcu, main)
    assert seen["three"] == {"ADRESH": 0, "ADRESL": 0, "ADCON0": 0x15, "ADCON1": 0x19, "ADCON2": 0xAA}
    assert seen["manual"] == {"ADRESH": 0, "ADRESL": 0, "ADCON0": 0x01, "ADCON1": 0x0E, "ADCON2": 0x07}
    assert seen["two"] == {"ADRESH": 0, "ADRESL": 0, "ADCON0": 0x01, "ADCON1": 0x0E, "ADCON2": 0x86}


def test_adc_int_on_clears_adif_and_sets_adie_and_peie_so_the_end_of_a_conversion_interrupts() -> None:
    from appsim.chip.sfr import HIGH_VECTOR

    _, mcu, _ = make_board(777)
    results: list[int] = []

    def high_isr() -> None:
        PIR1bits.ADIF = 0
        results.append(ReadADC())

    def main() -> None:
        PIR1bits.ADIF = 1
        OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_4_TAD, ADC_CH0 & ADC_INT_ON & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS,
                ADC_1ANA)
        results.append(SFR.PIE1 & 0x40 | SFR.INTCON & 0x40 | SFR.PIR1 & 0x40)      # ADIE, PEIE, ADIF
        INTCONbits.GIE = 1
        ConvertADC()
        Delay10KTCYx(1)

    mcu.run(main, {HIGH_VECTOR: high_isr})
    mcu.sim.run(until=10 * 10**9)
    assert mcu.process is not None and mcu.process.failure is None, mcu.process.failure_text
    assert results == [0x40, 777]
