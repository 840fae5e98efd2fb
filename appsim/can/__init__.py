"""CAN as ISO 11898-1 defines it, independent of any chip: frames, their bits on the wire, bit timing, VCD, SLCAN.

May import only the standard library and python-can's types; nothing else of appsim.
"""
