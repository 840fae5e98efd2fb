"""What a sandbox holds: the Python runtime, bound read-only where it lies, and copies of the kit's package and of the
installed packages the firmware library imports; worked out once from what a zygote's boot imports and maps.

No folder of the grader's import path is given as such (PYTHONPATH, a .pth file's, the current folder, a user site,
site-packages): an answer key kept there is nowhere in the sandbox. `layout()` says what is, `contents()` the copies.
"""
from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import json
import os
import struct
import subprocess
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

KIT_FOLDER = "/kit"                 # the kit's package, copied: /kit/appsim/...
SITE_FOLDER = "/site"               # the installed packages the firmware library imports, copied
MAX_COPIED = 64 << 20               # what a sandbox may be given in copies, in all (the kit is about 1 MB)
SYSTEM_LINKS = ("/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32")    # merged-/usr systems make them links
SYSTEM_FILES = ("/etc/ld.so.cache", "/etc/localtime")
PROBE_S = 60.0
# The probe: a Python like the zygote's boots as a zygote does (`child.boot`, the one place that says what the firmware
# library loads, and `child.boot_c`, what a C firmware adds: the translator, pcpp, pycparser, the kit's headers) and
# says what it imported and what it mapped. The libraries the runtime's extension modules need are
# read from their ELF headers, as the dynamic loader would find them (`_needed_folders`).
PROBE = ("import json, sys; runtime = list(sys.path); sys.path[:0] = json.loads(sys.argv[1]); "
         "from appsim.workshop.sandbox.mounts import probe; probe(runtime)")
LOADER_DEFAULTS = ("/lib64", "/usr/lib64", "/lib", "/usr/lib")


class LayoutError(Exception):
    """The firmware library needs something the sandbox may not be given (the words say what, and what to do)."""


@dataclass(frozen=True)
class Layout:
    """The sandbox's files. `binds`: the runtime's folders and files, read-only at their own paths (`links`: the
    symbolic links its paths go through, as (target, link)); `covered`: what lies inside a bind and is not the
    runtime's (a site-packages folder inside the standard library's), under an empty folder; `copies`: (file on this
    machine, its path in the sandbox), the kit's package under /kit and the packages under /site; `path`: the import
    path ahead of the runtime's own; `executable`: the Python the sandbox runs."""

    executable: str
    binds: tuple[str, ...]
    links: tuple[tuple[str, str], ...]
    covered: tuple[str, ...]
    copies: tuple[tuple[str, str], ...]
    path: tuple[str, ...] = (KIT_FOLDER, SITE_FOLDER)


def executable() -> str:
    """The Python a sandbox runs: the grader's own interpreter (a venv's base), by its real path."""
    return os.path.realpath(getattr(sys, "_base_executable", None) or sys.executable)


def kit_package() -> Path:
    import appsim

    return Path(appsim.__file__).resolve().parent


def search_path() -> list[str]:
    """Where the probe looks for the packages the firmware library imports: the grader's own import path, but for its
    first entry (the script's folder or the current one) and anything that is not a folder."""
    return [entry for entry in sys.path[1:] if entry and os.path.isdir(entry)]


