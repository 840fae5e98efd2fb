"""The PIC18F8680 is built whole by the chip: every node on a bus, board or not, has all its peripherals."""
from __future__ import annotations

from appsim.bus.wire import Bus
from appsim.chip.mcu import PIC18F8680
from appsim.chip.sfr import ADDRESSES
from appsim.firmware import *
from appsim.sim import Simulator
from appsim.workshop.classroom import Classroom

MS = 10**9


def test_a_bare_chip_maps_every_register_of_the_data_sheet_extract() -> None:
    mcu = PIC18F8680(Simulator(), "bare")
    assert set(mcu.sfr_addresses) == set(ADDRESSES), "ECAN, A/D, Timer1, EUSART, PIR1/PIE1/IPR1 and PORTJ"
    assert mcu.read_name("IPR1") == 0xFF and mcu.read_name("TRISJ") == 0xFF, "the data sheet's reset values"


def test_firmware_on_a_chip_without_a_board_uses_the_adc_timer1_and_usart() -> None:
    """The classroom's monitor node and the checks' test nodes are chips alone: their peripherals work, the USART's
    pins lead nowhere (its bytes are sent, to no one), PORTJ's undriven pins read 0."""
    sim = Simulator()
    mcu = Bus(sim).attach(PIC18F8680(sim, "alone"))
    mcu.adc.inputs[0] = 700
    seen: dict[str, int] = {}

    def main() -> None:
        OpenADC(ADC_FOSC_64 & ADC_RIGHT_JUST & ADC_1ANA, ADC_CH0 & ADC_INT_OFF & ADC_VREFPLUS_VDD & ADC_VREFMINUS_VSS)
        ConvertADC()
        while BusyADC():
            pass
        seen["adc"] = ReadADC()
        OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
        OpenUSART(USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT & USART_CONT_RX
                  & USART_BRGH_HIGH, 129)
        putcUSART(0x55)
        while BusyUSART():
            pass
        seen["tmr1"] = ReadTimer1()
        seen["portj"] = SFR.PORTJ
        while True:
            Delay10KTCYx(1)

    mcu.run(main)
    sim.run(until=20 * MS)
    assert mcu.process is not None and mcu.process.failure is None, mcu.process.failure_text
    assert seen["adc"] == 700
    assert seen["tmr1"] > 0, "Timer1 counts on a chip with no board"
    assert seen["portj"] == 0


def test_the_classrooms_monitor_node_is_a_whole_chip() -> None:
    room = Classroom(Bus(Simulator(), 125_000), 2)
    assert room.monitor is not None
    assert set(room.monitor.sfr_addresses) == set(ADDRESSES)
