"""The APP023 GLCD: the workshop's 8x21 text screen, what firmware calls show, the pixels and the picture."""
from __future__ import annotations

from collections.abc import Callable

import matplotlib.image
import numpy as np
import pytest

from appsim.board.app023 import APP023
from appsim.board.glcd import CHARACTER_CYCLES, GLASS_MARGIN_PX, NotInitialised
from appsim.firmware import GLCD_Initial, putcGLCD, putrsGLCD, putsGLCD, setcurGLCD

TCY_PS = 100_000


def show(world, main: Callable[[], None], seconds: float = 0.05) -> APP023:
    board = APP023(world.bus, "station0")
    board.run(main)
    world.run(seconds)
    return board


def crash(world, main: Callable[[], None]) -> BaseException:
    board = APP023(world.bus, "station0")
    board.run(main)
    world.sim.run(until=world.sim.now + 10**10)         # 10 ms: GLCD_Initial() alone takes 2.6 ms
    assert board.mcu.process.failure is not None, "the firmware should have stopped with an error"
    return board.mcu.process.failure


def test_screen_is_blank_and_off_until_glcd_initial(world):
    board = APP023(world.bus, "station0")
    assert board.glcd.lines == [" " * 21] * 8
    assert not board.glcd.pixels().any()
    assert "GLCD_Initial() not called" in str(board.glcd)


def test_writing_before_glcd_initial_is_a_clear_error(world):
    failure = crash(world, lambda: putrsGLCD("CAN Workshop"))
    assert isinstance(failure, NotInitialised)
    assert "call GLCD_Initial() first, as EX1.C does" in str(failure)


def test_the_workshop_layout_shows_on_lines_1_to_4(world):
    def main() -> None:
        GLCD_Initial()
        putrsGLCD("CAN Workshop 202")
        setcurGLCD(2, 1)
        putsGLCD("TX ID: 0x100")
        setcurGLCD(3, 1)
        putsGLCD(b"A/D: 666")
        setcurGLCD(4, 1)
        putsGLCD([ord(c) for c in "RX ID: 0x088"] + [0])

    glcd = show(world, main).glcd
    assert [glcd.line(n) for n in range(1, 5)] == ["CAN Workshop 202", "TX ID: 0x100", "A/D: 666", "RX ID: 0x088"]
    assert len(glcd.lines) == 8 and {len(line) for line in glcd.lines} == {21}
    assert glcd.text().splitlines()[1] == "TX ID: 0x100".ljust(21)
    frame = str(glcd).splitlines()
    assert frame[0] == "┌" + "─" * 21 + "┐" and frame[2] == "│" + "TX ID: 0x100".ljust(21) + "│" and len(frame) == 10


def test_text_past_column_21_is_cut_off_not_wrapped(world):
    def main() -> None:
        GLCD_Initial()
        setcurGLCD(1, 18)
        putsGLCD("ABCDEFG")
        putcGLCD("H")

    glcd = show(world, main).glcd
    assert glcd.lines[0] == " " * 17 + "ABCD"
    assert glcd.line(2) == ""


def test_strings_stop_at_nul_as_in_c(world):
    def main() -> None:
        GLCD_Initial()
        putsGLCD(b"AB\0CD")
        putsGLCD([72, 105, 0, 33])
        putrsGLCD("!\0?")

    assert show(world, main).glcd.line(1) == "ABHi!"


def test_characters_advance_the_cursor_and_non_printable_ones_show_a_box(world):
    def main() -> None:
        GLCD_Initial()
        setcurGLCD(5, 3)
        putcGLCD(0x41)
        putcGLCD("b")
        putcGLCD(0x07)
        putsGLCD("\x7f")

    glcd = show(world, main).glcd
    assert glcd.line(5) == "  Ab\u25a1\u25a1"
    box = glcd.pixels()[32:40, 4 * 6:4 * 6 + 6]
    assert box[:7, :5].sum() == 5 + 5 + 5 * 2, "a hollow 5x7 rectangle"
    assert not box[7].any() and not box[:, 5].any()


