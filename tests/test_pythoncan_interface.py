"""appsim as a python-can interface: real python-can programs, in processes of their own, join a served classroom with
`can.Bus(interface="appsim", channel=...)`: their frames contend, are ACKed or not, lose arbitration and fail as on the
simulated wire; their error state is visible; every hostile or clumsy program is bounded and accounted for."""
from __future__ import annotations

import contextlib
import json
import os
import pwd
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from textwrap import dedent
from typing import Any

import pytest
from pythoncan_clients import KIT, Served, private_runtime, program, start

from appsim.can import pythoncan as P

USER = os.environ.get("APPSIM_TEST_USER")
USER_PYTHON = os.environ.get("APPSIM_TEST_USER_PYTHON")


@pytest.fixture
def env(tmp_path) -> dict[str, str]:
    return private_runtime(tmp_path)


def raw_client(env: dict[str, str], channel: str = "test", *, token: str | None = None) -> socket.socket:
    """A program that speaks the protocol by hand (what a hostile one would do): it has said hello."""
    found = json.loads((Path(env["XDG_RUNTIME_DIR"]) / "appsim" / f"{channel}.json").read_text())
    sock = socket.create_connection(("127.0.0.1", found["port"]), timeout=10)
    sock.sendall(json.dumps({"appsim": 1, "token": token or found["token"]}).encode() + b"\n")
    return sock


def answer(sock: socket.socket) -> dict:
    line = b""
    while not line.endswith(b"\n"):
        byte = sock.recv(1)
        assert byte, f"the classroom closed the connection after {line!r}"
        line += byte
    return json.loads(line)


JOIN = """
import can, time
for _ in range(100):                                    # until the board's command serves it
    try:
        bus = can.Bus(interface='appsim', channel='{channel}', {options})
        break
    except can.CanInitializationError:
        time.sleep(0.1)
"""


