"""`appsim grade` attacked as a dishonest student would: one class run with honest classmates and one attacker
submission per attack, each attack built on the Ex1 starter (3 of 5 points when handed in as it is).

What must hold: no attacker earns more than the starter's honest marks; where the attack did something (the sandbox
refused a call, the grader caught a forged message, a limit stopped it) the record says what; every honest classmate's
record is the one it gets in a run of the class without any attacker; nothing of the run is left behind (no process,
no temporary folder), and nothing outside the sandbox was read or written.

An attack that fails silently goes on as the starter, so its record is the starter's, check for check. An attack that
gets through shows it: a stolen solution (or classmate's file) is run, for full marks; anything else raises an error
that names the route, so its record differs from the starter's.

Two attacks stand alone: killing the grader itself while a firmware runs (nothing of it may run on), and a zip that
names its folders after classmates (the class must still be graded); and a --trusted run must leave no folder either.

Signals aimed outside the sandbox (at the grader, its workers, classmates' sandboxes) are sent as signal 0: the kernel
makes the same checks (can this process be named? may it be signalled?) without the harm, should a wall ever fail.
"""
from __future__ import annotations

import ctypes
import dataclasses
import hashlib
import io
import json
import os
import platform
import secrets
import signal
import struct
import subprocess
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest

from appsim.workshop.course import EXERCISE_FILES
from appsim.workshop.grading.grade import run
from appsim.workshop.sandbox.children import Limits

KIT = Path(__file__).resolve().parent.parent
SOLUTIONS = KIT / "solutions"
STARTER_EX1 = (KIT / "exercises" / "ex1.py").read_text()
SEED = 2024
LIMITS = Limits(time_s=8, stall_s=2, memory_mb=128)
SECRET_NAME = "APPSIM_ATTACK_TEST_SECRET"        # in the grader's environment during the attacked run only
RUN_MARK = "APPSIM_ATTACK_TEST_RUN"             # marks every process the graded runs start (for the leftover check)
SOLUTION_MARK = b"RX_Filter0 = MESSAGE_ID1"      # a line only the reference solution of Ex1 has
RUNS_AS_ROOT = os.geteuid() == 0


def solution(exercise: str) -> str:
    return (SOLUTIONS / EXERCISE_FILES[exercise]).read_text()


FULL = {exercise: solution(exercise) for exercise in EXERCISE_FILES}
HONEST = {                                      # names spread among the attackers', so they grade alongside them
    "alice_full": FULL,
    "ken_starter": {"ex1": STARTER_EX1},        # the honest marks every attacker is held to
    "pat_full": FULL,
    "zoe_ex1_ex2": {"ex1": solution("ex1"), "ex2": solution("ex2")},
}


# ====================================================================== what every attack file starts with

COMMON = r'''
import json as _json, os as _os, signal as _signal, struct as _struct, sys as _sys, time as _time

from appsim.chip.sfr import current_mcu as _current_mcu

_FDS = {"read_fd": _current_mcu()._channel.read_fd,     # the sandbox child's two pipe ends, as its firmware library
        "write_fd": _current_mcu()._channel.write_fd}   # (which it can patch at will) holds them


def _syscall(number, *args):
    """A raw system call by number (libc's syscall()): its result and errno."""
    import ctypes
    global _LIBC
    if "_LIBC" not in globals():
        _LIBC = ctypes.CDLL(None, use_errno=True)
        _LIBC.syscall.restype = ctypes.c_long
    ctypes.set_errno(0)
    result = _LIBC.syscall(ctypes.c_long(number), *[ctypes.c_long(a) if isinstance(a, int) else a for a in args])
    return result, ctypes.get_errno()


def _say(data):
    """Bytes to the grader, on the pipe the firmware library writes its messages to."""
    view = memoryview(data)
    while view:
        view = view[_os.write(_FDS["write_fd"], view):]


def _message(body):
    return _struct.pack("<I", len(body)) + body


def _outside_pids():
    """The grader's PID and the PIDs its workers and classmates' sandboxes have on the machine (near it)."""
    grader = _CTX["grader_pid"]
    near = {*range(2, 40000), *range(max(2, grader - 500), grader + 20000)} - {1, _os.getpid(), grader}
    return [grader, *sorted(near)]
'''


def attack(body: str, *, top: str = "") -> str:
    """The Ex1 starter with `top` after its import line and `body` first in its main() (`_CTX` is added per run)."""
    head, rest = STARTER_EX1.split("from appsim.firmware import *\n", 1)
    source = head + "from appsim.firmware import *\n@CTX@\n" + COMMON + top + "\n" + rest
    body = "".join(f"    {line}\n" for line in body.strip("\n").splitlines())
    assert source.count("def main():\n") == 1
    return source.replace("def main():\n", "def main():\n" + body, 1)


# ---------------------------------------------------------------------- kill or stop anything
KILL_SIGNALS = attack("_attack()", top=r'''
def _attack():
    reached = []
    for target in sorted({_os.getppid(), 1}):           # its parent, and pid 1 of its namespace (bubblewrap)
        for sig in (_signal.SIGSTOP, _signal.SIGKILL):  # never delivered to any init, should this one be the machine's
            try:
                _os.kill(target, sig)
            except OSError:
                pass
    for pid in _outside_pids():
        try:
            _os.kill(pid, 0)
        except ProcessLookupError:
            continue
        except OSError:
            pass                                        # EPERM: it exists and can be named
        reached.append(f"kill({pid})")
    for name, call in (("kill(-1)", lambda: _os.kill(-1, 0)),
                       ("killpg(grader)", lambda: _os.killpg(_CTX["grader_pgid"], 0)),
                       ("getpriority(grader)", lambda: _os.getpriority(_os.PRIO_PROCESS, _CTX["grader_pid"])),
                       ("sched_setaffinity(grader)", lambda: _os.sched_setaffinity(_CTX["grader_pid"], {0})),
                       ("prlimit(grader)", lambda: __import__("resource").prlimit(_CTX["grader_pid"], 7))):
        try:
            call()
        except (ProcessLookupError, PermissionError):
            continue
        reached.append(name)
    if reached:
        raise RuntimeError("the sandbox reached other processes: " + ", ".join(reached[:8]))
''')

