"""`python -m bench`: how fast the kit simulates, against the bus's physical limit and python-can, in one table.

Every ratio is measured in the same run on the same machine; `--quick` is a tiny configuration for the tests.
"""
from __future__ import annotations

import argparse
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from appsim.bus.link import PYTHON_QUEUE_FRAMES
from appsim.workshop.course import SOLUTIONS
from bench import busywait, cfirmware, flood, fullload, grading, interrupts, knobs, linked, memory, pythoncan, served
from bench.figures import Figure, machine, repeat, table


@dataclass(frozen=True)
class Config:
    runs: int
    full_load_s: float          # simulated seconds per full-load run
    scaling_s: float
    python_can_frames: int
    busy_wait_s: float
    linked_s: float             # wall seconds of the Ex2 board linked in real time
    round_trips: int
    class_size: int             # submissions graded by `appsim grade --jobs 2`
    isolation_class: int        # submissions graded sandboxed and --trusted, for the isolation's cost
    knob_turns: int             # slider moves per exercise notebook
    served_frames: int          # frames from one python-can program to another through the "appsim" interface
    memory_hogs: tuple[str, ...] | None     # bench.memory's firmware whose worker memory is measured (None: all)
    classroom_s: float          # simulated seconds of a classroom, polling against interrupt-driven stations
    flood_s: float              # simulated seconds of the classroom under an error flood
    peer_s: float               # wall seconds of the linked classroom with a flooding python-can peer in the process


FULL = Config(runs=3, full_load_s=0.05, scaling_s=0.02, python_can_frames=20_000, busy_wait_s=10.0,
              linked_s=1.5, round_trips=10, class_size=60, isolation_class=4, knob_turns=5, served_frames=5000,
              memory_hogs=None, classroom_s=5.0, flood_s=5.0, peer_s=300.0)
QUICK = Config(runs=1, full_load_s=0.002, scaling_s=0.001, python_can_frames=200, busy_wait_s=0.3,
               linked_s=0.2, round_trips=2, class_size=2, isolation_class=1, knob_turns=1, served_frames=100,
               memory_hogs=("call sites",), classroom_s=0.1, flood_s=0.1,
               peer_s=3.0)


def _runs(config: Config, nodes: int, load: float, simulated_s: float, *, bit_rate: int = fullload.BIT_RATE,
          one_sender: bool = False) -> list[fullload.Run]:
    """`config.runs` timed full-model runs (at least one)."""
    return [fullload.run(nodes, load, simulated_s, bit_rate=bit_rate, one_sender=one_sender)
            for _ in range(max(config.runs, 1))]


def _full_load(config: Config) -> list[Figure]:
    runs = _runs(config, 7, 1.0, config.full_load_s)
    last = runs[-1]
    rtf = Figure("real-time factor: 7 nodes, 1 Mbit/s, 100 % load", "sim s / wall s",
                 tuple(r.real_time_factor for r in runs), target=1, aim=10,
                 note=f"load {last.bus_busy:.0%}, firmware read {last.read_by_firmware:.0%} of deliveries")
    fps = Figure("frames per wall second at that load", "frames/s",
                 tuple(r.frames_per_wall_second for r in runs),
                 note=f"bus limit {last.bus_limit_fps:,.0f} frames/s ({last.mean_frame_bits:.1f} bits a frame "
                      "with stuffing and intermission)")
    filtered = _runs(config, 7, 1.0, config.full_load_s, one_sender=True)
    classroom_like = Figure("real-time factor: 7 nodes, 1 Mbit/s, 100 % load, each reads one sender's frames",
                            "sim s / wall s", tuple(r.real_time_factor for r in filtered),
                            note=f"masks and filters pass 1 frame in 6, as a classroom "
                                 f"station's do; firmware read {filtered[-1].read_by_firmware:.0%} of deliveries")
    workshop = _runs(config, 7, 1.0, 8 * config.full_load_s, bit_rate=125_000)
    workshop_rate = Figure("real-time factor: 7 nodes, 125 kbit/s (the workshop's), 100 % load", "sim s / wall s",
                           tuple(r.real_time_factor for r in workshop),
                           note=f"load {workshop[-1].bus_busy:.0%}, firmware read "
                                f"{workshop[-1].read_by_firmware:.0%} of deliveries; >= 1 keeps up with a real bus")
    return [rtf, fps, classroom_like, workshop_rate]