def lone_board(env: dict[str, str], cwd: Path, channel: str, seconds: float) -> subprocess.Popen[str]:
    """`appsim board solutions/ex2.py --serve CHANNEL`: station 1's Ex2 alone on its bus, served."""
    return subprocess.Popen([sys.executable, "-m", "appsim", "board", str(KIT / "solutions" / "ex2.py"), "--serve",
                             channel, "--seconds", str(seconds)], env=env, cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def test_the_interface_is_found_by_python_can_through_its_entry_point(env):
    result = program("""
        import can, sys
        print('appsim' in can.VALID_INTERFACES)
        print('appsim.bus' in sys.modules, 'appsim.workshop' in sys.modules)
        can.interface._get_class_for_interface('appsim')
        print(sorted(m for m in sys.modules if m.startswith('appsim')))
    """, env)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == "True"
    assert lines[1] == "False False", "import can alone loads none of the kit"
    assert lines[2] == "['appsim', 'appsim.can', 'appsim.can.pythoncan']", "the plugin loads only its own module"


def test_a_program_joins_a_board_alone_on_its_bus_and_acks_its_frames(env, tmp_path):
    """`appsim board my_ex2.py --serve`: the student's script is the only other node, so the board's frames get their
    ACK from it; the board's trace says so."""
    classroom = lone_board(env, tmp_path, "desk", 6)
    try:
        result = program(JOIN.format(channel="desk", options="name='laptop'") + dedent("""
            frames = [m for m in (bus.recv(2) for _ in range(5)) if m is not None]
            print(bus.node, bus.state.name, ','.join(sorted({hex(m.arbitration_id) for m in frames})),
                  frames[0].data.hex())
            bus.shutdown()
        """), env)
        assert result.returncode == 0, result.stderr
        node, state, ids, data = result.stdout.split(maxsplit=3)
        assert (node, state) == ("laptop", "ACTIVE")
        assert ids == "0x100", "station 1's Ex2 frames, every 52 ms"
        assert data.strip().startswith("010203"), "01 02 03 ADRESH ADRESL"
    finally:
        out, err = classroom.communicate(timeout=30)
    assert any(line.endswith("01 02 03 02 9A           laptop") for line in out.splitlines()), out
    assert "ACK error" in out, "once the laptop has left, nobody ACKs the board"
    assert "served as 'desk'" in out and "1 python-can program(s) joined" in out, out


def test_its_frames_are_acked_and_come_back_when_asked_and_others_see_them(env):
    with Served(env) as served:
        listener = start("""
            import can
            bus = can.Bus(interface='appsim', channel='test', name='listener')
            print('ready', flush=True)
            message = bus.recv(10)
            print(hex(message.arbitration_id), message.data.hex(), message.is_rx, flush=True)
        """, env)
        assert listener.stdout.readline().strip() == "ready"
        result = program("""
            import can
            with can.Bus(interface='appsim', channel='test', name='talker', receive_own_messages=True) as bus:
                bus.send(can.Message(arbitration_id=0x1F0, data=[1, 2, 3], is_extended_id=False))
                echo = bus.recv(10)
                print(hex(echo.arbitration_id), echo.is_rx, echo.timestamp > 0, bus.state.name, bus.tec)
        """, env)
        assert result.returncode == 0, result.stderr
        assert result.stdout.split() == ["0x1f0", "False", "True", "ACTIVE", "0"]
        assert listener.communicate(timeout=20)[0].split() == ["0x1f0", "010203", "True"]
        [event] = [e for e in served.bus.trace if e.frame.can_id == 0x1F0]
        assert event.sender == "talker" and event.acked_by == ("listener",)


def test_alone_on_the_bus_its_frame_gets_no_ack_and_it_goes_error_passive(env):
    """Nobody to ACK: each try ends in an ACK error, TEC += 8 up to 128 (error-passive), then an error-passive
    sender's ACK errors no longer count (ISO 11898-1); python-can sees SocketCAN-style error frames and the state."""
    with Served(env) as served:
        result = program("""
            import can, time
            bus = can.Bus(interface='appsim', channel='test')
            bus.send(can.Message(arbitration_id=0x123, data=[0xAA], is_extended_id=False))
            errors = []
            deadline = time.monotonic() + 10
            while bus.state != can.BusState.PASSIVE and time.monotonic() < deadline:
                message = bus.recv(1)
                if message is not None and message.is_error_frame:
                    errors.append(message)
            # the state can overtake the error frames that led to it: read those too (the error-passive node goes
            # on retrying, its ACK errors no longer counted, so more keep coming)
            until = time.monotonic() + 0.3
            while time.monotonic() < until:
                message = bus.recv(0.1)
                if message is not None and message.is_error_frame:
                    errors.append(message)
            first = errors[0]
            print(bus.state.name, bus.tec, len(errors), hex(first.arbitration_id), first.data.hex())
            try:
                bus.send(can.Message(arbitration_id=0x124, is_extended_id=False), timeout=0)
                bus.flush_tx_buffer()
                print('flushed')
            except can.CanOperationError as error:
                print('error', error)
            bus.shutdown()
        """, env)
        assert result.returncode == 0, result.stderr
        state, tec, count, error_class, data = result.stdout.splitlines()[0].split()
        assert state == "PASSIVE" and tec == "128" and int(count) >= 16
        error_class = int(error_class, 16)
        assert error_class & P.CAN_ERR_ACK and error_class & P.CAN_ERR_PROT and error_class & P.CAN_ERR_CNT
        data = bytes.fromhex(data)
        assert data[2] & P.CAN_ERR_PROT_TX and data[3] == P.CAN_ERR_PROT_LOC_ACK and data[6] == 8, \
            "the first error frame: a transmitter's ACK error, TEC 8"
        assert result.stdout.splitlines()[1] == "flushed"
        assert all("ACK error" in e.error for e in served.bus.trace), "the trace shows the same ACK errors"


def test_the_lower_identifier_wins_arbitration_and_the_loser_sees_it(env, monkeypatch):
    """Two nodes with frames waiting: 0x100 goes before every 0x300 still queued, whatever order they were sent in;
    the 0x300 node is told it lost arbitration (CAN_ERR_LOSTARB), and its frames go through after."""
    from appsim.bus import serve

    queued: dict[str, list[int]] = {"high": [], "low": []}   # when (simulated ps) each frame reached its node's queue
    transmit = serve.ClientNode.transmit

    def noting_when(node: serve.ClientNode, frame: Any) -> None:
        queued[node.name].append(node.wire.sim.time())
        transmit(node, frame)

    monkeypatch.setattr(serve.ClientNode, "transmit", noting_when)
    with Served(env) as served:
        result = program("""
            import can, time
            high = can.Bus(interface='appsim', channel='test', name='high', receive_own_messages=True)
            low = can.Bus(interface='appsim', channel='test', name='low')
            time.sleep(0.3)                            # both have joined (11 recessive bits, and the polls)
            for _ in range(40):                        # 18 ms of the bus: 0x100 comes while some still wait
                high.send(can.Message(arbitration_id=0x300, data=[3], is_extended_id=False))
            for _ in range(10):
                low.send(can.Message(arbitration_id=0x100, data=[1], is_extended_id=False))
            seen, lost = [], 0
            while len(seen) < 50:
                message = high.recv(10)
                if message.is_error_frame:
                    lost += bool(message.arbitration_id & 0x002)
                else:
                    seen.append(message.arbitration_id)
            print(lost, ' '.join(hex(i) for i in seen))
        """, env)
        assert result.returncode == 0, result.stderr
        lost, *order = result.stdout.split()
        frames = [e for e in served.bus.trace if e.ok]
        assert [hex(e.frame.can_id) for e in frames] == order, "the loser's order is the bus's order"
        assert order.count("0x300") == 40 and order.count("0x100") == 10
        bit_ps = 8_000_000                                      # 125 kbit/s
        for event in (e for e in frames if e.sender == "high"):
            waiting = sum(t < event.start_ps - bit_ps for t in queued["low"]) \
                - sum(e.sender == "low" and e.start_ps < event.start_ps for e in frames)
            assert waiting == 0, f"a 0x300 frame started at {event.start_ps} ps while {waiting} 0x100 frames waited"
        assert order.index("0x100") < 40 and int(lost) >= 1, "0x100 came while 0x300 frames waited, and won"


def test_its_own_frames_come_back_where_the_bus_carried_them_however_long_the_slice(env, monkeypatch):
    """receive_own_messages: a program's frame comes back (SENT) in the bus's order among the others' frames, also when
    several frames went by between two polls (a busy machine runs long slices). The server is polled by hand here, so
    the slices are known: 30 ms of the bus, six frames, in one."""
    from appsim.bus.serve import ClassroomServer
    from appsim.bus.wire import Bus
    from appsim.sim import Simulator

    monkeypatch.setenv("XDG_RUNTIME_DIR", env["XDG_RUNTIME_DIR"])
    bus = Bus(Simulator(), 125_000)

    def poll_for(ms: float) -> None:
        server.poll()
        bus.sim.run_for(ms / 1000)
        server.poll()

    def client_of(sock: socket.socket) -> Any:
        return next((c for c in server.clients if c.sock.getpeername() == sock.getsockname()), None)

    def poll_until(condition: Any) -> None:
        """Poll, the bus stopped, until `condition()` (the bytes sent have crossed the loopback and been read)."""
        deadline = time.monotonic() + 10
        while not condition():
            assert time.monotonic() < deadline, "the server did not read what was sent"
            time.sleep(0.001)
            server.poll()

    def send(sock: socket.socket, can_id: int, count: int) -> None:
        client = client_of(sock)
        before = client.frames_in
        sock.sendall(P.TO_CLASSROOM.pack(P.SEND, 0, can_id, 1, bytes(8)) * count)
        poll_until(lambda: client.frames_in == before + count)
        bus.sim.run_for(0.1 / 1000)         # a frame of theirs takes 0.4 ms: the first has started, not ended

    with ClassroomServer(bus, "test") as server:
        high, low = raw_client(env), raw_client(env)
        poll_until(lambda: len(server.clients) == 2 and all(c.node is not None for c in server.clients))
        server.poll()                                   # the welcomes go out
        assert answer(high)["ok"] and answer(low)["ok"]
        poll_for(1)                                     # both have joined: 11 recessive bits
        send(high, 0x300, 3)                            # the first 0x300 is on the wire before 0x100 comes
        send(low, 0x100, 3)
        poll_for(30)
        high.settimeout(2)
        got = b""
        seen: list[str] = []
        while len(seen) < 6:
            got += high.recv(65536)
            whole = len(got) - len(got) % P.FROM_CLASSROOM.size
            seen = [("sent " if kind == P.SENT else "") + hex(can_id)
                    for kind, _, can_id, *_ in P.FROM_CLASSROOM.iter_unpack(got[:whole]) if kind in (P.SENT, P.FRAME)]
        name = client_of(high).name
        on_the_bus = [("sent " if e.sender == name else "") + hex(e.frame.can_id) for e in bus.trace if e.ok]
        assert on_the_bus == ["sent 0x300", "0x100", "0x100", "0x100", "sent 0x300", "sent 0x300"]
        assert seen == on_the_bus, "its own frames come back where the bus carried them"


def test_a_program_that_does_not_read_its_answers_is_not_read_so_they_stay_bounded(env):
    """Every frame record a program sends is answered (SENT, REFUSED or ABORTED), and answers are never dropped: so a
    program that sends refused records and never reads is no longer read once 64 answers wait; its own socket fills,
    the classroom's memory stays bounded, and every answer it is owed is there when it reads."""
    with Served(env) as served:
        hostile = raw_client(env)
        hostile.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)       # so that its own socket fills soon
        assert answer(hostile)["ok"]
        hostile.settimeout(0.5)
        too_wide = P.TO_CLASSROOM.pack(P.SEND, 0, 0x900, 1, bytes(8))        # 12 bits for an 11-bit identifier
        sent = 0                                                            # bytes
        try:
            while sent < 15_000_000:
                sent += hostile.send(too_wide * 100)
        except (TimeoutError, BlockingIOError):
            pass
        [client] = [c for c in served.server.clients if c.node is not None]
        assert sent < 15_000_000, "its own socket filled: the classroom stopped reading it"
        assert client.replies_waiting <= 2 * 64 and len(client.outbox) <= 65 * P.FROM_CLASSROOM.size, \
            "what waits for it stays bounded"
        records, got, refused = sent // P.TO_CLASSROOM.size, b"", 0
        deadline = time.monotonic() + 60
        while refused < records and time.monotonic() < deadline:            # it reads at last: all are answered
            try:
                got += hostile.recv(65536)
            except TimeoutError:
                continue
            kinds = Counter((kind, data[0]) for kind, _, _, _, data, _ in
                            P.FROM_CLASSROOM.iter_unpack(got[:len(got) - len(got) % P.FROM_CLASSROOM.size]))
            refused = kinds[P.REFUSED, 1]                                   # REFUSALS[1]: an identifier too wide
        assert refused == client.frames_in == records, "every whole record it sent was read in the end and answered"
        hostile.close()
    assert "refused" in served.report, served.report