KILL_PIDFD = attack("_attack()", top=r'''
def _attack():
    import fcntl
    reached = []
    own_init, _ = _syscall(434, 1, 0)                   # pidfd_open(1, 0)
    if own_init >= 0:
        for sig in (_signal.SIGSTOP, _signal.SIGKILL):
            _syscall(424, own_init, sig, None, 0)       # pidfd_send_signal: a namespace's init ignores them
        _os.close(own_init)
    import platform
    x86_64 = platform.machine() == "x86_64"
    for pid in _outside_pids():
        fd, _ = _syscall(434, pid, 0)
        if fd >= 0:
            _os.close(fd)
            reached.append(f"pidfd_open({pid})")
        if x86_64 and (_syscall(200, pid, 0)[0] == 0 or _syscall(234, pid, pid, 0)[0] == 0):   # tkill, tgkill
            reached.append(f"tkill({pid})")
    for owner in (_CTX["grader_pid"], -_CTX["grader_pgid"]):    # SIGIO to the grader when it reads this pipe
        try:
            fcntl.fcntl(_FDS["write_fd"], fcntl.F_SETOWN, owner)
        except ProcessLookupError:
            continue
        reached.append(f"F_SETOWN {owner}")
    if reached:
        raise RuntimeError("the sandbox reached other processes: " + ", ".join(reached[:8]))
''')

KILL_SELF_STOP = attack("_os.kill(_os.getpid(), _signal.SIGSTOP)")
KILL_SELF = attack("_os.kill(_os.getpid(), _signal.SIGKILL)")
KILL_OWN_GROUP = attack("_os.killpg(0, _signal.SIGKILL)")     # its group: itself, and its init, which ignores it

# Its own submission's sandbox: the zygote (pid 1 there, which forks the process of each of this submission's
# exercises) stopped, killed, limited, slowed, read or written by every route. Whatever gets through may cost this
# submission only; its next exercise runs in a fresh process all the same (in a fresh sandbox if need be).
HARM_OWN_SANDBOX = attack("_attack()", top=r'''
def _attack():
    import resource
    tries = [lambda: _os.kill(1, _signal.SIGSTOP), lambda: _os.kill(1, _signal.SIGKILL),
             lambda: _os.kill(1, _signal.SIGTERM), lambda: _os.kill(-1, _signal.SIGSTOP),
             lambda: [_os.kill(1, _signal.SIGCHLD) for _ in range(1000)],
             lambda: resource.prlimit(1, resource.RLIMIT_NOFILE, (3, 3)),
             lambda: resource.prlimit(1, resource.RLIMIT_NPROC, (0, 0)),
             lambda: resource.prlimit(1, resource.RLIMIT_AS, (1 << 20, 1 << 20)),
             lambda: _os.setpriority(_os.PRIO_PROCESS, 1, 19), lambda: _os.sched_setaffinity(1, {0}),
             lambda: open("/proc/1/mem", "r+b").write(b"\\xcc" * 64),
             lambda: open("/proc/1/environ", "rb").read(), lambda: _os.listdir("/proc/1/fd")]
    for harm in tries:
        try:
            harm()
        except (OSError, ValueError):
            pass
''')

# ---------------------------------------------------------------------- read what it must not
READ_HELPERS = r'''
def _read_at(folder, rest):
    descriptor = _os.open(folder, _os.O_RDONLY | _os.O_DIRECTORY)
    try:
        inner = _os.open(rest, _os.O_RDONLY, dir_fd=descriptor)
    finally:
        _os.close(descriptor)
    with open(inner, "rb") as file:
        return file.read()


def _via_link(folder, path):
    link = f"{folder}/link-{abs(hash(path))}"
    if not _os.path.lexists(link):
        _os.symlink(path, link)
    with open(link, "rb") as file:
        return file.read()


def _read(path):
    with open(path, "rb") as file:
        return file.read()


def _routes(path):
    """Every route this sandbox might have to `path` on the grader's machine: (name, reader)."""
    yield "a plain path", lambda: _read(path)
    pids = [p for p in _os.listdir("/proc") if p.isdigit()]
    for root in ["/proc/self/root", "/proc/thread-self/root", *(f"/proc/{p}/root" for p in pids),
                 *(f"/proc/{p}/cwd/../../../../../../.." for p in pids)]:
        yield root, lambda root=root: _read(root + path)
    parts = path.strip("/").split("/")
    for depth in range(len(parts)):
        folder, rest = "/" + "/".join(parts[:depth]), "/".join(parts[depth:])
        yield f"openat({folder}, {rest})", lambda folder=folder, rest=rest: _read_at(folder, rest)
    for folder in ("/firmware", "/tmp"):
        yield f"a symlink in {folder}", lambda folder=folder: _via_link(folder, path)


def _ancestors(path):
    parts = [p for p in path.split("/") if p]
    return ["/" + "/".join(parts[:n]) for n in range(len(parts), 0, -1)]


def _derived(names):
    """Paths to try, found where a sandbox might learn the grader's layout: its mounts and its init's command."""
    seen = []
    with open("/proc/self/mountinfo") as mounts:
        for line in mounts:
            fields = line.split()
            seen += [fields[3], fields[4]]
    try:
        seen += _read("/proc/1/cmdline").decode(errors="replace").split("\0")
    except OSError:
        pass
    try:
        import appsim
        seen.append(_os.path.dirname(_os.path.dirname(appsim.__file__)))
    except ImportError:
        pass
    found = []
    for place in seen:
        if place.startswith("/"):
            for folder in _ancestors(place):
                found += [folder + "/" + name for name in names]
    return list(dict.fromkeys(found))
'''

