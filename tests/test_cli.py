"""The `appsim` command as a user types it: the demo, one board, the classroom, bad input."""
from __future__ import annotations

import subprocess
import sys
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


@pytest.mark.parametrize("argv, complaint", [
    (["board", "no/such/file.py"], "no/such/file.py"),
    (["board", "exercises/ex1.py", "--potentiometer", "2000"], "0..1023"),
    (["classroom", "--exercise", "7"], "exercises 1..6"),
    (["classroom", "--station", "9"], "stations are numbered 1..6"),
    (["board", "exercises/ex1.py", "--interface", "nonsense", "--channel", "x"], "cannot open the python-can bus"),
])
def test_bad_input_gets_a_clear_error(argv, complaint):
    result = appsim(*argv, cwd=KIT)
    assert result.returncode != 0 and complaint in result.stderr


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
    assert "Demo1 CAN monitor on the USB-CDC port socket://127.0.0.1:" in out
    assert "link outside (Virtual bus channel cli-monitor):" in out, "the link's report, printed as it closes"
    assert len(seen) > 5 and {m.arbitration_id for m in seen} >= {0x088, 0x100}
