"""The APP023's 128x64 graphic LCD as the workshop uses it: 8 lines of 21 characters, driven by APP023_GLCD.C's API.

Not register level: the C driver bit-bangs ports; here each driver operation costs the instruction cycles it would take.
"""
from __future__ import annotations

import io
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple, overload

from appsim.board import font5x7
from appsim.chip.mcu import PIC18F8680
from appsim.errors import NotInitialised

if TYPE_CHECKING:
    import numpy as np
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure, SubFigure

LINES, COLUMNS = 8, 21                      # text lines of 6x8 cells on 128x64 pixels
WIDTH_PX, HEIGHT_PX = 128, 64
CELL_WIDTH, CELL_HEIGHT = 6, 8              # 5x7 glyph, one blank column and one blank row
# Instruction cycles, from how a KS0108-style driver bit-bangs the controller: one display byte (a
# column of 8 pixels, or a command) is a data-port write, RS/RW set-up, an enable pulse >= 450 ns
# and a busy-flag check, about 25 Tcy at 10 MIPS.
BYTE_CYCLES = 25
CHARACTER_CYCLES = 6 * BYTE_CYCLES          # 5 glyph columns + 1 blank column: 150 Tcy = 15 µs
CURSOR_CYCLES = 2 * BYTE_CYCLES             # set page (line) and column address
INITIAL_CYCLES = 10 * BYTE_CYCLES + WIDTH_PX * LINES * BYTE_CYCLES   # set-up commands, then clear 1024 bytes
HISTORY_WRITES = 10_000                     # the writes `history` keeps, the latest (a long run's would fill memory)
GLASS_MARGIN_PX = 4                         # lit glass around the dot matrix, in pixels: text never touches its edge


class Write(NamedTuple):
    """One thing the firmware wrote: when (ps, when it finished), where (line, column from 1) and what."""

    time_ps: int
    line: int
    column: int
    text: str