READ_SOLUTIONS = attack("_attack()", top=READ_HELPERS + r'''
def _by_handle(path, kind, handle):
    """open_by_handle_at() with the file's handle as the grader's machine knows it (the 'shocker' escape)."""
    import ctypes, appsim, platform
    mount = _os.open(_os.path.dirname(appsim.__file__), _os.O_RDONLY)
    try:
        raw = bytes.fromhex(handle)
        buffer = ctypes.create_string_buffer(_struct.pack("<Ii", len(raw), kind) + raw)
        fd, errno = _syscall({"aarch64": 265}.get(platform.machine(), 304), mount, buffer, _os.O_RDONLY)
    finally:
        _os.close(mount)
    if fd < 0:
        raise OSError(errno, "open_by_handle_at")
    with open(fd, "rb") as file:
        return file.read()


def _imported():
    """The kit's own ways to the solutions, as the grader finds them."""
    def by_course():
        from appsim.workshop import course
        return course.solution("ex1").read_bytes()

    def by_resources():
        import importlib.resources
        return (importlib.resources.files("appsim.workshop.solutions") / "ex1.py").read_bytes()

    def by_import():
        import importlib
        return _read(importlib.import_module("appsim.workshop.solutions.ex1").__file__)
    return [("course.solution()", by_course), ("importlib.resources", by_resources), ("import", by_import)]


def _walked():
    for top in ("/work", "/root", "/home", "/srv", "/opt", "/etc", "/tmp", "/firmware", "/proc/1/root/work"):
        for folder, _, files in _os.walk(top):
            for name in files:
                if name == "ex1.py":
                    yield f"a walk of {top}", lambda p=_os.path.join(folder, name): _read(p)


def _steal():
    targets = _CTX["solutions"] + _CTX["classmates"]
    targets += [p for p in _derived(["solutions/ex1.py", "appsim/workshop/solutions/ex1.py"]) if p not in targets]
    routes = [(f"{route} to {target}", read) for target in targets for route, read in _routes(target)]
    routes += [(f"open_by_handle_at({path})", lambda a=(path, *h): _by_handle(*a))
               for path, h in _CTX["handles"].items()]
    import itertools
    for route, read in itertools.chain(routes, _imported(), _walked()):
        try:
            data = read()
        except Exception:                               # this route is closed: the next one
            continue
        if _MARK in data:
            return route, data
    return None


_MARK = b"RX_Filter0 = " + b"MESSAGE_ID1"        # SOLUTION_MARK, not written out here


def _attack():
    found = _steal()
    if found is not None:                               # run the solution: full marks, if this ever got here
        stolen = {"__name__": "stolen"}
        exec(compile(found[1], "ex1.py", "exec"), stolen)
        stolen["main"]()
''')

READ_RECORDS = attack("_attack()", top=READ_HELPERS + r'''
def _attack():
    got = []
    targets = _CTX["results"] + [p for p in _derived(["class.grades.jsonl", "class/alice_full/ex1.py"])]
    for target in targets:
        for route, read in _routes(target):
            try:
                read()
            except Exception:
                continue
            got.append(f"{target} by {route}")
    if got:
        raise RuntimeError("read outside the sandbox: " + "; ".join(got[:5]))
''')

LEAK_ENVIRONMENT = attack("_attack()", top=r'''
def _attack():
    """The environment the grader runs in (tokens, paths...), from the one process of the sandbox that kept it."""
    found = []
    for pid in [p for p in _os.listdir("/proc") if p.isdigit()]:
        try:
            with open(f"/proc/{pid}/environ", "rb") as file:
                environment = file.read().split(b"\0")
        except OSError:
            continue
        found += [item.decode(errors="replace") for item in environment if b"SECRET" in item]
    if found:
        raise RuntimeError("the grader's environment: " + " ".join(found))
''')

KERNEL_SETTINGS = attack("_attack()", top=r'''
def _attack():
    """Kernel settings of the whole machine (core_pattern runs a program as root on the next crash): each opened
    for writing, never written (the kernel checks the permission when a file is opened)."""
    writable = []                                       # (not pid_max: Linux 6.14 gives each PID namespace its own)
    for path in ("/proc/sys/kernel/core_pattern", "/proc/sys/kernel/modprobe", "/proc/sys/kernel/threads-max",
                 "/proc/sys/vm/panic_on_oom", "/proc/sys/fs/file-max", "/proc/sysrq-trigger"):
        try:
            descriptor = _os.open(path, _os.O_WRONLY)
        except OSError:
            continue
        _os.close(descriptor)
        writable.append(path)
    if writable:
        raise RuntimeError("could write the grading machine's kernel settings: " + ", ".join(writable))
''')

# ---------------------------------------------------------------------- append or rewrite grade records
WRITE_RECORDS = attack("_attack()", top=r'''
def _writes(path, line):
    yield "append", lambda: open(path, "a").write(line)
    for root in ("/proc/self/root", "/proc/1/root"):
        yield f"append via {root}", lambda root=root: open(root + path, "a").write(line)
    folder, name = _os.path.split(path)

    def at():
        descriptor = _os.open(folder, _os.O_RDONLY | _os.O_DIRECTORY)
        try:
            inner = _os.open(name, _os.O_WRONLY | _os.O_APPEND | _os.O_CREAT, dir_fd=descriptor)
        finally:
            _os.close(descriptor)
        _os.write(inner, line.encode())
        _os.close(inner)
    yield "openat", at

    def replace():
        temporary = f"{folder}/.{name}.forged"
        with open(temporary, "w") as file:
            file.write(line)
        _os.replace(temporary, path)
    yield "replace", replace

    def link():
        alias = f"/firmware/alias-{abs(hash(path))}"
        if not _os.path.lexists(alias):
            _os.symlink(path, alias)
        open(alias, "a").write(line)
    yield "a symlink in /firmware", link


def _attack():
    record = {"submission": "write_records", "score": 35, "max_score": 35, "seed": _CTX["seed"], "exercises": {}}
    line = _json.dumps(record) + "\n"
    targets = [*_CTX["results"], _CTX["class"] + "/write_records/ex1.py", _CTX["class"] + "/alice_full/ex1.py",
               _CTX["class"] + "/forged/ex1.py"]
    wrote = []
    for target in targets:
        for route, write in _writes(target, line):
            try:
                write()
            except OSError:
                continue
            wrote.append(f"{target} by {route}")
    if wrote:
        raise RuntimeError("wrote outside the sandbox: " + "; ".join(wrote[:5]))
''')

# ---------------------------------------------------------------------- forge the protocol
def forged(data: str, *, at_load: bool = False) -> str:
    """Firmware that writes `data` (a Python expression for bytes) to the grader's pipe, then waits to be judged."""
    if at_load:
        return attack("", top=f"_say({data})\n")
    return attack(f"_say({data})\n_time.sleep(60)")


