"""What a graded firmware's sandbox holds: the Python runtime, the kit's package and the packages its firmware library
imports, nothing else. An answer key on any kind of path the grader's Python has is out of reach, the mount table names
none of the grader's own folders, and every standard library module that imports in `appsim check` imports there."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from appsim.workshop.course import SOLUTIONS, STARTERS
from appsim.workshop.sandbox import mounts
from appsim.workshop.sandbox.isolation import isolation

SEED = 2024
STARTER_EX1 = (STARTERS / "ex1.py").read_text()
SOLUTION_EX1 = (SOLUTIONS / "ex1.py").read_text()
ROUTES = ("pythonpath", "pth", "cwd", "user_site", "site_packages")


def stealing(module: str, path: Path) -> str:
    """The Ex1 starter, which first looks for the answer key `module` (the reference Ex1): by import, then by its
    path. Found, its main() runs instead: 5/5 where the starter earns 3/5."""
    head, rest = STARTER_EX1.split("def main():\n", 1)
    return (head + f'''
def _answer_key():
    import importlib
    try:
        return importlib.import_module({module!r}).main
    except ImportError:
        pass
    try:
        with open({str(path)!r}) as file:
            source = file.read()
    except OSError:
        return None
    found = {{"__name__": "stolen"}}
    exec(compile(source, "stolen.py", "exec"), found)
    return found["main"]


def main():
    stolen = _answer_key()
    if stolen is not None:
        stolen()
''' + rest)


def a_grader(tmp_path: Path) -> tuple[Path, dict[str, str], Path, dict[str, Path]]:
    """A Python for the grader (a venv over this one's, the kit importable from it) with an answer key on each kind
    of path it has: PYTHONPATH, a folder a .pth file adds, the current folder, the user site, and site-packages
    itself (a module dropped there, in no installed package). Its python, environment, current folder, and keys."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", "--system-site-packages", str(venv)], check=True)
    python = venv / "bin" / "python"
    site_packages = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                                        capture_output=True, text=True, check=True).stdout.strip())
    ours = sysconfig.get_path("purelib")        # where this kit and its packages are installed
    (site_packages / "kit.pth").write_text(f"import site; site.addsitedir({ours!r})\n")
    home = tmp_path / "home"
    user_site = Path(subprocess.run([str(python), "-c", "import site; print(site.getusersitepackages())"],
                                    env={"HOME": str(home)}, capture_output=True, text=True, check=True).stdout.strip())
    folders = {"pythonpath": tmp_path / "course_on_pythonpath", "pth": tmp_path / "course_in_a_pth",
               "cwd": tmp_path / "course_here", "user_site": user_site, "site_packages": site_packages}
    (site_packages / "course.pth").write_text(f"{folders['pth']}\n")
    keys = {}
    for route, folder in folders.items():
        folder.mkdir(parents=True, exist_ok=True)
        keys[route] = folder / f"answers_{route}.py"
        keys[route].write_text(SOLUTION_EX1)
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": str(home), "LANG": "C.UTF-8",
           "PYTHONPATH": str(folders["pythonpath"])}
    return python, env, folders["cwd"], keys


