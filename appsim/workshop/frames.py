"""The workshop's frames as a CAN database: the master's 0x088 with its A/D value, the answers to the RTRs 0x081..0x086,
and each station's 0x100..0x150, built with cantools and shipped as workshop.dbc for the kit and any DBC tool.

`python -m appsim.workshop.frames` writes the shipped file again from this definition (a test checks they agree).
"""
from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from appsim.workshop.course import MASTER_ID, RTR_IDS, STATION_IDS, STATIONS

if TYPE_CHECKING:
    from cantools.database.can import Database, Signal

VERSION = "CAN Workshop 202"
MASTER, MONITOR = "MASTER", "MONITOR"
STATION_NODES = tuple(f"STATION{k}" for k in range(1, STATIONS + 1))
DATA = "01 02 03 ADRESH ADRESL, as every workshop frame carries (TxData[5] in the firmware)"
AD = ("ADRESH:ADRESL, the 10-bit A/D result of the potentiometer on AN0, right-justified (ADRESH holds its top two "
      "bits): 0..1023 for 0..5 V (Vin = ADRES x 5 V / 1023)")


def _file() -> Path:
    root = Path(__file__).resolve().parents[2]
    if (root / "pyproject.toml").is_file():
        return Path(__file__).with_name("workshop.dbc")
    return Path(str(resources.files("appsim.workshop") / "workshop.dbc"))


WORKSHOP_DBC = _file()          # the shipped file (package data)


def _payload(receivers: list[str]) -> list[Signal]:
    from cantools.database.can import Signal

    constants = [Signal(f"TxData{n}", 8 * n, 8, comment=f"TxData[{n}], the constant 0x0{n + 1}",
                        receivers=receivers, minimum=0, maximum=255) for n in range(3)]
    # Big-endian (Motorola): the MSB is bit 1 of byte 3 (ADRESH<1>), the LSB bit 0 of byte 4 (ADRESL<0>).
    adres = Signal("ADRES", 3 * 8 + 1, 10, byte_order="big_endian", comment=AD, unit="counts", minimum=0,
                   maximum=1023, receivers=receivers)
    return [*constants, adres]


def database() -> Database:
    """The workshop's frames as a cantools database."""
    from cantools.database.can import Database, Message, Node

    nodes = [Node(MASTER, "the master console: 0x088 every 100 ms, answers RTR 0x081..0x086, polls 0x100..0x150"),
             *(Node(name, f"student station {k}: MESSAGE_ID1 0x{STATION_IDS[k - 1]:03X}, RTR_ID "
                          f"0x{RTR_IDS[k - 1]:03X}") for k, name in enumerate(STATION_NODES, start=1)),
             Node(MONITOR, "the PC's CAN monitor (CANKing): it ACKs and lists every frame")]
    messages = [Message(MASTER_ID, "MASTER_BROADCAST", 5, _payload([*STATION_NODES, MONITOR]), senders=[MASTER],
                        cycle_time=100, comment=f"The master console's broadcast every 100 ms: {DATA}. Ex3's filters "
                                                "let it in; Ex4 waits for it before it leaves Listen-only mode.")]
    for k, (rtr_id, station) in enumerate(zip(RTR_IDS, STATION_NODES, strict=True), start=1):
        messages.append(Message(rtr_id, f"MASTER_ANSWER{k}", 5, _payload([station, MONITOR]), senders=[MASTER],
                                comment=f"Ex5: station {k} asks with a remote frame (RTR, DLC 0) of identifier "
                                        f"0x{rtr_id:03X}; the master answers with this data frame: {DATA}."))
    for k, (station_id, station) in enumerate(zip(STATION_IDS, STATION_NODES, strict=True), start=1):
        messages.append(Message(station_id, station, 5, _payload([MASTER, MONITOR]), senders=[station],
                                comment=f"Station {k}'s frame (MESSAGE_ID1): {DATA}. Ex2..Ex4 send it every Timer1 "
                                        "overflow (52.4288 ms); in Ex6 the master polls it with a remote frame (RTR) "
                                        "and the station answers with it."))
    return Database(messages=messages, nodes=nodes, version=VERSION)


def as_dbc() -> str:
    """The database as DBC text, as cantools writes it."""
    return database().as_dbc_string()


def main(argv: list[str] | None = None) -> int:
    """Write workshop.dbc again (to the path given, else over the shipped file)."""
    target = Path((argv or sys.argv[1:] or [str(WORKSHOP_DBC)])[0])
    target.write_bytes(as_dbc().encode("utf-8"))      # as cantools writes it, CR LF line ends (as Vector's tools)
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
