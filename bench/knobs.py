"""A knob turned in a notebook: the kernel's time from a slider's move to the board redrawn (LCD picture and status).

Before, each move ran the whole classroom again from zero and drew the LCD with matplotlib (the old `lcd_for` cells);
now `Station.turn` lets the live classroom go on, as a turned knob does on a running board, and `GLCD.png` draws it.
"""
from __future__ import annotations

import io
import time
from contextlib import redirect_stdout

from appsim.workshop.course import solution

SECONDS = {"ex1": 0.2, "ex2": 0.5, "ex3": 0.5, "ex4": 0.5, "ex5": 0.5, "ex6": 1.0}     # each notebook's first run
GOING_ON = ("ex2", "ex3", "ex4", "ex5", "ex6")      # EX1 reads its knob once: a turn restarts its board


def _values(turns: int) -> list[int]:
    return [(97 * k + 300) % 1024 for k in range(1, turns + 1)]


def rerun_from_zero_s(exercise: str, turns: int) -> list[float]:
    """Wall seconds per move as the notebooks did it: a new classroom run from zero, the LCD printed and drawn by
    matplotlib as the inline backend draws a figure (PNG, tight bounding box)."""
    import matplotlib
    import matplotlib.pyplot as plt

    from appsim.bus.wire import Bus
    from appsim.sim import Simulator
    from appsim.workshop.classroom import Classroom

    matplotlib.use("Agg")
    times = []
    for master in _values(turns):
        started = time.perf_counter()
        room = Classroom(Bus(Simulator()), int(exercise[2:]), master_potentiometer=master)
        board = room.join(solution(exercise), station=1)
        board.adc.potentiometer = 300
        room.run(SECONDS[exercise])
        with redirect_stdout(io.StringIO()):
            print(board.glcd)
        figure = board.glcd.picture(scale=3)
        figure.savefig(io.BytesIO(), format="png", bbox_inches="tight")
        plt.close(figure)
        times.append(time.perf_counter() - started)
    return times


def turn_s(exercise: str, turns: int) -> list[float]:
    """Wall seconds per move now: `Station.turn` and the board's new LCD picture and status line."""
    from appsim.workshop.notebook import Station

    station = Station(exercise, solution(exercise), seconds=SECONDS[exercise])
    station.lcd_html()                                  # the first picture loads the PNG encoder
    times = []
    for master in _values(turns):
        started = time.perf_counter()
        station.turn(master=master)
        station.lcd_html(), station.status_html()
        times.append(time.perf_counter() - started)
        if station.fault is not None:
            raise RuntimeError(f"the solution of {exercise} stopped: {station.fault.message}")
    return times