def test_a_listen_only_program_never_acks_and_sees_the_error_frames_of_a_lone_board(env, tmp_path):
    classroom = lone_board(env, tmp_path, "quiet", 4)
    try:
        result = program(JOIN.format(channel="quiet", options="listen_only=True") + dedent("""
            errors = [m for m in (bus.recv(2) for _ in range(20)) if m is not None and m.is_error_frame]
            try:
                bus.send(can.Message(arbitration_id=0x7, is_extended_id=False))
            except can.CanOperationError as error:
                print('refused:', error)
            print(len(errors), bus.state.name)
            bus.shutdown()
        """), env)
    finally:
        out, _ = classroom.communicate(timeout=30)
    assert result.returncode == 0, result.stderr
    refused, counts = result.stdout.splitlines()
    assert "Listen-only" in refused
    assert int(counts.split()[0]) >= 10 and counts.split()[1] == "ACTIVE"
    assert "ACK error" in out and "ACK by" not in out, "nobody ACKs the board: the listen-only node never does"


def test_a_classroom_out_of_file_descriptors_goes_on_and_says_how_often_it_could_not_take_one(env, tmp_path):
    """The classroom's process may hold 40 files: forty connections that never say hello exhaust it. It does not fail:
    the report says it could not take connections (tries, not programs), and once they are gone a program joins."""
    script = tmp_path / "starved.py"
    script.write_text(dedent("""
        import resource, socket, sys, time
        sys.path[:0] = sys.argv[1:]
        from pythoncan_clients import Served
        resource.setrlimit(resource.RLIMIT_NOFILE, (40, 40))
        import can                                      # loaded before the limit bites
        with Served({"XDG_RUNTIME_DIR": sys.argv[3]}) as served:
            port = served.server.port
            held = []
            for _ in range(60):
                try:
                    held.append(socket.create_connection(("127.0.0.1", port), timeout=1))
                except OSError:
                    break
            time.sleep(0.5)
            starved = sum(served.server.accept_failures.values())
            for sock in held:
                sock.close()
            time.sleep(0.5)
            import os
            os.environ["XDG_RUNTIME_DIR"] = sys.argv[3]
            with can.Bus(interface="appsim", channel="test") as bus:
                print("joined", bus.node)
            print("running", served.served.running, "starved", starved > 0, flush=True)
        print(served.report)
    """))
    result = subprocess.run([sys.executable, str(script), str(KIT / "tests"), str(KIT), env["XDG_RUNTIME_DIR"]],
                            env=env, capture_output=True, text=True, timeout=60)
    assert "joined pycan" in result.stdout and "running True starved True" in result.stdout, \
        result.stdout + result.stderr
    assert "could not take a connection (Too many open files): " in result.stdout, result.stdout


