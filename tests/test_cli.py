"""The `appsim` command as a user types it: the demo, one board, the classroom, bad input; a firmware that stops,
outputs that cannot be written, a full disk, Ctrl-C."""
from __future__ import annotations

import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import can
import pytest

from appsim.cli import main

KIT = Path(__file__).resolve().parent.parent


def appsim(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "appsim", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


def test_demo_shows_the_whole_classroom_and_writes_the_trace_and_the_lcd_picture(tmp_path):
    result = appsim("demo", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    text = result.stdout
    rows = [line.split() for line in text.splitlines()]
    assert any(r[1:3] == ["master", "088"] for r in rows if len(r) > 3), "the master's broadcast"
    for k, ident in [(2, "110"), (3, "120"), (4, "130")]:
        assert any(r[1:3] == [f"station{k}", ident] for r in rows if len(r) > 3), f"station {k}'s data frames"
    assert any(r[1:5] == ["station5", "085", "STD", "RTR"] for r in rows if len(r) > 4), "Ex5's RTR"
    assert any(r[1:5] == ["master", "100", "STD", "RTR"] for r in rows if len(r) > 4), "the master's poll"
    assert text.count("┌─────────────────────┐") == 7, "every LCD"
    assert "EX1 LOOPBACK" in text and "MASTER CONSOLE" in text and "0 error frames" in text
    log = list(can.LogReader(tmp_path / "out" / "trace.log"))
    assert len(log) > 200 and {m.arbitration_id for m in log} >= {0x088, 0x085, 0x110, 0x150}
    assert (tmp_path / "out" / "lcds.png").read_bytes()[:4] == b"\x89PNG"


def test_demo_is_deterministic(tmp_path):
    first, second = (appsim("demo", "--out", str(tmp_path / name)).stdout for name in ("a", "b"))
    assert first.replace(str(tmp_path / "a"), "") == second.replace(str(tmp_path / "b"), "")


def test_board_joins_a_python_can_bus_in_real_time(capsys):
    with can.Bus(interface="virtual", channel="cli-test") as peer:
        assert main(["board", str(KIT / "solutions" / "ex2.py"), "--interface", "virtual",
                     "--channel", "cli-test", "--seconds", "0.2", "--potentiometer", "300"]) == 0
        frames = list(iter(lambda: peer.recv(timeout=0), None))
    assert [(m.arbitration_id, bytes(m.data)) for m in frames] == [(0x100, b"\x01\x02\x03\x01\x2C")] * 3
    out = capsys.readouterr().out
    assert "3 frames sent outside" in out and "EX2 ON THE BUS" in out


def test_classroom_with_your_own_board_on_a_station(tmp_path, capsys):
    log = tmp_path / "trace.asc"
    assert main(["classroom", "--exercise", "2", "--join", str(KIT / "solutions" / "ex2.py"),
                 "--station", "1", "--seconds", "0.2", "--log", str(log)]) == 0
    out = capsys.readouterr().out
    assert "station1 runs" in out
    log = list(can.LogReader(log))
    data = [m.arbitration_id for m in log if not m.is_remote_frame]
    assert data.count(0x100) == 3 and data.count(0x150) == 3 and not any(m.is_error_frame for m in log)


def test_joining_with_another_stations_id_warns_and_the_bus_shows_why(tmp_path):
    result = appsim("classroom", "--exercise", "2", "--join", str(KIT / "solutions" / "ex2.py"),
                    "--station", "3", "--seconds", "0.2")
    assert "MESSAGE_ID1 = 0x100 but station 3's is 0x120" in result.stderr
    assert "two nodes sent identifier 0x100 at once" in result.stdout


def test_classroom_injects_an_error_and_the_trace_shows_it_at_its_bit(capsys):
    assert main(["classroom", "--exercise", "2", "--seconds", "0.15", "--inject", "station1:stuff:30:0x100"]) == 0
    out = capsys.readouterr().out
    assert "** stuff error at bit 30: six equal bits (injected) (station1)" in out
    assert "1 error frames" in out


@pytest.mark.parametrize("argv, complaint", [
    (["board", "no/such/file.py"], "no/such/file.py"),
    (["classroom", "--inject", "nobody:bit:3"], "no node 'nobody' in the classroom; its nodes are master, station1"),
    (["board", "exercises/ex1.py", "--potentiometer", "2000"], "0..1023"),
    (["classroom", "--exercise", "7"], "the classroom's stations run Ex1..Ex6 (1..6, ex1..ex6); got '7'"),
    (["classroom", "--station", "9"], "stations are numbered 1..6"),
    (["board", "exercises/ex1.py", "--interface", "nonsense", "--channel", "x"], "cannot open the python-can bus"),
])
def test_bad_input_gets_a_clear_error(argv, complaint):
    result = appsim(*argv, cwd=KIT)
    assert result.returncode != 0 and complaint in result.stderr


@pytest.mark.parametrize("argv, complaint", [
    (["board", "exercises/ex1.py", "--potentiometer", "abc"],
     "argument --potentiometer: the potentiometer on AN0 gives a 10-bit A/D value, a whole number 0..1023; got 'abc'"),
    (["board", "exercises/ex1.py", "--seconds", "0"],
     "argument --seconds: a run lasts more than 0 and at most 86400 seconds (a day); got 0"),
    (["classroom", "--seconds", "nan"], "a run lasts more than 0 and at most 86400 seconds (a day); got nan"),
    (["classroom", "--station", "2"], "--station says which station your firmware takes, so it goes with --join: "
                                      "--join my_ex3.py --station 2"),
    (["classroom", "--exercise", "demo1"], "Demo1, the monitor, runs with: appsim monitor"),
    (["classroom", "--inject", "station1:late:3"], "an injected error is NODE:KIND:BIT[:ID], KIND one of bit, stuff"),
    (["monitor", "--exercise", "x"], "the classroom's stations run Ex1..Ex6 (1..6, ex1..ex6); got 'x'"),
    (["check", "ex9"], "argument EXERCISE: exercise 'ex9' does not exist: the workshop has Ex1..Ex6 (1..6, ex1..ex6) "
                       "and demo1"),
    (["demo", "--seed", "x"], "argument --seed: a seed is a whole number, e.g. 2024; got 'x'"),
    (["grade", "class", "--time-limit", "0"], "the time limit is CPU seconds, more than 0 and at most 3600"),
    (["grade", "class", "--jobs", "two"], "--jobs is how many exercises are graded at once, a whole number: 1 or more; "
                                          "got 'two'"),
    (["bittiming", "0"], "classic CAN runs at 1 bit/s .. 1,000,000 bit/s (1 Mbit/s, ISO 11898): give the bit rate in "
                         "bit/s, e.g. 125000; got 0"),
    (["bittiming", "2000000"], "classic CAN runs at 1 bit/s .. 1,000,000 bit/s (1 Mbit/s, ISO 11898)"),
    (["bittiming", "125k"], "give the bit rate in bit/s, e.g. 125000; got '125k'"),
    (["bittiming", "--fosc", "80000000"], "Fosc is the PIC18F8680's clock in Hz, 1 .. 40,000,000 (the data sheet's "
                                          "40 MHz)"),
    (["bittiming", "--top", "0"], "--top is how many settings to list, a whole number: 1 or more; got 0"),
])
def test_a_usage_error_is_said_in_the_workshops_words_with_status_2(argv, complaint):
    result = appsim(*argv, cwd=KIT)
    assert result.returncode == 2 and complaint in result.stderr, result.stderr
    assert result.stderr.splitlines()[-1].startswith(f"appsim {argv[0]}: error: ")
    assert "Traceback" not in result.stderr and not re.search(r"invalid \w+ value", result.stderr), \
        "no argparse internals"


@pytest.mark.parametrize("exercise", ["3", "ex3", "EX3", " Ex3 "])
def test_an_exercise_is_3_ex3_or_EX3_everywhere(exercise):
    checked = appsim("check", exercise, str(KIT / "solutions" / "ex3.py"), "--seed", "3")
    assert checked.returncode == 0 and "EX3: 5/5 (seed 3)" in checked.stdout, checked.stderr
    room = appsim("classroom", "--exercise", exercise, "--seconds", "0.05")
    assert room.returncode == 0 and "Classroom at exercise 3:" in room.stdout


def test_frames_past_the_first_40_are_said_to_be_in_the_log_only_when_there_is_one(tmp_path):
    alone = appsim("classroom", "--exercise", "2", "--seconds", "1")
    assert re.search(r"\.\.\. \d+ more frames \(--log trace.log keeps them; --full-trace prints them\)", alone.stdout)
    assert "see the trace log" not in alone.stdout
    logged = appsim("classroom", "--exercise", "2", "--seconds", "1", "--log", str(tmp_path / "t.blf"))
    assert re.search(rf"\.\.\. \d+ more frames \(all of them are in {tmp_path}/t.blf; --full-trace prints them\)",
                     logged.stdout)
    assert re.search(rf"wrote {tmp_path}/t.blf \(Vector BLF, \d+ frames\)", logged.stdout)


def test_bittiming_lists_settings_within_the_iso_rule_on_sjw():
    result = appsim("bittiming", "1000000", "--top", "40")
    assert result.returncode == 0 and "SJW <= min(PS1, PS2) (ISO 11898-1)" in result.stdout
    rows = [line.split() for line in result.stdout.splitlines()[3:]]
    assert len(rows) == 36 and all(int(sjw) <= min(int(ps1), int(ps2)) for sjw, _, ps1, ps2, *_ in rows), \
        "every setting at 40 MHz, none with SJW above PS1"


def test_check_gives_the_verdict_and_exit_status_a_script_can_use():
    starter = appsim("check", "ex1", "--seed", "3", cwd=KIT)
    assert starter.returncode == 1 and "EX1: 3/5 (seed 3)" in starter.stdout
    assert "Set RX_Filter0 to MESSAGE_ID1" in starter.stdout
    solution = appsim("check", "ex1", str(KIT / "solutions" / "ex1.py"), "--seed", "3", cwd=KIT)
    assert solution.returncode == 0 and "EX1: 5/5 (seed 3)" in solution.stdout


def test_monitor_opens_demo1s_port_and_closes_its_link(capsys):
    with can.Bus(interface="virtual", channel="cli-monitor") as peer:
        assert main(["monitor", "--seconds", "0.3", "--transport", "socket",
                     "--interface", "virtual", "--channel", "cli-monitor"]) == 0
        seen = list(iter(lambda: peer.recv(timeout=0), None))
    out = capsys.readouterr().out
    assert "Demo1 CAN monitor (the solution, demo1_monitor.py) on the USB-CDC port socket://127.0.0.1:" in out
    assert "link outside (Virtual bus channel cli-monitor):" in out, "the link's report, printed as it closes"
    assert len(seen) > 5 and {m.arbitration_id for m in seen} >= {0x088, 0x100}


# ------------------------------------------------------------------ a firmware that stops
def write(folder: Path, name: str, source: str) -> Path:
    path = folder / name
    path.write_text("from appsim.firmware import *\n\n" + textwrap.dedent(source))
    return path


@pytest.mark.parametrize("source, said", [
    ("def main():\n    GLCD_Initial()\n    x = 1023 // 0\n",
     "station1 (crash.py) stopped: main() crashed at line 5 of crash.py (`x = 1023 // 0`): ZeroDivisionError"),
    ("def main():\n    GLCD_Initial()\n", "station1 (crash.py) stopped: main() returned"),
    ("def main():\n    raise KeyboardInterrupt\n",
     "station1 (crash.py) stopped: main() crashed at line 4 of crash.py (`raise KeyboardInterrupt`): "
     "KeyboardInterrupt"),
])
def test_board_says_where_its_firmware_stopped_and_exits_1(tmp_path, source, said):
    write(tmp_path, "crash.py", source)
    result = appsim("board", "crash.py", cwd=tmp_path)
    assert result.returncode == 1 and said in result.stderr and "Traceback" not in result.stderr
    assert "┌─────────────────────┐" in result.stdout, "the run's report as usual"


def test_a_joined_firmware_that_hangs_inside_except_exception_stops_its_own_station_only(tmp_path):
    hang = write(tmp_path, "hang.py", """\
        MESSAGE_ID1 = 0x100

        def main():
            CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)
            while True:
                try:
                    spins = 0
                    while True:
                        spins += 1
                except Exception:
                    pass
        """)
    result = appsim("classroom", "--exercise", "2", "--join", str(hang), "--seconds", "1")
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert any(f"station1 ({hang}) stopped: main() ran 2 s (CPU time) at line {line} without touching any register: "
               "an endless loop" in result.stderr for line in ("10 of hang.py (`while True:`)",
                                                                "11 of hang.py (`spins += 1`)")), result.stderr
    assert "station2       110  STD" in result.stdout, "the class goes on"


def test_check_says_a_sleep_is_a_sleep_instead_of_hanging(tmp_path):
    sleeper = write(tmp_path, "ex1.py", "import time\n\ndef main():\n    time.sleep(3600)\n")
    result = appsim("check", "ex1", str(sleeper), "--seed", "1")
    assert result.returncode == 1 and "EX1: 0/5" in result.stdout
    assert "main() ran 2 s (wall time) at line 6 of ex1.py (`time.sleep(3600)`)" in result.stdout
    assert "waiting: a sleep (time.sleep)" in result.stdout


def test_an_outside_frame_shorter_than_a_students_firmware_reads_is_reported_in_the_workshops_words(tmp_path, capsys):
    unguarded = tmp_path / "ex3.py"
    unguarded.write_text((KIT / "solutions" / "ex3.py").read_text().replace("if DataLen >= 5:", "if True:"))
    with can.Bus(interface="virtual", channel="cli-short") as peer:
        def short_frame_once_linked():                 # the classroom's first frame out here: the link is up
            peer.recv(timeout=30)
            peer.send(can.Message(arbitration_id=0x088, data=[1], is_extended_id=False))

        later = threading.Thread(target=short_frame_once_linked)
        later.start()
        status = main(["classroom", "--exercise", "3", "--join", str(unguarded), "--interface", "virtual",
                       "--channel", "cli-short", "--seconds", "0.6"])
        later.join()
    err = capsys.readouterr().err
    assert status == 1
    assert ("station1 (" + str(unguarded) + ") stopped: main() crashed at line") in err
    assert "IndexError: the frame had 1 data byte; check DataLen before reading RxData[3]" in err


# ------------------------------------------------------------------ outputs: checked first, written as it goes
@pytest.mark.parametrize("argv, complaint", [
    (["classroom", "--log", "{tmp}/no/such/folder/trace.log"], "there is no directory {tmp}/no/such/folder"),
    (["classroom", "--log", "{tmp}/trace.txt"], "cannot write a CAN log named trace.txt: use .log (candump)"),
    (["board", "exercises/ex1.py", "--log", "{tmp}/folder.log"], "that is a directory"),
    (["demo", "--out", "{tmp}/file/out"], "cannot write {tmp}/file/out"),
])
def test_an_output_that_cannot_be_written_is_refused_before_anything_runs(tmp_path, argv, complaint):
    (tmp_path / "file").write_text("a file, not a folder")
    (tmp_path / "folder.log").mkdir()
    result = appsim(*(arg.format(tmp=tmp_path) for arg in argv), cwd=KIT)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.startswith("appsim: ") and complaint.format(tmp=tmp_path) in result.stderr


def private_tmpfs(tmp_path: Path, options: str, *argv: str) -> subprocess.CompletedProcess:
    """`appsim ARGV` in a private mount namespace where DISK (in ARGV) is a fresh tmpfs mounted with `options`; what it
    wrote there is copied to tmp_path/kept afterwards (the tmpfs goes with the namespace)."""
    disk, kept = tmp_path / "disk", tmp_path / "kept"
    disk.mkdir()
    kept.mkdir()
    script = ('mount -t tmpfs -o "$OPTIONS" appsim-test "$DISK" || exit 99\n'
              '"$@"; status=$?\n'
              'cp -r "$DISK"/. "$KEPT"/\n'
              'exit $status\n')
    command = ["unshare", "-m", "sh", "-c", script, "sh", sys.executable, "-m", "appsim",
               *(arg.replace("DISK", str(disk)) for arg in argv)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=KIT,
                            env={**os.environ, "OPTIONS": options, "DISK": str(disk), "KEPT": str(kept)})
    if result.returncode == 99:
        pytest.skip(f"cannot mount a tmpfs in a private mount namespace here: {result.stderr.strip()}")
    return result


needs_root = pytest.mark.skipif(os.geteuid() != 0 or shutil.which("unshare") is None,
                                reason="a private tmpfs needs root and unshare (util-linux)")


@needs_root
def test_a_read_only_place_is_refused_before_anything_runs(tmp_path):
    result = private_tmpfs(tmp_path, "ro,size=64k", "classroom", "--log", "DISK/trace.log")
    assert result.returncode == 2 and result.stdout == ""
    assert f"cannot write {tmp_path}/disk/trace.log: that file system is read-only" in result.stderr


@needs_root
@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv"])
def test_a_full_disk_ends_the_log_at_its_last_whole_frame_and_says_so(tmp_path, suffix):
    result = private_tmpfs(tmp_path, "size=64k", "classroom", "--exercise", "2", "--seconds", "600",
                           "--log", f"DISK/trace{suffix}")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    said = re.search(rf"appsim: cannot write {tmp_path}/disk/trace\{suffix}: the disk is full\. The log holds the "
                     r"run's first (\d+) frames, each one whole", result.stderr)
    assert said, result.stderr
    logged = list(can.LogReader(tmp_path / "kept" / f"trace{suffix}"))
    assert len(logged) == int(said[1]) > 100


# ------------------------------------------------------------------ Ctrl-C
def interrupt(tmp_path: Path, log: Path, *argv: str) -> tuple[int, str]:
    """Start `appsim ARGV`, press Ctrl-C once `log` reads back 20 frames: the exit status, the last line of stderr."""
    with (tmp_path / "stdout").open("w") as out:
        process = subprocess.Popen([sys.executable, "-m", "appsim", *argv], stdout=out, stderr=subprocess.PIPE,
                                   text=True, cwd=KIT)
        try:
            while len(read_back(log)) < 20:
                assert process.poll() is None, process.stderr.read()
                time.sleep(0.05)
            assert process.poll() is None, f"the run ended before Ctrl-C: {process.stderr.read()}"
            process.send_signal(signal.SIGINT)
            _, err = process.communicate(timeout=60)
        finally:
            process.kill()
    assert "Traceback" not in err, err
    return process.returncode, err.strip().splitlines()[-1]


def read_back(log: Path) -> list[can.Message]:
    """The frames `log` holds so far: up to the one being written (a run still writing has a partial last line)."""
    frames: list[can.Message] = []
    try:
        for frame in can.LogReader(log):
            frames.append(frame)
    except (OSError, ValueError, struct.error, can.CanError):       # not there yet, its header only, a partial line
        pass
    return frames


@pytest.mark.parametrize("argv, log", [
    (["demo", "--seconds", "600", "--out", "{tmp}/out"], "out/trace.log"),
    (["classroom", "--seconds", "3600", "--log", "{tmp}/trace.blf"], "trace.blf"),
    (["classroom", "--seconds", "3600", "--log", "{tmp}/trace.asc", "--interface", "virtual", "--channel", "ctrl-c"],
     "trace.asc"),
    (["monitor", "--seconds", "3600", "--log", "{tmp}/trace.log", "--transport", "socket"], "trace.log"),
], ids=["demo", "classroom", "linked classroom", "monitor"])
def test_ctrl_c_ends_with_one_line_and_130_and_the_log_reads_back_to_its_last_frame(tmp_path, argv, log):
    status, last = interrupt(tmp_path, tmp_path / log, *(arg.format(tmp=tmp_path) for arg in argv))
    said = re.fullmatch(rf"appsim {argv[0]}: interrupted \(Ctrl-C\) at [\d.]+ s of simulated time; "
                        rf"{tmp_path / log} holds its first (\d+) frames.*", last)
    assert status == 130 and said, last
    assert len(list(can.LogReader(tmp_path / log))) == int(said[1])     # whole: no partial last frame
