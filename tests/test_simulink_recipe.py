"""The README's Simulink recipe as two sockets: a UDP Send block (its own local port, chosen by the system)
sends HELLO and the COMMANDs; a UDP Receive block (a local port of its own) receives CONFIG, the SAMPLEs and
the STOP, because the HELLO names that port as its reply port (docs/protocol.md, HELLO). The session runs to
its end and equals the in-process run; a HELLO without the reply port is answered at the sending socket."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from serving import answer, in_thread, session_of

from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.log import TRUTH_FIELDS
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop
from twin.serving.server import ServeError, Server, SessionSettings
from twin.wire import protocol as p


def _blocks() -> tuple[socket.socket, socket.socket]:
    """(UDP Send: local port automatic, remote = the server; UDP Receive: local port R, from anyone)."""
    send = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receive = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receive.bind(("127.0.0.1", 0))
    receive.settimeout(5.0)
    return send, receive


def test_separate_send_and_receive_blocks_complete_a_session() -> None:
    x0, th0 = list(HARDWARE_STARTS.values())[0]
    settings = SessionSettings(x0_m=x0, theta0_rad=th0, seed=1, duration_s=1.0, wait_client_s=10.0)
    server = Server(settings, "127.0.0.1", 0, log=lambda _: None)
    target = ("127.0.0.1", server.port)
    send, receive = _blocks()
    reply_port = receive.getsockname()[1]
    controller = registry.make("appendix-sf", Parameters())
    commands: list[float] = []
    with in_thread(server) as box, send, receive:
        send.sendto(
            p.encode(p.Hello(role=p.ROLE_CONTROL, client="simulink", reply_port=reply_port), 0), target
        )
        frame = p.decode_frame(receive.recv(200))  # the receive width of the recipe: the longest frame
        assert isinstance(frame.msg, p.Config) and frame.msg.role == p.ROLE_CONTROL
        session = frame.session
        while True:
            msg = p.decode_frame(receive.recv(200)).msg
            if isinstance(msg, p.Stop):
                break
            assert isinstance(msg, p.Sample)
            command = answer(controller, msg)
            commands.append(command)
            send.sendto(p.encode(p.Command(msg.seq, command), session), target)
        send.setblocking(False)
        try:
            stray = send.recv(4096)  # nothing went to the sending block
        except BlockingIOError:
            stray = b""
    assert stray == b""
    served = session_of(box)
    assert msg == p.Stop(p.STOP_DONE) and served.stop_reason == p.STOP_DONE
    assert served.client == "simulink" and served.counts.unauthorised_commands == 0
    ref = run_closed_loop(
        registry.make("appendix-sf", Parameters()), x0_m=x0, theta0_rad=th0, duration_s=1.0, seed=1
    )
    assert served.result.log.aout.tobytes() == np.asarray(commands).tobytes() == ref.log.aout.tobytes()
    for name in TRUTH_FIELDS:
        assert getattr(served.result.log, name).tobytes() == getattr(ref.log, name).tobytes(), name


def test_without_a_reply_port_the_answer_goes_to_the_sending_socket() -> None:
    """Protocol 1 as written before the reply port: CONFIG to the HELLO's address, not to another socket."""
    settings = SessionSettings(x0_m=0.1, duration_s=0.2, wait_client_s=10.0, timeout_s=0.5)
    server = Server(settings, "127.0.0.1", 0, log=lambda _: None)
    send, receive = _blocks()
    with pytest.raises(ServeError, match="ended before"), in_thread(server), send, receive:
        send.settimeout(5.0)
        send.sendto(p.encode(p.Hello(role=p.ROLE_CONTROL, client="old"), 0), ("127.0.0.1", server.port))
        assert isinstance(p.decode(send.recv(200)), p.Config)
        receive.settimeout(0.3)
        try:
            got = receive.recv(200)
        except TimeoutError:
            got = b""
        assert got == b""  # then the session ends: no COMMAND within 0.5 s, nothing logged
