"""The notebooks' side of the kit: your firmware cell's file on your board in the classroom, shown as the board (LCD,
knobs) with the bus as a trace table and a timeline, and the check, every line numbered as in the firmware cell.

A firmware that does not load or stops is never a traceback here: the cell shows what the check will say about it, and
every later cell says there is nothing to show, so Run All reaches the check. The cells stay one line each:

    station = Station("ex3", "ex3.py", seconds=0.5)      # the classroom of EX3 for half a second, you on station 1
    station                                              # the board: LCD and potentiometers, or why it stopped
    station.trace(ids=0x088)                             # the monitor's lines for the master's frames
    station.timeline()                                   # zoom, hover
    check("ex3", "ex3.py")
"""
from __future__ import annotations

import base64
import functools
import html
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from appsim.bus import monitor
from appsim.bus.monitor import TraceTable
from appsim.bus.serve import ServedInBackground
from appsim.bus.signals import Signals
from appsim.bus.wire import Bus, BusEvent
from appsim.chip import usart
from appsim.chip.usart import Sent
from appsim.firmware.loader import is_c, load_source
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop import checks, plots
from appsim.workshop.checks import RUNS, CheckResult, Verdict
from appsim.workshop.checks.ex4 import before_the_first_0x088
from appsim.workshop.checks.trial import Fatal, Firmware, Trial, loaded
from appsim.workshop.checks.verdict import results_html, results_text
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import CLASSROOM_BIT_RATE, STATIONS, exercise_name
from appsim.workshop.faults import Fault
from appsim.workshop.frames import WORKSHOP_DBC

if TYPE_CHECKING:
    from matplotlib.figure import Figure

CELL = "the firmware cell"          # how messages name the code a firmware cell wrote
C_CELL = "the C firmware cell"      # ... and the code the C firmware cell wrote
SEED = 202                          # the potentiometers of the other stations (yours and the master's are knobs)
KNOB_SECONDS = 0.2                  # the classroom goes on this long after a knob is turned: two master broadcasts
RESET_ON_TURN = {"ex1": "EX1 reads the potentiometer once, before its only frame: each turn also presses RESET, and "
                        "your board starts again"}
WATCHED_CLASSROOM = 2               # Demo1's monitor watches the classroom of EX2
NOTHING_RAN = "Nothing to show: the firmware did not run (see the board above)."
T = TypeVar("T")


# ---------------------------------------------------------------------------------------------------- the firmware cell
def cell_that_wrote(path: Path, text: bytes) -> str | None:
    """The source of the cell that wrote `path` with `%%writefile` in this notebook's kernel, its first line made a
    comment (`#`, in C `//`), if the file still holds what that cell wrote; else None (no kernel, or the file changed
    since)."""
    try:
        from IPython import get_ipython
    except ImportError:
        return None
    shell = get_ipython()
    if shell is None:
        return None
    for cell in reversed(shell.history_manager.input_hist_raw):
        first, _, body = cell.partition("\n")
        words = first.split()
        if words[:1] == ["%%writefile"] and len(words) > 1 and Path(words[-1]).resolve() == path.resolve():
            comment = "//" if is_c(path) else "#"
            return (f"{comment} {first}\n{body}" if body.rstrip("\n") == text.decode("utf-8", "replace").rstrip("\n")
                    else None)
    return None


class FirmwareCell:
    """A firmware file as its notebook cell wrote it: lines are numbered as in the cell (the `%%writefile` line is line
    1) and called "the firmware cell" ("the C firmware cell") in messages, as long as the file holds what the cell
    wrote. `c_options`: C18's options for a .c file (-Oi)."""

    def __init__(self, path: str | Path, c_options: Sequence[str] = ()):
        self.path = Path(path)
        self.c_options = tuple(c_options)

    def load(self) -> Firmware:
        if not self.path.is_file():
            raise Fatal(Fault("load", f"there is no {self.path} yet: run the firmware cell first (its first line, "
                                      f"%%writefile {self.path.name}, writes it)"))
        text = self.path.read_bytes()
        cell = cell_that_wrote(self.path, text)
        language = "c" if is_c(self.path) else "python"
        if cell is None:
            return loaded(lambda: load_source(self.path, text, c_options=self.c_options), str(self.path),
                          str(self.path))
        name = C_CELL if language == "c" else CELL
        return loaded(lambda: load_source(name, cell.encode(), language=language, c_options=self.c_options), name,
                      str(self.path))