LONE_READ = '_message(b"B" + _struct.pack("<cHq", b"R", {address}, 0))'
WIRE = {
    "wire_garbage": (forged('b"GARBAGE! \\xff\\xfe not a message at all"'),
                     f"a message of {struct.unpack('<I', b'GARB')[0]} bytes"),
    "wire_4gb_length": (forged('_struct.pack("<I", 0xFFFFFFFF) + b"B"'), "a message of 4294967295 bytes"),
    "wire_huge_message": (forged('_message(b"B" + b"W\\x00\\x00\\x00" * (4 << 20))'), "a message of 16777217 bytes"),
    "wire_zero_length": (forged('_struct.pack("<I", 0)'), "a message of 0 bytes"),
    "wire_nested_identity": (forged('_message(b"L" + b"[" * 20000 + b"]" * 20000)', at_load=True),
                             "an identity too long to be one"),
    "wire_nested_identity_short": (forged('_message(b"L{\\"MESSAGE_ID1\\": " + b"[" * 200 + b"]" * 200 + b"}")',
                                          at_load=True), "an identity whose values are not integers"),
    "wire_fake_loaded_at_load": (forged('_message(b"L" + _json.dumps({"MESSAGE_ID1": 0x100}).encode())',
                                        at_load=True), "a message of kind b'L' while running"),
    "wire_fake_loaded": (forged('_message(b"L{}")'), "a message of kind b'L' while running"),
    "wire_fake_hello": (forged('_message(b"H")'), "a message of kind b'H' while running"),
    "wire_grader_reply": (forged('_message(b"V\\x05")'), "a message of kind b'V' while running"),
    "wire_display_lie": (forged('_message(b"B" + _struct.pack("<cBH", b"D", 2, 1000) + b"abc")'),
                         "a display operation that is not one"),
    "wire_access_after_read": (forged('_message(b"B" + _struct.pack("<cHq", b"R", 0xF00, 0) + '
                                      '_struct.pack("<cHB", b"W", 0xF00, 1))'),
                               "an access after one that waits for its answer"),
    "wire_bad_address": (forged(LONE_READ.format(address=0xFFFF)), "address 0xFFFF is outside"),
    "wire_unknown_access": (forged('_message(b"BX")'), "no access of kind b'X'"),
    "wire_cut_short": (forged('_message(b"B" + _struct.pack("<cHB", b"W", 0xF00, 1)[:2])'), "an access cut short"),
    # a read the child says it answered itself ('r', address, site, value), with a value the board never gave
    "wire_served_lie": (forged('_message(b"B" + _struct.pack("<cHqB", b"r", 0xF00, 0, 0xAB) + '
                               '_struct.pack("<cHq", b"R", 0xF00, 0))'), ""),
}

FAKE_EXITED = forged('_message(b"Q")')
HALF_A_MESSAGE = forged('_struct.pack("<I", 12)[:3]')
CLOSED_PIPES = attack('_os.close(_FDS["write_fd"])\n_os.close(_FDS["read_fd"])\n_time.sleep(3600)')

# ---------------------------------------------------------------------- outlive the grader
OUTLIVE_FORK = attack("if _os.fork() == 0:\n    _time.sleep(3600)")
OUTLIVE_DOUBLE_FORK = attack("""
try:
    _os.setsid()
except OSError:
    pass
if _os.fork() == 0:
    _os.setsid()
    if _os.fork() == 0:
        _time.sleep(3600)
    _os._exit(0)
""")
OUTLIVE_THREAD = attack("import threading\nthreading.Thread(target=_time.sleep, args=(3600,), daemon=False).start()")
OUTLIVE_SUBPROCESS = attack('import subprocess\nsubprocess.Popen(["sleep", "3600"], start_new_session=True)')
OUTLIVE_SPAWN = attack('_os.posix_spawn("/bin/sleep", ["sleep", "3600"], {})')
OUTLIVE_RAW_CALLS = attack("_attack()", top=r'''
def _attack():
    """fork, clone, clone3 (and fork by its x32 number), unshare, setns, io_uring, ptrace, by number."""
    import platform
    if platform.machine() != "x86_64":                 # the numbers below are x86_64's
        return
    made = []
    for name, number, args in (("fork", 57, ()), ("clone", 56, (int(_signal.SIGCHLD), 0, 0, 0, 0)),
                               ("clone3", 435, (None, 0)), ("x32 fork", 0x40000000 | 57, ()),
                               ("unshare", 272, (0x10000000,)), ("setns", 308, (0, 0)),
                               ("io_uring_setup", 425, (8, None)), ("ptrace", 101, (16, 1, 0, 0))):
        result, _ = _syscall(number, *args)
        if result == 0 and name in ("fork", "clone", "x32 fork"):
            _time.sleep(3600)                           # a child that got out
        if result >= 0:
            made.append(name)
    if made:
        raise RuntimeError("the sandbox allowed " + ", ".join(made))
''')
OUTLIVE_I386 = attack("_attack()", top=r'''
def _attack():
    """fork by the 32-bit ABI (int 0x80, eax = 2), which a filter written for x86_64 numbers might miss."""
    import ctypes, mmap, platform
    if platform.machine() != "x86_64":
        raise RuntimeError("this attack is written for x86_64")
    code = mmap.mmap(-1, 4096, prot=mmap.PROT_READ | mmap.PROT_WRITE | mmap.PROT_EXEC)
    code.write(b"\xb8\x02\x00\x00\x00\xcd\x80\xc3")        # mov eax, 2; int 0x80; ret
    pid = ctypes.CFUNCTYPE(ctypes.c_int)(ctypes.addressof(ctypes.c_char.from_buffer(code)))()
    if pid == 0:
        _time.sleep(3600)
    raise RuntimeError(f"int 0x80 fork returned {pid}")
''')

# ---------------------------------------------------------------------- fill the disk
DISK_HUGE_FILE = attack("""
with open("/huge", "wb") as huge:
    for _ in range(256):
        huge.write(bytes(1 << 20))
""")
DISK_FILL = attack("_attack()", top=r'''
def _attack():
    written = 0
    for folder in ("/firmware", "/tmp", "/dev/shm", "/var/tmp", "/"):
        for number in range(64):
            try:
                with open(f"{folder}/fill{number}", "wb") as file:
                    for _ in range(8):
                        file.write(bytes(1 << 20))
                        file.flush()
                        written += 1
            except OSError:
                break
    if written:
        raise RuntimeError(f"wrote {written} MB: the sandbox has no folder to write in")
''')
DISK_MANY_FILES = attack("_attack()", top=r'''
def _attack():
    """Empty files: no bytes of the 32 MB, but an inode and a directory entry each in the kernel's memory."""
    name = "f" * 200
    for folder in ("/", "/dev"):
        for number in range(15000):
            _os.close(_os.open(f"{folder}/{name}{number}", _os.O_WRONLY | _os.O_CREAT, 0o600))
    raise RuntimeError("made 30000 files, about 40 MB of the machine's kernel memory: "
                       "the sandbox has no folder to write in")
''')
DISK_HIDDEN_FOLDER = attack("_attack()", top=r'''
def _attack():
    """The folder of a copy of the solutions on the grader's import path: is it there, can it be written?"""
    folder, written = _CTX["hidden"], 0
    for number in range(8):
        with open(f"{folder}/fill{number}", "wb") as file:
            file.write(bytes(8 << 20))
        written += 8
    raise RuntimeError(f"wrote {written} MB into {folder}: the sandbox has no folder to write in")
''')

