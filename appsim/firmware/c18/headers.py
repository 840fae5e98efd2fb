"""The kit's C18 headers (package data in include/): where they are, and p18f8680.h written from the kit's register map.

`python -m appsim.firmware.c18.headers` rewrites include/p18f8680.h from appsim.chip.sfr (a test keeps them equal).
"""
from __future__ import annotations

import sys
from pathlib import Path

from appsim.chip.sfr import ADDRESSES, BITFIELDS

INCLUDE = Path(__file__).resolve().parent / "include"   # package data, installed as files (importlib.resources
#                                                         costs a sandbox 3 ms to import, and the kit is never zipped)
DEVICE_HEADER = "p18f8680.h"
HEADERS = ("p18f8680.h", "CAN18XX8.h", "adc.h", "timers.h", "usart.h", "delays.h", "stdio.h", "string.h",
           "stdlib.h", "APP023_GLCD.h")


def header_text(name: str) -> str:
    """The text of one of the kit's headers, by its name as #include gives it (any case: C18 runs on Windows)."""
    for known in HEADERS:
        if known.lower() == name.lower():
            return (INCLUDE / known).read_text(encoding="utf-8")
    raise KeyError(name)


def canonical(name: str) -> str | None:
    """The kit header an #include names (ignoring case, as the workshop's Windows file system did), or None."""
    return next((known for known in HEADERS if known.lower() == name.lower()), None)


def _layouts(fields: dict[str, tuple[int, int]]) -> list[list[tuple[str, int, int]]]:
    """The register's fields as structs of non-overlapping fields, each lowest bit first (C18's layout)."""
    layouts: list[list[tuple[str, int, int]]] = []
    for name, (shift, width) in sorted(fields.items(), key=lambda item: (-item[1][1], item[1][0])):
        bits = set(range(shift, shift + width))
        for layout in layouts:
            if not any(bits & set(range(s, s + w)) for _, s, w in layout):
                layout.append((name, shift, width))
                break
        else:
            layouts.append([(name, shift, width)])
    return [sorted(layout, key=lambda field: field[1]) for layout in layouts]


def device_header() -> str:
    """p18f8680.h: every SFR the kit models, at its address, and a `NAMEbits` union for each with bit fields."""
    lines = [
        "/* p18f8680.h: the PIC18F8680's special function registers, as the kit models them (CAN Workshop 202).",
        " * Written by the kit from its register map (appsim.chip.sfr), in the style of MPLAB C18's device header:",
        " * each register an `extern volatile near unsigned char` (the linker places it at the address shown), and for",
        " * each register with named bits a `NAMEbits` union of structs, lowest bit first. */",
        "#ifndef __18F8680_H",
        "#define __18F8680_H",
        "",
    ]
    for name, address in sorted(ADDRESSES.items(), key=lambda item: item[1]):
        lines.append(f"extern volatile near unsigned char {name};{' ' * (12 - len(name))}/* 0x{address:03X} */")
        fields = BITFIELDS.get(name)
        if not fields:
            continue
        lines.append("extern volatile near union {")
        for layout in _layouts(fields):
            lines.append("  struct {")
            bit = 0
            for field, shift, width in layout:
                if shift > bit:
                    lines.append(f"    unsigned :{shift - bit};")
                lines.append(f"    unsigned {field}:{width};")
                bit = shift + width
            lines.append("  };")
        lines.append(f"}} {name}bits;")
    lines += [
        "",
        "/* The instructions C18 offers as functions: one cycle each (ClrWdt: the watchdog timer is not simulated). */",
        "void Nop(void);",
        "void ClrWdt(void);",
        "void Reset(void);",
        "",
        "#endif",
        "",
    ]
    return "\n".join(lines)


def _write() -> None:
    path = INCLUDE / DEVICE_HEADER
    path.write_text(device_header(), encoding="utf-8")
    print(f"wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    _write()
