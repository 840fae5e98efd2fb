"""What the notebooks' cells show: the board (its LCD and knobs) or why the firmware stopped, in the check's words and
numbered as in the firmware cell; the trace table (ACK in a few words, errors in red); the timeline's hover texts."""
from __future__ import annotations

import html
import re
import shutil
from pathlib import Path

import pytest
from workshop import lone_node

from appsim.bus.monitor import TraceTable, acks
from appsim.bus.wire import BusEvent
from appsim.can.frame import CanFrame
from appsim.workshop import notebook
from appsim.workshop.notebook import KNOB_SECONDS, NOTHING_RAN, Note, Station, check

KIT = Path(__file__).resolve().parent.parent
TYPO = ("CANSetFilter(CAN_FILTER_B1_F1,", "CANSetFliter(CAN_FILTER_B1_F1,")


@pytest.fixture
def here(tmp_path, monkeypatch) -> Path:
    """A notebook's folder: the current directory, as a kernel's is."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def write(folder: Path, exercise: str, old: str = "", new: str = "", *, source: str = "solutions") -> str:
    """exN.py in `folder`, from the solution (or the starter) with `old` replaced by `new`."""
    text = (KIT / source / f"{exercise}.py").read_text()
    assert not old or text.count(old) == 1
    (folder / f"{exercise}.py").write_text(text.replace(old, new) if old else text)
    return text.replace(old, new) if old else text


@pytest.fixture
def shell():
    """An IPython shell, as the notebook's kernel runs one: cells run through it are in its history."""
    from IPython.core.interactiveshell import InteractiveShell

    yield InteractiveShell.instance()
    InteractiveShell.clear_instance()


def lcd_text(station: Station) -> str:
    """The LCD's lines as the picture's alt text gives them."""
    return re.search(r"alt='([^']*)'", station.lcd_html()).group(1)


# ------------------------------------------------------------------ the board
def test_a_working_firmware_shows_its_lcd_once_and_how_far_the_classroom_ran(here):
    write(here, "ex3")
    station = Station("ex3", "ex3.py", seconds=0.5, master=700)
    assert station.fault is None
    assert "line 3: A/D     700 / line 4: RX ID  0x088" in lcd_text(station)
    shown = station._repr_html_()
    assert shown.count("<img") == 1, "the LCD is drawn once"
    assert "ex3.py on station1" in shown and "frames, 0 error frames in 0.500 s" in shown
    assert "A/D     700" in repr(station)


def test_turning_the_masters_knob_goes_on_from_where_the_classroom_is_and_line_3_follows(here):
    write(here, "ex3")
    station = Station("ex3", "ex3.py", seconds=0.5, master=700)
    frames = len(station.trial.bus.trace)
    station.turn(master=123)
    assert station.now == pytest.approx(0.5 + KNOB_SECONDS)
    assert len(station.trial.bus.trace) > frames, "the same classroom, further on"
    assert "line 3: A/D     123" in lcd_text(station)


def test_ex1_reads_its_knob_once_so_a_turn_restarts_the_board(here):
    write(here, "ex1")
    station = Station("ex1", "ex1.py", seconds=0.2, potentiometer=300)
    assert "line 3: A/D     300" in lcd_text(station)
    station.turn(potentiometer=1000)
    assert station.now == pytest.approx(0.2), "started again from zero"
    assert "line 3: A/D    1000" in lcd_text(station)


def test_the_knobs_widget_turns_the_knobs_and_redraws_the_lcd(here):
    widgets = pytest.importorskip("ipywidgets")
    write(here, "ex3")
    station = Station("ex3", "ex3.py", seconds=0.5)
    board = station.knobs(widgets)
    status, row = board.children
    lcd, (yours, masters, note) = row.children[0], row.children[1].children
    assert yours.description == "your potentiometer (AN0)" and masters.description == "the master's potentiometer"
    assert yours.style.description_width == "initial", "labels are shown whole"
    assert "go on for 200 ms" in note.value, "the note says what a turn does"
    masters.value = 42
    assert "line 3: A/D      42" in lcd.value
    assert "0.700 s" in status.value


def test_a_typo_shows_the_checks_words_numbered_as_in_the_cell_and_the_check_says_the_same(here, shell):
    source = write(here, "ex3", *TYPO, source="exercises")
    shell.run_cell(f"%%writefile ex3.py\n{source}", store_history=True)
    cell_line = f"%%writefile ex3.py\n{source}".splitlines().index(
        next(line for line in source.splitlines() if "CANSetFliter" in line)) + 1
    station = Station("ex3", "ex3.py", seconds=0.5)
    message = (f"main() crashed at line {cell_line} of the firmware cell (`CANSetFliter(CAN_FILTER_B1_F1, RX_Filter0, "
               "CAN_CONFIG_STD_MSG)`): NameError: name 'CANSetFliter' is not defined. Did you mean: 'CANSetFilter'?")
    assert station.fault.kind == "exception" and station.fault.message.startswith(message)
    shown = station._repr_html_()
    assert "stopped. The check will say:" in shown and "FAIL" in shown
    assert "Traceback" not in shown and "classroom.py" not in shown and "an738.py" not in repr(station)
    verdict = check("ex3", "ex3.py", seed=1)
    assert verdict.checks[0].message == station.fault.message
    assert verdict.score == 0