def _scaling(config: Config) -> list[Figure]:
    figures = []
    for nodes, load in ((7, 1.0), (14, 1.0), (28, 1.0), (7, 0.5), (7, 0.25)):
        runs = _runs(config, nodes, load, config.scaling_s)
        per_delivery = statistics.median(r.wall_s / max(r.frames * (r.nodes - 1), 1) for r in runs) * 1e6
        figures.append(Figure(f"real-time factor: {nodes} nodes, {load:.0%} load", "sim s / wall s",
                              tuple(r.real_time_factor for r in runs),
                              note=f"load {runs[-1].bus_busy:.0%}; {per_delivery:.0f} us wall per frame received"))
    return figures


def _python_can(config: Config) -> list[Figure]:
    kit, bare, ratios = [], [], []
    for _ in range(max(config.runs, 1)):
        kit.append(pythoncan.kit_fps(config.full_load_s))
        bare.append(pythoncan.python_can_fps(config.python_can_frames))
        ratios.append(kit[-1] / bare[-1])
    return [Figure("full model / python-can virtual bus, 1 sender -> 6 receivers", "ratio", tuple(ratios),
                   target=0.5, aim=1,
                   note=f"kit {statistics.median(kit):,.0f} frames/s, "
                        f"python-can {statistics.median(bare):,.0f} frames/s")]


def _busy_wait(config: Config) -> list[Figure]:
    return [
        Figure("busy-wait on CANIsRxReady(), a frame every 100 ms", "wall ms / sim s",
               repeat(config.runs, lambda: busywait.wall_ms_per_simulated_second(True, config.busy_wait_s))),
        Figure("busy-wait on CANIsRxReady(), no frames", "wall ms / sim s",
               repeat(config.runs, lambda: busywait.wall_ms_per_simulated_second(False, config.busy_wait_s))),
    ]


def _grading(config: Config) -> list[Figure]:
    first = Figure("check one submission (solutions of Ex1..Ex6 and Demo1), in process", "wall s",
                   repeat(config.runs, grading.one_submission_s), note="appsim.workshop.checks.check")
    alone = repeat(config.runs, lambda: grading.appsim_grade_s(1, jobs=2))
    sandboxed = Figure("appsim grade: one full submission (Ex1..Ex6, Demo1), sandboxed", "wall s", alone,
                       target=1.5, aim=1, lower_is_better=True,
                       note="the whole command, Python's start included, --jobs 2")
    isolated = repeat(config.runs, lambda: grading.appsim_grade_s(config.isolation_class, jobs=2))
    trusted = repeat(config.runs, lambda: grading.appsim_grade_s(config.isolation_class, jobs=2, trusted=True))
    exercises = 7 * config.isolation_class
    cost = Figure("isolation's cost per exercise (sandboxed minus --trusted)", "wall s",
                  tuple((i - t) / exercises for i, t in zip(isolated, trusted, strict=True)),
                  target=0.1, lower_is_better=True,
                  note=f"a class of {config.isolation_class} graded both ways, {exercises} exercises")
    room = Figure(f"appsim grade: a class of {config.class_size} with --jobs 2", "wall s",
                  repeat(config.runs, lambda: grading.appsim_grade_s(config.class_size, jobs=2)),
                  target=60 if config.class_size == 60 else None, lower_is_better=True,
                  note="full submissions (Ex1..Ex6, Demo1), the whole command")
    return [first, sandboxed, cost, room, *_memory(config)]


