"""The workshop's frames as a CAN database: shipped as workshop.dbc, read by cantools (the kit writes no DBC parser),
used where people read frames (`--dbc` on the trace, the notebook's trace table and timeline) and by `cantools decode`
on the kit's own logs."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cantools
import pytest

from appsim.bus.monitor import TraceTable
from appsim.bus.signals import DbcError, Signals
from appsim.bus.wire import BusEvent
from appsim.can.frame import CanFrame
from appsim.workshop import frames
from appsim.workshop.course import MASTER_ID, RTR_IDS, STATION_IDS
from appsim.workshop.timeline import describe

CANTOOLS = [sys.executable, "-m", "cantools"]       # wherever pip put its script


def appsim(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "appsim", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_the_shipped_dbc_is_what_the_definition_writes():
    assert frames.WORKSHOP_DBC.read_bytes().decode("utf-8") == frames.as_dbc(), \
        "run python -m appsim.workshop.frames to write workshop.dbc again"


def test_every_workshop_frame_is_in_it_with_its_sender_and_the_ad_value_as_one_10_bit_signal():
    database = cantools.database.load_file(str(frames.WORKSHOP_DBC))
    by_id = {message.frame_id: message for message in database.messages}
    assert set(by_id) == {MASTER_ID, *RTR_IDS, *STATION_IDS}
    assert by_id[MASTER_ID].name == "MASTER_BROADCAST" and by_id[MASTER_ID].senders == ["MASTER"]
    assert by_id[MASTER_ID].cycle_time == 100
    for k, station_id in enumerate(STATION_IDS, start=1):
        assert by_id[station_id].senders == [f"STATION{k}"]
    for k, rtr_id in enumerate(RTR_IDS, start=1):
        assert by_id[rtr_id].name == f"MASTER_ANSWER{k}" and "remote frame" in by_id[rtr_id].comment
    for adresh, adresl, value in ((0x02, 0x9A, 666), (0x03, 0xFF, 1023), (0x00, 0x00, 0), (0x01, 0x00, 256)):
        payload = bytes((1, 2, 3, adresh, adresl))
        assert by_id[MASTER_ID].decode(payload)["ADRES"] == value
        assert by_id[0x130].encode({"TxData0": 1, "TxData1": 2, "TxData2": 3, "ADRES": value}) == payload
    adres = by_id[0x100].get_signal_by_name("ADRES")
    assert (adres.length, adres.byte_order, adres.minimum, adres.maximum) == (10, "big_endian", 0, 1023)


def test_a_frame_reads_as_its_message_and_signals_and_a_frame_it_does_not_know_as_nothing():
    signals = Signals(frames.WORKSHOP_DBC)
    assert signals.describe(CanFrame(0x088, bytes((1, 2, 3, 2, 0x9A)))) == \
        "MASTER_BROADCAST: TxData0=1 TxData1=2 TxData2=3 ADRES=666 counts"
    assert signals.describe(CanFrame(0x083, remote=True)) == "remote request (RTR) for MASTER_ANSWER3"
    assert signals.describe(CanFrame(0x110, b"\x01")) == "STATION2: 1 data bytes where the DBC says 5"
    assert signals.describe(CanFrame(0x7FF, b"")) == ""
    assert signals.describe(CanFrame(0x088, bytes(5), extended=True)) == "", "extended 0x088 is another frame"


@pytest.mark.parametrize("content, words", [(None, "there is no CAN database"),
                                            ("BO_ this is not a dbc", "is not a DBC file cantools can read"),
                                            (b"\xff\xfe\x00\x1b[2J", "is not a DBC file"),
                                            ("folder", "cannot read")])
def test_a_dbc_that_cannot_be_read_is_an_error_in_words(tmp_path, content, words):
    path = tmp_path / "course.dbc"
    if content == "folder":
        path.mkdir()
    elif isinstance(content, str):
        path.write_text(content)
    elif content is not None:
        path.write_bytes(content)
    with pytest.raises(DbcError, match=words) as raised:
        Signals(path)
    assert str(raised.value).isprintable()
    result = appsim("classroom", "--dbc", str(path), "--seconds", "0.1", cwd=tmp_path)
    assert result.returncode != 0 and words in result.stderr and "Traceback" not in result.stderr


def test_the_terminal_trace_shows_each_frames_signals_under_it_with_dbc(tmp_path):
    result = appsim("classroom", "--exercise", "5", "--dbc", "--seconds", "0.3", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    broadcast = next(n for n, line in enumerate(lines) if "master         088  STD" in line)
    assert lines[broadcast + 1].strip().startswith("MASTER_BROADCAST: TxData0=1 TxData1=2 TxData2=3 ADRES=")
    assert any(line.strip() == "remote request (RTR) for MASTER_ANSWER1" for line in lines)
    frames_shown = [line for line in lines if line[13:14] != " " and " STD " in line]
    assert len(frames_shown) == 40 and "more frames" in result.stdout, "the limit counts frames, not lines"
    plain = appsim("classroom", "--exercise", "5", "--seconds", "0.3", cwd=tmp_path)
    assert "MASTER_BROADCAST" not in plain.stdout, "signals only when asked"


def test_a_dbc_of_ones_own_names_the_frames_it_describes(tmp_path):
    own = tmp_path / "mine.dbc"
    own.write_text('VERSION ""\n\nBS_:\n\nBU_: ME\n\nBO_ 256 MY_KNOB: 5 ME\n'
                   ' SG_ Knob : 25|10@0+ (0.1,0) [0|102.3] "%" Vector__XXX\n\n')
    result = appsim("classroom", "--exercise", "2", "--dbc", str(own), "--seconds", "0.2", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "MY_KNOB: Knob=" in result.stdout and "MASTER_BROADCAST" not in result.stdout


def test_the_trace_table_and_the_timeline_show_signals_when_asked():
    event = BusEvent(0, 10**9, "master", CanFrame(0x088, bytes((1, 2, 3, 3, 0xFF))), ("station1",))
    signals = Signals(frames.WORKSHOP_DBC)
    table = TraceTable([event], ["master", "station1"], signals=signals)
    assert "signals (DBC)" in table._repr_html_() and "ADRES=1023 counts" in table._repr_html_()
    assert str(table).splitlines()[2].strip() == "MASTER_BROADCAST: TxData0=1 TxData1=2 TxData2=3 ADRES=1023 counts"
    assert "signals" not in TraceTable([event], ["master"])._repr_html_()
    assert "ADRES=1023" in describe(event, ["master", "station1"], signals)
    assert "ADRES" not in describe(event, ["master", "station1"])


def test_the_notebook_station_reads_frames_through_the_dbc():
    from appsim.workshop.course import solution
    from appsim.workshop.notebook import Station

    station = Station("ex2", solution("ex2"), seconds=0.2)
    table = station.trace(ids=0x088, dbc=True)
    assert "MASTER_BROADCAST: TxData0=1 TxData1=2 TxData2=3 ADRES=512 counts" in str(table)
    figure = station.timeline(dbc=True)
    hovers = [text for bar in figure.data for text in bar.hovertext]
    assert any("STATION1: TxData0=1" in text for text in hovers)


def test_cantools_decode_reads_the_kits_own_log_with_the_workshop_dbc(tmp_path):
    result = appsim("classroom", "--exercise", "5", "--log", "trace.log", "--seconds", "0.5", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    where = appsim("dbc", cwd=tmp_path).stdout.strip()
    assert Path(where) == frames.WORKSHOP_DBC
    decoded = subprocess.run([*CANTOOLS, "decode", where], input=(tmp_path / "trace.log").read_text(),
                             capture_output=True, text=True, timeout=60)
    assert decoded.returncode == 0, decoded.stderr
    assert "MASTER_BROADCAST(" in decoded.stdout and "MASTER_ANSWER1(" in decoded.stdout
    assert "ADRES: 512 counts" in decoded.stdout
    assert any(f"STATION{k}(" in decoded.stdout for k in range(1, 7)) is False, \
        "in Ex5 the stations send only RTR frames (which cantools leaves undecoded)"
