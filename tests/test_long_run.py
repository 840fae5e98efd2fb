"""A long run keeps its memory bounded: the trace in memory is a window, the log on disk gets every frame.

The measured run is `appsim classroom --exercise 2 --seconds S --log long.log` in a process of its own, S from
APPSIM_LONG_RUN_SECONDS (default 300 simulated seconds, about half a minute here: twice what fills the trace's window
of 20,000 events). A whole simulated hour was measured with S = 3600 (AMD EPYC, 2 cores shared with other work,
CPython 3.11.7): peak RSS 66 MB (67,256 kB), 483,983 frames in the log, every one read back by can.LogReader,
8 minutes of wall time (333 s of CPU). Before the window (and the bounded LCD history) an hour grew to about 0.7 GB.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys

import can

from appsim.bus.trace import TRACE_WINDOW

LONG_RUN_SECONDS = float(os.environ.get("APPSIM_LONG_RUN_SECONDS", "300"))
RSS_LIMIT_MB = 200


def test_a_long_classroom_run_with_a_log_stays_under_200_mb_and_logs_every_frame(tmp_path):
    log = tmp_path / "long.log"
    with (tmp_path / "stdout").open("w") as out:
        process = subprocess.Popen([sys.executable, "-m", "appsim", "classroom", "--exercise", "2",
                                    "--seconds", f"{LONG_RUN_SECONDS:g}", "--log", str(log)],
                                   stdout=out, stderr=subprocess.PIPE)
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
    text = (tmp_path / "stdout").read_text()
    rss_mb = usage.ru_maxrss / (2**20 if sys.platform == "darwin" else 2**10)
    frames = int(re.search(r"^(\d+) frames, 0 error frames in", text, re.MULTILINE)[1])
    print(f"\n{LONG_RUN_SECONDS:g} s of an Ex2 classroom with --log: peak RSS {rss_mb:.0f} MB, {frames} frames")
    assert process.returncode == 0, process.stderr.read()
    assert rss_mb < RSS_LIMIT_MB
    assert sum(1 for _ in can.LogReader(log)) == frames
    if frames > TRACE_WINDOW:
        assert f"frames not kept in memory: {frames - TRACE_WINDOW} (the trace keeps the last {TRACE_WINDOW}" in text