# ---------------------------------------------------------------------- flood the output
FLOOD = attack("_attack()", top=r'''
print("FLOOD-MARK at load " * 1000)
_sys.stderr.write("FLOOD-MARK at load " * 1000)


def _attack():
    chunk = b"FLOOD-MARK " * 100000
    for _ in range(16):
        _sys.stdout.write(chunk.decode())
        _sys.stderr.write(chunk.decode())
        _os.write(1, chunk)
        _os.write(2, chunk)
    for fd in (1, 2):                                   # the sandbox's init's own output: the grader's pipes
        try:
            descriptor = _os.open(f"/proc/1/fd/{fd}", _os.O_WRONLY | _os.O_NONBLOCK)
        except OSError:
            continue
        try:
            for _ in range(64):
                _os.write(descriptor, chunk)
        except OSError:
            pass
        _os.close(descriptor)
''')

# ---------------------------------------------------------------------- eat memory
MEMORY_HOARD = attack("hoard = []\nwhile True:\n    hoard.append(bytearray(1 << 20))")
MEMORY_CAUGHT = attack("""
try:
    hoard = bytearray(64 << 30)
except MemoryError:
    pass
""")
MEMORY_FILES = attack("_attack()", top=r'''
def _attack():
    """Memory the address-space limit does not count: files in memory (memfd), each up to the file-size limit."""
    held, files = 0, []
    try:
        while held <= 2 * _CTX["memory_mb"]:
            descriptor = _os.memfd_create("hoard")
            files.append(descriptor)
            for _ in range(_CTX["file_mb"]):
                _os.write(descriptor, b"\x01" * (1 << 20))
                held += 1
    except OSError:
        pass
    if held > _CTX["memory_mb"]:
        raise RuntimeError(f"held {held} MB in memory files, beyond the {_CTX['memory_mb']} MB memory limit")
''')

# ---------------------------------------------------------------------- spin without a word to the board
SPIN_PASS = attack("_spins = 0\nwhile True:\n    _spins += 1")     # `while True: pass` waits for an interrupt
SPIN_SLEEP = attack("_time.sleep(3600)")
SPIN_AT_LOAD = attack("", top="while True:\n    pass\n")

# ---------------------------------------------------------------------- what the sandbox holds
READ_ANSWER_KEYS = attack("_attack()", top=READ_HELPERS + r'''
def _attack():
    """An answer key (the reference Ex1) on the grader's import path and in its current folder: by import, by path."""
    import importlib
    for module in _CTX["answer_modules"]:
        try:
            stolen = importlib.import_module(module).main
        except ImportError:
            continue
        stolen()
    for path in _CTX["answer_files"]:
        try:
            source = _read(path)
        except OSError:
            continue
        found = {"__name__": "stolen"}
        exec(compile(source, "stolen.py", "exec"), found)
        found["main"]()
''')

READ_MOUNT_TABLE = attack("_attack()", top=r'''
def _attack():
    """The mount table names where each bind comes from: none of the grader's own folders may show."""
    with open("/proc/self/mountinfo") as table:
        seen = table.read()
    named = [place for place in _CTX["host_paths"] if place in seen]
    if named:
        raise RuntimeError("the mount table names " + ", ".join(named))
''')

# ---------------------------------------------------------------------- make the grader look at fault
# A byte for a busy USART only fills TXREG: the read-ahead tells the child what PIR1 reads after that write. The child
# writes, then spends the time it takes the USART to finish (which sets TXIF), and claims the value foretold for
# before: the board reads otherwise. It broke the protocol (it spent past its budget): never the grader's mistake.
WIRE_FORETOLD_LIE = attack("_attack()", top=r'''
def _attack():
    mcu = _current_mcu()
    SFR.SPBRG = 129
    SFR.TXSTA = 0x24
    SFR.RCSTA = 0x90
    SFR.TXREG = 0x41
    SFR.PIR1
    foretold = mcu._after.get(0xFAD) if mcu._ahead is not None else None
    if foretold is None:
        raise RuntimeError("no write was foretold: the attack could not be made")
    mcu.flush()
    _say(_message(b"B" + _struct.pack("<cHB", b"W", 0xFAD, 0x42) + _struct.pack("<cQ", b"S", 20000)
                  + _struct.pack("<cHqB", b"r", 0xF9E, 0, foretold[0xF9E]) + _struct.pack("<cHq", b"R", 0xF9E, 0)))
    _time.sleep(60)
''')
WIRE_FAKE_ERROR = forged('_message(b"Z" + _json.dumps(["RuntimeError", "the grader failed"]).encode())')

# ---------------------------------------------------------------------- make the grader keep more
# Every read from a new call site (its library patched): a polling loop that never repeats itself.
SITES_WITHOUT_END = attack("_attack()", top=r'''
def _attack():
    import itertools
    from appsim.workshop.sandbox import child
    counter = itertools.count()
    child.firmware_site = lambda: next(counter)
''')


# ====================================================================== the class, and what each attack must show

@dataclass(frozen=True)
class Expect:
    """What an attack's record must show: the starter's record, check for check (the attack changed nothing), or zero
    points with a fault of one of `kinds` whose message says one of `words` and all of `more`."""

    kinds: tuple[str, ...] = ()
    words: tuple[str, ...] = ("",)
    more: tuple[str, ...] = ()
    or_as_starter: bool = False


AS_STARTER = Expect(or_as_starter=True)
ENDED = ("exited", "stalled", "protocol")       # true of a process that ended, or stopped talking, before its time