def check(exercise: str | int, firmware: str | Path, *, seed: int | None = None,
          c_options: Sequence[str] = ()) -> Verdict:
    """`appsim.workshop.checks.check` on a firmware cell's file (.py, or .c: then with C18's `c_options`, such as
    ("-Oi",)): the same verdict, its lines numbered as in the cell."""
    return checks.check(exercise, FirmwareCell(firmware, c_options), seed=seed)


# ---------------------------------------------------------------------------------------------------- what cells show
class Note:
    """Text as a cell's output: a remark, or (`table`) lines in columns."""

    def __init__(self, text: str, *, table: bool = False):
        self.text = text
        self.table = table

    def __repr__(self) -> str:
        return self.text

    def _repr_html_(self) -> str:
        if self.table:
            return f"<pre>{html.escape(self.text)}</pre>"
        return f"<p style='color:#57606a'><i>{html.escape(self.text)}</i></p>"


def _after_a_run(method: Callable[..., T]) -> Callable[..., T | Note]:
    """A view of the run, or `NOTHING_RAN` when the firmware did not load."""
    @functools.wraps(method)
    def view(self: Station, *args: Any, **kwargs: Any) -> T | Note:
        return Note(NOTHING_RAN) if self.trial is None else method(self, *args, **kwargs)
    return view


def _shown(figure: Figure) -> Figure:
    """A new figure for the cell's result to show, once: pyplot lets go of it, so the inline backend does not draw it
    a second time."""
    import matplotlib.pyplot as plt

    plt.close(figure)
    return figure


def _signals(dbc: bool | str | Path) -> Signals | None:
    """A DBC's reading of frames: the workshop's for True, the file named, or none for False."""
    if dbc is False:
        return None
    return Signals(WORKSHOP_DBC if dbc is True else dbc)


def _ids(ids: int | Iterable[int] | None) -> set[int] | None:
    return None if ids is None else {ids} if isinstance(ids, int) else set(ids)


