"""Every output a command writes as it runs (--log, --vcd, the demo's folder, appsim grade's files), tried as a clumsy
user and a hostile reader would: FIFOs whose reader stalls, reads slowly, closes or never comes, /dev/full, a folder an
ordinary user cannot write, and one file named twice in every way a path can be (links, ./x, /dev/stdout, the
firmware itself). Nothing blocks the run or Ctrl-C, nothing is lost without a count, every failure has its words."""
from __future__ import annotations

import fcntl
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import can
import pytest

from appsim.cli import main

KIT = Path(__file__).resolve().parent.parent
F_SETPIPE_SZ = 1031                     # Linux <fcntl.h>: a pipe's capacity
SMALLEST_PIPE = 4096
ENDS_S = 5.0                            # Ctrl-C ends a run within a second: this leaves room for a busy machine

# (argv with {fifo} and {tmp}, the line it prints once it runs): each command that writes a waveform or a log
COMMANDS = {
    "classroom --vcd": (["classroom", "--seconds", "3600", "--vcd", "{fifo}", "--log", "{tmp}/trace.log"],
                        "Classroom at exercise 6"),
    "classroom --log .log": (["classroom", "--seconds", "3600", "--log", "{fifo}", "--log", "{tmp}/trace.log"],
                             "Classroom at exercise 6"),
    "board --log .asc": (["board", str(KIT / "solutions" / "ex2.py"), "--seconds", "3600", "--log", "{fifo}"],
                         "APP023 'station1' running"),
    "demo --vcd": (["demo", "--seconds", "3600", "--out", "{tmp}/demo", "--vcd", "{fifo}"], "CAN Workshop 202"),
    "monitor --vcd": (["monitor", "--seconds", "3600", "--transport", "socket", "--vcd", "{fifo}", "--log",
                       "{tmp}/trace.log"], "Demo1 CAN monitor"),
}
SUFFIX = {"classroom --log .log": ".log", "board --log .asc": ".asc"}


def appsim(*args: str, cwd: Path = KIT, **options: object) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "appsim", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=120, **options)


def fifo(tmp_path: Path, name: str = "line.vcd") -> Path:
    path = tmp_path / name
    os.mkfifo(path)
    return path


