"""The operating system's walls around one sandboxed firmware: Linux namespaces by bubblewrap, and a seccomp filter.

Each child gets its own user, PID, mount, network, IPC and UTS namespaces: it sees only itself, and, read-only, the
Python runtime and copies of the kit's package (no solutions) and of the packages it imports (`mounts`); it can write
nowhere, has no network and no capabilities, cannot start a process or a thread, and dies with the grader.
docs/grading.md says why bubblewrap.
"""
from __future__ import annotations

import dataclasses
import functools
import os
import platform
import shutil
import struct
import subprocess
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from appsim.errors import SandboxUnavailable
from appsim.workshop.sandbox import mounts

# /proc files that the sandbox's user could write were it the grader's own root (it has no capabilities, but is the
# owner): the kernel's settings, the magic SysRq key, interrupt routing. Covered read-only, whoever grades.
PROC_READ_ONLY = ("/proc/sys", "/proc/sysrq-trigger", "/proc/irq", "/proc/bus", "/proc/fs", "/proc/driver")
ENVIRONMENT = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8", "HOME": "/"}     # all bubblewrap and the child get

# ------------------------------------------------------------------ seccomp: no process, no thread, nothing exotic
# Classic BPF (struct sock_filter: u16 code, u8 jt, u8 jf, u32 k) over struct seccomp_data (nr at 0, arch at 4).
_LOAD, _JEQ, _JGE, _RETURN = 0x20, 0x15, 0x35, 0x06
_ALLOW, _ERRNO, _KILL = 0x7FFF_0000, 0x0005_0000, 0x8000_0000
_EPERM = 1
# Per machine: (AUDIT_ARCH, the first syscall number of a foreign ABI on it or None, the refused calls by number).
# x86_64: clone 56 fork 57 vfork 58 clone3 435, ptrace 101, add_key 248 request_key 249 keyctl 250, unshare 272,
# setns 308, mount 165 umount2 166 pivot_root 155 chroot 161, perf_event_open 298, bpf 321, userfaultfd 323,
# process_vm_readv 310 process_vm_writev 311, io_uring_setup 425; memory that RLIMIT_AS does not count:
# memfd_create 319, shmget 29 shmat 30 shmctl 31, msgget 68, mq_open 240. aarch64 (asm-generic numbers, no fork or
# vfork): clone 220 clone3 435, ptrace 117, add_key 217 request_key 218 keyctl 219, unshare 97, setns 268, mount 40
# umount2 39 pivot_root 41 chroot 51, perf_event_open 241, bpf 280, userfaultfd 282, process_vm_* 270 271, 425;
# memfd_create 279, shmget 194 shmat 196 shmctl 195, msgget 186, mq_open 180.
_REFUSED_CALLS: dict[str, tuple[int, int | None, tuple[int, ...]]] = {
    "x86_64": (0xC000_003E, 0x4000_0000,
               (56, 57, 58, 435, 101, 248, 249, 250, 272, 308, 165, 166, 155, 161, 298, 321, 323, 310, 311, 425,
                319, 29, 30, 31, 68, 240)),
    "aarch64": (0xC000_00B7, None,
                (220, 435, 117, 217, 218, 219, 97, 268, 40, 39, 41, 51, 241, 280, 282, 270, 271, 425,
                 279, 194, 196, 195, 186, 180)),
}
_FORK_CALLS = {"x86_64": (56, 57, 58, 435), "aarch64": (220, 435)}     # clone fork vfork clone3 / clone clone3


def seccomp_program(machine: str | None = None, *, may_fork: bool = False) -> bytes:
    """The filter: other ABIs kill the process; the refused calls fail with EPERM; everything else is allowed.
    `may_fork` lets a process start processes (a sandbox's zygote); each child it forks adds the whole filter."""
    try:
        arch, foreign, refused = _REFUSED_CALLS[machine or platform.machine()]
    except KeyError:
        raise SandboxUnavailable(f"the grader's seccomp filter knows x86_64 and aarch64, not "
                                 f"{machine or platform.machine()}") from None
    if may_fork:
        refused = tuple(call for call in refused if call not in _FORK_CALLS[machine or platform.machine()])

    def op(code: int, k: int, jt: int = 0, jf: int = 0) -> bytes:
        return struct.pack("<HBBI", code, jt, jf, k)

    # A jump skips `jt` instructions: each test below jumps over the tests after it and the ALLOW, to the EPERM.
    program = [op(_LOAD, 4), op(_JEQ, arch, 1, 0), op(_RETURN, _KILL), op(_LOAD, 0)]
    if foreign is not None:
        program.append(op(_JGE, foreign, len(refused) + 1, 0))
    for number, call in enumerate(refused):
        program.append(op(_JEQ, call, len(refused) - number, 0))
    program += [op(_RETURN, _ALLOW), op(_RETURN, _ERRNO | _EPERM)]
    return b"".join(program)