class Station:
    """Your firmware (a firmware cell's file) on your station's board in the classroom of `exercise` (Demo1's: a board
    of its own on EX2's classroom), run for `seconds` of simulated time. `potentiometer` is your board's knob, `master`
    the master console's; the other stations' are fixed. You are station 1 unless MESSAGE_ID1 says otherwise, as in
    the check, which this runs in the same way (`appsim.workshop.checks.prepare`).

    In the notebook it shows itself as the board: its LCD, with the two knobs beside it when ipywidgets is there. A turn
    of a knob goes on from where the classroom is, for `KNOB_SECONDS`, as turning it on a running board does (EX1 reads
    its knob once: there a turn restarts the board). When the firmware does not load or stops, it shows why, as the
    check will say it; `fault` holds it.
    """

    def __init__(self, exercise: str | int, firmware: str | Path, *, seconds: float,
                 potentiometer: int = 300, master: int = 512, c_options: Sequence[str] = ()):
        self.exercise = exercise_name(exercise)
        self.firmware = Path(firmware)
        self.c_options = tuple(c_options)
        self.seconds = seconds
        self.potentiometer = potentiometer
        self.master = master
        self.trial: Trial | None = None
        self.fault: Fault | None = None
        self.usb = bytearray()              # what the board sent the PC through the USB-CDC port
        self.line: list[Sent] = []          # the same on the USART's TX line: (start_ps, byte, bit_ps) each
        self._start()

    # -------------------------------------------------------------- running
    def _start(self) -> None:
        """Load the firmware and run the classroom from zero, for `seconds`."""
        self.trial, self.fault = None, None
        self.usb.clear()
        self.line.clear()
        try:
            trial = checks.prepare(self.exercise, FirmwareCell(self.firmware, self.c_options), SEED)
        except Fatal as fatal:
            self.fault = fatal.fault
            return
        number = WATCHED_CLASSROOM if self.exercise == "demo1" else int(self.exercise.removeprefix("ex"))
        trial.classroom(number, STATIONS, own_board="demo1" if self.exercise == "demo1" else None)
        board_usart = trial.board.usart

        def sent(byte: int, time_ps: int) -> None:
            self.usb.append(byte)
            self.line.append((time_ps - board_usart.frame_ps(), byte, board_usart.bit_ps()))
        trial.board.usb.listeners.append(sent)
        self.trial = trial
        self._knobs()
        self._run(self.seconds)

    def _knobs(self) -> None:
        assert self.trial is not None
        self.trial.board.adc.potentiometer = self.potentiometer
        self.trial.room.master.adc.potentiometer = self.master

    def _run(self, seconds: float) -> None:
        assert self.trial is not None
        try:
            self.trial.run(seconds)
        except Fatal as fatal:
            self.fault = fatal.fault

    def turn(self, *, potentiometer: int | None = None, master: int | None = None) -> None:
        """Turn your knob and/or the master's: the classroom goes on for `KNOB_SECONDS` (EX1: starts again)."""
        self.potentiometer = self.potentiometer if potentiometer is None else potentiometer
        self.master = self.master if master is None else master
        if self.trial is None or self.fault is not None or self.exercise in RESET_ON_TURN:
            self._start()
        else:
            self._knobs()
            self._run(KNOB_SECONDS)

    # -------------------------------------------------------------- the board
    @property
    def now(self) -> float:
        """Simulated seconds since the classroom started."""
        return 0.0 if self.trial is None else self.trial.now / PS_PER_SECOND

    def lcd_html(self) -> str:
        """The board's LCD as it looks (its text lines in `alt` and `title`, for readers and tests)."""
        if self.trial is None:
            return ""
        glcd = self.trial.board.glcd
        text = " / ".join(f"line {n}: {line.strip()}" for n, line in enumerate(glcd.lines, 1) if line.strip())
        label = html.escape(f"the LCD of {self.trial.name}: {text or 'blank'}", quote=True)
        picture = base64.b64encode(glcd.png()).decode("ascii")
        return (f"<div class='appsim-lcd' style='display:inline-block;background:#202020;border:2px solid #505050;"
                f"border-radius:8px;padding:12px'><img src='data:image/png;base64,{picture}' alt='{label}' "
                f"title='{label}' style='image-rendering:pixelated;display:block'></div>")

    def status_html(self) -> str:
        """Why the firmware stopped, as the check will say it; else how far the classroom has run."""
        if self.fault is not None:
            return (f"<div class='appsim-fault'><b style='color:#cf222e'>{html.escape(self._who())} stopped. "
                    f"The check will say:</b>{results_html(self._results())}</div>")
        assert self.trial is not None
        return (f"<div class='appsim-status' style='color:#57606a'>{html.escape(self._who())}, "
                f"{html.escape(monitor.summary(self.trial.bus))}</div>")

    def _who(self) -> str:
        return self.firmware.name if self.trial is None else f"{self.firmware.name} on {self.trial.name}"

    def _results(self) -> tuple[CheckResult, ...]:
        assert self.fault is not None
        return (CheckResult(RUNS, False, self.fault.message),)

    def _repr_html_(self) -> str:
        return f"<div>{self.status_html()}{self.lcd_html()}</div>"

    def __repr__(self) -> str:
        if self.fault is not None:
            return f"{self._who()} stopped. The check will say:\n{results_text(self._results())}"
        assert self.trial is not None
        return f"{self.trial.board.glcd}\n{self._who()}, {monitor.summary(self.trial.bus)}"

    def _ipython_display_(self) -> None:
        from IPython.display import HTML, display

        try:
            import ipywidgets
        except ImportError:                 # no widgets: the board as it is now
            ipywidgets = None
        if ipywidgets is None or self.trial is None:
            display(HTML(self._repr_html_()))
        else:
            display(self.knobs(ipywidgets))

    def knobs(self, widgets: Any) -> Any:
        """The board as a widget: status, LCD and the knobs, which `turn` the classroom on and redraw."""
        status, lcd = widgets.HTML(self.status_html()), widgets.HTML(self.lcd_html())
        style, layout = {"description_width": "initial"}, widgets.Layout(width="420px")
        yours = widgets.IntSlider(self.potentiometer, min=0, max=1023, description="your potentiometer (AN0)",
                                  continuous_update=False, style=style, layout=layout)
        masters = widgets.IntSlider(self.master, min=0, max=1023, description="the master's potentiometer",
                                    continuous_update=False, style=style, layout=layout)
        what = RESET_ON_TURN.get(self.exercise, f"a turn lets the classroom go on for {KNOB_SECONDS * 1000:.0f} ms, "
                                                "as on a running board")
        note = widgets.HTML(f"<span style='color:#57606a'>{html.escape(what)}</span>")

        def turned(change: dict[str, Any]) -> None:
            self.turn(potentiometer=yours.value, master=masters.value)
            status.value, lcd.value = self.status_html(), self.lcd_html()

        yours.observe(turned, names="value")
        masters.observe(turned, names="value")
        return widgets.VBox([status, widgets.HBox([lcd, widgets.VBox([yours, masters, note])])])

    # -------------------------------------------------------------- the bus
    @property
    def nodes(self) -> list[str]:
        return [] if self.trial is None else [mcu.name for mcu in self.trial.bus.boards()]

    @property
    def message_id(self) -> int | None:
        """The MESSAGE_ID1 your board sends with (None if nothing ran)."""
        return None if self.trial is None else self.trial.own_id

    def _events(self, ids: int | Iterable[int] | None, mine: bool, loopback: bool) -> list[BusEvent]:
        assert self.trial is not None
        wanted = _ids(ids)
        return [e for e in (self.trial.bus.loopback_trace if loopback else self.trial.bus.trace)
                if (wanted is None or e.frame.can_id in wanted) and (not mine or e.sender == self.trial.name)]

    @_after_a_run
    def trace(self, ids: int | Iterable[int] | None = None, *, mine: bool = False, limit: int = 16,
              loopback: bool = False, acceptance: bool = False, dbc: bool | str | Path = False) -> TraceTable:
        """The monitor's lines, the first `limit`, of the frames with `ids` (all if None) or `mine` (your board's);
        `loopback`: the frames nodes in Loopback mode sent themselves; `acceptance`: one more column, what your board's
        acceptance logic did with each frame; `dbc`: one more, each frame's signals (True: the workshop's DBC, or
        the path of another)."""
        assert self.trial is not None
        column = (f"{self.trial.name}'s acceptance logic", self._reception) if acceptance else None
        return TraceTable(self._events(ids, mine, loopback)[:limit], self.nodes, column=column,
                          signals=_signals(dbc))

    @_after_a_run
    def before_the_master(self) -> TraceTable:
        """EX4: the master's first 0x088 and every frame your board sent or ACKed that started before it ended, the
        list the check judges (`checks.ex4.before_the_first_0x088`): the 0x088 alone if your node listened."""
        assert self.trial is not None
        name = self.trial.name
        first, before = before_the_first_0x088(self.trial.bus, name)

        def what(event: BusEvent) -> str:
            if event.sender == name:
                return "sent it"
            master = "the master's first 0x088" if event is first else ""
            return f"ACKed {master or 'it'}" if name in event.acked_by else master

        return TraceTable([*([first] if first is not None else []), *(e for e in before if e is not first)],
                          self.nodes, column=(f"{name}", what))

    @_after_a_run
    def wire_bits(self, *, loopback: bool = False) -> Figure | Note:
        """Your board's first frame (on the bus, or `loopback`: in Loopback mode) bit by bit (`plots.wire_bits`)."""
        sent = self._events(None, True, loopback)
        return _shown(plots.wire_bits(sent[0].frame)) if sent else Note(f"{self._who()} sent no frame.")

    def _reception(self, event: BusEvent) -> str:
        assert self.trial is not None
        return self.trial.reception(event) or ("(sent it)" if event.sender == self.trial.name else "-")

    @_after_a_run
    def timeline(self, *, start_ms: float = 0, end_ms: float | None = None, static: bool = False,
                 dbc: bool | str | Path = False) -> Any:
        """The bus from `start_ms` to `end_ms` (the end of the run if None) as a timeline to zoom into and hover over;
        `static` (or without Plotly): the same as a matplotlib picture; `dbc`: hovering shows each frame's signals
        (True: the workshop's DBC, or the path of another)."""
        assert self.trial is not None
        signals = _signals(dbc)
        start_ps = round(start_ms * PS_PER_SECOND / 1000)
        end_ps = self.trial.now if end_ms is None else round(end_ms * PS_PER_SECOND / 1000)
        if not static:
            try:
                from appsim.workshop.timeline import bus_timeline
                events = [e for e in self.trial.bus.trace if e.end_ps > start_ps and e.start_ps < end_ps]
                return bus_timeline(events, self.nodes, signals)
            except ImportError:
                pass
        return _shown(plots.bus_timeline(self.trial.bus.trace, start_ps=start_ps, end_ps=end_ps, signals=signals))

    @_after_a_run
    def error_counters(self) -> Note:
        """Each board's TEC, REC and error state (`monitor.error_counters`)."""
        assert self.trial is not None
        return Note(monitor.error_counters(self.trial.bus), table=True)

    @_after_a_run
    def bus_load(self, *, window_ms: float = 10) -> Figure:
        """The bus load in windows of `window_ms` over the whole run (`plots.bus_load_over_time`)."""
        assert self.trial is not None
        window_ps = round(window_ms * PS_PER_SECOND / 1000)
        return _shown(plots.bus_load_over_time(self.trial.bus.trace, 0, self.trial.now, window_ps))

    @_after_a_run
    def write_log(self, path: str | Path, *, show: int = 5) -> Note:
        """The run's frames written as a CAN log (.log for candump, .asc, .blf, .csv: `monitor.write_log`), and the
        first `show` lines of a text log."""
        assert self.trial is not None
        log = monitor.write_log(self.trial.bus.trace, path)
        first = [] if log.suffix == ".blf" else log.read_text().splitlines()[:show]
        return Note("\n".join([f"{log}: {len(self.trial.bus.trace)} frames", *first]), table=True)

    @_after_a_run
    def terminal(self, *, characters: int = 1500) -> Note:
        """What a terminal on the PC shows of the USB-CDC port: the first `characters` of what the PIC18F2550's UART,
        at 19200 baud, decoded of the board's TX line. At another baud rate that is garbage, and a first line says
        so."""
        assert self.trial is not None
        decoded = usart.decode(self.line, usart.PC_BAUD)
        read = bytes(received.data for received in decoded)
        text = read.decode("latin-1").replace("\0", "")[:characters] or "(nothing)"   # C18's putsUSART sends the NUL
        if read == self.usb:                                                        # too; terminals skip it
            return Note(text, table=True)
        shown = "".join(c if c.isprintable() or c in "\r\n" else "·" for c in text)
        errors = sum(received.framing_error for received in decoded)
        return Note(f"[the USART sends at {self.trial.board.usart.baud:.0f} baud, the PIC18F2550 reads "
                    f"{usart.PC_BAUD}: of the {len(self.usb)} bytes sent it decoded {len(decoded)}, {errors} of them "
                    f"with a framing error. This is what the PC's terminal shows (· for what it cannot print):]\n"
                    f"{shown}", table=True)


# ------------------------------------------------------------------------------------------------- a served classroom
class ServedClassroom(ServedInBackground):
    """The classroom of `exercise` (the master and six stations running its solution, the PC's monitor) served to
    python-can programs as `channel` (`appsim classroom --serve` in a cell): it runs in real time in the background
    for `seconds`, or until `stop()`, while other cells join it with `can.Bus(interface="appsim", channel=channel)`.
    It shows itself as how to join, and once stopped, what its programs sent and received."""

    def __init__(self, exercise: int = 2, channel: str = "notebook", *, seconds: float = 60.0):
        self.exercise = exercise

        def build() -> Bus:
            bus = Bus(Simulator(), CLASSROOM_BIT_RATE)
            Classroom(bus, exercise, seed=SEED)
            return bus

        super().__init__(build, channel, seconds=seconds, what=f"the notebook's classroom at exercise {exercise}")

    def __repr__(self) -> str:
        if self.running:
            return f"The classroom of EX{self.exercise} is running in real time, {self.how_to_join}"
        return self.report or f"The classroom stopped: {self.failure}"
