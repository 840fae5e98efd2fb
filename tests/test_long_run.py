"""A long run keeps its memory bounded: the trace in memory is a window, the log on disk gets every frame.

The measured run is `appsim classroom --exercise 2 --seconds S --log long.log` in a process of its own, S from
APPSIM_LONG_RUN_SECONDS (default 300 simulated seconds, about half a minute here: twice what fills the trace's window
of 20,000 events). Measured here (AMD EPYC, 2 cores shared, CPython 3.11.7), the run's own peak RSS: 60.4 MB at
150 s, 60.5 MB at 300 s, 61.4 MB at 600 s; a whole simulated hour 66 MB with 483,983 frames in the log, every one
read back by can.LogReader. Before the window (and the bounded LCD history) an hour grew to about 0.7 GB.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys

import can

from appsim.bus.trace import TRACE_WINDOW

LONG_RUN_SECONDS = float(os.environ.get("APPSIM_LONG_RUN_SECONDS", "300"))
RSS_LIMIT_MB = 100


# The run's own peak (VmHWM of its memory map), written by the run itself as it exits. The rusage of a child is no
# measure here: Linux keeps the larger of the child's peak and the RSS of the process it was forked from, and the
# pytest process that starts it holds about 200 MB by the time this test runs in the whole suite.
MEASURED = """
import atexit, re, runpy, sys
def keep_peak(path=sys.argv.pop(1)):
    with open('/proc/self/status') as status, open(path, 'w') as out:
        out.write(re.search(r'VmHWM:\\s*(\\d+) kB', status.read())[1])
atexit.register(keep_peak)
sys.argv[0] = 'appsim'
runpy.run_module('appsim', run_name='__main__')
"""


def test_a_long_classroom_run_with_a_log_stays_under_100_mb_and_logs_every_frame(tmp_path):
    log, peak = tmp_path / "long.log", tmp_path / "peak_kb"
    with (tmp_path / "stdout").open("w") as out:
        process = subprocess.run([sys.executable, "-c", MEASURED, str(peak), "classroom", "--exercise", "2",
                                  "--seconds", f"{LONG_RUN_SECONDS:g}", "--log", str(log)],
                                 stdout=out, stderr=subprocess.PIPE, text=True)
    text = (tmp_path / "stdout").read_text()
    rss_mb = int(peak.read_text()) / 2**10
    frames = int(re.search(r"^(\d+) frames, 0 error frames in", text, re.MULTILINE)[1])
    print(f"\n{LONG_RUN_SECONDS:g} s of an Ex2 classroom with --log: peak RSS {rss_mb:.0f} MB, {frames} frames")
    assert process.returncode == 0, process.stderr
    assert rss_mb < RSS_LIMIT_MB
    assert sum(1 for _ in can.LogReader(log)) == frames
    if frames > TRACE_WINDOW:
        assert f"frames not kept in memory: {frames - TRACE_WINDOW} (the trace keeps the last {TRACE_WINDOW}" in text