class GLCD:
    """The screen of one APP023, as text cells; what the firmware's GLCD calls change and when.

    Before `GLCD_Initial()` the screen is off and blank. Text is written at the cursor, which advances
    one cell per character; characters that would fall past column 21 are cut off (the line does not
    wrap). Characters outside printable ASCII (0x20..0x7E) show as a box (a hollow 5x7 rectangle; "□"
    in the text views). Strings stop at a NUL, as C strings do.
    """

    def __init__(self, mcu: PIC18F8680):
        self.mcu = mcu
        self.initialised = False
        self.backlight = False
        self._codes = [[0x20] * COLUMNS for _ in range(LINES)]
        self._line = 0
        self._column = 0
        self.history: deque[Write] = deque(maxlen=HISTORY_WRITES)

    # -------------------------------------------------------------- what the firmware's GLCD library does
    def initial(self) -> None:
        """GLCD_Initial: set-up commands, then clear the screen; cursor to line 1 column 1, backlight on."""
        self.mcu.spend_cycles(INITIAL_CYCLES)
        self._codes = [[0x20] * COLUMNS for _ in range(LINES)]
        self._line = self._column = 0
        self.initialised = True
        self.backlight = True

    def set_cursor(self, line: int, column: int) -> None:
        """setcurGLCD: the page (line 1..8) and column (1..21) address."""
        if not (1 <= line <= LINES and 1 <= column <= COLUMNS):
            raise ValueError(f"setcurGLCD({line!r}, {column!r}): lines are numbered 1..{LINES} and columns "
                             f"1..{COLUMNS} on the APP023's {LINES}x{COLUMNS} screen")
        self._initialised()
        self.mcu.spend_cycles(CURSOR_CYCLES)
        self._line, self._column = line - 1, column - 1

    def write(self, codes: Sequence[int], *, length: int | None = None) -> None:
        """Draw character `codes` at the cursor and advance, taking the driver's time; past column 21 is cut off.
        `length`: how many the firmware wrote, of which `codes` are the first (all that can show: the grader's
        sandbox sends no more)."""
        self._initialised()
        line, column = self._line, self._column
        drawn = list(codes[:max(0, COLUMNS - column)])
        self._codes[line][column:column + len(drawn)] = drawn
        self._column += len(codes) if length is None else length
        self.mcu.spend_cycles(len(drawn) * CHARACTER_CYCLES)
        text = "".join(font5x7.shows_as(code) for code in drawn)
        self.history.append(Write(self.mcu.sim.time(), line + 1, column + 1, text))

    def _initialised(self) -> None:
        if not self.initialised:
            raise NotInitialised("the GLCD is not set up yet: call GLCD_Initial() first, as EX1.C does")

    # -------------------------------------------------------------- what a person sees
    @property
    def lines(self) -> list[str]:
        """The 8 text lines, 21 characters each (blank before GLCD_Initial)."""
        return ["".join(font5x7.shows_as(code) for code in codes) for codes in self._codes]

    def line(self, n: int) -> str:
        """Text line `n` (1..8, as the workshop numbers them), without trailing blanks."""
        if not isinstance(n, int) or not 1 <= n <= LINES:
            raise IndexError(f"the APP023's screen has lines 1..{LINES}; got {n!r}")
        return self.lines[n - 1].rstrip()

    def text(self) -> str:
        """The whole screen as 8 lines of text."""
        return "\n".join(self.lines)

    def __str__(self) -> str:
        state = "" if self.initialised else " (off: GLCD_Initial() not called)"
        return "\n".join([f"┌{'─' * COLUMNS}┐{state}", *(f"│{text}│" for text in self.lines), f"└{'─' * COLUMNS}┘"])

    def pixels(self) -> np.ndarray:
        """The 64 x 128 pixels (True = dark), drawn with the 5x7 font in 6x8 cells."""
        import numpy as np

        screen = np.zeros((HEIGHT_PX, WIDTH_PX), dtype=bool)
        rows = np.arange(font5x7.HEIGHT)
        for line, codes in enumerate(self._codes):
            for column, code in enumerate(codes):
                x, y = column * CELL_WIDTH, line * CELL_HEIGHT
                for dx, bits in enumerate(font5x7.glyph(code)):
                    screen[y:y + font5x7.HEIGHT, x + dx] = (bits >> rows) & 1
        return screen

    def colours(self, margin: int = 0) -> np.ndarray:
        """The 64 x 128 pixels as RGB bytes: dark ink on the yellow-green backlight, grey-green when it is off; with
        `margin` pixels of the lit glass around them."""
        import numpy as np

        on = self.initialised and self.backlight
        background, ink = ("#b5d334", "#1d2a10") if on else ("#8e9a86", "#3c4436")
        pixels = np.pad(self.pixels(), margin, constant_values=False)
        return np.where(pixels[..., None], _rgb(ink), _rgb(background)).astype(np.uint8)

    def png(self, *, scale: int = 3) -> bytes:
        """The screen alone (its glass, the dot matrix inside it) as a PNG, each pixel `scale` x `scale` (quick to
        make: for a picture that changes often)."""
        from PIL import Image

        buffer = io.BytesIO()
        image = Image.fromarray(self.colours(GLASS_MARGIN_PX), "RGB")
        image.resize((image.width * scale, image.height * scale), Image.Resampling.NEAREST).save(buffer, format="png")
        return buffer.getvalue()

    @overload
    def picture(self, ax: None = None, *, scale: float = 4.0) -> Figure: ...
    @overload
    def picture(self, ax: Axes, *, scale: float = 4.0) -> Figure | SubFigure: ...

    def picture(self, ax: Axes | None = None, *, scale: float = 4.0) -> Figure | SubFigure:
        """Draw the module as it looks: dark pixels on the yellow-green backlight (grey-green when off). Returns the
        figure drawn on: a new one, or `ax`'s."""
        import matplotlib.pyplot as plt
        from matplotlib.patches import FancyBboxPatch

        figure: Figure | SubFigure
        if ax is None:
            side = 2 * (GLASS_MARGIN_PX + 9) * scale / 100
            figure = plt.figure(figsize=(WIDTH_PX * scale / 100 + side, HEIGHT_PX * scale / 100 + side), dpi=100)
            ax = figure.add_axes((0, 0, 1, 1))
        else:
            figure = ax.figure
        glass, margin = GLASS_MARGIN_PX, GLASS_MARGIN_PX + 6          # the glass inside a 6-pixel bezel
        ax.add_patch(FancyBboxPatch((-margin, -margin), WIDTH_PX + 2 * margin, HEIGHT_PX + 2 * margin,
                                    boxstyle="round,pad=2", facecolor="#202020", edgecolor="#505050", linewidth=2))
        ax.imshow(self.colours(glass), extent=(-glass, WIDTH_PX + glass, HEIGHT_PX + glass, -glass),
                  interpolation="nearest", zorder=2)
        ax.set_xlim(-margin - 3, WIDTH_PX + margin + 3)
        ax.set_ylim(HEIGHT_PX + margin + 3, -margin - 3)
        ax.set_aspect("equal")
        ax.axis("off")
        return figure

    def save_png(self, path: str | Path, *, scale: float = 4.0) -> Path:
        """Save `picture()` as a PNG file."""
        import matplotlib.pyplot as plt

        figure = self.picture(scale=scale)
        figure.savefig(path)
        plt.close(figure)
        return Path(path)


def _rgb(colour: str) -> tuple[int, int, int]:
    return tuple(int(colour[i:i + 2], 16) for i in (1, 3, 5))    # type: ignore[return-value]


def attach_glcd(mcu: PIC18F8680) -> GLCD:
    """Wire a GLCD to `mcu` (on the APP023 its ports drive the module)."""
    if mcu.glcd is not None:
        raise ValueError(f"{mcu.name} already has its GLCD")
    screen = mcu.glcd = GLCD(mcu)
    return screen