def test_no_answer_key_on_any_of_the_grader_s_paths_reaches_a_firmware(tmp_path):
    python, env, here, keys = a_grader(tmp_path)
    reachable = subprocess.run([str(python), "-c", "import " + ", ".join(f"answers_{r}" for r in ROUTES)],
                               cwd=here, env=env, capture_output=True, text=True)
    assert reachable.returncode == 0, f"the answer keys must be importable by the grader itself: {reachable.stderr}"
    room = tmp_path / "class"
    for name, source in {"honest": STARTER_EX1, **{f"by_{r}": stealing(f"answers_{r}", keys[r]) for r in ROUTES},
                         "reference": SOLUTION_EX1}.items():
        (room / name).mkdir(parents=True)
        (room / name / "ex1.py").write_text(source)
    done = subprocess.run([str(python), "-m", "appsim", "grade", str(room), "--jobs", "2", "--seed", str(SEED),
                           "--json", str(tmp_path / "grades.jsonl")], cwd=here, env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    records = {r["submission"]: r["exercises"]["ex1"]
               for r in map(json.loads, (tmp_path / "grades.jsonl").read_text().splitlines())}
    assert records["reference"]["score"] == 5 and records["honest"]["score"] == 3
    for route in ROUTES:
        assert records[f"by_{route}"] == records["honest"], route


def test_the_sandbox_is_given_the_runtime_and_copies_and_none_of_the_grader_s_import_folders(tmp_path, monkeypatch):
    """What is bound is the runtime's (the interpreter, its standard library, its libraries); what is copied is the
    kit's package without its solutions, and only the installed packages the firmware library imports (greenlet) and
    the C translator does (pcpp, pycparser)."""
    course = tmp_path / "course"
    course.mkdir()
    monkeypatch.setattr(sys, "path", [sys.path[0], str(course), *sys.path[1:]])
    monkeypatch.chdir(course)
    walls = isolation()
    import greenlet
    import pcpp
    import pycparser

    import appsim

    kit = Path(appsim.__file__).resolve().parent
    packages = [Path(package.__file__).parent for package in (greenlet, pcpp, pycparser)]
    for folder in (course, kit, Path(sys.prefix), Path(sysconfig.get_path("purelib"))):
        folder = folder.resolve()
        inside = [bound for bound in walls.binds if folder.is_relative_to(bound)]
        assert not inside or any(folder.is_relative_to(c) for c in walls.covered), (folder, inside)
    sources = {Path(source) for source, _ in walls.copies}
    assert all(s.is_relative_to(kit) or any(s.is_relative_to(package) for package in packages) for s in sources)
    assert not any(s.is_relative_to(SOLUTIONS.resolve()) or "solutions" in s.parts for s in sources)
    assert {d.split("/")[2] for _, d in walls.copies if d.startswith(mounts.SITE_FOLDER + "/")} == {
        "greenlet", "pcpp", "pycparser"}, "the firmware library's packages, and the C translator's (child.boot_c)"


def test_the_mount_table_names_none_of_the_grader_s_folders(tmp_path):
    """/proc/self/mountinfo in the sandbox: each bind shows where it comes from (the kernel's mount root, which
    bubblewrap cannot change), so only the runtime's folders may show; the kit, the venv, the class do not."""
    from test_grade import _graded_alone, firmware

    import appsim
    secret_places = [Path(appsim.__file__).resolve().parent.parent, tmp_path.resolve(), Path.cwd().resolve()]
    if sys.prefix != sys.base_prefix:
        secret_places.append(Path(sys.prefix).resolve())     # the venv (outside one, the prefix is the runtime's own)
    looking = firmware("with open('/proc/self/mountinfo') as table:\n    seen = table.read()\n"
                       f"for place in {[str(p) for p in secret_places]!r}:\n"
                       "    if place in seen:\n        raise RuntimeError('the mount table names ' + place)\n"
                       "while True:\n    CANIsRxReady()")
    from appsim.workshop.sandbox.children import Limits
    result = _graded_alone(tmp_path, "ex1", looking, Limits(time_s=8, stall_s=2))
    assert result["fault"] is None, result["checks"][0]["message"]


def test_every_standard_library_module_that_imports_here_imports_in_the_sandbox(tmp_path):
    """Extension modules too (sqlite3, ssl, ctypes, curses ...): their libraries are bound with the runtime."""
    from test_grade import _graded_alone, firmware

    from appsim.workshop.sandbox.children import Limits
    names = sorted(name for name in sys.stdlib_module_names if not name.startswith(("_", "idlelib", "test", "tkinter",
                                                                                   "turtle", "antigravity", "this")))
    importable = subprocess.run([sys.executable, "-I", "-c", "import importlib, json, sys\nfound = []\n"
                                 f"for name in {names!r}:\n    try:\n        importlib.import_module(name)\n"
                                 "    except Exception:\n        continue\n    found.append(name)\n"
                                 "print(json.dumps(found))"], capture_output=True, text=True, check=True, cwd="/")
    modules = json.loads(importable.stdout.splitlines()[-1])
    assert {"sqlite3", "ssl", "ctypes", "decimal", "hashlib", "lzma"} <= set(modules)
    importing = firmware("import importlib\nmissing = []\n"
                         f"for name in {modules!r}:\n    try:\n        importlib.import_module(name)\n"
                         "    except ImportError as error:\n        missing.append(f'{name} ({error})')\n"
                         "if missing:\n    raise RuntimeError('not in the sandbox: ' + ', '.join(missing))\n"
                         "while True:\n    CANIsRxReady()")
    result = _graded_alone(tmp_path, "ex1", importing, Limits(time_s=30, stall_s=10))
    assert result["fault"] is None, result["checks"][0]["message"]


@pytest.mark.parametrize("what", ["a .dist-info names it", "an .egg-info names it"])
def test_a_package_counts_as_installed_only_where_a_distribution_names_it(tmp_path, what):
    site = tmp_path / "site"
    (site / "mylib").mkdir(parents=True)
    (site / "loose.py").write_text("")
    if what.startswith("a .dist"):
        (site / "my_lib-1.0.dist-info").mkdir()
        (site / "my_lib-1.0.dist-info" / "RECORD").write_text("mylib/__init__.py,sha256=x,0\n")
    else:
        (site / "mylib-1.0.egg-info").mkdir()
        (site / "mylib-1.0.egg-info" / "top_level.txt").write_text("mylib\n")
    assert mounts._installed(site, "mylib") and not mounts._installed(site, "loose.py")


def test_a_module_of_the_firmware_library_from_no_installed_package_refuses_the_sandbox_in_words(tmp_path,
                                                                                               monkeypatch):
    (tmp_path / "vendored" / "greenlet").mkdir(parents=True)
    monkeypatch.setattr(sys, "path", [sys.path[0], str(tmp_path / "vendored"), *sys.path[1:]])
    with pytest.raises(mounts.LayoutError, match="where no installed package holds it"):
        mounts._layout([], [str(tmp_path / "vendored" / "greenlet" / "__init__.py")], [], [])


def test_bytecode_is_copied_only_where_it_is_this_very_source_s(tmp_path):
    source = tmp_path / "module.py"
    source.write_text("VALUE = 1\n")
    import py_compile
    py_compile.compile(str(source), doraise=True)
    copied = dict(mounts.contents(((str(source), "/kit/module.py"),)))
    assert "/kit/__pycache__/" + Path(py_compile.importlib.util.cache_from_source(str(source))).name in copied
    source.write_text("VALUE = 22\n")           # edited since: its bytecode is stale and is not copied
    os.utime(source, (1, 1))
    mounts.contents.cache_clear()
    assert len(mounts.contents(((str(source), "/kit/module.py"),))) == 1


def test_a_package_in_a_site_packages_inside_the_standard_library_s_folder_is_copied(tmp_path, monkeypatch):
    """pyenv's Pythons, and any built from source, keep site-packages inside lib/python3.X, the standard library's
    folder the sandbox binds (with its site-packages covered): a package the firmware library imports from there is
    copied in like any other. (Found grading with pyenv's Python: every exercise was the grader's fault, 'No module
    named greenlet' in the sandbox.)"""
    stdlib = tmp_path / "home" / "lib" / "python3.11"
    site = stdlib / "site-packages"
    (site / "greenlet").mkdir(parents=True)
    (site / "greenlet" / "__init__.py").write_text("")
    (site / "greenlet-3.0.dist-info").mkdir()
    (site / "greenlet-3.0.dist-info" / "RECORD").write_text("greenlet/__init__.py,sha256=x,0\n")
    monkeypatch.setattr(sys, "path", [sys.path[0], str(site), *sys.path[1:]])
    walls = mounts._layout([str(stdlib)], [str(site / "greenlet" / "__init__.py")], [], [])
    assert (str(site / "greenlet" / "__init__.py"), f"{mounts.SITE_FOLDER}/greenlet/__init__.py") in walls.copies
    assert str(stdlib) in walls.binds and str(site) in walls.covered
