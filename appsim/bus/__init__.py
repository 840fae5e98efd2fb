"""The bus: the simulated wire (arbitration, ACK, errors), links to python-can buses, wall-clock pacing, the monitor.

May import appsim.sim and appsim.can; it talks to controllers through a small interface and imports no chip.
"""
