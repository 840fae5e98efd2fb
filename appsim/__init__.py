"""appsim: Microchip's APP023 CAN training board (PIC18F8680 ECAN, AN738), simulated at register level on a CAN bus.

Layers, each importing only those below it (an import-linter contract in pyproject.toml): cli > session > workshop >
board > firmware > chip > bus > can > sim, errors, watchdog, schedstat, provenance.
"""

__version__ = "0.1.0"            # the one home of the kit's version (pyproject.toml reads it)
