"""The PIC18F8680's ECAN in legacy Mode 0: its registers as the data sheet lists them (`registers`), what the silicon
does on each event (`controller`), and the acceptance masks and filters (`acceptance`).
"""
