"""A CAN 2.0A/2.0B data or remote frame as the application sees it.

The logical content only (identifier, format, RTR, DLC, data); how it looks on the wire is `appsim.can.bits`.
"""
from __future__ import annotations

from dataclasses import dataclass

from appsim.errors import FrameError

STANDARD_ID_MAX = 0x7FF
EXTENDED_ID_MAX = 0x1FFF_FFFF


@dataclass(frozen=True, slots=True)
class CanFrame:
    """One CAN frame: 11-bit (standard, 2.0A) or 29-bit (extended, 2.0B) identifier.

    `dlc` is the 4-bit Data Length Code sent on the wire. For a data frame it defaults to
    `len(data)`; DLC 9..15 is legal on the wire and still means 8 data bytes. For a remote
    frame (RTR) there is no data field and `dlc` is the length being requested.
    """

    can_id: int
    data: bytes = b""
    extended: bool = False
    remote: bool = False
    dlc: int = -1

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", bytes(self.data))
        limit = EXTENDED_ID_MAX if self.extended else STANDARD_ID_MAX
        kind = "an extended (29-bit)" if self.extended else "a standard (11-bit)"
        if not 0 <= self.can_id <= limit:
            hint = "" if self.extended else "; use extended=True for a 29-bit identifier"
            raise FrameError(
                f"identifier 0x{self.can_id:X} does not fit {kind} frame (0..0x{limit:X}){hint}"
            )
        if self.remote and self.data:
            raise FrameError("a remote frame (RTR) carries no data; give only dlc=<requested length>")
        if len(self.data) > 8:
            raise FrameError(f"a CAN frame carries at most 8 data bytes, got {len(self.data)}")
        if self.dlc == -1:
            object.__setattr__(self, "dlc", len(self.data))
        if not 0 <= self.dlc <= 15:
            raise FrameError(f"DLC is a 4-bit field (0..15), got {self.dlc}")
        if not self.remote and len(self.data) != min(self.dlc, 8):
            raise FrameError(
                f"DLC {self.dlc} means {min(self.dlc, 8)} data bytes but {len(self.data)} were given"
            )

    @property
    def base_id(self) -> int:
        """The 11 identifier bits sent first on the wire (SID10..0, or EID28..18 when extended)."""
        return self.can_id >> 18 if self.extended else self.can_id

    def __str__(self) -> str:
        ident = f"{self.can_id:08X}" if self.extended else f"{self.can_id:03X}"
        if self.remote:
            return f"{ident} [{self.dlc}] remote request"
        return f"{ident} [{self.dlc}] {self.data.hex(' ').upper()}".rstrip()
