"""A Gradescope autograder: the zip `appsim gradescope-autograder` writes (setup.sh, run_autograder, the kit as a wheel)
and what run_autograder does in Gradescope's container: `appsim grade`'s own run on /autograder/submission, written as
Gradescope's results.json, one test per check.

Gradescope's layout (its "Autograder Specifications"): the zip's files in /autograder/source, the student's in
/autograder/submission, the results in /autograder/results/results.json. `root` stands for /autograder (tests use a
folder of their own). docs/grading.md says what isolation each container gets.
"""
from __future__ import annotations

import base64
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from appsim.errors import GradeError, SandboxUnavailable
from appsim.workshop.course import EXERCISES
from appsim.workshop.grading.results import Record, kit_version

ROOT = Path("/autograder")
CONFIG = "appsim-autograder.json"
VISIBILITIES = ("visible", "after_due_date", "after_published", "hidden")     # Gradescope's, for tests and output
NOT_ISOLATED = ("This container does not let appsim build its sandbox ({why}), so the firmware ran without it, "
                "inside Gradescope's container, which holds this submission alone: the container is the boundary.")

SETUP = r"""#!/usr/bin/env bash
# Gradescope runs this once, as root, when it builds the autograder's image: the kit from the wheel beside it, in a
# venv of its own, and bubblewrap (appsim grade's sandbox) where the image has apt. `setup.sh --install-only` does the
# install step alone (no apt); APPSIM_AUTOGRADER_ROOT stands for /autograder, APPSIM_AUTOGRADER_PYTHON for python3.
set -euo pipefail
root="${APPSIM_AUTOGRADER_ROOT:-/autograder}"
python="${APPSIM_AUTOGRADER_PYTHON:-python3}"
if [ "${1:-}" != "--install-only" ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends python3 python3-venv python3-pip >/dev/null
  apt-get install -y -qq --no-install-recommends bubblewrap >/dev/null \
    || echo "setup.sh: no bubblewrap in this image: submissions are graded with the container as the boundary"
fi
"$python" -m venv --system-site-packages "$root/appsim-venv"
"$root/appsim-venv/bin/python" -m pip install --quiet --disable-pip-version-check "$root"/source/appsim-*.whl
"$root/appsim-venv/bin/python" -c "import appsim, can, cantools; print('setup.sh: appsim', appsim.__version__)"
"""

RUN = r"""#!/usr/bin/env bash
# Gradescope runs this for each submission: appsim grade's checks on /autograder/submission, written to
# /autograder/results/results.json (one test per check). APPSIM_AUTOGRADER_ROOT stands for /autograder.
root="${APPSIM_AUTOGRADER_ROOT:-/autograder}"
exec "$root/appsim-venv/bin/python" -m appsim.workshop.grading.autograder "$root"
"""


# ====================================================================== the zip

def build(out: Path, *, seed: int, time_limit_s: float = 60.0, visibility: str = "visible",
          c_options: Sequence[str] = ()) -> Path:
    """Write the autograder zip to `out`: setup.sh, run_autograder, the kit as a wheel and its settings (among them
    C18's `c_options` for .c firmware, such as -Oi, as `appsim grade --c-option` takes them)."""
    if visibility not in VISIBILITIES:
        raise GradeError(f"visibility is one of Gradescope's {', '.join(VISIBILITIES)}; got {visibility!r}")
    if out.suffix.lower() != ".zip":
        raise GradeError(f"{out}: Gradescope takes the autograder as a .zip; give a name such as autograder.zip")
    if not out.resolve().parent.is_dir():
        raise GradeError(f"{out}: the folder {out.resolve().parent} does not exist; create it or give another path")
    with tempfile.TemporaryDirectory(prefix="appsim-autograder-") as scratch:
        wheel = kit_wheel(Path(scratch))
        settings = {"seed": seed, "time_limit_s": time_limit_s, "visibility": visibility, "kit": kit_version(),
                    "wheel": wheel.name, "c_options": list(c_options)}
        temporary = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        try:
            with zipfile.ZipFile(temporary, "w", zipfile.ZIP_DEFLATED) as archive:
                for name, text in (("setup.sh", SETUP), ("run_autograder", RUN)):
                    info = zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0))
                    info.external_attr = 0o100755 << 16          # executable, as Gradescope runs them
                    info.compress_type = zipfile.ZIP_DEFLATED
                    archive.writestr(info, text)
                archive.writestr(CONFIG, json.dumps(settings, indent=1) + "\n")
                archive.write(wheel, wheel.name)
            os.replace(temporary, out)
        except OSError as error:
            raise GradeError(f"cannot write {out}: {error.strerror or error}") from None
        finally:
            temporary.unlink(missing_ok=True)
    return out


def kit_wheel(folder: Path) -> Path:
    """A wheel of the kit that is running: built from its checkout, or packed again from its installed files."""
    import appsim

    package = Path(appsim.__file__).resolve().parent
    root = package.parent
    if (root / "pyproject.toml").is_file():
        return _built(root, folder)
    return _repacked(folder)


def _built(checkout: Path, folder: Path) -> Path:
    """`pip wheel` of a copy of the checkout's sources (the checkout itself is left as it was)."""
    source = folder / "source"
    junk = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build", "dist", ".*")
    for part in ("appsim", "exercises", "solutions"):
        shutil.copytree(checkout / part, source / part, ignore=junk)
    for part in ("pyproject.toml", "README.md"):
        shutil.copy2(checkout / part, source / part)
    for isolation in ("--no-build-isolation", None):
        result = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(folder),
                                 *([isolation] if isolation else []), str(source)], capture_output=True, text=True)
        wheels = sorted(folder.glob("appsim-*.whl"))
        if result.returncode == 0 and wheels:
            return wheels[-1]
    raise GradeError(f"could not build a wheel of the kit from {checkout}: {result.stderr.strip()[-500:]}")