def test_a_clumsy_program_gets_can_errors_in_words_and_a_dropped_bus_is_collected(env):
    """After shutdown() (also while another thread waits in recv), and after the classroom ended, send, flush and recv
    are can.CanOperationErrors that say which; a NaN timeout or a send of something else than a can.Message says what
    is wrong, an infinite timeout waits; a bus dropped without shutdown() is collected and leaves the classroom."""
    with Served(env) as served:
        acker = raw_client(env)
        assert answer(acker)["ok"]
        clumsy = start("""
            import can, gc, math, signal, sys, threading, time, weakref
            signal.alarm(60)                                # whatever happens, it does not hang the tests
            def attempt(what, call):
                try:
                    call()
                    print(what, "returned")
                except (can.CanOperationError, ValueError, TypeError) as error:
                    print(what, type(error).__name__, error)
            m = can.Message(arbitration_id=0x10, data=[1], is_extended_id=False)
            bus = can.Bus(interface='appsim', channel='test', receive_own_messages=True)
            attempt("nan", lambda: bus.recv(timeout=math.nan))
            attempt("not a message", lambda: bus.send("hello"))
            bus.send(m)
            print("forever", hex(bus.recv(timeout=math.inf).arbitration_id))
            waiting = []
            def reader():
                try:
                    bus.recv(None)
                except can.CanOperationError as error:
                    waiting.append(str(error))
            thread = threading.Thread(target=reader)
            thread.start()
            time.sleep(0.3)
            bus.shutdown()
            thread.join(5)
            print("waiting in recv:", waiting)
            for what, call in (("send", lambda: bus.send(m)), ("flush", bus.flush_tx_buffer),
                               ("recv", lambda: bus.recv(0.1))):
                attempt(what + " after shutdown", call)
            refs = [weakref.ref(can.Bus(interface='appsim', channel='test')) for _ in range(5)]
            gc.collect()
            time.sleep(0.5)
            print("alive", sum(r() is not None for r in refs),
                  sum(t.name.startswith("appsim-") for t in threading.enumerate()))
            keeper = can.Bus(interface='appsim', channel='test')
            print("ready", flush=True)
            sys.stdin.readline()
            time.sleep(0.5)
            for what, call in (("send", lambda: keeper.send(m)), ("flush", keeper.flush_tx_buffer),
                               ("recv", lambda: keeper.recv(0.1))):
                attempt(what + " after the end", call)
        """, env)
        lines = []
        while (line := clumsy.stdout.readline()) and line.strip() != "ready":
            lines.append(line.strip())
        served.wait_for(lambda s: sum(c.node is not None for c in s.clients) == 2)     # the acker, the keeper
    out, err = clumsy.communicate("\n", timeout=30)
    lines += out.splitlines()
    text = "\n".join(lines)
    assert "nan ValueError appsim: recv's timeout is a number of seconds" in text, text
    assert "not a message TypeError appsim: send takes a can.Message, not str" in text, text
    [waiting] = [line for line in lines if line.startswith("waiting in recv:")]
    assert "forever 0x10" in text and "this bus was shut down" in waiting, text
    for what in ("send", "flush", "recv"):
        assert f"{what} after shutdown CanOperationError" in text and text.count("this bus was shut down") >= 4, text
        assert f"{what} after the end CanOperationError" in text, text
    assert text.count("the classroom ended (appsim stopped serving it)") == 3, text
    assert "alive 0 0" in text, "the dropped buses were collected, their readers ended"
    assert "Traceback" not in err, err


def test_a_classroom_that_is_not_served_is_a_clear_initialization_error(env):
    result = program("""
        import can
        try:
            can.Bus(interface='appsim', channel='classroom')
        except can.CanInitializationError as error:
            print(error)
    """, env)
    assert "no classroom is served as 'classroom'" in result.stdout and "appsim classroom --serve" in result.stdout
    folder = Path(env["XDG_RUNTIME_DIR"]) / "appsim"
    folder.mkdir(mode=0o700)
    dead = socket.socket()
    dead.bind(("127.0.0.1", 0))
    port = dead.getsockname()[1]
    dead.close()                                    # nobody listens there any more: a classroom that was killed
    (folder / "gone.json").write_text(json.dumps({"appsim": 1, "host": "127.0.0.1", "port": port, "token": "x",
                                                  "pid": 1}))
    result = program("""
        import can
        try:
            can.Bus(interface='appsim', channel='gone')
        except can.CanInitializationError as error:
            print(error)
        for channel in ('../etc/passwd', ''):
            try:
                can.Bus(interface='appsim', channel=channel)
            except can.CanInitializationError as error:
                print(type(error).__name__)
    """, env)
    assert "the classroom served as 'gone' (process 1) is not running any more" in result.stdout, result.stderr
    assert result.stdout.count("ChannelError") == 2, result.stdout + result.stderr


def test_a_wrong_token_garbage_and_a_silent_hello_are_turned_away_in_words(env):
    with Served(env) as served:
        wrong = raw_client(env, token="0" * 32)
        assert answer(wrong) == {"appsim": 1, "ok": False,
                                 "error": "wrong token: a program may join only a classroom its own user serves"}
        port = served.server.port
        garbage = socket.create_connection(("127.0.0.1", port))
        garbage.sendall(b"GET / HTTP/1.0\r\n\r\n")
        assert "did not open as appsim's python-can interface does" in answer(garbage)["error"]
        endless = socket.create_connection(("127.0.0.1", port))
        endless.sendall(b"x" * (P.HELLO_LIMIT + 10))
        assert "longer than" in answer(endless)["error"]
        served.wait_for(lambda s: sum(s.turned_away.values()) == 3)
    assert "turned away 1 x wrong token" in served.report


