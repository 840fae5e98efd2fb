"""An output file a run writes as it goes (a log, a waveform, the LCDs' picture, a gradebook): checked before anything
runs, written in whole records that never block the simulation, each failure said in the workshop's words.

A regular file gets every record whole, and a full disk cuts it back to its last whole record. A FIFO, a pipe or a
terminal is written without blocking: what its reader has not taken yet waits in a bounded backlog, a record that finds
the backlog full is dropped and counted, and a reader that closes ends that output (counted), not the run.
"""
from __future__ import annotations

import errno
import io
import os
import select
import stat
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable
from contextlib import suppress
from pathlib import Path

from appsim.errors import OutputError

BACKLOG_BYTES = 1 << 20     # what a FIFO's, a pipe's or a terminal's reader may fall behind by before records drop
DRAIN_S = 0.5               # at the end of a run, how long the backlog may take to reach its reader (Ctrl-C: < 1 s)
FIFO_WAIT_S = 60.0          # how long a FIFO that no program reads is waited for, then refused
FIFO_POLL_S = 0.05

_REASONS = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is used up",
    errno.EFBIG: "the file is larger than that file system or your limits allow",
    errno.EROFS: "that file system is read-only: give a path where you can write",
    errno.EACCES: "no permission to write there: give a path where you can write",
    errno.EPERM: "no permission to write there: give a path where you can write",
    errno.EISDIR: "that is a directory: give a file name such as trace.log",
    errno.ENOTDIR: "a part of that path is a file, not a directory",
    errno.ENAMETOOLONG: "that name is too long for the file system",
    errno.ELOOP: "that path goes round a loop of symbolic links",
    errno.ETXTBSY: "that file is a program that is running",
    errno.EPIPE: "the program reading it closed it",
    errno.ENXIO: "no program has that FIFO open for reading, or that device is not there",
    errno.EIO: "the device reported an input/output error (a terminal that was closed, a failing disk)",
}


def reason(error: OSError, path: Path | None = None) -> str:
    """What went wrong, in words that say what to do."""
    if error.errno == errno.ENOENT and path is not None:
        return f"there is no directory {path.parent}: create it first, or give another path"
    return _REASONS.get(error.errno or 0) or error.strerror or str(error)


def cannot_write(path: str | Path, error: OSError) -> OutputError:
    """The error for a file the kit cannot write, in words that say what to do."""
    return OutputError(f"cannot write {path}: {reason(error, Path(path))}")


def say_on_stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------- one file per output
def _identity(path: Path) -> tuple[object, ...]:
    """What tells one file from another however it is named (a symbolic or hard link, ./x or x, /dev/stdout): its
    device and inode if it exists, else its absolute path with every link resolved."""
    try:
        return _file(path.stat())
    except OSError:
        return ("new", os.path.realpath(path))


def _file(info: os.stat_result) -> tuple[object, ...]:
    if not stat.S_ISCHR(info.st_mode):
        return ("file", info.st_dev, info.st_ino)
    if info.st_rdev == _CONTROLLING_TERMINAL:     # /dev/tty: the terminal the command runs in, by its own name
        for fd in (0, 1, 2):
            with suppress(OSError):
                return ("device", os.stat(os.ttyname(fd)).st_rdev)
    return ("device", info.st_rdev)


_CONTROLLING_TERMINAL = os.makedev(5, 0)


_PRINTED = ((1, "standard output, where appsim prints its report"),
            (2, "standard error, where appsim prints its progress and warnings"))


def check_distinct(outputs: Iterable[tuple[str, Path | None]], inputs: Iterable[tuple[str, Path | None]] = ()) -> None:
    """An `OutputError` before anything runs if two of `outputs` ((what, path): "--log", trace.log) are one file, or
    one of them is one of `inputs` (a firmware, a submission) or where the command prints (/dev/null may be many)."""
    null = _identity(Path(os.devnull))
    taken: dict[tuple[object, ...], tuple[str, str]] = {}       # a file -> (what it is, what writing it would do)
    for fd, where in _PRINTED:
        with suppress(OSError):
            taken.setdefault(_file(os.fstat(fd)), (where, "mix the two"))
    for what, path in inputs:
        if path is not None:
            taken.setdefault(_identity(Path(path)), (f"{what} {path}, which this command reads", "destroy it"))
    for what, path in outputs:
        if path is None or (key := _identity(Path(path))) == null:
            continue
        if key in taken:
            other, harm = taken[key]
            if harm:
                raise OutputError(f"{what} {path} is {other}: writing it would {harm}; give {what} a file of its own")
            raise OutputError(f"{other} and {what} {path} name one file: each output needs a file of its own")
        taken[key] = (f"{what} {path}", "")