def _repacked(folder: Path) -> Path:
    """The installed kit as a wheel again: its files as its RECORD lists them, with a RECORD of their own."""
    from importlib import metadata

    distribution = metadata.distribution("appsim")
    version = distribution.version
    wheel = folder / f"appsim-{version}-py3-none-any.whl"
    info = f"appsim-{version}.dist-info"
    record = []
    with zipfile.ZipFile(wheel, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in distribution.files or ():
            name = file.as_posix()
            if name.startswith("..") or "__pycache__" in name or name.endswith((".pyc", "/RECORD", "/INSTALLER",
                                                                                 "/direct_url.json", "/REQUESTED")):
                continue
            data = Path(str(distribution.locate_file(file))).read_bytes()
            archive.writestr(name, data)
            digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            record.append(f"{name},sha256={digest},{len(data)}")
        record.append(f"{info}/RECORD,,")
        archive.writestr(f"{info}/RECORD", "\n".join(record) + "\n")
    return wheel


# ====================================================================== in Gradescope's container

def run(root: Path = ROOT) -> int:
    """Grade `root`/submission as `appsim grade` does, with the zip's seed, into `root`/results/results.json."""
    started = time.monotonic()
    results = root / "results"
    results.mkdir(parents=True, exist_ok=True)
    settings = json.loads((root / "source" / CONFIG).read_text(encoding="utf-8"))
    try:
        answer, status = _grade(root / "submission", settings)
    except GradeError as error:             # the upload's doing: the student reads why
        answer, status = failed(f"This upload cannot be graded: {error}"), 0
    except Exception as error:              # the grader's: the instructor reads the traceback in Gradescope's stdout
        import traceback

        traceback.print_exc()
        answer, status = failed(f"The autograder failed on this submission ({type(error).__name__}: {error}); it is "
                                "not your doing: ask your instructor to regrade it"), 1
    answer["execution_time"] = round(time.monotonic() - started, 1)
    (results / "results.json").write_text(json.dumps(answer, indent=1) + "\n", encoding="utf-8")
    print(answer.get("output", ""))
    return status


def _grade(submission: Path, settings: dict[str, Any]) -> tuple[Record, int]:
    from appsim.workshop.grading.grade import run as grade
    from appsim.workshop.sandbox.children import Limits
    from appsim.workshop.sandbox.isolation import isolation

    try:
        isolation([])
        note, trusted = "", False
    except SandboxUnavailable as error:
        note, trusted = NOT_ISOLATED.format(why=error), True
    time_s = float(settings["time_limit_s"])
    with tempfile.TemporaryDirectory(prefix="appsim-autograder-") as scratch:
        records = grade([submission], results=Path(scratch) / "grades.jsonl", seed=int(settings["seed"]),
                        limits=Limits(time_s=time_s, stall_s=min(10.0, time_s),
                                      c_options=tuple(settings.get("c_options", ()))),
                        trusted=trusted, out=sys.stdout)
    if len(records) != 1:
        found = ", ".join(r["submission"] for r in records) or "none"
        return failed(f"Hand in one submission: the files ex1.py .. ex6.py and demo1_monitor.py (in C: ex1.c .. "
                      f"ex6.c and demo1_monitor.c; or the workshop's notebooks), at the top of the upload or in one "
                      f"folder; this upload holds {len(records)} "
                      f"({found}).", note), 0
    return results_json(records[0], settings["visibility"], note, isolated=not trusted), 0


def failed(why: str, note: str = "") -> Record:
    """A results.json for an upload that could not be graded: no points, and why, for the student to see."""
    return {"score": 0, "output": "\n\n".join(filter(None, (why, note))), "tests": []}


def results_json(record: Record, visibility: str = "visible", note: str = "", *, isolated: bool = True) -> Record:
    """One submission's record as Gradescope's results.json: a test per check, its points, its words."""
    tests = []
    for number, exercise in enumerate(EXERCISES, start=1):
        result = record["exercises"][exercise]
        fault = result.get("fault")
        for part, check in enumerate(result["checks"], start=1):
            points = check["points"] if check["passed"] else 0
            tests.append({"name": f"{exercise.upper()}: {check['name']}", "number": f"{number}.{part}",
                          "score": points, "max_score": check["points"],
                          "status": "passed" if check["passed"] else "failed", "output": check["message"],
                          "tags": [exercise, *([fault] if fault else [])], "visibility": visibility})
    summary = (f"{record['score']}/{record['max_score']} points: "
               + ", ".join(f"{e.upper()} {r['score']}/{r['max_score']}" for e, r in record["exercises"].items())
               + f". Graded by appsim {record['kit']} with seed {record['seed']}: `appsim grade` with the same seed "
               "gives the same marks.")
    return {"score": record["score"], "output": "\n\n".join(filter(None, (summary, note))), "visibility": visibility,
            "stdout_visibility": "hidden", "tests": tests,
            "extra_data": {"seed": record["seed"], "kit": record["kit"], "hash": record["hash"],
                           "isolated": isolated}}


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    return run(Path(args[0]) if args else ROOT)


if __name__ == "__main__":
    sys.exit(main())