HOSTILE_HELLOS = {
    "JSON nested 2,000 deep": b"[" * 2000 + b"\n",
    "a lone surrogate for a token": b'{"appsim": 1, "token": "\\ud800"}\n',
    "a list": b'[1, 2, 3]\n',
    "a string": b'"hello"\n',
    "a token that is a number": b'{"appsim": 1, "token": 7}\n',
    "bytes that are not UTF-8": b'{"appsim": 1, "token": "\xff\xfe"}\n',
    "one line of 60 kB": b'{"appsim": 1, "token": "' + b"a" * 60_000 + b'"}\n',
}


def test_a_program_that_is_not_read_now_costs_no_poll_and_still_leaves_when_it_closes(env):
    """A program with no room for what it sends (64 answers unread) is out of the selector, so that what waits in its
    socket is not looked at at every poll (250 of them held the simulation to 0.58 of real time); it is looked at now
    and then, so closing its end still makes it leave; and once it reads, it is read again."""
    with Served(env) as served:
        held = raw_client(env)
        held.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        assert answer(held)["ok"]
        held.setblocking(False)
        too_wide = P.TO_CLASSROOM.pack(P.SEND, 0, 0x900, 1, bytes(8))
        with contextlib.suppress(BlockingIOError):
            while True:
                held.send(too_wide * 100)
        served.wait_for(lambda s: any(c.held for c in s.clients))
        [client] = [c for c in served.server.clients if c.node is not None]
        assert client.sock not in {k.fileobj for k in served.server._selector.get_map().values()}
        held.setblocking(True)
        held.settimeout(2)
        for _ in range(20):                             # it reads some: it is read again
            held.recv(65536)
        served.wait_for(lambda s: client.frames_in > 64 * 3)
        served.wait_for(lambda s: client.held)
        held.close()                                    # it ends while held again
        served.wait_for(lambda s: client not in s.clients, timeout=5)
    assert " 0 still on" in served.report


@pytest.mark.parametrize("what", HOSTILE_HELLOS)
def test_a_hostile_hello_is_turned_away_in_words_and_the_classroom_goes_on(env, what):
    """Whatever a hello holds, the program that sent it is turned away with why, and only it: the classroom keeps
    running and the program already on it keeps getting its frames."""
    with Served(env) as served:
        bystander = raw_client(env)
        assert answer(bystander)["ok"]
        hostile = socket.create_connection(("127.0.0.1", served.server.port), timeout=10)
        hostile.sendall(HOSTILE_HELLOS[what])
        told = answer(hostile)
        assert told["ok"] is False and ("did not open as appsim's" in told["error"] or "longer than" in told["error"])
        assert served.served.running and served.served.failure is None, "the classroom goes on"
        result = program("""
            import can
            with can.Bus(interface='appsim', channel='test') as bus:
                bus.send(can.Message(arbitration_id=0x123, data=[1], is_extended_id=False), timeout=5)
        """, env)
        assert result.returncode == 0, result.stderr
        bystander.settimeout(5)
        got = b""
        while not any(r[0] == P.FRAME and r[2] == 0x123 for r in _records(got)):
            got += bystander.recv(65536)


def _records(data: bytes) -> list[tuple[Any, ...]]:
    return list(P.FROM_CLASSROOM.iter_unpack(data[:len(data) - len(data) % P.FROM_CLASSROOM.size]))


def test_connections_that_never_say_hello_are_bounded_and_a_program_waits_its_turn(env):
    """A hundred connections that say nothing: past 64 waiting to say hello the next are told at once to come again;
    none of them counts as a program, and a real program that comes meanwhile asks again until there is room."""
    with Served(env) as served:
        silent = [socket.create_connection(("127.0.0.1", served.server.port), timeout=10) for _ in range(100)]
        served.wait_for(lambda s: sum(s.turned_away.values()) >= 100 - 64)
        assert len(served.server.clients) <= 64
        told = [answer(s) for s in silent[64:]]
        assert all(t["again"] and "64 connections were waiting to say hello already" in t["error"] for t in told)
        joining = start("""
            import can
            with can.Bus(interface='appsim', channel='test') as bus:
                print(bus.node)
        """, env)
        time.sleep(1)
        for sock in silent:
            sock.close()
        out, err = joining.communicate(timeout=30)
        assert joining.returncode == 0 and out.startswith("pycan"), err
    assert "x 64 connections were waiting to say hello already" in served.report


def test_a_first_packet_of_thousands_of_records_is_held_back_like_any_other(env):
    """A hello followed at once by 4,000 frame records (and then by refused ones): its node's queue holds 64 frames,
    the answers waiting for it 64, the rest stays in its own socket."""
    with Served(env) as served:
        found = json.loads((Path(env["XDG_RUNTIME_DIR"]) / "appsim" / "test.json").read_text())
        hostile = socket.create_connection(("127.0.0.1", found["port"]), timeout=10)
        hostile.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        hello = json.dumps({"appsim": 1, "token": found["token"]}).encode() + b"\n"
        frame = P.TO_CLASSROOM.pack(P.SEND, 0, 0x55, 1, b"\x55".ljust(8, b"\0"))
        hostile.setblocking(False)
        with contextlib.suppress(BlockingIOError):      # nobody ACKs: nothing leaves its queue, so it is not read
            hostile.sendall(hello + frame * 4000)
        served.wait_for(lambda s: any(c.node is not None and len(c.node.queue) == 64 for c in s.clients))
        time.sleep(0.2)                                 # it would grow past 64 now, if it could
        [client] = [c for c in served.server.clients if c.node is not None]
        assert len(client.node.queue) == 64 and len(client.inbox) < P.HELLO_LIMIT, "held back, not buffered"