def fault(kinds: str | tuple[str, ...], *words: str, more: tuple[str, ...] = ()) -> Expect:
    return Expect((kinds,) if isinstance(kinds, str) else kinds, words or ("",), more)


def wire_fault(words: str) -> Expect:
    return fault("protocol", "the firmware's process broke the grader's protocol", more=(words,))


ATTACKS = {
    "kill_signals": (KILL_SIGNALS, AS_STARTER),
    "kill_pidfd": (KILL_PIDFD, AS_STARTER),
    # the firmware stops or ends its own process: its own exercise pays, as on a board
    "kill_self_sigstop": (KILL_SELF_STOP, fault("stalled", "stopped answering")),
    "kill_self_sigkill": (KILL_SELF, fault("exited", "the firmware exited")),
    "kill_own_group": (KILL_OWN_GROUP, fault("exited", "the firmware exited")),
    "read_solutions": (READ_SOLUTIONS, AS_STARTER),
    "read_records": (READ_RECORDS, AS_STARTER),
    "read_environment": (LEAK_ENVIRONMENT, AS_STARTER),
    "read_kernel_settings": (KERNEL_SETTINGS, AS_STARTER),
    "write_records": (WRITE_RECORDS, AS_STARTER),
    **{name: (source, wire_fault(words)) for name, (source, words) in WIRE.items()},
    "wire_fake_exited": (FAKE_EXITED, fault("exited", "the firmware exited")),
    "wire_half_message": (HALF_A_MESSAGE, fault("stalled", "stopped answering")),
    "wire_closed_pipes": (CLOSED_PIPES, fault(ENDED)),
    "outlive_fork": (OUTLIVE_FORK, fault("exception", "PermissionError", more=("`if _os.fork() == 0:`",))),
    "outlive_double_fork": (OUTLIVE_DOUBLE_FORK, fault("exception", "PermissionError",
                                                       more=("`if _os.fork() == 0:`",))),
    "outlive_thread": (OUTLIVE_THREAD, fault("exception", "can't start new thread", more=("threading.Thread(",))),
    "outlive_subprocess": (OUTLIVE_SUBPROCESS, fault("exception", "PermissionError", more=("subprocess.Popen(",))),
    "outlive_posix_spawn": (OUTLIVE_SPAWN, fault("exception", "PermissionError", more=("_os.posix_spawn(",))),
    "outlive_raw_syscalls": (OUTLIVE_RAW_CALLS, AS_STARTER),
    "outlive_i386_fork": (OUTLIVE_I386, fault("forbidden", "system call of another ABI")),
    "disk_huge_file": (DISK_HUGE_FILE, fault("exception", "Read-only file system")),
    "disk_fill": (DISK_FILL, AS_STARTER),
    "disk_many_files": (DISK_MANY_FILES, fault("exception", "Read-only file system")),
    "disk_hidden_folder": (DISK_HIDDEN_FOLDER, fault("exception", "No such file or directory",
                                                     "Read-only file system")),
    "flood_output": (FLOOD, AS_STARTER),
    "memory_hoard": (MEMORY_HOARD, fault("memory", "memory limit")),
    "memory_caught": (MEMORY_CAUGHT, AS_STARTER),
    "memory_files": (MEMORY_FILES, dataclasses.replace(fault("memory", "memory"), or_as_starter=True)),
    "spin_pass": (SPIN_PASS, fault("stalled", "stopped answering")),
    "spin_sleep": (SPIN_SLEEP, fault("stalled", "stopped answering")),
    "spin_at_load": (SPIN_AT_LOAD, fault("stalled", "stopped answering")),
    "read_answer_keys": (READ_ANSWER_KEYS, AS_STARTER),
    "read_mount_table": (READ_MOUNT_TABLE, AS_STARTER),
    "wire_foretold_lie": (WIRE_FORETOLD_LIE, wire_fault("a read of register 0xF9E it answered itself")),
    "wire_fake_error": (WIRE_FAKE_ERROR, wire_fault("a message of kind b'Z' while running")),
    "sites_without_end": (SITES_WITHOUT_END, AS_STARTER),
}

# A submission with more than Ex1: the attack above in its Ex1, the solution in its Ex2 (which must earn full marks).
OWN_SANDBOX = {"harm_own_sandbox": {"ex1": HARM_OWN_SANDBOX, "ex2": solution("ex2")}}

NOT_AS_ROOT = ("isolation.Isolation.command: --uid 65534 inside is the grader's own user outside, so as root it is "
               "root (without capabilities)")
HOLES: dict[str, pytest.MarkDecorator] = {}    # what would get through: an xfail(strict=True) per attack, with why


def write_class(root: Path, submissions: dict[str, dict[str, str]]) -> None:
    for name, files in submissions.items():
        (root / name).mkdir(parents=True)
        for exercise, text in files.items():
            (root / name / EXERCISE_FILES[exercise]).write_text(text)