def _memory(config: Config) -> list[Figure]:
    """The grading worker's peak memory per exercise, each graded in a run of its own (`bench.memory`)."""
    solutions = memory.solutions()
    if config.memory_hogs is not None:
        solutions = dict(list(solutions.items())[:1])
    measured = grading.worker_memory([*solutions, *(config.memory_hogs or memory.HOGS)])
    honest = {name: m["peak_kb"] / 1024 for name, m in measured.items() if name in solutions}
    hogs = {name: m["peak_kb"] / 1024 for name, m in measured.items() if name not in solutions}
    worst = max(hogs, key=hogs.__getitem__)
    fault = measured[worst]["fault"]
    return [
        Figure("grading worker's peak memory per exercise: the solutions", "MB", tuple(honest.values()),
               note=", ".join(f"{name.removeprefix('solution ')} {value:.1f}" for name, value in honest.items())),
        Figure("grading worker's peak memory per exercise: firmware written to make the grader keep more", "MB",
               tuple(hogs.values()), note=f"{len(hogs)} of them (bench.memory.HOGS), each as Demo1; the worst: "
                                          f"{worst}, {hogs[worst]:.1f} MB" + (f" (fault {fault})" if fault else "")),
        Figure("the worst of them above the solutions' peak", "MB", (hogs[worst] - max(honest.values()),),
               target=64, lower_is_better=True),
    ]


def _interrupts(config: Config) -> list[Figure]:
    figures = []
    for exercise in (3, 6):
        polling, driven = [], []
        for _ in range(max(config.runs, 1)):
            polling.append(interrupts.classroom_wall_ms_per_simulated_s(exercise, SOLUTIONS, config.classroom_s))
            driven.append(interrupts.classroom_wall_ms_per_simulated_s(exercise, interrupts.INTERRUPT_DRIVEN,
                                                                       config.classroom_s))
        figures += [
            Figure(f"classroom at Ex{exercise}, the stations polling (solutions/)", "wall ms / sim s", tuple(polling),
                   note="master, six stations, the PC's monitor"),
            Figure(f"classroom at Ex{exercise}, the stations interrupt-driven (solutions/interrupts/)",
                   "wall ms / sim s", tuple(driven)),
            Figure(f"interrupts' cost in the Ex{exercise} classroom (interrupt-driven / polling)", "ratio",
                   tuple(d / p for d, p in zip(driven, polling, strict=True))),
        ]
    interrupts.checks_s(SOLUTIONS)              # the checks imported and warm, as in the figures above
    for what, measure, how in (("check Ex1, Ex3, Ex6 in process", interrupts.checks_s, ""),
                               ("appsim grade of Ex1, Ex3, Ex6, sandboxed", interrupts.appsim_grade_s,
                                " (the whole command, --jobs 2)")):
        both = [(measure(SOLUTIONS), measure(interrupts.INTERRUPT_DRIVEN)) for _ in range(max(config.runs, 1))]
        polling_s, driven_s = (statistics.median(pair[i] for pair in both) for i in (0, 1))
        figures.append(Figure(f"{what}: interrupt-driven / polling", "ratio", tuple(d / p for p, d in both),
                              note=f"polling {polling_s:.2f} s, interrupt-driven {driven_s:.2f} s{how}"))
    return figures