def test_a_lone_frame_retried_for_ever_does_not_grow_what_waits_for_a_program_that_does_not_read(env):
    """Alone on the bus its frame is never ACKed and is sent again and again: each error changes its counters, but
    what waits for it (error frames, its state) stays within its bounds while it does not read."""
    with Served(env, rx_queue=64) as served:
        lone = raw_client(env)
        lone.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        assert answer(lone)["ok"]
        lone.sendall(P.TO_CLASSROOM.pack(P.SEND, 0, 0x42, 0, bytes(8)))
        [client] = [c for c in served.server.clients if c.node is not None]
        served.wait_for(lambda s: client.dropped > 2000)
        assert len(client.outbox) <= 67 * P.FROM_CLASSROOM.size and len(client.records) <= 64


def test_a_classroom_ends_within_a_second_however_many_programs_do_not_read(env):
    """Fifty programs that never read while frames flow: stopping the classroom takes about a second for them all,
    and its report says what did not reach them."""
    with Served(env) as served:
        deaf = []
        for _ in range(50):
            sock = raw_client(env)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            assert answer(sock)["ok"]
            deaf.append(sock)
        talker = start("""
            import can, time
            with can.Bus(interface='appsim', channel='test', name='talker') as bus:
                while True:
                    bus.send(can.Message(arbitration_id=0x200, data=[1] * 8, is_extended_id=False), timeout=10)
        """, env)
        served.wait_for(lambda s: all(c.outbox for c in s.clients if c.node is not None and c.node.name != "talker"),
                        timeout=60)
        started = time.monotonic()
        served.served.stop()
        took = time.monotonic() - started
        talker.kill()
        talker.wait()
        for sock in deaf:
            sock.close()
    assert took < 3, f"stopping took {took:.1f} s"
    assert "had not reached programs that were not reading" in served.report, served.report


def test_a_frame_on_the_wire_when_its_program_leaves_is_counted_where_it_went(env):
    """Programs that send and leave at once, a thousand times: the frames the bus carried from them are all counted
    as gone through, and those it did not as left unsent; the two add up to what they sent."""
    with Served(env) as served:
        acker = raw_client(env)
        assert answer(acker)["ok"]
        result = program("""
            import can
            for _ in range(300):
                bus = can.Bus(interface='appsim', channel='test')
                for n in range(5):
                    bus.send(can.Message(arbitration_id=0x300 + n, is_extended_id=False), timeout=5)
                bus.shutdown()
        """, env, timeout=300)
        assert result.returncode == 0, result.stderr
        served.wait_for(lambda s: len([c for c in s.clients if c.node is not None]) == 1)
        time.sleep(0.2)                                         # the last frame on the wire ends
        carried = sum(1 for e in served.bus.trace if e.ok and e.sender != served.server.clients[0].name)
        acker.close()
    numbers = re.search(r"they sent (\d+) frames = (\d+) went through \+ 0 refused \+ 0 taken off by "
                        r"flush_tx_buffer \+ (\d+) left unsent when the program left \+ 0 still queued",
                        served.report)
    assert numbers is not None, served.report
    sent, through, unsent = map(int, numbers.groups())
    assert sent == 1500 and through == carried and through + unsent == sent


def test_a_program_that_never_reads_loses_the_newest_frames_counted_and_told(env):
    """Its queue holds `rx_queue` frames: past that each new frame is dropped and counted, in the classroom's report
    and in a LOST record the program gets when it reads again; the bus and the other programs go on."""
    with Served(env, rx_queue=8) as served:
        silent = raw_client(env)
        silent.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        assert answer(silent)["ok"]
        result = program("""
            import can
            with can.Bus(interface='appsim', channel='test', name='talker') as bus:
                for n in range(4000):
                    bus.send(can.Message(arbitration_id=0x200, data=n.to_bytes(2, 'big'), is_extended_id=False),
                             timeout=10)
            print('sent')
        """, env, timeout=120)
        assert result.stdout.strip() == "sent", result.stderr
        served.wait_for(lambda s: any(c.dropped for c in s.clients))
        [client] = [c for c in served.server.clients if c.node is not None and c.node.name != "talker"]
        assert len(client.records) <= 8, "memory stays bounded whatever it does not read"
        silent.settimeout(5)
        got = b""
        while True:
            got += silent.recv(65536)
            records = [r for r in P.FROM_CLASSROOM.iter_unpack(got[:len(got) - len(got) % P.FROM_CLASSROOM.size])]
            lost = sum(r[2] for r in records if r[0] == P.LOST)
            if lost:
                break
        assert lost == client.dropped - client.dropped_untold
        silent.close()
    assert "dropped (not read in time)" in served.report and " 0 dropped" not in served.report, served.report


def test_a_flood_is_held_back_not_buffered_and_a_full_queue_is_an_error_in_words(env):
    """Nobody ACKs, so nothing leaves the queue: a program's send() past `tx_queue` frames waits, then says why; a
    hand-made flooder that ignores that is simply not read (its own socket fills), so the classroom's memory stays
    bounded; both leave and the report accounts for every frame."""
    with Served(env) as served:
        flooder = raw_client(env)
        assert answer(flooder)["ok"]
        flooder.settimeout(2)
        record = P.TO_CLASSROOM.pack(P.SEND, 0, 0x55, 1, b"\x55".ljust(8, b"\0"))
        sent = 0
        try:
            while sent < 1_000_000:
                flooder.send(record * 100)
                sent += 100
        except (TimeoutError, BlockingIOError):
            pass
        [client] = [c for c in served.server.clients if c.node is not None]
        assert len(client.node.queue) <= 64 and len(client.inbox) < P.TO_CLASSROOM.size, "held back, not buffered"
        assert sent < 1_000_000, "the flooder's own socket filled: the classroom stopped reading it"
        flooder.close()
        served.wait_for(lambda s: not any(c.node is not None for c in s.clients))
        result = program("""
            import can, time
            with can.Bus(interface='appsim', channel='test') as bus:
                for _ in range(64):
                    bus.send(can.Message(arbitration_id=0x56, is_extended_id=False), timeout=0)
                started = time.monotonic()
                try:
                    bus.send(can.Message(arbitration_id=0x56, is_extended_id=False), timeout=0.3)
                except can.CanOperationError as error:
                    print(round(time.monotonic() - started, 1), error)
        """, env)
        assert result.stdout.startswith("0.3 appsim:"), result.stdout + result.stderr
        assert "transmit queue of 64 frames is full" in result.stdout and "nobody ACKs" in result.stdout
    assert "left unsent when the program left" in served.report