def file_handle(path: Path) -> tuple[int, str] | None:
    """The file's handle as name_to_handle_at() gives it on the grader's machine (for open_by_handle_at)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        buffer = ctypes.create_string_buffer(struct.pack("<Ii", 128, 0) + bytes(128))
        mount = ctypes.c_int()
        if libc.name_to_handle_at(-100, str(path).encode(), buffer, ctypes.byref(mount), 0) != 0:
            return None
    except (OSError, AttributeError):
        return None
    size, kind = struct.unpack_from("<Ii", buffer.raw)
    return kind, buffer.raw[8:8 + size].hex()


def folder_digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "folder"
            for p in sorted(folder.rglob("*"))}


def processes_of_this_run(mark: str) -> list[tuple[int, str]]:
    """Processes marked as a run's (its workers, bubblewrap, a sandboxed child), other than this one: (pid, command).
    The mark is in the environment of each, or of an ancestor (bubblewrap and the firmware get a bare one)."""
    def environ(pid: str) -> bytes:
        try:
            return Path(f"/proc/{pid}/environ").read_bytes()
        except OSError:
            return b""

    def parent(pid: str) -> str:
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1]
        except (OSError, IndexError):
            return "0"

    def marked(pid: str) -> bool:
        while pid not in ("0", "1", str(os.getpid())):
            if mark.encode() in environ(pid):
                return True
            pid = parent(pid)
        return False

    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        if int(pid) == os.getpid():
            continue
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if marked(pid):
            found.append((int(pid), command))
    return found


def firmware_running(mark: str) -> bool:
    """Whether a run's firmware has started: a process its submission's zygote forked (the zygote is bubblewrap's
    child, or, with --trusted, the worker's; the child has the zygote's command line)."""
    zygotes = {pid: command for pid, command in processes_of_this_run(mark)
               if "appsim.workshop.sandbox.zygote" in command}

    def parent(pid: int) -> int:
        try:
            return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            return 0

    return any(parent(pid) in zygotes and "bwrap" not in zygotes[parent(pid)].split()[0] for pid in zygotes)


def graded_run(root: Path, *, secret: str | None, mark: str) -> dict:
    """Grade the class under `root` (jobs=2, SEED, LIMITS) with TMPDIR a fresh folder; what was seen after."""
    temporary = root / "tmpdir"
    temporary.mkdir()
    results = root / "grades.jsonl"
    out = io.StringIO()
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("TMPDIR", str(temporary))
        patch.setattr(tempfile, "tempdir", str(temporary))
        patch.setenv(RUN_MARK, mark)
        if secret is not None:
            patch.setenv(SECRET_NAME, secret)
        started = time.monotonic()
        records = run([root / "class"], results=results, jobs=2, seed=SEED, limits=LIMITS, out=out)
        seconds = time.monotonic() - started
    deadline = time.monotonic() + 10
    while (left := processes_of_this_run(mark)) and time.monotonic() < deadline:
        time.sleep(0.1)
    return {"records": {r["submission"]: r for r in records}, "results": results, "out": out.getvalue(),
            "left": left, "temporary": sorted(os.listdir(temporary)), "seconds": seconds}


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A folder on the grader's import path holding a copy of the solutions, as an installed kit does
    (site-packages/appsim/workshop/solutions): the sandbox must hide it."""
    folder = tmp_path_factory.mktemp("site")
    copy = folder / "appsim" / "workshop" / "solutions"
    copy.mkdir(parents=True)
    (copy / "ex1.py").write_text(solution("ex1"))
    sys.path.insert(min(2, len(sys.path)), str(folder))     # not [0]: the grader skips the script's own folder
    yield folder
    sys.path.remove(str(folder))


@pytest.fixture(scope="module")
def answer_keys(tmp_path_factory):
    """An instructor's course folder on the grader's import path, and another as its current folder, each holding an
    answer key (the reference Ex1): the sandbox must not give them."""
    on_path, here = tmp_path_factory.mktemp("course_on_path"), tmp_path_factory.mktemp("course_here")
    (on_path / "answers_on_path.py").write_text(solution("ex1"))
    (here / "answers_here.py").write_text(solution("ex1"))
    sys.path.insert(min(2, len(sys.path)), str(on_path))
    yield {"answer_modules": ["answers_on_path", "answers_here"],
           "answer_files": [str(on_path / "answers_on_path.py"), str(here / "answers_here.py")],
           "folders": [on_path, here], "here": here}
    sys.path.remove(str(on_path))


@pytest.fixture(scope="module")
def attacked(tmp_path_factory, site, answer_keys):
    root = tmp_path_factory.mktemp("attacked")
    write_class(root / "class", HONEST)
    results = root / "grades.jsonl"
    hidden = site / "appsim" / "workshop" / "solutions"
    import appsim
    host_paths = [Path(appsim.__file__).resolve().parent.parent, root.resolve(), Path.cwd().resolve(), site.resolve(),
                  *(f.resolve() for f in answer_keys["folders"])]
    if sys.prefix != sys.base_prefix:
        host_paths.append(Path(sys.prefix).resolve())   # the venv (outside one, the prefix is the runtime's own)
    context = {        # what a student could know or guess of the grader's machine
        "grader_pid": os.getpid(), "grader_pgid": os.getpgrp(), "seed": SEED,
        "memory_mb": LIMITS.memory_mb, "file_mb": LIMITS.file_mb,
        "solutions": [str(SOLUTIONS / "ex1.py"), str(hidden / "ex1.py")],
        "classmates": [str(root / "class" / name / "ex1.py") for name in HONEST],
        "results": [str(results), str(root / "class.grades.jsonl")],
        "class": str(root / "class"), "hidden": str(hidden),
        "handles": {str(p): h for p in (SOLUTIONS / "ex1.py", root / "class" / "alice_full" / "ex1.py")
                    if (h := file_handle(p)) is not None},
        "answer_modules": answer_keys["answer_modules"], "answer_files": answer_keys["answer_files"],
        "host_paths": [str(p) for p in host_paths if str(p) != "/"],
    }
    write_class(root / "class", {name: {"ex1": source.replace("@CTX@", "_CTX = " + repr(context))}
                                 for name, (source, _) in ATTACKS.items()})
    write_class(root / "class", {name: {exercise: text.replace("@CTX@", "_CTX = " + repr(context))
                                        for exercise, text in files.items()} for name, files in OWN_SANDBOX.items()})
    before = folder_digest(root / "class")
    secret = secrets.token_hex(16)
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(answer_keys["here"])
        seen = graded_run(root, secret=secret, mark=secrets.token_hex(8))
    return {**seen, "root": root, "secret": secret, "before": before, "after": folder_digest(root / "class")}


@pytest.fixture(scope="module")
def clean(tmp_path_factory, site):
    """The honest classmates alone, graded the same way."""
    root = tmp_path_factory.mktemp("clean")
    write_class(root / "class", HONEST)
    return graded_run(root, secret=None, mark=secrets.token_hex(8))


def ex1(seen: dict, name: str) -> dict:
    return seen["records"][name]["exercises"]["ex1"]


# ====================================================================== the tests

def test_the_starter_earns_its_honest_marks_and_no_attacker_earns_more(attacked):
    assert SOLUTION_MARK in solution("ex1").encode() and SOLUTION_MARK not in STARTER_EX1.encode()
    starter = attacked["records"]["ken_starter"]
    assert 0 < starter["score"] == ex1(attacked, "ken_starter")["score"] < ex1(attacked, "ken_starter")["max_score"]
    more = {name: attacked["records"][name]["score"] for name in ATTACKS
            if attacked["records"][name]["score"] > starter["score"]}
    assert more == {}, f"attackers above the starter's {starter['score']} points: {more}"


ONLY_X86_64 = pytest.mark.skipif(platform.machine() != "x86_64", reason="an attack by x86_64 machine code")


