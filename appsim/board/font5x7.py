"""A 5x7 dot-matrix font for ASCII 0x20..0x7E, the classic HD44780/KS0108 glyph shapes, and a box for the rest.

Each glyph is 5 column bytes, left to right; bit 0 is the top row, bit 6 the bottom one (KS0108 page order).
"""
from __future__ import annotations

WIDTH, HEIGHT = 5, 7
FIRST, LAST = 0x20, 0x7E
BOX = (0x7F, 0x41, 0x41, 0x41, 0x7F)        # what a character outside 0x20..0x7E shows

_GLYPHS = bytes.fromhex(
    "0000000000 00005f0000 0007000700 147f147f14 242a7f2a12 2313086462 3649552250 0005030000"  # sp ! " # $ % & '
    "001c224100 0041221c00 142a1c2a14 08083e0808 0050300000 0808080808 0060600000 2010080402"  # ( ) * + , - . /
    "3e5149453e 00427f4000 4261514946 2141454b31 1814127f10 2745454539 3c4a494930 0171090503"  # 0 .. 7
    "3649494936 064949291e 0036360000 0056360000 0814224100 1414141414 0041221408 0201510906"  # 8 9 : ; < = > ?
    "324979413e 7e1111117e 7f49494936 3e41414122 7f4141221c 7f49494941 7f09090901 3e41415132"  # @ A .. G
    "7f0808087f 00417f4100 2040413f01 7f08142241 7f40404040 7f020c027f 7f0408107f 3e4141413e"  # H .. O
    "7f09090906 3e4151215e 7f09192946 4649494931 01017f0101 3f4040403f 1f2040201f 3f4038403f"  # P .. W
    "6314081463 0708700807 6151494543 007f414100 0204081020 0041417f00 0402010204 4040404040"  # X Y Z [ \\ ] ^ _
    "0001020400 2054545478 7f48444438 3844444420 384444487f 3854545418 087e090102 0c5252523e"  # ` a .. g
    "7f08040478 00447d4000 2040443d00 7f10284400 00417f4000 7c04180478 7c08040478 3844444438"  # h .. o
    "7c14141408 081414187c 7c08040408 4854545420 043f444020 3c4040207c 1c2040201c 3c4030403c"  # p .. w
    "4428102844 0c5050503c 4464544c44 0008364100 00007f0000 0041360800 0804081008"             # x .. ~
)


def glyph(code: int) -> tuple[int, ...]:
    """The 5 column bytes of character `code` (0..255); codes outside 0x20..0x7E give a box."""
    if FIRST <= code <= LAST:
        offset = (code - FIRST) * WIDTH
        return tuple(_GLYPHS[offset:offset + WIDTH])
    return BOX


def shows_as(code: int) -> str:
    """The character a text view shows for `code`: itself if printable ASCII, else a white square (the box)."""
    return chr(code) if FIRST <= code <= LAST else "\u25a1"