# ------------------------------------------------------------------ what the child sees
@dataclass(frozen=True)
class Isolation:
    """How to start a sandboxed child: bubblewrap, and the sandbox's files (see `mounts.Layout`)."""

    bwrap: str
    executable: str
    binds: tuple[str, ...]
    links: tuple[tuple[str, str], ...]
    covered: tuple[str, ...]
    copies: tuple[tuple[str, str], ...]
    path: tuple[str, ...]

    def __post_init__(self) -> None:        # from the JSON a worker gets: lists back to tuples
        for name in ("binds", "covered", "path"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        for name in ("links", "copies"):
            object.__setattr__(self, name, tuple(tuple(pair) for pair in getattr(self, name)))

    def command(self, argv: Sequence[str], seccomp_fd: int) -> tuple[list[str], list[int]]:
        """The bwrap command line that runs `argv` in a fresh sandbox (with the filter read from `seccomp_fd`), and
        the descriptors it reads the copies from (to pass to it, and close once it started).

        The root and /dev are read-only, and nothing writable is mounted: firmware acts only through the board, so it
        has no use for files (its source reaches it through its pipe). `argv` runs as the sandbox's pid 1, so no
        other process is in there (nor its environment or its command line in /proc).
        """
        command = [self.bwrap]
        for path in self.binds:
            command += ["--ro-bind", path, path]
        for target, link in self.links:
            command += ["--symlink", target, link]
        for path in self.covered:
            command += (["--tmpfs", path, "--remount-ro", path] if os.path.isdir(path)
                        else ["--ro-bind", os.devnull, path])
        descriptors = []
        try:
            for path, data in mounts.contents(self.copies):
                descriptor = os.memfd_create("appsim-sandbox-file")
                descriptors.append(descriptor)
                view = memoryview(data)
                while view:
                    view = view[os.write(descriptor, view):]
                os.lseek(descriptor, 0, os.SEEK_SET)
                command += ["--perms", "0444", "--file", str(descriptor), path]
        except BaseException:
            for descriptor in descriptors:
                os.close(descriptor)
            raise
        command += ["--proc", "/proc"]
        for path in PROC_READ_ONLY:
            command += ["--ro-bind-try", path, path]
        command += ["--dev", "/dev", "--remount-ro", "/dev", "--remount-ro", "/",
                    "--unshare-all", "--unshare-user", "--disable-userns", "--as-pid-1", "--die-with-parent",
                    "--new-session", "--cap-drop", "ALL", "--uid", "65534", "--gid", "65534", "--hostname", "sandbox",
                    "--clearenv", *(a for name, value in ENVIRONMENT.items() for a in ("--setenv", name, value)),
                    "--chdir", "/", "--seccomp", str(seccomp_fd), *argv]
        return command, descriptors


def import_path() -> list[str]:
    """Where a child outside a sandbox (--trusted) imports from: the folder holding the kit's package, then the
    grader's own installation's."""
    import appsim

    kit = str(Path(appsim.__file__).resolve().parent.parent)
    installed = [entry for entry in sys.path[1:] if entry and os.path.isdir(entry) and entry != kit]
    return [kit, *installed]


def isolation(secrets: Iterable[Path] = ()) -> Isolation:
    """The walls for this machine; SandboxUnavailable says why there are none (and what an instructor can do).
    The sandbox's files are worked out by a probe of the firmware library (`mounts`), once per import path."""
    key = (mounts.executable(), tuple(sys.path), tuple(sorted(str(Path(p).resolve()) for p in secrets)))
    layout = _layouts.get(key)
    started = mounts.start_probe() if layout is None and sys.platform == "linux" else None
    try:
        bwrap = _usable_bwrap()
        if layout is None:
            assert started is not None
            layout = _layouts[key] = mounts.layout(started, secrets)
    except mounts.LayoutError as error:
        raise SandboxUnavailable(f"the sandbox cannot be given the firmware library: {error}") from None
    finally:
        if started is not None:
            mounts.stop(started)
    return Isolation(bwrap, **dataclasses.asdict(layout))


_layouts: dict[tuple[object, ...], mounts.Layout] = {}     # by import path: each probe costs about 0.1 s


@functools.lru_cache(maxsize=1)
def _usable_bwrap() -> str:
    """bubblewrap's path, once it has been seen to build a sandbox on this machine."""
    if sys.platform != "linux":
        raise SandboxUnavailable(f"this is {platform.system()}: the grader isolates student firmware with Linux "
                                 "namespaces, which this system does not have")
    bwrap = shutil.which("bwrap")
    if bwrap is None:
        raise SandboxUnavailable("bubblewrap (bwrap) is not installed: `sudo apt-get install bubblewrap` (Debian, "
                                 "Ubuntu), `sudo dnf install bubblewrap` (Fedora)")
    program = seccomp_program()
    read, write = os.pipe()
    os.write(write, program)
    os.close(write)
    try:
        probe = subprocess.run([bwrap, "--ro-bind", "/", "/", "--unshare-all", "--unshare-user", "--disable-userns",
                                "--die-with-parent", "--cap-drop", "ALL", "--seccomp", str(read), "true"],
                               pass_fds=(read,), capture_output=True, text=True, timeout=30, check=False)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise SandboxUnavailable(f"bubblewrap could not be run: {error}") from None
    finally:
        os.close(read)
    if probe.returncode != 0:
        why = probe.stderr.strip() or f"exit status {probe.returncode}"
        raise SandboxUnavailable(f"bubblewrap cannot build a sandbox here ({why}): this kernel does not let this "
                                 "user create namespaces (check `sysctl kernel.unprivileged_userns_clone` and, "
                                 "on Ubuntu, `kernel.apparmor_restrict_unprivileged_userns`)")
    return bwrap