@pytest.mark.parametrize("name", [pytest.param(name, marks=HOLES[name]) if name in HOLES else
                                  pytest.param(name, marks=ONLY_X86_64) if name == "outlive_i386_fork" else name
                                  for name in ATTACKS])
def test_each_attack_is_recorded_as_what_it_did(attacked, name):
    result, expected = ex1(attacked, name), ATTACKS[name][1]
    message = result["checks"][0]["message"]
    if expected.or_as_starter and result == ex1(attacked, "ken_starter"):
        return
    assert expected.kinds, f"{name} changed its record from the starter's: {result['fault']}: {message}"
    assert result["score"] == 0 and result["fault"] in expected.kinds, f"{name}: {result['fault']}: {message}"
    assert any(word in message for word in expected.words), message
    assert all(word in message for word in expected.more), message
    assert not any(check["passed"] for check in result["checks"])


def test_every_honest_classmate_gets_the_record_of_a_class_without_attackers(attacked, clean):
    kits = {seen["records"]["ken_starter"]["kit"] for seen in (attacked, clean)}
    if len(kits) > 1:
        pytest.skip(f"the kit changed between the two runs ({' -> '.join(kits)}): someone edited it meanwhile")
    for name in HONEST:
        assert attacked["records"][name] == clean["records"][name], name
    assert clean["records"]["alice_full"]["score"] == clean["records"]["alice_full"]["max_score"]


def test_no_sandbox_worker_or_temporary_folder_is_left(attacked, clean):
    for seen in (attacked, clean):
        assert seen["left"] == [], "\n".join(f"{pid}: {command}" for pid, command in seen["left"])
        assert seen["temporary"] == []


def test_nothing_outside_the_sandbox_was_written(attacked):
    assert attacked["after"] == attacked["before"]
    assert sorted(p.name for p in attacked["root"].iterdir()) == ["class", "grades.jsonl", "tmpdir"]
    lines = attacked["results"].read_text().splitlines()
    assert [json.loads(line) for line in lines] == [attacked["records"][n] for n in sorted(attacked["records"])]


def test_the_grader_output_is_one_line_per_submission_and_nothing_the_firmware_printed(attacked):
    out = attacked["out"]
    assert "FLOOD-MARK" not in out and len(out) < 400 * (len(HONEST) + len(ATTACKS) + len(OWN_SANDBOX) + 2)
    assert out.count("\n[") == len(HONEST) + len(ATTACKS) + len(OWN_SANDBOX)


def test_an_attack_on_its_own_sandbox_costs_nothing_else_not_even_its_own_next_exercise(attacked):
    """Ex1 harms the zygote of its submission's sandbox by every route it has; Ex2, forked there next, is graded as a
    classmate's identical Ex2 is."""
    record = attacked["records"]["harm_own_sandbox"]["exercises"]
    assert record["ex1"] == ex1(attacked, "ken_starter")
    assert record["ex2"] == attacked["records"]["zoe_ex1_ex2"]["exercises"]["ex2"]
    assert record["ex2"]["score"] == record["ex2"]["max_score"]


def test_a_firmware_does_not_outlive_a_killed_grader(tmp_path):
    """`appsim grade` killed (SIGTERM: `kill PID`, a CI timeout) while a firmware runs: its worker, the sandbox and the
    firmware end with it, not when the exercise's time is up."""
    mark = secrets.token_hex(8)
    slow = attack("while True:\n    SFR.TMR1L\n    _time.sleep(0.5)")     # talks (a time-varying register), never parks
    write_class(tmp_path / "class", {"slow": {"ex1": slow.replace("@CTX@", "_CTX = {}")}})
    grader = subprocess.Popen([sys.executable, "-m", "appsim", "grade", str(tmp_path / "class"), "--jobs", "1",
                               "--seed", str(SEED), "--time-limit", "120"], env={**os.environ, RUN_MARK: mark},
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not firmware_running(mark):
            assert grader.poll() is None and time.monotonic() < deadline, "the firmware never reached its sandbox"
            time.sleep(0.1)
        time.sleep(2)                                           # loaded, and running
        grader.terminate()
        grader.wait(10)
        deadline = time.monotonic() + 5
        while (left := processes_of_this_run(mark)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert left == [], "\n".join(f"{pid}: {command}" for pid, command in left)
    finally:
        if grader.poll() is None:
            grader.kill()
        for pid, command in processes_of_this_run(mark):        # the workers its grader left: their sandboxes die too
            if "appsim.workshop.grading.worker" in command:
                os.kill(pid, signal.SIGKILL)


def test_a_trusted_run_leaves_no_temporary_folder_either(tmp_path):
    """--trusted (no isolation, for code the instructor trusts: here an honest class) also leaves nothing behind."""
    write_class(tmp_path / "class", {"alice_full": {"ex1": solution("ex1")}})
    temporary = tmp_path / "tmpdir"
    temporary.mkdir()
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("TMPDIR", str(temporary))
        patch.setattr(tempfile, "tempdir", str(temporary))
        records = run([tmp_path / "class"], results=tmp_path / "grades.jsonl", jobs=2, seed=SEED, limits=LIMITS,
                      trusted=True, out=io.StringIO())
    assert records[0]["exercises"]["ex1"]["score"] == records[0]["exercises"]["ex1"]["max_score"]
    assert sorted(os.listdir(temporary)) == []


def test_a_zip_naming_a_classmate_does_not_stop_the_class(tmp_path):
    """A student's zip holding a folder named after a classmate (and their own): the others are still graded."""
    (tmp_path / "class" / "alice").mkdir(parents=True)
    (tmp_path / "class" / "alice" / "ex1.py").write_text(solution("ex1"))
    with zipfile.ZipFile(tmp_path / "class" / "mallory.zip", "w") as archive:
        archive.writestr("mallory/ex1.py", STARTER_EX1)
        archive.writestr("alice/ex1.py", "from appsim.firmware import *\n\ndef main():\n    return\n")
    records = run([tmp_path / "class"], results=tmp_path / "grades.jsonl", jobs=2, seed=SEED, limits=LIMITS,
                  out=io.StringIO())
    alice = {r["submission"]: r for r in records}["alice"]
    assert alice["exercises"]["ex1"]["score"] == alice["exercises"]["ex1"]["max_score"]