def test_pixels_draw_the_5x7_font_in_6x8_cells(world):
    def main() -> None:
        GLCD_Initial()
        setcurGLCD(2, 2)
        putcGLCD("H")

    pixels = show(world, main).glcd.pixels()
    assert pixels.shape == (64, 128) and pixels.dtype == np.bool_
    cell = pixels[8:16, 6:12]
    expected_h = ["#...#", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"]
    assert ["".join("#" if dot else "." for dot in row[:5]) for row in cell[:7]] == expected_h
    assert not cell[7].any() and not cell[:, 5].any()
    assert pixels.sum() == cell.sum()


@pytest.mark.parametrize(("line", "column"), [(0, 0), (9, 1), (1, 22), (1, 0), ("1", 1)])
def test_cursor_out_of_range_says_how_the_screen_is_numbered(world, line, column):
    def main() -> None:
        GLCD_Initial()
        setcurGLCD(line, column)

    failure = crash(world, main)
    assert f"setcurGLCD({line!r}, {column!r}): lines are numbered 1..8 and columns 1..21" in str(failure)


@pytest.mark.parametrize(("call", "message"), [
    (lambda: putsGLCD(12), "takes a string"),
    (lambda: putsGLCD("20 \u20ac"), "one byte per character"),
    (lambda: putcGLCD("ab"), "one character"),
    (lambda: putcGLCD(256), "one character"),
])
def test_bad_text_is_a_clear_error(world, call, message):
    def main() -> None:
        GLCD_Initial()
        call()

    assert message in str(crash(world, main))


def test_history_says_what_was_written_where_and_when_and_writing_takes_time(world):
    def main() -> None:
        GLCD_Initial()
        putsGLCD("x" * 21)
        setcurGLCD(3, 5)
        putsGLCD("666")

    history = show(world, main).glcd.history
    assert [(w.line, w.column, w.text) for w in history] == [(1, 1, "x" * 21), (3, 5, "666")]
    assert history[1].time_ps - history[0].time_ps >= 3 * CHARACTER_CYCLES * TCY_PS
    assert history[0].time_ps >= 21 * CHARACTER_CYCLES * TCY_PS


def test_firmware_on_a_bare_mcu_has_no_glcd(world):
    mcu = world.node("bare", GLCD_Initial)
    world.sim.run(until=10**9)
    assert "has no GLCD" in str(mcu.process.failure)


def test_picture_is_yellow_green_with_dark_pixels_when_on_and_grey_when_off(world, tmp_path):
    board = APP023(world.bus, "station0")
    off = matplotlib.image.imread(board.glcd.save_png(tmp_path / "off.png"))
    board.run(lambda: (GLCD_Initial(), putrsGLCD("#" * 21)))
    world.run(0.05)
    on = matplotlib.image.imread(board.glcd.save_png(tmp_path / "on.png"))

    def colours(image: np.ndarray) -> set[tuple[int, ...]]:
        middle_row, middle_column = image.shape[0] // 2, image.shape[1] // 2
        centre = image[middle_row - 20:middle_row + 20, middle_column - 20:middle_column + 20]
        return {tuple(round(c * 255) for c in pixel[:3]) for row in centre for pixel in row}

    assert colours(off) == {(0x8E, 0x9A, 0x86)}
    assert colours(on) == {(0xB5, 0xD3, 0x34)}, "a blank middle of the screen shows the backlight"
    top = on[:on.shape[0] // 3]
    assert {(0x1D, 0x2A, 0x10)} <= {tuple(round(c * 255) for c in p[:3]) for row in top for p in row}


@pytest.mark.parametrize("picture", ["png", "save_png"])
def test_the_text_keeps_off_the_edge_of_the_glass(world, tmp_path, picture):
    """Line 1 from column 1, in the notebook's PNG and in the framed picture: lit glass all round the dot matrix."""
    board = show(world, lambda: (GLCD_Initial(), putrsGLCD("#" * 21), setcurGLCD(8, 1), putrsGLCD("#" * 21)))
    if picture == "png":
        (tmp_path / "lcd.png").write_bytes(board.glcd.png(scale=1))
        image, scale = matplotlib.image.imread(tmp_path / "lcd.png"), 1
    else:
        image, scale = matplotlib.image.imread(board.glcd.save_png(tmp_path / "lcd.png", scale=4)), 4
    rgb = np.round(image[..., :3] * 255).astype(int)
    lit = np.argwhere((rgb == (0xB5, 0xD3, 0x34)).all(axis=-1))
    ink = np.argwhere((rgb == (0x1D, 0x2A, 0x10)).all(axis=-1))
    assert len(ink) and len(lit)
    (top, left), (bottom, right) = lit.min(axis=0), lit.max(axis=0)
    (ink_top, ink_left), (ink_bottom, ink_right) = ink.min(axis=0), ink.max(axis=0)
    margin = GLASS_MARGIN_PX * scale - 1                # give or take a pixel of the picture's scaling
    assert ink_top - top >= margin and ink_left - left >= margin, "glass above and left of line 1, column 1"
    assert bottom - ink_bottom >= margin and right - ink_right >= margin
