"""The kit among python-can programs and on Gradescope: frames per second through the "appsim" interface (a served
bus at 1 Mbit/s, one python-can program sending to another) against python-can's own virtual bus; and a Gradescope
run (run_autograder on a full submission, after setup.sh) against `appsim grade` of the same submission.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import can

from appsim.can.bits import INTERMISSION_BITS, frame_bits
from appsim.can.frame import CanFrame
from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS

BIT_RATE = 1_000_000
SERVE = """
import sys
from appsim.bus.realtime import WallClock
from appsim.bus.serve import ClassroomServer
from appsim.bus.wire import Bus
from appsim.sim import Simulator
bus = Bus(Simulator(), {bit_rate})
server = ClassroomServer(bus, "bench")
print("serving", flush=True)
clock = WallClock(bus.sim)
clock.add_poller(server.poll)
clock.run({seconds})
server.close()
"""


def interface_fps(frames: int) -> tuple[float, float]:
    """Frames per wall second from one python-can program to another through a served bus at 1 Mbit/s (the server in
    a process of its own, paced to the wall clock), and the bus's own limit for those frames."""
    with tempfile.TemporaryDirectory(prefix="appsim-bench-") as scratch:
        runtime = Path(scratch) / "run"
        runtime.mkdir(mode=0o700)
        env = {**os.environ, "XDG_RUNTIME_DIR": str(runtime)}
        server = subprocess.Popen([sys.executable, "-c", SERVE.format(bit_rate=BIT_RATE, seconds=120)], env=env,
                                  stdout=subprocess.PIPE, text=True)
        saved = os.environ.get("XDG_RUNTIME_DIR")
        os.environ["XDG_RUNTIME_DIR"] = str(runtime)
        try:
            assert server.stdout is not None and server.stdout.readline().strip() == "serving"
            sender = can.Bus(interface="appsim", channel="bench")
            receiver = can.Bus(interface="appsim", channel="bench")
            message = can.Message(arbitration_id=0x100, data=bytes(range(8)), is_extended_id=False)
            time.sleep(0.2)                         # both have joined the bus
            started = time.perf_counter()
            got = 0
            for _ in range(frames):
                sender.send(message, timeout=10)
                while receiver.recv(0) is not None:
                    got += 1
            while got < frames:
                if receiver.recv(10) is None:
                    raise RuntimeError(f"the receiver got {got} of {frames} frames")
                got += 1
            wall = time.perf_counter() - started
            sender.shutdown()
            receiver.shutdown()
        finally:
            if saved is None:
                os.environ.pop("XDG_RUNTIME_DIR", None)
            else:
                os.environ["XDG_RUNTIME_DIR"] = saved
            server.terminate()
            server.wait(30)
    bits = frame_bits(CanFrame(message.arbitration_id, bytes(message.data))) + INTERMISSION_BITS
    return frames / wall, BIT_RATE / bits


def virtual_fps(frames: int) -> float:
    """Frames per wall second python-can's virtual bus passes from one program to another."""
    sender = can.Bus(interface="virtual", channel="appsim-bench-served")
    receiver = can.Bus(interface="virtual", channel="appsim-bench-served")
    message = can.Message(arbitration_id=0x100, data=bytes(range(8)), is_extended_id=False)
    started = time.perf_counter()
    for _ in range(frames):
        sender.send(message)
        if receiver.recv(1) is None:
            raise RuntimeError("python-can's virtual bus lost a frame")
    wall = time.perf_counter() - started
    sender.shutdown()
    receiver.shutdown()
    return frames / wall


def _submission(folder: Path) -> Path:
    folder.mkdir(parents=True)
    for name in EXERCISE_FILES.values():
        shutil.copy(SOLUTIONS / name, folder)
    return folder


def gradescope_against_grade_s(seed: int = 1) -> tuple[float, float]:
    """Wall seconds of run_autograder on a full submission (the kit installed by setup.sh's install step first, not
    timed) and of `appsim grade` on the same submission with --jobs 2, both the whole command."""
    with tempfile.TemporaryDirectory(prefix="appsim-bench-") as scratch:
        root = Path(scratch) / "autograder"
        root.mkdir()
        subprocess.run([sys.executable, "-m", "appsim", "gradescope-autograder", str(root / "a.zip"), "--seed",
                        str(seed)], check=True, capture_output=True)
        with zipfile.ZipFile(root / "a.zip") as archive:
            archive.extractall(root / "source")
        env = {**os.environ, "APPSIM_AUTOGRADER_ROOT": str(root), "APPSIM_AUTOGRADER_PYTHON": sys.executable}
        subprocess.run(["bash", str(root / "source" / "setup.sh"), "--install-only"], env=env, check=True,
                       capture_output=True)
        _submission(root / "submission")
        (root / "results").mkdir()
        started = time.perf_counter()
        subprocess.run(["bash", str(root / "source" / "run_autograder")], env=env, check=True, capture_output=True)
        gradescope = time.perf_counter() - started
        answer = json.loads((root / "results" / "results.json").read_text())
        if answer["score"] != 35:
            raise RuntimeError(f"the solutions did not get full marks on the autograder: {answer['output']}")
        alone = _submission(Path(scratch) / "alone")
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "appsim", "grade", str(alone), "--jobs", "2", "--seed", str(seed)],
                       check=True, capture_output=True)
        grade = time.perf_counter() - started
    return gradescope, grade
