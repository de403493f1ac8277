"""--scheduler at an address where something other than a Dask scheduler answers (issue 34): an HTTP server
(Dask's dashboard port), a listener that never speaks, a server that sends garbage. Each is refused within
the timeout, naming the address; never a hang or an unnamed 'out of memory'. Every peer is a real local
listener on 127.0.0.1."""

from __future__ import annotations

import http.server
import os
import socket
import threading
import time

import pytest

from rangekit.app.batch.sessions import SchedulerUnreachable, probe_scheduler


@pytest.fixture
def listener():
    """Start a TCP server on 127.0.0.1 whose connections ``handle(conn)``; yields a starter."""
    servers = []

    def start(handle) -> str:
        srv = socket.socket()
        srv.bind(("127.0.0.1", 0))
        srv.listen(4)
        servers.append(srv)

        def serve():
            while True:
                try:
                    conn, _ = srv.accept()
                except OSError:
                    return
                threading.Thread(target=handle, args=(conn,), daemon=True).start()

        threading.Thread(target=serve, daemon=True).start()
        return f"tcp://127.0.0.1:{srv.getsockname()[1]}"

    yield start
    for srv in servers:
        srv.close()


def _silent(conn):
    time.sleep(30)
    conn.close()


def _garbage(conn):
    conn.sendall(os.urandom(64) + b"\xff" * 8)
    time.sleep(5)
    conn.close()


def _closes(conn):
    conn.sendall(b"abc")
    conn.close()


@pytest.mark.parametrize("handle, words", [
    (_silent, "sent no Dask handshake within 1 s"),
    (_closes, "closed the connection after 3 bytes"),
])
def test_a_peer_that_is_not_a_scheduler_is_named_within_the_timeout(listener, handle, words):
    address = listener(handle)
    t0 = time.monotonic()
    with pytest.raises(SchedulerUnreachable, match=words) as info:
        probe_scheduler(address, timeout=1.0)
    assert address in str(info.value) and time.monotonic() - t0 < 5


def test_a_peer_sending_garbage_is_another_protocol(listener):
    address = listener(lambda conn: (conn.sendall(b"\xff" * 8 + os.urandom(64)), time.sleep(5), conn.close()))
    with pytest.raises(SchedulerUnreachable, match="speaks another protocol") as info:
        probe_scheduler(address, timeout=2.0)
    assert address in str(info.value)


@pytest.mark.slow
def test_an_http_server_is_refused_from_the_command_line(cli, tmp_session, tmp_path):
    """Dask's dashboard port: an HTTP server waits for a request, so no handshake ever comes."""
    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        address = f"tcp://127.0.0.1:{server.server_address[1]}"
        other = tmp_path / "other"
        import shutil

        shutil.copytree(tmp_session, other)
        t0 = time.monotonic()
        run = cli("process", tmp_session, other, "--scheduler", address)
        assert run.code == 1, run.err
        line = run.err.strip().splitlines()[-1]
        assert address in line and "no Dask handshake" in line and "Traceback" not in run.err
        assert time.monotonic() - t0 < 30
    finally:
        server.shutdown()