def _c_firmware(config: Config) -> list[Figure]:
    """C firmware (translated) against the Python firmware it twins: run time, load time, a class graded."""
    seconds = 8 * config.scaling_s * 25
    ratios = []
    for _ in range(max(config.runs, 1)):
        python, c = cfirmware.classroom_run_s("python", seconds), cfirmware.classroom_run_s("c", seconds)
        ratios.append(c / python)
    run = Figure("C firmware / Python firmware, run time: six stations, Ex2..Ex6", "ratio", tuple(ratios),
                 target=1.3, lower_is_better=True,
                 note=f"{seconds:g} simulated s each, the same bus trace (tests/test_c_firmware.py)")
    first = Figure("C: translate and load a solution, first in a process (headers parsed)", "wall ms",
                   repeat(config.runs, cfirmware.first_load_ms), note="python -c: import the translator, ex6.c")
    each = Figure("C: translate and load one more solution file (headers known)", "wall ms",
                  repeat(config.runs, cfirmware.next_load_ms), note="ex1.c .. ex6.c, demo1_monitor.c: the mean")
    fresh = [cfirmware.fresh_child_ms() for _ in range(max(config.runs, 1))]
    in_child = Figure("C: ex3.c translated in a child forked from a zygote, first / again in that child", "ratio",
                      tuple(first / again for first, again in fresh), lower_is_better=True,
                      note="CPU ms, first " + ", ".join(f"{first:.0f}" for first, _ in fresh) + "; again "
                           + ", ".join(f"{again:.0f}" for _, again in fresh) + ": each exercise's child pays the first")
    cached = Figure("C: load a file translated before (cached by content, defines, options)", "wall ms",
                    repeat(config.runs, cfirmware.cached_load_ms), note="a fresh module: globals of its own")
    size = config.class_size
    graded = []
    for _ in range(max(config.runs, 1)):
        python = grading.appsim_grade_s(size, jobs=2, language="python")
        graded.append(grading.appsim_grade_s(size, jobs=2, language="c") / python)
    room = Figure(f"appsim grade: a class of {size} in C / the same class in Python, --jobs 2", "ratio",
                  tuple(graded), target=1.2, lower_is_better=True,
                  note="full submissions (Ex1..Ex6, Demo1), sandboxed, the whole command")
    return [run, first, each, in_child, cached, room]


def _linked(config: Config) -> list[Figure]:
    spacing = linked.frame_spacing_ms(config.linked_s)
    jitter = [abs(gap - linked.EX2_PERIOD_MS) for gap in spacing]
    trips = linked.round_trips_ms(config.round_trips)
    return [
        Figure("linked: Ex2 frame spacing at a python-can peer", "wall ms", tuple(spacing),
               note=f"nominal {linked.EX2_PERIOD_MS:g} ms (Timer1), {len(spacing)} gaps; virtual bus"),
        Figure(f"linked: frame period jitter, abs(gap - {linked.EX2_PERIOD_MS:g} ms)", "wall ms", tuple(jitter)),
        Figure("linked: RTR round trip peer -> master -> peer", "wall ms", tuple(trips),
               note=f"{len(trips)} requests; WallClock slices of 1 ms"),
    ]


def _knobs(config: Config) -> list[Figure]:
    turns = config.knob_turns
    each = f"{turns} turn{'' if turns == 1 else 's'} of the master's knob each"
    before = [t for exercise in knobs.SECONDS for t in knobs.rerun_from_zero_s(exercise, turns)]
    going_on = [t for exercise in knobs.GOING_ON for t in knobs.turn_s(exercise, turns)]
    return [
        Figure("notebook knob turn, as before: the classroom rerun from zero, LCD drawn by matplotlib", "wall s",
               tuple(before), note=f"Ex1..Ex6 after their notebooks' first runs, {each}"),
        Figure("notebook knob turn: the live classroom goes on 0.2 s, LCD redrawn (Ex2..Ex6)", "wall s",
               tuple(going_on), target=0.25, lower_is_better=True, note=f"{each}; the kernel's side"),
        Figure("notebook knob turn on Ex1: the board restarts (it reads its knob once)", "wall s",
               tuple(knobs.turn_s("ex1", turns)), target=0.25, lower_is_better=True, note=each),
    ]