def test_a_program_that_disconnects_mid_frame_leaves_its_node_and_the_report_says_what_was_cut(env):
    with Served(env) as served:
        sock = raw_client(env)
        assert answer(sock)["ok"]
        whole = P.TO_CLASSROOM.pack(P.SEND, 0, 0x42, 2, b"\x01\x02".ljust(8, b"\0"))
        sock.sendall(whole + whole[:7])
        served.wait_for(lambda s: any(c.frames_in for c in s.clients))
        sock.close()
        served.wait_for(lambda s: not s.clients)
        bad = raw_client(env)
        assert answer(bad)["ok"]
        bad.sendall(P.TO_CLASSROOM.pack(P.SEND, 0x80, 0x800, 9, bytes(8)))
        records = b""
        while len(records) < 2 * P.FROM_CLASSROOM.size:
            records += bad.recv(4096)
        kinds = [r[0] for r in P.FROM_CLASSROOM.iter_unpack(records[:2 * P.FROM_CLASSROOM.size])]
        assert P.REFUSED in kinds
        bad.close()
        served.wait_for(lambda s: not s.clients)
    assert "7 bytes of unfinished records were dropped when programs left in the middle of one" in served.report
    assert "refused 1 x a flag byte" in served.report
    assert "2 python-can program(s) joined, 0 still on" in served.report


def test_two_hundred_programs_join_at_once_each_gets_every_frame_and_the_bus_stays_bounded(env):
    with Served(env) as served:
        started = [start("""
            import can, sys
            buses = [can.Bus(interface='appsim', channel='test') for _ in range(100)]
            print('joined', flush=True)
            sys.stdin.readline()
            counts = []
            for bus in buses:
                got = 0
                while (message := bus.recv(5)) is not None and not message.is_error_frame:
                    got += 1
                    if got == 3:
                        break
                counts.append(got)
            print(min(counts), len({bus.node for bus in buses}), flush=True)
            for bus in buses:
                bus.shutdown()
        """, env) for _ in range(2)]
        for process in started:
            assert process.stdout.readline().strip() == "joined", process.stderr.read()
        served.wait_for(lambda s: sum(c.node is not None for c in s.clients) == 200)
        talker = program("""
            import can
            with can.Bus(interface='appsim', channel='test') as bus:
                for n in range(3):
                    bus.send(can.Message(arbitration_id=0x321, data=[n], is_extended_id=False), timeout=5)
                print(bus.node)
        """, env)
        assert talker.returncode == 0, talker.stderr
        for process in started:
            out, err = process.communicate("\n", timeout=60)
            assert out.split() == ["3", "100"], out + err
    assert "201 python-can program(s) joined" in served.report, served.report
    assert len(served.bus.ports) <= 201


def test_many_programs_coming_and_going_reuse_nodes_so_the_bus_does_not_grow(env):
    with Served(env) as served:
        result = program("""
            import can
            for _ in range(30):
                with can.Bus(interface='appsim', channel='test') as bus:
                    pass
            print('done')
        """, env)
        assert result.stdout.strip() == "done", result.stderr
        served.wait_for(lambda s: not s.clients)
        assert len(served.bus.ports) <= 3
    assert "30 python-can program(s) joined, 0 still on" in served.report


def test_the_classroom_ending_is_an_operation_error_for_its_programs(env):
    served = Served(env)
    with served:
        client = start("""
            import can
            bus = can.Bus(interface='appsim', channel='test')
            print('on', flush=True)
            try:
                while True:
                    bus.recv(1)
            except can.CanOperationError as error:
                print(error)
        """, env)
        assert client.stdout.readline().strip() == "on"
    out, err = client.communicate(timeout=20)
    assert "the classroom ended" in out, out + err
    assert not (Path(env["XDG_RUNTIME_DIR"]) / "appsim" / "test.json").exists(), "the announcement is withdrawn"


def test_a_second_classroom_under_a_name_in_use_is_refused_and_the_registry_is_private(env):
    with Served(env):
        folder = Path(env["XDG_RUNTIME_DIR"]) / "appsim"
        assert folder.stat().st_mode & 0o777 == 0o700
        assert (folder / "test.json").stat().st_mode & 0o777 == 0o600
        result = subprocess.run([sys.executable, "-m", "appsim", "classroom", "--serve", "test", "--seconds", "1"],
                                env=env, capture_output=True, text=True, timeout=60)
        assert result.returncode != 0
        assert "a classroom is already served as 'test'" in result.stderr, result.stderr
        assert "Traceback" not in result.stderr