# ---------------------------------------------------------------------- the file
class OutputFile(io.RawIOBase):
    """The file under a writer (python-can's, the VCD's, a picture's): what it writes waits here until `commit()`
    hands it to the operating system as one record. Opening it is the check that the path can be written: a FIFO
    that no program reads is waited for (`FIFO_WAIT_S`, `waiting` says so), then refused.

    `needs_seek`, if given, says why this output cannot go to a FIFO, a pipe or a terminal (a .blf's header is written
    last). `keep_until_written`: the file is not emptied until the first record (a picture written at the end), and
    one the kit created is removed again if none came."""

    def __init__(self, path: str | Path, *, needs_seek: str | None = None, keep_until_written: bool = False,
                 waiting: Callable[[str], None] = say_on_stderr):
        super().__init__()
        self.path = Path(path)
        self.name = str(path)
        self.delivered = 0              # records the reader has whole (a file: records in it)
        self.fell_behind = 0            # records dropped: the reader of a stream was too slow
        self.after_close = 0            # records not written: the reader of a stream had closed it
        self.reader_closed_after: int | None = None     # records it had when its reader closed it
        self._pending = bytearray()
        self._backlog: deque[tuple[memoryview, bool]] = deque()     # a stream's records its reader has not taken
        self._backlog_bytes = 0
        self._position = 0              # the operating system's file position (a regular file)
        self._whole = 0                 # the file's length after the last commit
        self._truncate = keep_until_written
        existed = os.path.lexists(self.path)
        self._fd = self._open(waiting, keep_until_written)
        self.stream = not stat.S_ISREG(os.fstat(self._fd).st_mode)
        self._created = keep_until_written and not existed      # removed again if nothing comes
        if self.stream:
            if needs_seek is not None:
                os.close(self._fd)
                raise OutputError(f"cannot write {path}: that is not a regular file (a FIFO, a pipe or a terminal), "
                                  f"and {needs_seek}")
            os.set_blocking(self._fd, False)

    def _open(self, waiting: Callable[[str], None], keep: bool) -> int:
        flags = os.O_WRONLY | os.O_CREAT | os.O_NONBLOCK | os.O_CLOEXEC | (0 if keep else os.O_TRUNC)
        try:
            info = self.path.stat()
        except OSError:
            info = None
        if info is not None and stat.S_ISSOCK(info.st_mode):
            raise OutputError(f"cannot write {self.path}: that is a socket, not a file: give a file name")
        fifo = info is not None and stat.S_ISFIFO(info.st_mode)
        deadline = time.monotonic() + FIFO_WAIT_S
        told = False
        try:
            while True:
                try:
                    return os.open(self.path, flags, 0o666)
                except OSError as error:
                    if not (fifo and error.errno == errno.ENXIO):
                        raise cannot_write(self.path, error) from None
                if time.monotonic() >= deadline:
                    raise OutputError(f"cannot write {self.path}: it is a FIFO (named pipe) and no program opened it "
                                      f"for reading in {FIFO_WAIT_S:g} s: start the reader first (e.g. cat "
                                      f"{self.path} > copy), or give a file name")
                if not told:
                    waiting(f"appsim: {self.path} is a FIFO (named pipe): waiting for a program to open it for "
                            f"reading (up to {FIFO_WAIT_S:g} s; nothing runs until then; Ctrl-C gives up)")
                    told = True
                time.sleep(FIFO_POLL_S)
        except KeyboardInterrupt:
            if not fifo:
                raise
            raise KeyboardInterrupt(f"interrupted (Ctrl-C) while waiting for a program to read the FIFO "
                                    f"{self.path}: nothing ran") from None

    # ------------------------------------------------------------------ what a writer sees
    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return not self.stream

    def write(self, data: bytes) -> int:    # type: ignore[override]
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self._position + len(self._pending)

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        if self.stream:
            raise io.UnsupportedOperation(f"{self.path} is a stream: it cannot seek")
        self.commit(counted=False)
        self._position = os.lseek(self._fd, offset, whence)
        return self._position

    # ------------------------------------------------------------------ records
    def commit(self, *, counted: bool = True) -> bool:
        """Hand what the writer wrote since the last commit to the operating system as one record (`counted`: one
        of the records the counts count). True if it went (or waits for the stream's reader), False if it was dropped
        (the reader fell behind, or closed it). Raises OSError if it cannot be written (a full disk, an input/output
        error): a regular file is cut back to its last whole record first."""
        record, self._pending = bytes(self._pending), bytearray()
        if self.stream:
            return self._to_stream(record, counted)
        self._to_file(record)
        self.delivered += counted
        return True

    def _to_file(self, record: bytes) -> None:
        try:
            if self._truncate:
                os.ftruncate(self._fd, 0)
                self._truncate = self._created = False
            done = 0
            while done < len(record):
                done += os.write(self._fd, record[done:])
        except OSError:
            with suppress(OSError):
                os.ftruncate(self._fd, self._whole)
                self._position = os.lseek(self._fd, self._whole, os.SEEK_SET)
            raise
        self._position += len(record)
        self._whole = max(self._whole, self._position)

    def _to_stream(self, record: bytes, counted: bool) -> bool:
        self._send_backlog()
        if self.reader_closed_after is not None:
            self.after_close += counted
            return False
        if self._backlog:
            if self._backlog_bytes + len(record) > BACKLOG_BYTES:
                self.fell_behind += counted
                return False
            self._queue(memoryview(record), counted)
            return True
        done = self._send(memoryview(record))
        if done is None:
            self.after_close += counted
            return False
        if done < len(record):           # the rest of a record begun goes, whatever the backlog holds
            self._queue(memoryview(record)[done:], counted)
        else:
            self.delivered += counted
        return True

    def _queue(self, rest: memoryview, counted: bool) -> None:
        self._backlog.append((rest, counted))
        self._backlog_bytes += len(rest)

    def _send(self, data: memoryview) -> int | None:
        """Write what the stream takes now: the bytes written, or None if its reader has closed it."""
        try:
            return os.write(self._fd, data)
        except BlockingIOError:
            return 0
        except (BrokenPipeError, ConnectionResetError):
            self.reader_closed_after = self.delivered
            self.after_close += sum(counted for _, counted in self._backlog)
            self._backlog.clear()
            self._backlog_bytes = 0
            return None

    def _send_backlog(self) -> None:
        while self._backlog:
            data, counted = self._backlog[0]
            done = self._send(data)
            if done is None:
                return
            self._backlog_bytes -= done
            if done < len(data):
                self._backlog[0] = (data[done:], counted)
                return
            self._backlog.popleft()
            self.delivered += counted

    def _drain(self, deadline: float) -> None:
        """Give the reader until `deadline` (time.monotonic()) to take the backlog; a Ctrl-C meanwhile ends the wait."""
        poller = select.poll()
        poller.register(self._fd, select.POLLOUT)
        try:
            while self._backlog and (left := deadline - time.monotonic()) > 0:
                poller.poll(max(1, int(left * 1000)))
                self._send_backlog()
        except KeyboardInterrupt:
            pass
        self.fell_behind += sum(counted for _, counted in self._backlog)
        self._backlog.clear()

    def close(self, drain_until: float | None = None) -> None:
        """Write what is pending; a stream's reader gets until `drain_until` (time.monotonic(); by default `DRAIN_S`
        from now) to take what waits for it, the rest is counted."""
        if self.closed:
            return
        try:
            if self._pending:
                self.commit(counted=False)
            if self.stream:
                self._drain(time.monotonic() + DRAIN_S if drain_until is None else drain_until)
        finally:
            os.close(self._fd)
            if self._created:
                with suppress(OSError):
                    self.path.unlink()
            super().close()

    # ------------------------------------------------------------------ what became of the records
    def losses(self, unit: str = "record") -> str:
        """What the reader of a stream did not get, in a few words ("" if it got them all); `unit` names a record."""
        said = []
        if self.fell_behind:
            said.append(f"its reader fell behind: {count(self.fell_behind, unit)} dropped")
        if self.reader_closed_after is not None:
            said.append(f"its reader closed it after {count(self.reader_closed_after, unit)}: "
                        f"{count(self.after_close, unit)} after that not written")
        return "; ".join(said)


def count(number: int, unit: str) -> str:
    """ "1 frame", "2 frames"."""
    return f"{number:,} {unit}{'' if number == 1 else 's'}"