def test_a_file_changed_since_its_cell_ran_is_numbered_as_the_file(here, shell):
    source = write(here, "ex3", *TYPO, source="exercises")
    shell.run_cell(f"%%writefile ex3.py\n{source}", store_history=True)
    (here / "ex3.py").write_text("\n" + source)
    line = ("\n" + source).splitlines().index(next(s for s in source.splitlines() if "CANSetFliter" in s)) + 1
    assert f"crashed at line {line} of ex3.py" in Station("ex3", "ex3.py", seconds=0.1).fault.message


def test_a_firmware_that_does_not_load_shows_why_and_the_later_cells_say_nothing_ran(here, shell):
    source = write(here, "ex2", "def main():", "def main()")
    shell.run_cell(f"%%writefile ex2.py\n{source}", store_history=True)
    cell_line = f"%%writefile ex2.py\n{source}".splitlines().index("def main()") + 1
    station = Station("ex2", "ex2.py", seconds=0.5)
    assert station.trial is None and station.fault.kind == "load"
    assert f"the firmware cell, line {cell_line}: expected ':'" in station.fault.message
    for view in (station.trace(), station.timeline(), station.error_counters(), station.bus_load(),
                 station.write_log(here / "x.log")):
        assert isinstance(view, Note) and repr(view) == NOTHING_RAN
    assert "stopped" in station._repr_html_() and "<img" not in station._repr_html_()


def test_no_file_yet_says_to_run_the_firmware_cell(here):
    station = Station("ex4", "ex4.py", seconds=0.5)
    assert "run the firmware cell first" in station.fault.message


def test_demo1_runs_as_a_board_of_its_own_on_ex2s_classroom_and_keeps_what_it_sent_the_pc(here):
    shutil.copy(KIT / "solutions" / "demo1_monitor.py", here)
    station = Station("demo1", "demo1_monitor.py", seconds=0.3)
    assert station.fault is None and station.trial.name == "demo1"
    assert "0x088  STD  DATA  DLC 5" in station.usb.decode("latin-1")
    assert {"master", "station6", "demo1"} <= set(station.nodes)


# ------------------------------------------------------------------ the trace
def test_the_trace_says_who_acked_in_a_few_words_and_filters_by_id(here):
    write(here, "ex3")
    station = Station("ex3", "ex3.py", seconds=0.5)
    table = station.trace(ids=0x088, limit=3)
    assert isinstance(table, TraceTable) and len(table) == 3
    assert all(event.frame.can_id == 0x088 for event in table.events)
    rows = table._repr_html_().split("<tr")[2:]
    assert len(rows) == 3 and all(">all<" in row for row in rows), "every other node ACKs the master"
    mine = station.trace(ids=[0x100], acceptance=True, limit=1)
    assert "station1's acceptance logic" in html.unescape(mine._repr_html_()) and "(sent it)" in mine._repr_html_()


def test_ack_in_a_few_words():
    nodes = ["master", "station1", "station2", "station3", "monitor"]

    def sent(*acked: str) -> BusEvent:
        return BusEvent(0, 1, "master", CanFrame(0x088, b"\x01"), acked)

    assert acks(sent("station1", "station2", "station3", "monitor"), nodes) == "all"
    assert acks(sent(), nodes) == "none"
    assert acks(sent("station1", "station2", "monitor"), nodes) == "all but station3"
    assert acks(sent("monitor"), nodes) == "monitor"


def test_error_frames_stand_out_in_the_trace_and_the_timeline():
    bus = lone_node(0.005)
    table = TraceTable(bus.trace, ["alone"])
    shown = table._repr_html_()
    assert shown.count("background:#ffebe9") == len(bus.trace) > 0
    assert "error: " in shown
    pytest.importorskip("plotly")
    from appsim.workshop.timeline import bus_timeline

    figure = bus_timeline(bus.trace, ["alone"])
    [errors] = [bar for bar in figure.data if bar.name == "error frame"]
    assert len(errors.x) == len(bus.trace)
    assert "error: " in errors.hovertext[0]


def test_the_timeline_has_a_bar_per_frame_and_hovers_with_id_data_sender_and_ack(here):
    pytest.importorskip("plotly")
    write(here, "ex5")
    station = Station("ex5", "ex5.py", seconds=0.3)
    figure = station.timeline()
    bars = {bar.name: bar for bar in figure.data}
    assert sum(len(bar.x) for bar in figure.data) == len(station.trial.bus.trace)
    assert len(bars["remote frame (RTR)"].x) > 0
    first = station.trial.bus.trace[0]
    hover = next(text for bar in figure.data for text in bar.hovertext if f"at {first.start_ps / 1e9:.3f} ms" in text)
    assert f"0x{first.frame.can_id:03X}" in hover and f"from {first.sender}" in hover
    assert acks(first, station.nodes) == "monitor", "EX5's stations listen before they join: only the monitor ACKs"
    assert "<br>ACK: monitor" in hover
    assert first.frame.data.hex(" ").upper() in hover
    static = station.timeline(static=True)
    assert static.axes[0].get_xlabel() == "time (ms)"


def test_check_without_a_kernel_numbers_as_the_file(here):
    write(here, "ex3", *TYPO, source="exercises")
    assert notebook.cell_that_wrote(here / "ex3.py", (here / "ex3.py").read_bytes()) is None
    assert "of ex3.py (`CANSetFliter" in check("ex3", "ex3.py", seed=1).checks[0].message