def test_a_registry_folder_others_can_read_is_refused(env):
    folder = Path(env["XDG_RUNTIME_DIR"]) / "appsim"
    folder.mkdir()
    folder.chmod(0o755)
    result = subprocess.run([sys.executable, "-m", "appsim", "classroom", "--serve", "--seconds", "1"], env=env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode != 0 and "only you can read" in result.stderr, result.stderr


def _tmux_screen(session: str) -> str:
    return subprocess.run(["tmux", "capture-pane", "-p", "-t", session], capture_output=True, text=True).stdout


@pytest.mark.skipif(shutil.which("tmux") is None, reason="drives terminal programs in tmux (Debian package tmux)")
@pytest.mark.parametrize("tool, shows", [
    (["can.viewer", "-i", "appsim", "-c", "classroom"],
     ["0x088", "01 02 03", *(f"0x{i:03X}" for i in range(0x100, 0x160, 0x10))]),
    (["cantools", "monitor", "-i", "appsim", "-c", "classroom", "WORKSHOP_DBC"],
     ["MASTER_BROADCAST(", "ADRES: 512 counts", "STATION1(", "STATION2(", "Received: "]),
], ids=["can.viewer", "cantools monitor"])
def test_a_terminal_tool_watches_the_classroom(env, tmp_path, tool, shows):
    from appsim.workshop.frames import WORKSHOP_DBC

    classroom = subprocess.Popen([sys.executable, "-m", "appsim", "classroom", "--exercise", "2", "--serve",
                                  "--seconds", "30"], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
    session = f"appsim-{tool[0].replace('.', '-')}-{os.getpid()}"     # no dots: tmux reads them as panes
    try:
        assert "serving it to python-can" in classroom.stdout.readline() + classroom.stdout.readline()
        command = " ".join(["env", f"XDG_RUNTIME_DIR={env['XDG_RUNTIME_DIR']}", f"PYTHONPATH={KIT}",
                            sys.executable, "-m", *(str(WORKSHOP_DBC) if a == "WORKSHOP_DBC" else a for a in tool)])
        subprocess.run(["tmux", "new-session", "-d", "-s", session, "-x", "150", "-y", "40", command], check=True)
        deadline, screen = time.monotonic() + 20, ""
        while time.monotonic() < deadline and not all(text in screen for text in shows):
            time.sleep(0.3)
            screen = _tmux_screen(session)
        assert all(text in screen for text in shows), screen
        subprocess.run(["tmux", "send-keys", "-t", session, "q"], check=True)
    finally:
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
        classroom.send_signal(signal.SIGINT)
        out = classroom.communicate(timeout=30)[0]
    assert "python-can program(s) joined" in out


def test_can_logger_writes_the_classroom_and_cantools_decodes_it_with_the_workshop_dbc(env, tmp_path):
    from appsim.workshop.frames import WORKSHOP_DBC

    classroom = subprocess.Popen([sys.executable, "-m", "appsim", "classroom", "--exercise", "5", "--serve",
                                  "--seconds", "30"], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
    log = tmp_path / "class.log"
    try:
        assert "serving it to python-can" in classroom.stdout.readline() + classroom.stdout.readline()
        logger = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "appsim", "-c", "classroom", "-f",
                                   str(log)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(3)
        logger.send_signal(signal.SIGINT)
        logger.communicate(timeout=20)
    finally:
        classroom.send_signal(signal.SIGINT)
        classroom.communicate(timeout=30)
    lines = log.read_text().splitlines()
    assert any(" classroom 088#010203" in line for line in lines), lines[:5]
    decoded = subprocess.run([sys.executable, "-m", "cantools", "decode", str(WORKSHOP_DBC)],
                             input="\n".join(lines), capture_output=True, text=True, timeout=60)
    assert decoded.returncode == 0, decoded.stderr
    assert "MASTER_BROADCAST(" in decoded.stdout and "ADRES: 512" in decoded.stdout, decoded.stdout[:2000]
    assert "MASTER_ANSWER1(" in decoded.stdout, "Ex5: the master answers station 1's RTR"


def test_only_the_user_who_serves_a_classroom_can_join_it(env):
    """Another user finds no classroom (the announcement is in the server's private folder), and one that reaches
    the port anyway has no token: it is turned away."""
    if not (USER and os.geteuid() == 0):
        pytest.skip("needs root and APPSIM_TEST_USER (.ci/run makes the ordinary user)")
    account = pwd.getpwnam(USER)
    runuser = shutil.which("runuser") or "/usr/sbin/runuser"
    with Served(env, "classroom") as served:
        other = subprocess.run(
            [runuser, "-u", USER, "--", sys.executable, "-c",
             f"import socket, json; s = socket.create_connection(('127.0.0.1', {served.server.port})); "
             "s.sendall(json.dumps({'appsim': 1, 'token': 'guess'}).encode() + b'\\n'); print(s.recv(4096).decode())"],
            env={"PATH": "/usr/bin:/bin", "HOME": account.pw_dir}, capture_output=True, text=True, timeout=30)
        assert "wrong token" in other.stdout, other.stdout + other.stderr
        announcement = Path(env["XDG_RUNTIME_DIR"]) / "appsim" / "classroom.json"
        read = subprocess.run([runuser, "-u", USER, "--", "cat", str(announcement)], capture_output=True, text=True)
        assert read.returncode != 0 and "token" not in read.stdout


@pytest.mark.skipif(not (USER and USER_PYTHON and os.geteuid() == 0),
                    reason="needs root and APPSIM_TEST_USER / APPSIM_TEST_USER_PYTHON (.ci/run sets them up)")
def test_these_tests_pass_as_an_ordinary_user(tmp_path):
    account = pwd.getpwnam(USER)
    copy = Path(tempfile_folder(account))
    try:
        shutil.copytree(KIT / "tests", copy / "tests", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        shutil.copytree(KIT / "solutions", copy / "solutions")
        for path in (copy, *copy.rglob("*")):
            os.chown(path, account.pw_uid, account.pw_gid)
        env = {"PATH": f"{Path(USER_PYTHON).parent}:/usr/bin:/bin", "HOME": account.pw_dir, "LANG": "C.UTF-8"}
        result = subprocess.run(
            [shutil.which("runuser") or "/usr/sbin/runuser", "-u", USER, "--", USER_PYTHON, "-m", "pytest", "-q",
             "-p", "no:cacheprovider", "-x", "tests/test_pythoncan_interface.py", "-k",
             "not ordinary_user and not only_the_user and not two_hundred"],
            cwd=copy, env=env, capture_output=True, text=True, timeout=900)
        assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-3000:]
        assert " passed" in result.stdout
    finally:
        shutil.rmtree(copy, ignore_errors=True)


def tempfile_folder(account: pwd.struct_passwd) -> str:
    import tempfile

    return tempfile.mkdtemp(prefix="appsim-pythoncan-as-user-")
