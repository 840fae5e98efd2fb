"""The PIC18F8680 as the data sheet describes it: core timing, the SFR bus, ECAN, A/D, Timer1, EUSART, PIR1.

May import appsim.sim, appsim.errors, appsim.can and the bus's Controller interface; knows no board, no firmware
library, no workshop.
"""