def start_probe() -> subprocess.Popen[str]:
    """The probe, started (it takes about 0.05 s: `layout` waits for it)."""
    path = [str(kit_package().parent), *search_path()]
    return subprocess.Popen([executable(), "-I", "-S", "-B", "-c", PROBE, json.dumps(path)], cwd="/",
                            env={"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"}, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def stop(started: subprocess.Popen[str]) -> None:
    if started.poll() is None:
        started.kill()
    started.communicate()


def layout(started: subprocess.Popen[str], secrets: Iterable[Path] = ()) -> Layout:
    """The sandbox's files, from the probe `started` (see `start_probe`); LayoutError if the firmware library needs
    what no installed package holds. `secrets` (the class, the outputs) are covered wherever they lie in a bind."""
    try:
        out, err = started.communicate(timeout=PROBE_S)
    except subprocess.TimeoutExpired:
        stop(started)
        raise LayoutError(f"loading the firmware library took more than {PROBE_S:g} s") from None
    if started.returncode != 0:
        raise LayoutError(f"the firmware library does not load in a Python of its own: {err.strip()[-2000:]}")
    seen = json.loads(out)
    return _layout(seen["runtime"], seen["modules"], seen["mapped"], [Path(p) for p in secrets])


def probe(runtime: list[str]) -> None:
    """In the probe's process: boot as a zygote does (for a C firmware too), say what it imported and what it mapped."""
    from appsim.workshop.sandbox import child

    child.boot()
    child.boot_c()
    modules = sorted({file for module in list(sys.modules.values())
                      if isinstance(file := getattr(module, "__file__", None), str)})
    with open("/proc/self/maps") as maps:
        mapped = sorted({fields[5].rstrip("\n") for line in maps if len(fields := line.split(maxsplit=5)) == 6
                         and fields[5].startswith("/") and not fields[5].rstrip().endswith("(deleted)")})
    print(json.dumps({"runtime": runtime, "modules": modules, "mapped": mapped}))


# ====================================================================== from what the probe saw to the sandbox's files

def _layout(runtime: Sequence[str], modules: Sequence[str], mapped: Sequence[str], secrets: Sequence[Path]) -> Layout:
    python = executable()
    kit = kit_package()
    entries = [Path(os.path.realpath(e)) for e in [str(kit.parent), *search_path()]]
    runtime_dirs = sorted({Path(os.path.realpath(p)) for p in runtime if os.path.isdir(p)})
    binds: set[Path] = {*runtime_dirs, Path(python)}
    packages: set[tuple[Path, str]] = set()
    for name in [*modules, *mapped]:
        real = Path(os.path.realpath(name))
        if real == Path(python) or _inside(real, [kit]):
            continue
        entry = max((e for e in entries if _inside(real, [e]) and real != e), key=lambda e: len(e.parts), default=None)
        home = max((d for d in runtime_dirs if _inside(real, [d])), key=lambda d: len(d.parts), default=None)
        if entry is not None and (home is None or len(entry.parts) > len(home.parts)):
            # an installed package, also where site-packages lies inside the standard library's folder (pyenv, a
            # Python built from source): that folder is covered in the sandbox, so the package is copied
            packages.add((entry, real.relative_to(entry).parts[0]))
        elif home is not None:
            continue
        elif name in mapped:
            binds.add(real.parent if ".so" in real.name else real)     # a library's folder; a data file alone
        else:
            raise LayoutError(f"the firmware library imports {name}, which is neither in the Python installation "
                              "nor in an installed package")
    for entry, top in sorted(packages):
        if not _installed(entry, top):
            raise LayoutError(f"the firmware library imports {top} from {entry}, where no installed package holds "
                              f"it (no .dist-info or .egg-info names it): install it with pip")
    suffixes = tuple(importlib.machinery.EXTENSION_SUFFIXES)
    extensions = [str(folder / name) for folder in runtime_dirs for name in _listing(folder) if name.endswith(suffixes)]
    binds |= _needed_folders([python, *extensions, *(m for m in mapped if ".so" in Path(m).name)])
    binds |= {Path(f) for f in SYSTEM_FILES if os.path.exists(f)}
    chosen = _outermost(binds)
    return Layout(python, tuple(sorted(map(str, chosen))), tuple(_links(python, chosen)),
                  tuple(sorted(map(str, _covered(chosen, runtime_dirs, kit, secrets)))),
                  tuple(_copies(kit, packages)))


def _listing(folder: Path) -> list[str]:
    try:
        return sorted(os.listdir(folder))
    except OSError:
        return []


def _needed_folders(objects: Iterable[str]) -> set[Path]:
    """The folders of the shared libraries the ELF files `objects` need, and those need in turn, where the dynamic
    loader would find them: their RUNPATH (or RPATH), then /etc/ld.so.conf's folders, then the defaults."""
    search = _loader_folders()
    folders: set[Path] = set()
    seen: set[str] = set()
    waiting = [os.path.realpath(o) for o in objects]
    while waiting:
        path = waiting.pop()
        if path in seen:
            continue
        seen.add(path)
        needed, runpath = _dynamic(path)
        origin = os.path.dirname(path)
        where = [d.replace("${ORIGIN}", origin).replace("$ORIGIN", origin) for d in runpath] + search
        for name in needed:
            found = next((os.path.join(d, name) for d in where if os.path.exists(os.path.join(d, name))), None)
            if found is not None:
                real = os.path.realpath(found)
                folders |= {Path(os.path.realpath(os.path.dirname(found))), Path(real).parent}
                waiting.append(real)
    return folders


@functools.lru_cache(maxsize=1)
def _loader_folders() -> list[str]:
    """The dynamic loader's folders: /etc/ld.so.conf's (and those it includes), then its defaults."""
    import glob

    found: list[str] = []

    def read(conf: str, depth: int = 0) -> None:
        try:
            lines = Path(conf).read_text(errors="replace").splitlines()
        except OSError:
            return
        for line in lines:
            line = line.split("#", 1)[0].strip()
            if line.startswith("include ") and depth < 8:
                for included in sorted(glob.glob(os.path.join(os.path.dirname(conf), line.split(None, 1)[1]))):
                    read(included, depth + 1)
            elif line.startswith("/"):
                found.append(line)
    read("/etc/ld.so.conf")
    return [d for d in dict.fromkeys([*found, *LOADER_DEFAULTS]) if os.path.isdir(d)]


def _dynamic(path: str) -> tuple[list[str], list[str]]:
    """A 64-bit ELF file's DT_NEEDED names and its RUNPATH (else RPATH) folders; nothing for anything else. Only its
    headers, its dynamic section and its string table are read."""
    try:
        with open(path, "rb") as file:
            header = file.read(64)
            if len(header) < 64 or header[:4] != b"\x7fELF" or header[4] != 2:
                return [], []
            order = "<" if header[5] == 1 else ">"
            phoff, = struct.unpack_from(order + "Q", header, 32)
            phentsize, phnum = struct.unpack_from(order + "HH", header, 54)
            file.seek(phoff)
            table = file.read(phentsize * phnum)
            loads, dynamic = [], None
            for number in range(phnum):
                kind, _, offset, vaddr, _, size = struct.unpack_from(order + "IIQQQQ", table, number * phentsize)
                if kind == 1:                                   # PT_LOAD
                    loads.append((vaddr, offset, size))
                elif kind == 2:                                 # PT_DYNAMIC
                    dynamic = (offset, size)
            if dynamic is None:
                return [], []
            file.seek(dynamic[0])
            section = file.read(min(dynamic[1], 1 << 20))
            entries = []
            for position in range(0, len(section) - 15, 16):
                tag, value = struct.unpack_from(order + "qQ", section, position)
                if tag == 0:
                    break
                entries.append((tag, value))
            found = dict(entries)
            address, size = found[5], found[10]                 # DT_STRTAB (an address), DT_STRSZ
            file.seek(next(offset + address - vaddr for vaddr, offset, length in loads
                           if vaddr <= address < vaddr + length))
            strings = file.read(min(size, 16 << 20))
    except (OSError, struct.error, StopIteration, KeyError):
        return [], []

    def text(at: int) -> str:
        return strings[at:strings.find(b"\0", at)].decode(errors="replace")
    needed = [text(value) for tag, value in entries if tag == 1]                 # DT_NEEDED
    runpath = [text(value) for tag, value in entries if tag == 29] or \
        [text(value) for tag, value in entries if tag == 15]                     # DT_RUNPATH, else DT_RPATH
    return needed, [d for entry in runpath for d in entry.split(":") if d]


def _outermost(paths: Iterable[Path]) -> list[Path]:
    """The paths that lie in none of the others."""
    unique = sorted(set(paths))
    return [p for p in unique if not any(p != q and p.is_relative_to(q) for q in unique)]


def _inside(path: Path, folders: Iterable[Path]) -> bool:
    return any(path.is_relative_to(folder) for folder in folders)


def _installed(entry: Path, top: str) -> bool:
    """Whether a distribution installed in `entry` holds `top` (a folder or a module file there): its .dist-info's
    RECORD lists it, or its .egg-info's top_level.txt names it. The distribution named like it is read first."""
    try:
        infos = sorted(name for name in os.listdir(entry) if name.endswith((".dist-info", ".egg-info")))
    except OSError:
        return False
    stem = _normalised(top.split(".", 1)[0])
    likely = [name for name in infos if _normalised(name).startswith(stem)]
    return any(top in _names(entry / name) or top.split(".", 1)[0] in _names(entry / name)
               for name in [*likely, *(name for name in infos if name not in likely)])


def _normalised(name: str) -> str:
    return name.lower().replace("-", "_").replace(".", "_")


@functools.lru_cache(maxsize=256)
def _names(info: Path) -> frozenset[str]:
    """The top-level names one installed distribution holds (its RECORD's first folders and files, or its
    top_level.txt)."""
    record, first_column = (info / "RECORD", True) if info.name.endswith(".dist-info") else (info / "top_level.txt",
                                                                                           False)
    try:
        lines = record.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return frozenset()
    names = set()
    for line in lines:
        parts = Path(line.split(",", 1)[0] if first_column else line.strip()).parts
        if parts and parts[0] not in ("..", "/"):
            names.add(parts[0])
    return frozenset(names)


def _covered(binds: Sequence[Path], runtime: Sequence[Path], kit: Path, secrets: Sequence[Path]) -> set[Path]:
    """What lies inside a bind without being the runtime: every folder of the grader's import path and its sites, the
    current folder, the kit's and its solutions, and the secrets."""
    import site

    from appsim.workshop import course

    candidates = [*sys.path, *search_path(), _cwd(), str(kit), str(kit.parent), str(course.SOLUTIONS),
                  *(site.getsitepackages() if hasattr(site, "getsitepackages") else []),
                  site.getusersitepackages(), *os.environ.get("PYTHONPATH", "").split(os.pathsep), *map(str, secrets)]
    candidates += [str(folder / name) for folder in runtime for name in ("site-packages", "dist-packages")]
    candidates += [str(bound / python / name) for bound in binds for python in _listing(bound)
                   if python.startswith("python") for name in ("site-packages", "dist-packages")]
    covered = set()
    for candidate in candidates:
        if not candidate or not os.path.exists(candidate):
            continue
        real = Path(os.path.realpath(candidate))
        if real in runtime or any(r.is_relative_to(real) for r in runtime):
            continue                    # the standard library itself (a PYTHONPATH naming it changes nothing)
        if any(real != b and real.is_relative_to(b) for b in binds):
            covered.add(real)
    return set(_outermost(covered))


def _cwd() -> str:
    try:
        return os.getcwd()
    except OSError:                     # it was removed
        return ""


def _links(python: str, binds: Sequence[Path]) -> list[tuple[str, str]]:
    """The symbolic links the runtime's paths go through: the system's top folders (on merged-/usr systems), and the
    path of the program interpreter (the dynamic loader) that the Python's executable names."""
    links: dict[str, str] = {}
    for top in SYSTEM_LINKS:
        if os.path.islink(top):
            links[top] = os.readlink(top)
    interpreter = _program_interpreter(python)
    if interpreter is not None:
        _chain(interpreter, links)
    return [(target, link) for link, target in links.items() if not _inside(Path(link), binds)]


def _chain(path: str, links: dict[str, str], depth: int = 0) -> None:
    """Every link `path` goes through, component by component, into `links` (link -> target)."""
    if depth > 16:
        return
    current = "/"
    for part in Path(path).parts[1:]:
        step = os.path.join(current, part)
        if os.path.islink(step):
            target = os.readlink(step)
            links[step] = target
            _chain(os.path.join(current, target), links, depth + 1)
            current = os.path.realpath(step)
        else:
            current = step


def _program_interpreter(executable: str) -> str | None:
    """An ELF executable's PT_INTERP: the path of the dynamic loader the kernel starts it with (None if static)."""
    try:
        with open(executable, "rb") as file:
            header = file.read(64)
            if header[:4] != b"\x7fELF" or header[4] != 2:          # 64-bit ELF only (x86_64, aarch64)
                return None
            order = "<" if header[5] == 1 else ">"
            phoff, = struct.unpack_from(order + "Q", header, 32)
            phentsize, phnum = struct.unpack_from(order + "HH", header, 54)
            for number in range(phnum):
                file.seek(phoff + number * phentsize)
                kind, _, offset, _, _, size = struct.unpack(order + "IIQQQQ", file.read(40))
                if kind == 3:                                        # PT_INTERP
                    file.seek(offset)
                    return file.read(size).rstrip(b"\0").decode()
    except (OSError, struct.error, UnicodeDecodeError):
        return None
    return None


def _copies(kit: Path, packages: Iterable[tuple[Path, str]]) -> list[tuple[str, str]]:
    """(file, path in the sandbox): the kit's package without its solutions, then each package's top folder (or
    module file); never a symbolic link, never a hidden file or bytecode (`contents` gives the bytecode)."""
    from appsim.workshop import course

    solutions = Path(os.path.realpath(course.SOLUTIONS))
    copies = [(str(f), f"{KIT_FOLDER}/{f.relative_to(kit.parent).as_posix()}") for f in _files(kit, solutions)]
    for entry, top in sorted(packages):
        copies += [(str(f), f"{SITE_FOLDER}/{f.relative_to(entry).as_posix()}") for f in _files(entry / top)]
    return copies


def _files(top: Path, skip: Path | None = None) -> list[Path]:
    if top.is_file() and not top.is_symlink():
        return [top]
    found = []
    for folder, folders, files in os.walk(top):
        here = Path(folder)
        folders[:] = sorted(f for f in folders if not f.startswith(".") and f != "__pycache__"
                            and (skip is None or (here / f).resolve() != skip))
        found += [here / f for f in sorted(files) if not f.startswith(".") and not f.endswith((".pyc", ".pyo"))
                  and not (here / f).is_symlink()]
    return found


# ====================================================================== the copies' bytes

@functools.lru_cache(maxsize=2)
def contents(copies: tuple[tuple[str, str], ...]) -> tuple[tuple[str, bytes], ...]:
    """Each copy's path in the sandbox and bytes, with the bytecode Python compiled for it (where that bytecode is up to
    date) made unchecked, so the sandbox runs it as compiled: read once per process (a forked worker has it)."""
    found: list[tuple[str, bytes]] = []
    size = 0
    for source, destination in copies:
        data = Path(source).read_bytes()
        found.append((destination, data))
        size += len(data)
        if destination.endswith(".py"):
            compiled = _unchecked_bytecode(Path(source), data)
            if compiled is not None:
                found.append((importlib.util.cache_from_source(destination), compiled))
                size += len(compiled)
        if size > MAX_COPIED:
            raise LayoutError(f"the kit's package and the packages its firmware library imports are more than "
                              f"{MAX_COPIED >> 20} MB: a sandbox is given at most that")
    return tuple(found)


def _unchecked_bytecode(source: Path, data: bytes) -> bytes | None:
    """The bytecode cached for `source` (PEP 3147), if it is of this Python and of this very source, as an unchecked
    hash-based pyc (PEP 552): a copy of the source has a new time, against which Python would compile it again."""
    try:
        cached = Path(importlib.util.cache_from_source(str(source))).read_bytes()
    except (OSError, NotImplementedError):
        return None
    if len(cached) < 16 or cached[:4] != importlib.util.MAGIC_NUMBER:
        return None
    flags, = struct.unpack_from("<I", cached, 4)
    if flags == 0:                      # timestamp-based: the source's mtime and size
        mtime, length = struct.unpack_from("<II", cached, 8)
        info = source.stat()
        if mtime != int(info.st_mtime) & 0xFFFFFFFF or length != len(data) & 0xFFFFFFFF:
            return None
    elif cached[8:16] != importlib.util.source_hash(data):
        return None
    return cached[:4] + struct.pack("<I", 0b01) + importlib.util.source_hash(data) + cached[16:]