def _floods(config: Config) -> list[Figure]:
    figures = []
    for varied, what in ((False, "one failing frame sent again and again"),
                         (True, "random data, each error at another bit: no two alike")):
        runs = [flood.error_flood(config.flood_s, varied=varied) for _ in range(max(config.runs, 1))]
        kind = "varied" if varied else "steady"
        figures.append(Figure(f"real-time factor: Ex6 classroom under a {kind} error flood from outside, 125 kbit/s",
                              "sim s / wall s", tuple(r.real_time_factor for r in runs), target=1,
                              note=f"{what}; {runs[-1].error_frames / runs[-1].simulated_s:,.0f} error frames a "
                                   "second, every frame bit by bit"))
    for scenario, words in (("", "the classroom's frames"), ("steady", "a steady error flood"),
                            ("varied", "a varied error flood")):
        figures.append(Figure(f"memory of a trace event: {words}", "bytes",
                              repeat(config.runs, lambda scenario=scenario: flood.bytes_per_event(scenario)),
                              target=flood.EVENT_BYTES, lower_is_better=True,
                              note=f"tracemalloc over {flood.EVENTS_MEASURED:,} events; appsim/bus/trace.py says "
                                   "about 200"))
    peer = flood.virtual_peer(config.peer_s, sample_s=max(1.0, config.peer_s / 30))
    settled = config.peer_s / 5
    name = f"linked classroom, an in-process virtual peer at full rate for {config.peer_s:g} s"
    figures.append(Figure(f"{name}: most frames python-can's queue held for the link", "frames",
                          (peer.most_unread,), target=2 * PYTHON_QUEUE_FRAMES, lower_is_better=True,
                          note=f"kept to {PYTHON_QUEUE_FRAMES:,} at each poll; the peer sent {peer.sent:,} frames, the "
                               f"link accounted for {peer.accounted:,}"))
    figures.append(Figure(f"{name}: resident memory growth after the first {settled:g} s", "MB",
                          (peer.growth_mb(settled),),
                          note=f"{peer.rss_mb[0]:.0f} MB at the start, {peer.rss_mb[-1]:.0f} MB at the end; meanwhile "
                               f"the boards' LCD histories fill towards their cap ({peer.lcd_writes:,} writes, about "
                               f"{peer.lcd_mb:.1f} MB, at the end), as without any peer"))
    figures.append(Figure(f"{name}: most it fell behind real time", "wall s", (peer.max_lag_s,),
                          note="the peer's thread takes its share of the CPU and the GIL; the run says so once"))
    return figures


def _served(config: Config) -> list[Figure]:
    through, bare, limits = [], [], []
    for _ in range(max(config.runs, 1)):
        fps, limit = served.interface_fps(config.served_frames)
        through.append(fps)
        limits.append(limit)
        bare.append(served.virtual_fps(config.served_frames))
    runs = [served.gradescope_against_grade_s() for _ in range(max(config.runs, 1))]
    return [
        Figure("python-can interface 'appsim': frames/s from one program to another, served bus at 1 Mbit/s",
               "frames/s", tuple(through),
               note=f"bus limit {limits[-1]:,.0f} frames/s of 8 bytes; python-can's virtual bus "
                    f"{statistics.median(bare):,.0f} frames/s in the same run"),
        Figure("python-can interface 'appsim' / python-can virtual bus", "ratio",
               tuple(t / b for t, b in zip(through, bare, strict=True)),
               note="the served bus is paced to the wall clock and arbitrates, ACKs and checks every frame"),
        Figure("Gradescope: run_autograder on one full submission (after setup.sh)", "wall s",
               tuple(g for g, _ in runs), lower_is_better=True,
               note=f"appsim grade of the same, --jobs 2: {statistics.median(a for _, a in runs):.2f} s"),
        Figure("Gradescope run / appsim grade, one full submission", "ratio", tuple(g / a for g, a in runs),
               lower_is_better=True),
    ]


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="a tiny configuration (seconds, not minutes)")
    parser.add_argument("--runs", type=int, help="repetitions of each figure (default 3; --quick: 1)")
    args = parser.parse_args(argv)
    config = QUICK if args.quick else FULL
    if args.runs is not None:
        if args.runs < 1:
            parser.error(f"--runs is how often each figure is measured, at least 1; got {args.runs}")
        config = Config(**{**config.__dict__, "runs": args.runs})
    figures: list[Figure] = []
    for part in (_full_load, _scaling, _python_can, _busy_wait, _grading, _interrupts, _c_firmware, _linked, _knobs,
                 _served, _floods):
        figures += part(config)
    print(f"appsim speed, {config.runs} run(s) per figure, on {machine()}\n")
    print(table(figures))


if __name__ == "__main__":
    main()
