"""The APP023 training board around a chip: the GLCD, DSW2 and PORTJ, the potentiometer, the PIC18F2550 USB bridge.

May import appsim.sim, appsim.can, appsim.bus and appsim.chip.
"""
