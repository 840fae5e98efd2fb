"""One run, one clock: the printed trace and every log (.log, .asc, .blf, .csv) give each frame the same time, to the
microsecond: its end of frame, in seconds since the boards' reset (docs/traces.md)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import can

KIT = Path(__file__).resolve().parent.parent
TRACE_LINE = re.compile(r"^ *(\d+\.\d{6})  (\S+) +([0-9A-F]{3}|[0-9A-F]{8})  ")


def test_the_printed_trace_and_every_log_give_each_frame_the_same_time(tmp_path):
    """A classroom where a student's board on station 3 sends station 1's ID: frames and error frames both."""
    logs = [tmp_path / f"trace{suffix}" for suffix in (".log", ".asc", ".blf", ".csv")]
    result = subprocess.run([sys.executable, "-m", "appsim", "classroom", "--exercise", "2", "--join",
                             str(KIT / "solutions" / "ex2.py"), "--station", "3", "--seconds", "0.3", "--full-trace",
                             *(argument for log in logs for argument in ("--log", str(log)))],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    printed = [match for line in result.stdout.splitlines() if (match := TRACE_LINE.match(line))]
    times = [match[1] for match in printed]
    assert len(times) > 50 and any("**" in match.string for match in printed), "frames and error frames"
    assert times[0] == "0.053949", "the master's first frame ends 53.949 ms after reset"
    for log in logs:
        messages = list(can.LogReader(log))
        assert [f"{m.timestamp:.6f}" for m in messages] == times, f"{log.name} gives the trace's times"
        assert [m.is_error_frame for m in messages] == ["**" in match.string for match in printed]
