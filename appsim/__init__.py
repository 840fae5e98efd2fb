"""appsim: Microchip's APP023 CAN training board (PIC18F8680 ECAN, AN738), simulated at register level on a CAN bus.

Layers, each importing only those below it: workshop > board > firmware > chip > bus > can > sim, errors, watchdog.
"""
