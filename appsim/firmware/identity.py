"""What a firmware calls itself: its MESSAGE_ID1 and RTR_ID, read as integers the same way in a student's own process
(`appsim check`) and in the grader's sandbox, which sends them across as JSON: one reading, one station.
"""
from __future__ import annotations

import operator
from types import ModuleType

NAMES = ("MESSAGE_ID1", "RTR_ID")
LIMIT = 1 << 64             # beyond 64 bits a value is no identifier of anything: it is kept as +-LIMIT


def identity_of(module: ModuleType) -> dict[str, int]:
    """The module's MESSAGE_ID1 and RTR_ID, where each acts as an integer: an int, an IntEnum member, anything with
    __index__ (never a bool, a float or a string, which are no identifier); beyond 64 bits, +-LIMIT."""
    found = {}
    for name in NAMES:
        value = getattr(module, name, None)
        if value is None or isinstance(value, bool):
            continue
        try:
            number = operator.index(value)
        except Exception:       # not an integer (its __index__ may raise anything): as if it named none
            continue
        found[name] = max(-LIMIT, min(number, LIMIT))
    return found


def shown(value: int) -> str:
    """An identifier as a message shows it: 0x130, -5, or what is beyond 64 bits."""
    if abs(value) >= LIMIT:
        return "a number of 64 bits or more"
    return f"0x{value:03X}" if value >= 0 else str(value)