class Running:
    """`appsim ARGV` running, its stdout and stderr read as they come by threads of their own."""

    def __init__(self, argv: list[str], banner: str):
        self.process = subprocess.Popen([sys.executable, "-m", "appsim", *argv], stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True, cwd=KIT,
                                        env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.out: list[str] = []
        self.err: list[str] = []
        self.banner, self.seen = banner, threading.Event()
        self.readers = [threading.Thread(target=self._read, args=(self.process.stdout, self.out), daemon=True),
                        threading.Thread(target=self._read, args=(self.process.stderr, self.err), daemon=True)]
        for reader in self.readers:
            reader.start()

    def _read(self, stream, lines: list[str]) -> None:
        for line in stream:
            lines.append(line)
            if self.banner in line:
                self.seen.set()
        self.seen.set()

    def interrupt(self) -> tuple[str, str]:
        """Ctrl-C, then its stdout and stderr; the test fails if the run has not ended within `ENDS_S`."""
        self.process.send_signal(signal.SIGINT)
        try:
            self.process.wait(timeout=ENDS_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"Ctrl-C did not end the run within {ENDS_S:g} s")
        for reader in self.readers:
            reader.join(5)
        return "".join(self.out), "".join(self.err)


@contextmanager
def started(argv: list[str], banner: str, ready: Callable[[], bool] | None = None) -> Iterator[Running]:
    """`appsim ARGV` running, once it has printed `banner` (or `ready()` says it runs: stdout may be held in a buffer
    until it is full); killed at the end whatever happened."""
    running = Running(argv, banner)
    try:
        ends = time.monotonic() + 60
        while not (running.seen.is_set() or (ready is not None and ready())) and time.monotonic() < ends:
            time.sleep(0.05)
        assert running.process.poll() is None, "".join(running.out + running.err)
        assert running.seen.is_set() or (ready is not None and ready()), "it never started"
        yield running
    finally:
        running.process.kill()
        running.process.wait()


# ---------------------------------------------------------------------- FIFOs
@pytest.mark.parametrize("command", COMMANDS)
def test_a_fifo_whose_reader_stalls_never_blocks_the_run_and_ctrl_c_ends_it_with_every_file_whole(tmp_path, command):
    argv, banner = COMMANDS[command]
    line = fifo(tmp_path, "line" + SUFFIX.get(command, ".vcd"))
    stalled = os.open(line, os.O_RDONLY | os.O_NONBLOCK)        # a reader that opens it and never reads
    fcntl.fcntl(stalled, F_SETPIPE_SZ, SMALLEST_PIPE)
    try:
        with started([arg.format(fifo=line, tmp=tmp_path) for arg in argv], banner,
                     ready=lambda: bool(select.select([stalled], [], [], 0)[0])) as running:
            time.sleep(3)                                       # long enough to fill the pipe, in real time too
            _, err = running.interrupt()
    finally:
        os.close(stalled)
    assert running.process.returncode == 130 and "Traceback" not in err, err
    said = re.search(rf"{line} holds its first (\d+) frames \(its reader fell behind: ([\d,]+) frames? dropped\)",
                     err)
    assert said, err
    if "--vcd" in command and "monitor" not in command:     # faster than real time, big records: the backlog fills
        assert err.count(f"{line}: its reader fell behind") == 1, "said as it happened, once"
    logged = tmp_path / "trace.log"
    if logged.exists():
        frames = re.search(rf"{logged} holds its first (\d+) frames", err)
        assert frames and len(list(can.LogReader(logged))) == int(frames[1]), "the regular log is whole"


@contextmanager
def reader_after(path: Path, seconds: float) -> Iterator[None]:
    """A reader that opens `path` after `seconds` (and never reads), if the block has not ended by then."""
    done = threading.Event()
    opened: list[int] = []
    timer = threading.Thread(target=lambda: done.wait(seconds) or opened.append(os.open(path, os.O_RDONLY |
                                                                                        os.O_NONBLOCK)), daemon=True)
    timer.start()
    try:
        yield
    finally:
        done.set()
        timer.join()
        for fd in opened:
            os.close(fd)


def read_slowly(path: Path, got: bytearray, chunk: int = 1024, pause_s: float = 0.02) -> threading.Thread:
    def read() -> None:
        with open(path, "rb") as reader:
            while data := reader.read(chunk):
                got.extend(data)
                time.sleep(pause_s)
    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    return thread


def totals(out: str) -> int:
    """Frames and error frames the run's summary counts."""
    frames, errors = re.search(r"^(\d+) frames, (\d+) error frames in", out, re.M).groups()
    return int(frames) + int(errors)


def test_a_reader_too_slow_for_the_waveform_gets_whole_records_and_the_rest_is_counted(tmp_path):
    line = fifo(tmp_path)
    got = bytearray()
    reader = read_slowly(line, got)
    result = appsim("classroom", "--seconds", "120", "--vcd", str(line))
    reader.join(30)
    assert result.returncode == 0, result.stderr
    said = re.search(rf"wrote {line} \(waveform for PulseView, (\d+) frames\); its reader fell behind: ([\d,]+) "
                     r"frames? dropped", result.stdout)
    assert said, result.stdout
    written, dropped = int(said[1]), int(said[2].replace(",", ""))
    assert written + dropped == totals(result.stdout), "every frame is in the file or counted"
    text = got.decode("ascii")
    assert text.startswith("$version appsim.can.vcd $end") and "$enddefinitions $end" in text
    body = text.split("$end\n#0\n$dumpvars\n1!\n$end\n", 1)[1].splitlines()
    assert body and all(re.fullmatch(r"#\d+|[01]!", entry) for entry in body), "whole lines, nothing cut"


def test_a_reader_that_closes_the_fifo_ends_that_output_the_run_goes_on_and_says_how_far_it_got(tmp_path):
    line = fifo(tmp_path, "line.log")

    def read_a_little() -> None:
        with open(line, "rb") as reader:
            fcntl.fcntl(reader.fileno(), F_SETPIPE_SZ, SMALLEST_PIPE)
            reader.read(300)

    reader = threading.Thread(target=read_a_little, daemon=True)
    reader.start()
    result = appsim("classroom", "--seconds", "120", "--log", str(line))
    reader.join(10)
    assert result.returncode == 0 and "Invalid argument" not in result.stdout + result.stderr, result.stderr
    said = re.search(rf"wrote {line} \(candump -L format, (\d+) frames\); its reader closed it after (\d+) frames?: "
                     r"([\d,]+) frames? after that not written", result.stdout)
    assert said, result.stdout
    assert said[1] == said[2] and int(said[2]) + int(said[3].replace(",", "")) == totals(result.stdout)
    assert "the program reading it closed it" in result.stderr, "said as it happened"


def test_a_fifo_nobody_reads_is_waited_for_with_a_message_and_ctrl_c_gives_up(tmp_path):
    line = fifo(tmp_path)
    waiting = f"appsim: {line} is a FIFO (named pipe): waiting for a program to open it for reading"
    with started(["classroom", "--vcd", str(line)], waiting) as running:
        assert any(waiting in told for told in running.err), "it says at once why nothing happens"
        out, err = running.interrupt()
    assert running.process.returncode == 130 and out == ""
    assert f"interrupted (Ctrl-C) while waiting for a program to read the FIFO {line}: nothing ran" in err


def test_a_fifo_nobody_opens_in_time_is_refused_before_anything_runs(tmp_path, monkeypatch, capsys):
    from appsim import output
    monkeypatch.setattr(output, "FIFO_WAIT_S", 0.3)
    line = fifo(tmp_path)
    with reader_after(line, 20):            # should the command block in open() instead, the test ends all the same
        assert main(["classroom", "--vcd", str(line)]) == 2
    said = capsys.readouterr()
    assert said.out == "" and f"appsim: cannot write {line}: it is a FIFO (named pipe) and no program opened it " \
                              "for reading in 0.3 s: start the reader first" in said.err


def test_a_blf_log_is_refused_on_a_fifo_as_it_is_written_last_at_its_start(tmp_path):
    line = fifo(tmp_path, "line.blf")
    holder = os.open(line, os.O_RDONLY | os.O_NONBLOCK)
    try:
        result = appsim("classroom", "--log", str(line))
    finally:
        os.close(holder)
    assert result.returncode == 2 and result.stdout == ""
    assert "a .blf file's header is written last, at its start: give a file name, or log .log or .asc" in \
           result.stderr


# ---------------------------------------------------------------------- full disks, places one cannot write
@pytest.mark.parametrize("argv", [
    ["classroom", "--vcd", "/dev/full"],
    ["classroom", "--log", "/dev/full"],
    ["board", "exercises/ex1.py", "--log", "{tmp}/full.asc"],         # a symbolic link to /dev/full
    ["demo", "--out", "{tmp}/demo", "--vcd", "/dev/full"],
    ["monitor", "--transport", "socket", "--vcd", "/dev/full"],
])
def test_dev_full_is_a_full_disk_in_those_words(tmp_path, argv):
    (tmp_path / "full.asc").symlink_to("/dev/full")
    result = appsim(*(arg.format(tmp=tmp_path) for arg in argv))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert re.search(r"appsim: cannot write \S+: the disk is full", result.stderr), result.stderr
    assert "Invalid argument" not in result.stderr


def as_ordinary_user() -> dict[str, object]:
    """subprocess options that run a command as an ordinary user: this one, or `nobody` when the tests run as root."""
    if os.geteuid() != 0:
        return {}
    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: no ordinary user to try it as")
    closed = [str(p) for p in (Path(sys.executable), KIT) for p in p.resolve().parents if not p.stat().st_mode & 0o001]
    if closed:
        pytest.skip(f"this Python or the kit lies under {closed[0]}, closed to other users (a pyenv in root's home): "
                    "nobody cannot run it (CI runs the tests in a venv of Debian's Python, which nobody can)")
    return {"user": 65534, "group": 65534, "extra_groups": []}


def test_as_an_ordinary_user_a_folder_one_cannot_write_and_a_full_disk_are_said_in_their_own_words():
    place = Path(tempfile.mkdtemp(prefix="appsim-readonly-"))
    try:
        place.chmod(0o755)
        (place / "locked").mkdir(mode=0o555)
        no_permission = "no permission to write there: give a path where you can write"
        for argv, said in ((["classroom", "--log", f"{place}/locked/trace.log"],
                            f"cannot write {place}/locked/trace.log: {no_permission}"),
                           (["classroom", "--vcd", f"{place}/locked/line.vcd"],
                            f"cannot write {place}/locked/line.vcd: {no_permission}"),
                           (["demo", "--out", f"{place}/locked"], f"cannot write {place}/locked/trace.log: "
                                                                  f"{no_permission}"),
                           (["classroom", "--vcd", "/dev/full"], "cannot write /dev/full: the disk is full")):
            result = appsim(*argv, **as_ordinary_user())
            assert result.returncode == 2 and result.stdout == "", result.stderr
            assert f"appsim: {said}" in result.stderr, result.stderr
    finally:
        shutil.rmtree(place)


# ---------------------------------------------------------------------- one file, two names
# Ways to give two outputs (or an output and the firmware) one file: argv, and what the refusal names.
NAMED_TWICE = {
    "the same name": (["classroom", "--vcd", "same.log", "--log", "same.log"], "--log same.log and --vcd same.log"),
    "./x and x": (["classroom", "--log", "./x.log", "--log", "x.log"], "--log x.log and --log x.log"),
    "a symbolic link": (["classroom", "--log", "x.log", "--vcd", "link.vcd"], "--log x.log and --vcd link.vcd"),
    "a hard link": (["classroom", "--log", "x.log", "--vcd", "hard.vcd"], "--log x.log and --vcd hard.vcd"),
    "sub/..": (["classroom", "--log", "sub/../x.log", "--vcd", "x.log"], "--log sub/../x.log and --vcd x.log"),
    "a dangling link": (["classroom", "--log", "new.log", "--vcd", "dangling.vcd"],
                        "--log new.log and --vcd dangling.vcd"),
    "the demo's own log": (["demo", "--out", "out", "--vcd", "out/trace.asc"],
                           "--out out/trace.asc and --vcd out/trace.asc"),
    "the firmware": (["board", "mine.py", "--vcd", "mine.py"],
                     "--vcd mine.py is FIRMWARE mine.py, which this command reads: writing it would destroy it"),
    "the joined firmware": (["classroom", "--exercise", "3", "--join", "mine.py", "--vcd", "./mine.py"],
                            "--vcd mine.py is --join mine.py, which this command reads"),
    "/dev/stdout": (["classroom", "--log", "/dev/stdout"],
                    "--log /dev/stdout is standard output, where appsim prints its report: writing it would mix"),
}


@pytest.mark.parametrize("way", NAMED_TWICE)
def test_two_outputs_naming_one_file_are_refused_before_anything_runs(tmp_path, way):
    (tmp_path / "x.log").write_text("kept\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "link.vcd").symlink_to(tmp_path / "x.log")
    os.link(tmp_path / "x.log", tmp_path / "hard.vcd")
    (tmp_path / "dangling.vcd").symlink_to(tmp_path / "new.log")
    firmware = (KIT / "solutions" / "ex3.py").read_text()
    (tmp_path / "mine.py").write_text(firmware)
    argv, said = NAMED_TWICE[way]
    result = appsim(*argv, cwd=tmp_path)
    assert result.returncode == 2 and result.stdout == "", result.stdout
    assert said in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert (tmp_path / "x.log").read_text() == "kept\n" and not (tmp_path / "same.log").exists()
    assert (tmp_path / "mine.py").read_text() == firmware and not (tmp_path / "new.log").exists()


def test_the_report_redirected_into_a_log_it_also_writes_is_refused(tmp_path):
    report = tmp_path / "report.log"
    with report.open("w") as stdout:
        result = subprocess.run([sys.executable, "-m", "appsim", "classroom", "--log", str(report)], stdout=stdout,
                                stderr=subprocess.PIPE, text=True, cwd=KIT, timeout=120)
    assert result.returncode == 2 and report.read_text() == ""
    assert f"--log {report} is standard output, where appsim prints its report" in result.stderr


def test_dev_null_may_take_every_output(tmp_path):
    result = appsim("classroom", "--seconds", "0.3", "--log", "/dev/null", "--vcd", "/dev/null")
    assert result.returncode == 0, result.stderr
    assert "wrote /dev/null (candump -L format, " in result.stdout and "wrote /dev/null (waveform" in result.stdout


@pytest.mark.parametrize("options, said", [
    (["--json", "{tmp}/grades.jsonl", "--csv", "{tmp}/grades.jsonl"],
     "--json {tmp}/grades.jsonl and --csv {tmp}/grades.jsonl name one file"),
    (["--csv", "{tmp}/class.zip"], "--csv {tmp}/class.zip is PATH {tmp}/class.zip, which this command reads"),
    (["--json", "{tmp}/link.jsonl", "--gradescope", "{tmp}/grades.jsonl"],
     "--json {tmp}/link.jsonl and --gradescope {tmp}/grades.jsonl name one file"),
])
def test_appsim_grade_refuses_an_output_named_twice_or_over_a_submission(tmp_path, capsys, options, said):
    with zipfile.ZipFile(tmp_path / "class.zip", "w") as archive:
        archive.writestr("alice/ex1.py", (KIT / "solutions" / "ex1.py").read_text())
    before = (tmp_path / "class.zip").read_bytes()
    (tmp_path / "grades.jsonl").write_text("")
    (tmp_path / "link.jsonl").symlink_to(tmp_path / "grades.jsonl")
    status = main(["grade", str(tmp_path / "class.zip"), *(o.format(tmp=tmp_path) for o in options)])
    err = capsys.readouterr().err
    assert status == 2 and said.format(tmp=tmp_path) in err, err
    assert (tmp_path / "class.zip").read_bytes() == before


def test_dev_tty_is_the_terminal_the_report_goes_to(tmp_path):
    """`--vcd /dev/tty` in a terminal: /dev/tty is the terminal the report is printed on, by another name."""
    import pty
    import termios
    master, slave = pty.openpty()
    try:
        process = subprocess.Popen([sys.executable, "-m", "appsim", "classroom", "--vcd", "/dev/tty"], stdin=slave,
                                   stdout=slave, stderr=slave, cwd=KIT, start_new_session=True,
                                   preexec_fn=lambda: fcntl.ioctl(0, termios.TIOCSCTTY, 0))
        os.close(slave)
        said = bytearray()
        ends = time.monotonic() + 60
        while process.poll() is None and time.monotonic() < ends:
            try:
                said += os.read(master, 4096)
            except OSError:
                break
        process.wait(timeout=10)
    finally:
        os.close(master)
    assert process.returncode == 2, said.decode(errors="replace")
    assert b"--vcd /dev/tty is standard output, where appsim prints its report" in said
