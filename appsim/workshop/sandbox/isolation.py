"""The operating system's walls around one sandboxed firmware: Linux namespaces by bubblewrap, and a seccomp filter.

Each child gets its own user, PID, mount, network, IPC and UTS namespaces: it sees only itself, and, read-only, the
Python runtime and the kit (reference solutions hidden); it can write nowhere, has no network and no capabilities,
cannot start a process or a thread, and dies with the grader. docs/grading.md says why bubblewrap.
"""
from __future__ import annotations

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

SYSTEM = ("/usr", "/lib", "/lib32", "/lib64", "/libx32", "/bin", "/sbin", "/etc/ld.so.cache", "/etc/localtime",
          "/etc/alternatives")
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
    """How to start a sandboxed child: bubblewrap with these read-only folders, these hidden inside them."""

    bwrap: str
    readable: tuple[str, ...]           # bound read-only at the same path
    hidden: tuple[str, ...]             # covered by an empty folder (or an empty file) inside what is readable

    def command(self, argv: Sequence[str], seccomp_fd: int) -> list[str]:
        """The bwrap command line that runs `argv` in a fresh sandbox (with the filter read from `seccomp_fd`).

        The root and /dev are read-only, and nothing writable is mounted: firmware acts only through the board, so it
        has no use for files (its source reaches it through its pipe). `argv` runs as the sandbox's pid 1, so no
        other process is in there (nor its environment or its command line in /proc).
        """
        command = [self.bwrap]
        for path in self.readable:
            command += ["--ro-bind-try", path, path]
        for path in self.hidden:
            command += (["--tmpfs", path, "--remount-ro", path] if os.path.isdir(path)
                        else ["--ro-bind", os.devnull, path])
        command += ["--proc", "/proc"]
        for path in PROC_READ_ONLY:
            command += ["--ro-bind-try", path, path]
        command += ["--dev", "/dev", "--remount-ro", "/dev", "--remount-ro", "/",
                    "--unshare-all", "--unshare-user", "--disable-userns", "--as-pid-1", "--die-with-parent",
                    "--new-session", "--cap-drop", "ALL", "--uid", "65534", "--gid", "65534", "--hostname", "sandbox",
                    "--clearenv", *(a for name, value in ENVIRONMENT.items() for a in ("--setenv", name, value)),
                    "--chdir", "/", "--seccomp", str(seccomp_fd), *argv]
        return command


def import_path() -> list[str]:
    """Where the child imports from: the folder holding the kit's package, then the grader's own installation's."""
    import appsim

    kit = str(Path(appsim.__file__).resolve().parent.parent)
    installed = [entry for entry in sys.path[1:] if entry and os.path.isdir(entry) and entry != kit]
    return [kit, *installed]


def isolation(secrets: Iterable[Path] = ()) -> Isolation:
    """The walls for this machine; SandboxUnavailable says why there are none (and what an instructor can do)."""
    bwrap = _usable_bwrap()
    readable = _readable()
    hidden = sorted({str(path) for path in _solutions(readable) | {Path(p).resolve() for p in secrets}
                     if _inside_any(path, readable) and path.exists()})
    return Isolation(bwrap, tuple(readable), tuple(hidden))


def _readable() -> list[str]:
    import appsim

    roots = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix,
             str(Path(sys.executable).resolve().parent.parent), str(Path(appsim.__file__).resolve().parent),
             *import_path()[1:]}
    kit_checkout = _checkout()
    chosen = [path for path in SYSTEM if os.path.exists(path)]
    for root in sorted(os.path.realpath(r) for r in roots if r):
        if kit_checkout is not None and _inside_any(Path(kit_checkout), [root]):
            continue                    # a folder holding the whole checkout (PYTHONPATH=.): only appsim/ is given
        if not _inside_any(Path(root), chosen):
            chosen.append(root)
    return chosen


def _checkout() -> str | None:
    """The repository the kit runs from, if it is a checkout (its solutions/ lie outside the package)."""
    from appsim.workshop import course

    package = Path(course.__file__).resolve().parents[1]
    return None if course.SOLUTIONS.resolve().is_relative_to(package) else str(package.parent)


def _solutions(readable: Iterable[str]) -> set[Path]:
    """Every copy of the reference solutions that lies inside a readable folder (an installed kit, a checkout)."""
    from appsim.workshop import course

    found = {course.SOLUTIONS.resolve()}
    for root in [*readable, *import_path()]:
        for candidate in (Path(root) / "appsim" / "workshop" / "solutions", Path(root) / "solutions"):
            if (candidate / "ex1.py").is_file():
                found.add(candidate.resolve())
    return found


def _inside_any(path: Path, roots: Iterable[str]) -> bool:
    return any(path == Path(root) or path.is_relative_to(root) for root in roots)


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
