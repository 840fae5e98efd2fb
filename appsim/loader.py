"""Loading a student's firmware file: plain Python with `from appsim.firmware import *` and a `main()`.

Each load is a fresh module, so two boards running the same file never share their globals.
"""
from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path
from types import ModuleType

_loads = itertools.count()


class FirmwareError(Exception):
    """A firmware file that cannot run, with what to do about it."""


def load_firmware(path: str | Path) -> ModuleType:
    """Load a firmware file as a new module; it must define `main()`."""
    path = Path(path)
    if not path.is_file():
        raise FirmwareError(f"there is no firmware file at {path}: give the path of a .py file such as "
                            "exercises/ex1.py")
    spec = importlib.util.spec_from_file_location(f"firmware_{path.stem}_{next(_loads)}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except SyntaxError as error:
        raise FirmwareError(f"{path}, line {error.lineno}: {error.msg}: fix the Python syntax there") from None
    except Exception as error:
        raise FirmwareError(f"{path} failed while loading, before main() ran: {type(error).__name__}: "
                            f"{error}. Only constants and functions belong at the top of the file; "
                            "CAN and LCD calls go inside main().") from error
    if not callable(getattr(module, "main", None)):
        raise FirmwareError(f"{path} has no main(): a firmware file defines `def main():` that loops "
                            "forever, as main() does in EX1.C")
    return module
